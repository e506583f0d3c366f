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

/// The best trachea-like air region of one axial slice.
struct Candidate {
    /// Centroid (world mm).
    centroid: Point3<f64>,
    /// Area (mm²).
    area: f64,
    /// Distance of the centroid from the body centre, in units of the body's half-width.
    offset: f64,
    /// The region's pixel nearest its centroid, as a voxel (i, j, k).
    pixel: [usize; 3],
}

/// How the axial slices sit in the grid.
struct SliceAxes {
    /// In-plane grid axes.
    u: usize,
    v: usize,
    /// The slice axis: the grid axis most aligned with world z.
    ax: usize,
    /// True when the slice index grows towards +z (superior).
    up: bool,
}

impl SliceAxes {
    fn of(ct: &Volume<f32>) -> Self {
        let ax = (0..3)
            .max_by(|&a, &b| column(ct, a).z.abs().total_cmp(&column(ct, b).z.abs()))
            .unwrap_or(2);
        let (u, v) = match ax {
            0 => (1, 2),
            1 => (0, 2),
            _ => (0, 1),
        };
        SliceAxes {
            u,
            v,
            ax,
            up: column(ct, ax).z > 0.0,
        }
    }

    /// Voxel (i, j, k) of in-plane pixel (a, b) in slice `s`.
    fn voxel(&self, a: usize, b: usize, s: usize) -> [usize; 3] {
        let mut ijk = [0usize; 3];
        ijk[self.u] = a;
        ijk[self.v] = b;
        ijk[self.ax] = s;
        ijk
    }
}

/// Grid axis `a`'s step in world mm (a column of the affine).
fn column(ct: &Volume<f32>, a: usize) -> Vector3<f64> {
    Vector3::new(ct.affine[(0, a)], ct.affine[(1, a)], ct.affine[(2, a)])
}

/// Find the trachea: in each of the upper axial slices, label the 4-connected air regions
/// that do not touch the slice border (enclosed by tissue), keep the round ones of
/// trachea-like area near the body centre, and take the first run (from the top) of such
/// candidates over `min_run_mm` of consecutive slices; the seed is the candidate pixel
/// nearest the centroid in the middle slice of the run.
pub fn find_trachea_seed(ct: &Volume<f32>, opts: &SeedOptions) -> Result<TracheaSeed> {
    // The axial axis is the grid axis most aligned with world z; "up" is +z (superior).
    let axes = SliceAxes::of(ct);
    let ns = ct.dims[axes.ax];
    let n_search = ((ns as f64 * opts.search_fraction).ceil() as usize).clamp(1, ns);
    let mut scan = SliceScan::new(ct, &axes, opts);
    let per_slice: Vec<Option<Candidate>> = (0..n_search)
        .map(|t| scan.candidate(if axes.up { ns - 1 - t } else { t }))
        .collect();
    // First run of consecutive slices whose candidates line up (centroids within 5 mm in-plane).
    let need = ((opts.min_run_mm / ct.spacing()[axes.ax]).ceil() as usize).max(1);
    let axis = column(ct, axes.ax).normalize();
    let mut run_start = 0;
    for t in 0..per_slice.len() {
        let continues = t > run_start
            && match (&per_slice[t], &per_slice[t - 1]) {
                (Some(a), Some(b)) => {
                    let d = a.centroid - b.centroid;
                    (d - axis * d.dot(&axis)).norm() < 5.0
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

/// One axial slice at a time: its air pixels, the body around them, and the air regions.
struct SliceScan<'a> {
    ct: &'a Volume<f32>,
    axes: &'a SliceAxes,
    opts: &'a SeedOptions,
    /// Slice size (pixels) along u and v.
    nu: usize,
    nv: usize,
    /// 1 where the slice is below `air_hu`.
    air: Vec<u8>,
    /// 1 where a pixel has been given to a region.
    label: Vec<u8>,
}

/// Centre (pixels along u, v) and half-width (mm) of the body in a slice.
struct Body {
    centre: Point3<f64>,
    half_width_mm: f64,
}

impl<'a> SliceScan<'a> {
    fn new(ct: &'a Volume<f32>, axes: &'a SliceAxes, opts: &'a SeedOptions) -> Self {
        let (nu, nv) = (ct.dims[axes.u], ct.dims[axes.v]);
        SliceScan {
            ct,
            axes,
            opts,
            nu,
            nv,
            air: vec![0u8; nu * nv],
            label: vec![0u8; nu * nv],
        }
    }

    /// The trachea candidate of slice `s`: of the enclosed air regions that pass the area,
    /// roundness and offset tests, the one nearest the body centre.
    fn candidate(&mut self, s: usize) -> Option<Candidate> {
        let body = self.read_slice(s)?;
        self.label.fill(0);
        let mut best: Option<Candidate> = None;
        for start in 0..self.nu * self.nv {
            if self.air[start] == 0 || self.label[start] != 0 {
                continue;
            }
            let pix = self.region_from(start);
            if let Some(cand) = self.judge_region(&pix, &body, s) {
                if best.as_ref().is_none_or(|b| cand.offset < b.offset) {
                    best = Some(cand);
                }
            }
        }
        best
    }

    /// Mark the air pixels of slice `s`; the body is the tissue: its centre is the centroid
    /// of the tissue pixels, its half-width their spread along u (at least 20 mm). `None`
    /// when the slice has no tissue.
    fn read_slice(&mut self, s: usize) -> Option<Body> {
        let (nu, nv) = (self.nu, self.nv);
        let (mut cx, mut cy, mut cn) = (0.0, 0.0, 0usize);
        let (mut umin, mut umax) = (usize::MAX, 0usize);
        for b in 0..nv {
            for a in 0..nu {
                let ijk = self.axes.voxel(a, b, s);
                let val = self.ct.get(ijk[0], ijk[1], ijk[2]);
                self.air[a + nu * b] = u8::from(val < self.opts.air_hu);
                if val > self.opts.tissue_hu {
                    cx += a as f64;
                    cy += b as f64;
                    cn += 1;
                    umin = umin.min(a);
                    umax = umax.max(a);
                }
            }
        }
        if cn == 0 {
            return None;
        }
        let sp_u = self.ct.spacing()[self.axes.u];
        Some(Body {
            centre: Point3::new(cx / cn as f64, cy / cn as f64, 0.0),
            half_width_mm: ((umax - umin) as f64 * sp_u / 2.0).max(20.0),
        })
    }

    /// The pixels of the 4-connected air region that holds `start`, labelled as they are
    /// collected.
    fn region_from(&mut self, start: usize) -> Vec<usize> {
        let (nu, nv) = (self.nu, self.nv);
        let mut pix = Vec::new();
        let mut stack = vec![start];
        self.label[start] = 1;
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
                if self.air[q] != 0 && self.label[q] == 0 {
                    self.label[q] = 1;
                    stack.push(q);
                }
            }
        }
        pix
    }

    /// The region `pix` of slice `s` as a candidate, if its area is trachea-like, it does not
    /// touch the slice border, it is round enough and near enough the body centre.
    fn judge_region(&self, pix: &[usize], body: &Body, s: usize) -> Option<Candidate> {
        let (nu, nv, opts) = (self.nu, self.nv, self.opts);
        let (u, v) = (self.axes.u, self.axes.v);
        let sp = self.ct.spacing();
        let area = pix.len() as f64 * (sp[u] * sp[v]);
        if area < opts.min_area_mm2 || area > opts.max_area_mm2 {
            return None;
        }
        if pix.iter().any(|&p| {
            let (a, b) = (p % nu, p / nu);
            a == 0 || b == 0 || a + 1 == nu || b + 1 == nv
        }) {
            return None;
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
        let offset = mm(ma - body.centre.x, mb - body.centre.y) / body.half_width_mm;
        if roundness < opts.min_roundness || offset > opts.max_offset {
            return None;
        }
        let &nearest = pix.iter().min_by(|&&p, &&q| {
            mm((p % nu) as f64 - ma, (p / nu) as f64 - mb)
                .total_cmp(&mm((q % nu) as f64 - ma, (q / nu) as f64 - mb))
        })?;
        let mut c = [0.0; 3];
        c[u] = ma;
        c[v] = mb;
        c[self.axes.ax] = s as f64;
        Some(Candidate {
            centroid: self.ct.index_to_world(Point3::new(c[0], c[1], c[2])),
            area,
            offset,
            pixel: self.axes.voxel(nearest % nu, nearest / nu, s),
        })
    }
}
