//! Automatic trachea seed: a round air region, enclosed by tissue, near the body's centre
//! line, found in consecutive upper axial slices.

use super::error::VolumeError;
use super::Volume;
use crate::math::{Point3, Vector3};
use crate::Result;

/// How the trachea is looked for. HU are Hounsfield units, lengths mm.
#[derive(Clone, Debug)]
pub struct SeedOptions {
    /// Air candidates are pixels below this (HU): the lumen is ~-1000, parenchyma ~-850.
    pub air_hu: f32,
    /// Tissue (for the body centre) is above this (HU).
    pub tissue_hu: f32,
    /// Fraction of the slices, from the top, that is searched.
    pub search_fraction: f64,
    /// Accepted cross-section area of the trachea (mm²).
    pub min_area_mm2: f64,
    /// Largest accepted cross-section area (mm²).
    pub max_area_mm2: f64,
    /// Smallest area / (pi r_max²), r_max the farthest pixel from the centroid (1 for a disc).
    pub min_roundness: f64,
    /// Largest distance of the centroid from the body's centre, in units of the body's
    /// half-width.
    pub max_offset: f64,
    /// The candidate must continue through this length of consecutive slices (mm).
    pub min_run_mm: f64,
}

impl Default for SeedOptions {
    fn default() -> Self {
        SeedOptions {
            air_hu: -900.0,
            tissue_hu: -500.0,
            search_fraction: 0.4,
            min_area_mm2: 25.0,
            max_area_mm2: 900.0,
            min_roundness: 0.45,
            max_offset: 0.35,
            min_run_mm: 8.0,
        }
    }
}

/// Where the seed was found.
#[derive(Clone, Debug, PartialEq)]
pub struct TracheaSeed {
    /// Seed voxel (i, j, k).
    pub voxel: [usize; 3],
    /// Seed position (world mm, RAS+).
    pub world: Point3<f64>,
    /// Cross-section area of the trachea in the seed's slice (mm²).
    pub area_mm2: f64,
}

struct Candidate {
    centroid: Point3<f64>,
    area: f64,
    offset: f64,
    pixel: [usize; 3],
}

/// Find the trachea: in each of the upper axial slices, label the 4-connected air regions
/// that do not touch the slice border (enclosed by tissue), keep the round ones of
/// trachea-like area near the body centre, and take the first run (from the top) of such
/// candidates over `min_run_mm` of consecutive slices; the seed is the candidate pixel
/// nearest the centroid in the middle slice of the run.
pub fn find_trachea_seed(ct: &Volume<f32>, opts: &SeedOptions) -> Result<TracheaSeed> {
    // The axial axis is the grid axis most aligned with world z; "up" is +z (superior).
    let col = |a: usize| Vector3::new(ct.affine[(0, a)], ct.affine[(1, a)], ct.affine[(2, a)]);
    let ax = (0..3)
        .max_by(|&a, &b| col(a).z.abs().total_cmp(&col(b).z.abs()))
        .unwrap_or(2);
    let (u, v) = match ax {
        0 => (1, 2),
        1 => (0, 2),
        _ => (0, 1),
    };
    let (nu, nv, ns) = (ct.dims[u], ct.dims[v], ct.dims[ax]);
    let sp = ct.spacing();
    let pixel_mm2 = sp[u] * sp[v];
    let up = col(ax).z > 0.0;
    let n_search = ((ns as f64 * opts.search_fraction).ceil() as usize).clamp(1, ns);
    let voxel = |a: usize, b: usize, s: usize| {
        let mut ijk = [0usize; 3];
        ijk[u] = a;
        ijk[v] = b;
        ijk[ax] = s;
        ijk
    };
    let mut per_slice: Vec<Option<Candidate>> = Vec::new();
    let mut air = vec![0u8; nu * nv];
    let mut label = vec![0u8; nu * nv];
    for t in 0..n_search {
        let s = if up { ns - 1 - t } else { t };
        // Body centre: centroid of tissue pixels; half-width: their spread along u.
        let (mut cx, mut cy, mut cn) = (0.0, 0.0, 0usize);
        let (mut umin, mut umax) = (usize::MAX, 0usize);
        for b in 0..nv {
            for a in 0..nu {
                let ijk = voxel(a, b, s);
                let val = ct.get(ijk[0], ijk[1], ijk[2]);
                air[a + nu * b] = u8::from(val < opts.air_hu);
                if val > opts.tissue_hu {
                    cx += a as f64;
                    cy += b as f64;
                    cn += 1;
                    umin = umin.min(a);
                    umax = umax.max(a);
                }
            }
        }
        if cn == 0 {
            per_slice.push(None);
            continue;
        }
        let centre = Point3::new(cx / cn as f64, cy / cn as f64, 0.0);
        let half_width_mm = ((umax - umin) as f64 * sp[u] / 2.0).max(20.0);
        label.fill(0);
        let mut best: Option<Candidate> = None;
        for start in 0..nu * nv {
            if air[start] == 0 || label[start] != 0 {
                continue;
            }
            // Collect this 4-connected component's pixels.
            let mut pix = Vec::new();
            let mut stack = vec![start];
            label[start] = 1;
            while let Some(p) = stack.pop() {
                pix.push(p);
                let (a, b) = (p % nu, p / nu);
                let ns4 = [
                    (a > 0).then(|| p - 1),
                    (a + 1 < nu).then(|| p + 1),
                    (b > 0).then(|| p - nu),
                    (b + 1 < nv).then(|| p + nu),
                ];
                for q in ns4.into_iter().flatten() {
                    if air[q] != 0 && label[q] == 0 {
                        label[q] = 1;
                        stack.push(q);
                    }
                }
            }
            let area = pix.len() as f64 * pixel_mm2;
            if area < opts.min_area_mm2 || area > opts.max_area_mm2 {
                continue;
            }
            if pix.iter().any(|&p| {
                let (a, b) = (p % nu, p / nu);
                a == 0 || b == 0 || a + 1 == nu || b + 1 == nv
            }) {
                continue;
            }
            let (ma, mb) = pix.iter().fold((0.0, 0.0), |(x, y), &p| {
                (x + (p % nu) as f64, y + (p / nu) as f64)
            });
            let (ma, mb) = (ma / pix.len() as f64, mb / pix.len() as f64);
            let mm = |da: f64, db: f64| ((da * sp[u]).powi(2) + (db * sp[v]).powi(2)).sqrt();
            let rmax = pix
                .iter()
                .map(|&p| mm((p % nu) as f64 - ma, (p / nu) as f64 - mb))
                .fold(0.0, f64::max)
                + 0.5 * sp[u].min(sp[v]);
            let roundness = area / (std::f64::consts::PI * rmax * rmax);
            let offset = mm(ma - centre.x, mb - centre.y) / half_width_mm;
            if roundness < opts.min_roundness || offset > opts.max_offset {
                continue;
            }
            let &nearest = pix
                .iter()
                .min_by(|&&p, &&q| {
                    mm((p % nu) as f64 - ma, (p / nu) as f64 - mb)
                        .total_cmp(&mm((q % nu) as f64 - ma, (q / nu) as f64 - mb))
                })
                .unwrap();
            let pixel = voxel(nearest % nu, nearest / nu, s);
            let mut c = [0.0; 3];
            c[u] = ma;
            c[v] = mb;
            c[ax] = s as f64;
            let cand = Candidate {
                centroid: ct.index_to_world(Point3::new(c[0], c[1], c[2])),
                area,
                offset,
                pixel,
            };
            if best.as_ref().is_none_or(|b| cand.offset < b.offset) {
                best = Some(cand);
            }
        }
        per_slice.push(best);
    }
    // First run of consecutive slices whose candidates line up (centroids within 5 mm in-plane).
    let need = ((opts.min_run_mm / sp[ax]).ceil() as usize).max(1);
    let mut run_start = 0;
    for t in 0..per_slice.len() {
        let continues = t > run_start
            && match (&per_slice[t], &per_slice[t - 1]) {
                (Some(a), Some(b)) => {
                    let d = a.centroid - b.centroid;
                    (d - col(ax).normalize() * d.dot(&col(ax).normalize())).norm() < 5.0
                }
                _ => false,
            };
        if !continues {
            run_start = t;
        }
        if per_slice[t].is_some() && t + 1 - run_start >= need {
            let mid = &per_slice[(run_start + t) / 2];
            if let Some(c) = mid {
                return Ok(TracheaSeed {
                    voxel: c.pixel,
                    world: ct.index_to_world(Point3::new(
                        c.pixel[0] as f64,
                        c.pixel[1] as f64,
                        c.pixel[2] as f64,
                    )),
                    area_mm2: c.area,
                });
            }
        }
    }
    Err(VolumeError::NoTracheaSeed {
        min_run_mm: opts.min_run_mm,
        search_fraction: opts.search_fraction,
    }
    .into())
}
