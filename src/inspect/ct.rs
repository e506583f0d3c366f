//! The CT part of `inspect` (and of `convert`'s summary): grid, orientation, HU statistics over
//! the finite voxels, and where the non-finite voxels (NaN, ±inf) are.

use crate::io::ct::{CtInfo, CtSource, DicomCtInfo};
use crate::math::Point3;
use crate::volume::Volume;
use rayon::prelude::*;
use serde::Serialize;
use std::fmt::Write as _;

/// Non-finite voxels of a CT: how many of each kind and the box that holds them all.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct NonFiniteVoxels {
    /// NaN + (+inf) + (−inf).
    pub count: usize,
    /// NaN voxels.
    pub nan: usize,
    /// +inf voxels.
    pub pos_inf: usize,
    /// −inf voxels.
    pub neg_inf: usize,
    /// Smallest and largest voxel index (i, j, k) of any non-finite voxel, inclusive; None when
    /// there is none.
    pub index_bounds: Option<[[usize; 3]; 2]>,
    /// World bounding box (RAS mm) of those voxels' centres: [min, max].
    pub world_bounds_mm: Option<[[f64; 3]; 2]>,
}

/// The CT part of the summary.
#[derive(Clone, Debug, Serialize)]
pub struct CtSummary {
    /// File or folder the CT came from.
    pub path: String,
    /// "nifti" or "dicom".
    pub format: String,
    /// Where the affine came from.
    pub affine_source: String,
    /// Transfer syntax, slice count and description of a DICOM series.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub dicom: Option<DicomCtInfo>,
    /// Grid size in voxels.
    pub dims: [usize; 3],
    /// Voxel spacing (mm).
    pub spacing_mm: [f64; 3],
    /// Orientation code of the grid axes, e.g. "LPS".
    pub orientation: String,
    /// Minimum and maximum HU of the finite voxels (None when no voxel is finite).
    pub hu_range: Option<[f32; 2]>,
    /// 1st and 99th percentile HU of the finite voxels (sampled on large volumes).
    pub hu_p1_p99: Option<[f32; 2]>,
    /// World bounding box of the voxel centres (mm, RAS): [min, max].
    pub world_bounds_mm: [[f64; 3]; 2],
    /// NaN and infinite voxels.
    pub non_finite: NonFiniteVoxels,
}

/// Per-slice tally, merged across slices.
#[derive(Clone, Copy)]
struct Tally {
    min: f32,
    max: f32,
    nan: usize,
    pos_inf: usize,
    neg_inf: usize,
    lo: [usize; 3],
    hi: [usize; 3],
}

impl Tally {
    const EMPTY: Tally = Tally {
        min: f32::INFINITY,
        max: f32::NEG_INFINITY,
        nan: 0,
        pos_inf: 0,
        neg_inf: 0,
        lo: [usize::MAX; 3],
        hi: [0; 3],
    };

    fn merge(self, o: Tally) -> Tally {
        Tally {
            min: self.min.min(o.min),
            max: self.max.max(o.max),
            nan: self.nan + o.nan,
            pos_inf: self.pos_inf + o.pos_inf,
            neg_inf: self.neg_inf + o.neg_inf,
            lo: std::array::from_fn(|a| self.lo[a].min(o.lo[a])),
            hi: std::array::from_fn(|a| self.hi[a].max(o.hi[a])),
        }
    }
}

/// Tally one slice `k` (nx·ny values, i fastest).
fn tally_slice(k: usize, nx: usize, slice: &[f32]) -> Tally {
    let mut t = Tally::EMPTY;
    for (n, &v) in slice.iter().enumerate() {
        if v.is_finite() {
            t.min = t.min.min(v);
            t.max = t.max.max(v);
            continue;
        }
        if v.is_nan() {
            t.nan += 1;
        } else if v > 0.0 {
            t.pos_inf += 1;
        } else {
            t.neg_inf += 1;
        }
        let ijk = [n % nx, n / nx, k];
        t.lo = std::array::from_fn(|a| t.lo[a].min(ijk[a]));
        t.hi = std::array::from_fn(|a| t.hi[a].max(ijk[a]));
    }
    t
}

/// Count the non-finite voxels of `ct` and bound them; also the finite HU range.
fn scan(ct: &Volume<f32>) -> (NonFiniteVoxels, Option<[f32; 2]>) {
    let [nx, ny, _] = ct.dims;
    let t = ct
        .data
        .par_chunks(nx * ny)
        .enumerate()
        .map(|(k, s)| tally_slice(k, nx, s))
        .reduce(|| Tally::EMPTY, Tally::merge);
    let count = t.nan + t.pos_inf + t.neg_inf;
    let (index_bounds, world_bounds_mm) = if count == 0 {
        (None, None)
    } else {
        // Corners of the index box through the affine: any rotation keeps the box's extremes
        // among its 8 corners.
        let (mut lo, mut hi) = ([f64::INFINITY; 3], [f64::NEG_INFINITY; 3]);
        for c in 0..8 {
            let pick = |a: usize| {
                if c >> a & 1 == 0 {
                    t.lo[a]
                } else {
                    t.hi[a]
                }
            } as f64;
            let w = ct.index_to_world(Point3::new(pick(0), pick(1), pick(2)));
            for a in 0..3 {
                lo[a] = lo[a].min(w[a]);
                hi[a] = hi[a].max(w[a]);
            }
        }
        (Some([t.lo, t.hi]), Some([lo, hi]))
    };
    let range = (t.min <= t.max).then_some([t.min, t.max]);
    let nf = NonFiniteVoxels {
        count,
        nan: t.nan,
        pos_inf: t.pos_inf,
        neg_inf: t.neg_inf,
        index_bounds,
        world_bounds_mm,
    };
    (nf, range)
}

/// Summarise the CT `ct` read from `source` with `info`.
pub fn summarize_ct(ct: &Volume<f32>, source: &CtSource, info: &CtInfo) -> CtSummary {
    let (non_finite, hu_range) = scan(ct);
    // Percentiles from at most ~2 M finite samples: exact enough for a summary, fast on 500 M.
    let mut sorted: Vec<f32> = ct
        .data
        .iter()
        .copied()
        .step_by((ct.len() / 2_000_000).max(1))
        .filter(|v| v.is_finite())
        .collect();
    sorted.sort_unstable_by(f32::total_cmp);
    let hu_p1_p99 = (!sorted.is_empty()).then(|| {
        let pct = |q: f64| sorted[((sorted.len() - 1) as f64 * q).round() as usize];
        [pct(0.01), pct(0.99)]
    });
    let (lo, hi) = ct.world_bounds();
    CtSummary {
        path: source.path().display().to_string(),
        format: info.format.to_string(),
        affine_source: info.affine_source.clone(),
        dicom: info.dicom.clone(),
        dims: ct.dims,
        spacing_mm: ct.spacing(),
        orientation: ct.orientation(),
        hu_range,
        hu_p1_p99,
        world_bounds_mm: [[lo.x, lo.y, lo.z], [hi.x, hi.y, hi.z]],
        non_finite,
    }
}

impl NonFiniteVoxels {
    /// "1000 (NaN 1000, +inf 0, -inf 0) in voxels i 10..19, j 10..19, k 10..19" or "none".
    pub fn describe(&self) -> String {
        let Some([lo, hi]) = self.index_bounds else {
            return "none".to_string();
        };
        format!(
            "{} (NaN {}, +inf {}, -inf {}) in voxels i {}..{}, j {}..{}, k {}..{}",
            self.count,
            self.nan,
            self.pos_inf,
            self.neg_inf,
            lo[0],
            hi[0],
            lo[1],
            hi[1],
            lo[2],
            hi[2]
        )
    }
}

impl CtSummary {
    /// Warnings a person should read about this CT.
    pub fn warnings(&self) -> Vec<String> {
        let mut w = Vec::new();
        if self.non_finite.count > 0 {
            w.push(format!(
                "{}: {} of {} voxels are not finite: {}; the HU statistics leave them out",
                self.path,
                self.non_finite.count,
                self.dims.iter().product::<usize>(),
                self.non_finite.describe()
            ));
        }
        w
    }

    /// The CT lines of the text summary, the first one starting with "CT".
    pub fn to_text(&self) -> String {
        let mut s = String::new();
        let _ = writeln!(
            s,
            "CT      {} ({}, affine from {})",
            self.path, self.format, self.affine_source
        );
        if let Some(d) = &self.dicom {
            let _ = writeln!(
                s,
                "        {} slices {:.3} mm apart, transfer syntax {}{}",
                d.slices,
                d.slice_step_mm,
                d.transfer_syntax,
                if d.series_description.is_empty() {
                    String::new()
                } else {
                    format!(", series '{}'", d.series_description)
                }
            );
        }
        let (c, sp) = (&self.dims, &self.spacing_mm);
        let _ = writeln!(
            s,
            "        {} x {} x {} voxels, spacing {:.3} x {:.3} x {:.3} mm, orientation {}",
            c[0], c[1], c[2], sp[0], sp[1], sp[2], self.orientation
        );
        match (self.hu_range, self.hu_p1_p99) {
            (Some(r), Some(p)) => {
                let _ = writeln!(
                    s,
                    "        HU {:.0} .. {:.0} (1st-99th percentile {:.0} .. {:.0})",
                    r[0], r[1], p[0], p[1]
                );
            }
            _ => {
                let _ = writeln!(s, "        HU: no finite voxel");
            }
        }
        let b = &self.world_bounds_mm;
        let _ = writeln!(
            s,
            "        world (RAS mm) x {:.1} .. {:.1}, y {:.1} .. {:.1}, z {:.1} .. {:.1}",
            b[0][0], b[1][0], b[0][1], b[1][1], b[0][2], b[1][2]
        );
        let _ = writeln!(
            s,
            "        non-finite voxels: {}",
            self.non_finite.describe()
        );
        s
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Matrix4;

    #[test]
    fn non_finite_voxels_are_counted_and_bounded() {
        // 6 x 5 x 4 grid, 2 mm voxels, origin (10, 20, 30).
        let mut aff = Matrix4::identity() * 2.0;
        aff[(3, 3)] = 1.0;
        aff[(0, 3)] = 10.0;
        aff[(1, 3)] = 20.0;
        aff[(2, 3)] = 30.0;
        let mut v = Volume::from_data([6, 5, 4], aff, vec![-1000.0f32; 120]).unwrap();
        v.data[1 + 6 * 2 + 30] = f32::NAN; // (1, 2, 1)
        v.data[4 + 6 * 3 + 30 * 2] = f32::INFINITY; // (4, 3, 2)
        v.data[2 + 6 + 30 * 2] = f32::NEG_INFINITY; // (2, 1, 2)
        v.data[0] = 500.0;
        let (nf, range) = scan(&v);
        assert_eq!((nf.count, nf.nan, nf.pos_inf, nf.neg_inf), (3, 1, 1, 1));
        assert_eq!(nf.index_bounds, Some([[1, 1, 1], [4, 3, 2]]));
        assert_eq!(
            nf.world_bounds_mm,
            Some([[12.0, 22.0, 32.0], [18.0, 26.0, 34.0]])
        );
        assert_eq!(range, Some([-1000.0, 500.0]));
        let (none, _) = scan(&Volume::from_data([2, 2, 2], aff, vec![0.0f32; 8]).unwrap());
        assert_eq!(none, NonFiniteVoxels::default());
    }
}
