//! The covered texels of an atlas prepared once for de-lighting and fusion: per-texel point and
//! normal as flat arrays ("slots"), chart ranges and boxes for the texture-domain blur, and
//! bounding spheres of blocks of texels for per-frame culling.

use super::atlas::TexelGeometry;
use crate::mesh::GeometryError;
use crate::Result;

/// Texels per culling block: small enough that a block is a compact surface patch, large enough
/// that the per-block test is negligible next to the per-texel work.
pub(crate) const BLOCK: usize = 256;

/// Bounding sphere of one block of consecutive slots (world mm).
#[derive(Clone, Copy, Debug)]
pub(crate) struct BlockSphere {
    pub centre: [f32; 3],
    pub radius: f32,
}

/// Rectangle of atlas texels, `x0..x1` × `y0..y1` (end exclusive).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct TexelRect {
    /// First column.
    pub x0: u32,
    /// First row.
    pub y0: u32,
    /// One past the last column.
    pub x1: u32,
    /// One past the last row.
    pub y1: u32,
}

/// The texels that carry chart data, in the order of [`TexelGeometry`] (by chart, then row,
/// then column). Slot `s` is the s-th such texel.
#[derive(Clone, Debug)]
pub struct TexelSet {
    /// Atlas size (texels).
    pub width: u32,
    /// Atlas height (texels).
    pub height: u32,
    /// Atlas index `y * width + x` of each slot.
    pub texel: Vec<u32>,
    /// 3-D point of each slot (world mm).
    pub point: Vec<[f32; 3]>,
    /// Unit normal of each slot, facing into the lumen.
    pub normal: Vec<[f32; 3]>,
    /// Chart of each slot.
    pub chart: Vec<u32>,
    /// Slot of each atlas texel, `u32::MAX` for the gutter (atlas-sized).
    pub slot_of_texel: Vec<u32>,
    /// Slots of chart c are `chart_start[c]..chart_start[c + 1]`.
    pub chart_start: Vec<u32>,
    /// Bounding rectangle of each chart's texels.
    pub chart_rect: Vec<TexelRect>,
    pub(crate) blocks: Vec<BlockSphere>,
}

impl TexelSet {
    /// Prepare the texels of `geo` (from [`super::atlas::rasterize_texels`]).
    ///
    /// Errors when the arrays of `geo` differ in length, a texel lies outside the atlas, or the
    /// texels are not ordered by chart.
    pub fn new(geo: &TexelGeometry) -> Result<TexelSet> {
        let n = geo.texel.len();
        let bad = |message: String| {
            Err(GeometryError::Degenerate {
                stage: "texel set",
                message,
            }
            .into())
        };
        if geo.point.len() != n || geo.normal.len() != n || geo.chart.len() != n {
            return bad(format!(
                "{n} texels but {} points, {} normals and {} chart ids",
                geo.point.len(),
                geo.normal.len(),
                geo.chart.len()
            ));
        }
        let (w, h) = (geo.width, geo.height);
        let atlas = w as usize * h as usize;
        let mut slot_of_texel = vec![u32::MAX; atlas];
        for (s, &t) in geo.texel.iter().enumerate() {
            if t as usize >= atlas {
                return bad(format!("texel index {t} outside the {w}x{h} atlas"));
            }
            slot_of_texel[t as usize] = s as u32;
        }
        if geo.chart.windows(2).any(|c| c[1] < c[0]) {
            return bad("texels are not ordered by chart".into());
        }
        let charts = geo.chart.last().map_or(0, |&c| c as usize + 1);
        let mut chart_start = vec![0u32; charts + 1];
        for &c in &geo.chart {
            chart_start[c as usize + 1] += 1;
        }
        for c in 0..charts {
            chart_start[c + 1] += chart_start[c];
        }
        let mut chart_rect = vec![
            TexelRect {
                x0: u32::MAX,
                y0: u32::MAX,
                x1: 0,
                y1: 0
            };
            charts
        ];
        for (&t, &c) in geo.texel.iter().zip(&geo.chart) {
            let (x, y) = (t % w, t / w);
            let r = &mut chart_rect[c as usize];
            r.x0 = r.x0.min(x);
            r.y0 = r.y0.min(y);
            r.x1 = r.x1.max(x + 1);
            r.y1 = r.y1.max(y + 1);
        }
        for r in &mut chart_rect {
            if r.x0 == u32::MAX {
                *r = TexelRect {
                    x0: 0,
                    y0: 0,
                    x1: 0,
                    y1: 0,
                };
            }
        }
        let blocks = geo.point.chunks(BLOCK).map(bounding_sphere).collect();
        Ok(TexelSet {
            width: w,
            height: h,
            texel: geo.texel.clone(),
            point: geo.point.clone(),
            normal: geo.normal.clone(),
            chart: geo.chart.clone(),
            slot_of_texel,
            chart_start,
            chart_rect,
            blocks,
        })
    }

    /// Number of slots (texels with chart data).
    pub fn len(&self) -> usize {
        self.texel.len()
    }

    /// True when no texel carries chart data.
    pub fn is_empty(&self) -> bool {
        self.texel.is_empty()
    }

    /// Number of charts.
    pub fn chart_count(&self) -> usize {
        self.chart_rect.len()
    }

    /// Chart id per atlas texel, `u32::MAX` for the gutter (as `TexelGeometry::chart_map`).
    pub fn chart_map(&self) -> Vec<u32> {
        self.slot_of_texel
            .iter()
            .map(|&s| {
                if s == u32::MAX {
                    u32::MAX
                } else {
                    self.chart[s as usize]
                }
            })
            .collect()
    }
}

/// A bounding sphere (centre of the box, radius to the farthest point): not minimal, but
/// within a factor sqrt(3) of it, and it only decides culling.
fn bounding_sphere(p: &[[f32; 3]]) -> BlockSphere {
    let mut lo = [f32::INFINITY; 3];
    let mut hi = [f32::NEG_INFINITY; 3];
    for q in p {
        for k in 0..3 {
            lo[k] = lo[k].min(q[k]);
            hi[k] = hi[k].max(q[k]);
        }
    }
    let centre = [0, 1, 2].map(|k| 0.5 * (lo[k] + hi[k]));
    let radius = p
        .iter()
        .map(|q| {
            let d = [q[0] - centre[0], q[1] - centre[1], q[2] - centre[2]];
            (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt()
        })
        .fold(0.0f32, f32::max);
    // Rounding margin so points on the sphere are never culled.
    BlockSphere {
        centre,
        radius: radius * 1.0001 + 1e-4,
    }
}
