//! Texel geometry: the charts rasterised in UV space, giving each texel a 3-D point and normal.
//!
//! A texel belongs to a chart when a bilinear lookup at some point of the chart's triangles
//! weighs it, i.e. when the square of half-size 1 texel around its centre meets a triangle.
//! Texels whose centre falls outside every triangle take the nearest triangle's plane
//! (extrapolated barycentrics), so filtering at chart borders reads plausible geometry.

use rayon::prelude::*;

use super::Atlas;
use crate::math::Vector3;
use crate::mesh::GeometryError;
use crate::mesh::TriMesh;
use crate::Result;

/// Geometry of every texel that carries chart data, as parallel arrays (one entry per texel,
/// ordered by chart, then row, then column).
#[derive(Clone, Debug, Default)]
pub struct TexelGeometry {
    /// Atlas size (texels).
    pub width: u32,
    pub height: u32,
    /// Linear texel index `y * width + x`; texel (x, y) has its centre at UV
    /// ((x + 0.5) / width, (y + 0.5) / height).
    pub texel: Vec<u32>,
    /// Triangle (index into the mesh, same in the atlas mesh) the texel samples.
    pub triangle: Vec<u32>,
    /// Barycentric coordinates of the texel centre in that triangle (corner order of the
    /// triangle); negative entries mark a centre outside it (extrapolated geometry).
    pub bary: Vec<[f32; 3]>,
    /// 3-D point (world mm) on the triangle's plane.
    pub point: Vec<[f32; 3]>,
    /// Unit normal interpolated from the mesh's vertex normals (barycentrics clamped to the
    /// triangle so extrapolation cannot flip it).
    pub normal: Vec<[f32; 3]>,
    /// Chart id of the texel.
    pub chart: Vec<u32>,
}

impl TexelGeometry {
    /// Chart id per atlas texel, `u32::MAX` for texels outside every chart (the gutter).
    pub fn chart_map(&self) -> Vec<u32> {
        let mut m = vec![u32::MAX; self.width as usize * self.height as usize];
        for (&t, &c) in self.texel.iter().zip(&self.chart) {
            m[t as usize] = c;
        }
        m
    }

    /// Number of texels with chart data.
    pub fn len(&self) -> usize {
        self.texel.len()
    }

    /// True when no texel carries chart data.
    pub fn is_empty(&self) -> bool {
        self.texel.is_empty()
    }
}

/// True when the axis-aligned square of half-size `r` around `c` meets triangle `abc`
/// (separating-axis test on the two axes and the three edge normals; touching counts).
pub(crate) fn square_hits_triangle(
    c: [f64; 2],
    r: f64,
    a: [f64; 2],
    b: [f64; 2],
    t: [f64; 2],
) -> bool {
    let pts = [a, b, t];
    for k in 0..2 {
        let lo = a[k].min(b[k]).min(t[k]);
        let hi = a[k].max(b[k]).max(t[k]);
        if hi < c[k] - r || lo > c[k] + r {
            return false;
        }
    }
    for i in 0..3 {
        let (p, q) = (pts[i], pts[(i + 1) % 3]);
        let n = [p[1] - q[1], q[0] - p[0]];
        let proj = |x: [f64; 2]| n[0] * x[0] + n[1] * x[1];
        let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
        for x in pts {
            lo = lo.min(proj(x));
            hi = hi.max(proj(x));
        }
        let pc = proj(c);
        let ext = r * (n[0].abs() + n[1].abs());
        if hi < pc - ext || lo > pc + ext {
            return false;
        }
    }
    true
}

/// Barycentric coordinates of `p` in triangle `abc` (any sign); `None` for a degenerate triangle.
pub(crate) fn barycentric(p: [f64; 2], a: [f64; 2], b: [f64; 2], c: [f64; 2]) -> Option<[f64; 3]> {
    let d = (b[0] - a[0]) * (c[1] - a[1]) - (c[0] - a[0]) * (b[1] - a[1]);
    if d == 0.0 {
        return None;
    }
    let l1 = ((b[0] - p[0]) * (c[1] - p[1]) - (c[0] - p[0]) * (b[1] - p[1])) / d;
    let l2 = ((c[0] - p[0]) * (a[1] - p[1]) - (a[0] - p[0]) * (c[1] - p[1])) / d;
    Some([l1, l2, 1.0 - l1 - l2])
}

/// True when `p` lies inside triangle `abc` or on its boundary.
pub(crate) fn point_in_triangle(p: [f64; 2], a: [f64; 2], b: [f64; 2], c: [f64; 2]) -> bool {
    barycentric(p, a, b, c).is_some_and(|l| l.iter().all(|&x| x >= 0.0))
}

/// Distance from `p` to triangle `abc` (0 inside), in texels.
fn distance_to_triangle(p: [f64; 2], a: [f64; 2], b: [f64; 2], c: [f64; 2]) -> f64 {
    if point_in_triangle(p, a, b, c) {
        return 0.0;
    }
    let seg = |s: [f64; 2], e: [f64; 2]| {
        let d = [e[0] - s[0], e[1] - s[1]];
        let l = d[0] * d[0] + d[1] * d[1];
        let t = if l > 0.0 {
            (((p[0] - s[0]) * d[0] + (p[1] - s[1]) * d[1]) / l).clamp(0.0, 1.0)
        } else {
            0.0
        };
        ((p[0] - s[0] - t * d[0]).powi(2) + (p[1] - s[1] - t * d[1]).powi(2)).sqrt()
    };
    seg(a, b).min(seg(b, c)).min(seg(c, a))
}

/// Rasterise the atlas's charts: every texel within bilinear reach of a chart gets the chart's
/// nearest triangle (the containing one when the centre is inside), its barycentrics, 3-D point
/// and interpolated normal. `mesh` is the mesh the atlas was built from (its vertex normals are
/// used, so normals are smooth across UV seams).
pub fn rasterize_texels(atlas: &Atlas, mesh: &TriMesh) -> Result<TexelGeometry> {
    check_same_mesh(atlas, mesh)?;
    let normals = mesh.vertex_normals();
    let mut by_chart: Vec<Vec<u32>> = vec![Vec::new(); atlas.chart_count];
    for (t, &c) in atlas.chart_of_triangle.iter().enumerate() {
        by_chart[c as usize].push(t as u32);
    }
    let parts: Vec<TexelGeometry> = by_chart
        .par_iter()
        .enumerate()
        .map(|(chart, tris)| rasterize_chart(atlas, mesh, &normals, chart as u32, tris))
        .collect();
    let mut out = TexelGeometry {
        width: atlas.width,
        height: atlas.height,
        ..Default::default()
    };
    let total: usize = parts.iter().map(|p| p.texel.len()).sum();
    out.texel.reserve(total);
    for p in parts {
        out.texel.extend(p.texel);
        out.triangle.extend(p.triangle);
        out.bary.extend(p.bary);
        out.point.extend(p.point);
        out.normal.extend(p.normal);
        out.chart.extend(p.chart);
    }
    Ok(out)
}

/// Fail unless `mesh` is the mesh `atlas` was built from: the same triangles, corner by
/// corner, through the atlas's map of split vertices to original ones.
fn check_same_mesh(atlas: &Atlas, mesh: &TriMesh) -> Result<()> {
    if mesh.triangles.len() != atlas.mesh.triangles.len()
        || atlas
            .original_vertex
            .iter()
            .any(|&v| v as usize >= mesh.positions.len())
        || mesh
            .triangles
            .iter()
            .zip(&atlas.mesh.triangles)
            .any(|(m, a)| (0..3).any(|k| atlas.original_vertex.get(a[k] as usize) != Some(&m[k])))
    {
        return Err(GeometryError::Degenerate {
            stage: "texel rasterisation",
            message: format!(
                "the mesh ({} triangles, {} vertices) is not the one the atlas was built from \
                 ({} triangles)",
                mesh.triangles.len(),
                mesh.positions.len(),
                atlas.mesh.triangles.len()
            ),
        }
        .into());
    }
    Ok(())
}

/// A rectangle of texels: columns x0..=x1, rows y0..=y1.
#[derive(Clone, Copy)]
struct TexelBox {
    x0: usize,
    y0: usize,
    x1: usize,
    y1: usize,
}

impl TexelBox {
    fn width(&self) -> usize {
        self.x1 + 1 - self.x0
    }

    fn height(&self) -> usize {
        self.y1 + 1 - self.y0
    }
}

/// The texels of one chart (triangles `tris`), in row-major order within the chart's box.
fn rasterize_chart(
    atlas: &Atlas,
    mesh: &TriMesh,
    normals: &[Vector3<f32>],
    chart: u32,
    tris: &[u32],
) -> TexelGeometry {
    let mut part = TexelGeometry::default();
    if tris.is_empty() {
        return part;
    }
    let (w, h) = (atlas.width as usize, atlas.height as usize);
    let uv_tex = |v: u32| {
        let p = atlas.uv[v as usize];
        [p[0] as f64 * w as f64, p[1] as f64 * h as f64]
    };
    let corners: Vec<[[f64; 2]; 3]> = tris
        .iter()
        .map(|&t| atlas.mesh.triangles[t as usize].map(uv_tex))
        .collect();
    // Chart bounding box grown by the bilinear reach.
    let (mut x0, mut y0, mut x1, mut y1) = (f64::MAX, f64::MAX, f64::MIN, f64::MIN);
    for c in corners.iter().flatten() {
        x0 = x0.min(c[0]);
        y0 = y0.min(c[1]);
        x1 = x1.max(c[0]);
        y1 = y1.max(c[1]);
    }
    let bx = TexelBox {
        x0: ((x0 - 1.5).floor().max(0.0)) as usize,
        y0: ((y0 - 1.5).floor().max(0.0)) as usize,
        x1: ((x1 + 0.5).ceil().max(0.0) as usize).min(w - 1),
        y1: ((y1 + 0.5).ceil().max(0.0) as usize).min(h - 1),
    };
    let best = nearest_triangles(&corners, bx);
    let bw = bx.width();
    for y in 0..bx.height() {
        for x in 0..bw {
            let (_, slot) = best[y * bw + x];
            if slot == u32::MAX {
                continue;
            }
            let t = tris[slot as usize];
            let [a, b, c] = corners[slot as usize];
            let (tx, ty) = (x + bx.x0, y + bx.y0);
            let ctr = [tx as f64 + 0.5, ty as f64 + 0.5];
            let Some(l) = barycentric(ctr, a, b, c) else {
                continue; // a degenerate UV triangle has no plane to extrapolate
            };
            let (point, n) = texel_point_normal(mesh, normals, t, l);
            part.texel.push((ty * w + tx) as u32);
            part.triangle.push(t);
            part.bary.push(l.map(|x| x as f32));
            part.point
                .push([point.x as f32, point.y as f32, point.z as f32]);
            part.normal.push([n.x as f32, n.y as f32, n.z as f32]);
            part.chart.push(chart);
        }
    }
    part
}

/// Per texel of `bx` (row-major), the distance (texels) to the nearest triangle whose bilinear
/// reach covers it, and that triangle's slot in `corners` (`u32::MAX`: none).
fn nearest_triangles(corners: &[[[f64; 2]; 3]], bx: TexelBox) -> Vec<(f64, u32)> {
    let bw = bx.width();
    let mut best = vec![(f64::INFINITY, u32::MAX); bw * bx.height()];
    for (slot, [a, b, c]) in corners.iter().enumerate() {
        let tx0 = ((a[0].min(b[0]).min(c[0]) - 1.5).floor().max(bx.x0 as f64)) as usize;
        let ty0 = ((a[1].min(b[1]).min(c[1]) - 1.5).floor().max(bx.y0 as f64)) as usize;
        let tx1 = ((a[0].max(b[0]).max(c[0]) + 0.5).ceil() as usize).min(bx.x1);
        let ty1 = ((a[1].max(b[1]).max(c[1]) + 0.5).ceil() as usize).min(bx.y1);
        for y in ty0..=ty1 {
            for x in tx0..=tx1 {
                let ctr = [x as f64 + 0.5, y as f64 + 0.5];
                if !square_hits_triangle(ctr, 1.0, *a, *b, *c) {
                    continue;
                }
                let d = distance_to_triangle(ctr, *a, *b, *c);
                let cell = &mut best[(y - bx.y0) * bw + (x - bx.x0)];
                if d < cell.0 {
                    *cell = (d, slot as u32);
                }
            }
        }
    }
    best
}

/// The point (world mm) at barycentrics `l` on the plane of mesh triangle `t`, and the unit
/// normal interpolated with the barycentrics clamped to the triangle (the face normal where
/// the vertex normals cancel).
fn texel_point_normal(
    mesh: &TriMesh,
    normals: &[Vector3<f32>],
    t: u32,
    l: [f64; 3],
) -> (Vector3<f64>, Vector3<f64>) {
    let tri = mesh.triangles[t as usize];
    let p = tri.map(|v| mesh.positions[v as usize].coords.cast::<f64>());
    let point = p[0] * l[0] + p[1] * l[1] + p[2] * l[2];
    let lc = l.map(|x| x.max(0.0));
    let s = lc[0] + lc[1] + lc[2];
    let mut n = (normals[tri[0] as usize].cast::<f64>() * lc[0]
        + normals[tri[1] as usize].cast::<f64>() * lc[1]
        + normals[tri[2] as usize].cast::<f64>() * lc[2])
        / s;
    if n.norm() < 1e-9 {
        n = (p[1] - p[0]).cross(&(p[2] - p[0]));
    }
    (point, n.try_normalize(0.0).unwrap_or_default())
}
