//! Voxelise the phantom airway tree into a CT volume (HU) with its truth.
//!
//! What real chest CT has and the phantom reproduces: a body outline (ellipse cylinder) with
//! air outside, a soft-tissue chest wall, lungs at about -850 HU with a smooth texture, a
//! mediastinum of soft tissue around the trachea, an airway wall of soft tissue around a
//! lumen of air, partial volume at every interface, Gaussian noise, anisotropic voxels and a
//! flipped (LPS-like) affine.

use super::anatomy::{AirwayTree, TreeOptions};
use crate::math::{Affine, Point3};
use crate::parallel::ordered_block_sum;
use crate::rng::Pcg32;
use crate::volume::Volume;
use crate::{Error, Result};
use rayon::prelude::*;

/// Options of [`make_ct_phantom`]. HU values are Hounsfield units, lengths mm.
#[derive(Clone, Debug)]
pub struct CtPhantomOptions {
    /// The airway tree to voxelise.
    pub tree: TreeOptions,
    /// Voxel size (mm) along the grid axes i, j, k (k is the axial slice axis).
    pub spacing_mm: [f64; 3],
    /// Grid size; `None` fits the body outline plus a few mm of outside air.
    pub dims: Option<[usize; 3]>,
    /// Airway wall thickness (mm).
    pub wall_thickness_mm: f64,
    /// Thickness of the soft-tissue chest wall inside the body outline (mm).
    pub chest_wall_mm: f64,
    /// Air (lumen and outside the body), HU.
    pub hu_air: f32,
    /// Airway wall, chest wall and mediastinum, HU.
    pub hu_tissue: f32,
    /// Mean lung parenchyma, HU.
    pub hu_lung: f32,
    /// Amplitude of the smooth lung texture, HU.
    pub lung_texture_hu: f32,
    /// Standard deviation of the additive Gaussian noise, HU.
    pub noise_sigma_hu: f32,
    /// Seed of the noise and the texture (the tree has its own seed).
    pub seed: u64,
    /// Sub-samples per axis for the lumen's partial-volume fraction at boundary voxels.
    pub supersample: usize,
}

impl Default for CtPhantomOptions {
    fn default() -> Self {
        CtPhantomOptions {
            tree: TreeOptions::default(),
            spacing_mm: [0.7, 0.7, 1.0],
            dims: None,
            wall_thickness_mm: 1.8,
            chest_wall_mm: 10.0,
            hu_air: -1000.0,
            hu_tissue: 40.0,
            hu_lung: -850.0,
            lung_texture_hu: 30.0,
            noise_sigma_hu: 20.0,
            seed: 7,
            supersample: 3,
        }
    }
}

impl CtPhantomOptions {
    /// The test-size phantom at twice the default voxel size (1.4 x 1.4 x 2.0 mm), about
    /// 8x fewer voxels.
    pub fn coarse() -> Self {
        CtPhantomOptions {
            spacing_mm: [1.4, 1.4, 2.0],
            ..Default::default()
        }
    }
}

/// A phantom CT with its truth.
#[derive(Clone, Debug)]
pub struct CtPhantom {
    /// The CT in HU, flipped affine (x and y columns negative).
    pub ct: Volume<f32>,
    /// Truth lumen: 1 where at least half of the voxel is lumen.
    pub truth_mask: Volume<u8>,
    /// Truth lumen volume inside the grid (ml): the sum of partial-volume fractions.
    pub truth_volume_ml: f64,
    /// The voxelised tree (centrelines and radii are the branch truth).
    pub tree: AirwayTree,
    /// Body outline: centre (world x, y mm) and semi-axes (mm).
    pub body_centre_mm: [f64; 2],
    /// Semi-axes of the body ellipse along world x and y (mm).
    pub body_semi_axes_mm: [f64; 2],
}

/// Smooth lung texture: a few oblique sinusoids with seeded phases, amplitude ~1.
struct Texture {
    waves: Vec<([f64; 3], f64)>,
}

impl Texture {
    fn new(seed: u64) -> Self {
        let mut r = Pcg32::new(seed, 0xBEEF);
        let waves = (0..6)
            .map(|_| {
                let f = r.range(0.15, 0.6);
                let (th, ph) = (
                    r.range(0.0, std::f64::consts::PI),
                    r.range(0.0, std::f64::consts::TAU),
                );
                (
                    [
                        f * th.cos() * ph.sin(),
                        f * th.sin() * ph.sin(),
                        f * ph.cos(),
                    ],
                    r.range(0.0, std::f64::consts::TAU),
                )
            })
            .collect();
        Texture { waves }
    }

    #[inline]
    fn at(&self, p: &Point3<f64>) -> f64 {
        let s: f64 = self
            .waves
            .iter()
            .map(|(k, ph)| (k[0] * p.x + k[1] * p.y + k[2] * p.z + ph).sin())
            .sum();
        s / (self.waves.len() as f64).sqrt()
    }
}

/// Voxelise the airway tree into a CT volume with its truth mask and volume.
///
/// Steps: check the options, lay the grid out around the tree ([`lay_out_grid`]), fill every
/// axial slice in parallel ([`Voxeliser::fill_slice`]), then sum the lumen fractions into the
/// truth volume and threshold them at one half into the truth mask.
pub fn make_ct_phantom(opts: &CtPhantomOptions) -> Result<CtPhantom> {
    let sp = opts.spacing_mm;
    if !sp.iter().all(|s| s.is_finite() && *s > 0.0) || opts.supersample == 0 {
        return Err(Error::BadOptions {
            stage: "phantom CT",
            message: format!(
                "spacing {} x {} x {} mm must be positive and supersample {} at least 1",
                sp[0], sp[1], sp[2], opts.supersample
            ),
        });
    }
    let tree = AirwayTree::new(&opts.tree);
    let grid = lay_out_grid(opts, &tree)?;
    let [nx, ny, nz] = grid.dims;
    let voxeliser = Voxeliser::new(opts, &tree, &grid);
    let mut ct = vec![0f32; nx * ny * nz];
    let mut frac = vec![0f32; nx * ny * nz];
    let slice = nx * ny;
    ct.par_chunks_mut(slice)
        .zip(frac.par_chunks_mut(slice))
        .enumerate()
        .for_each(|(k, (cts, frs))| voxeliser.fill_slice(k, cts, frs));
    let voxel_ml = sp[0] * sp[1] * sp[2] / 1000.0;
    let fractions = |r: std::ops::Range<usize>| frac[r].iter().map(|&f| f64::from(f)).sum::<f64>();
    let truth_volume_ml =
        ordered_block_sum(frac.len(), slice, 0.0, fractions, |a, b| a + b) * voxel_ml;
    let truth = frac.par_iter().map(|&f| u8::from(f >= 0.5)).collect();
    Ok(CtPhantom {
        ct: Volume::from_data(grid.dims, grid.affine, ct)?,
        truth_mask: Volume::from_data(grid.dims, grid.affine, truth)?,
        truth_volume_ml,
        tree,
        body_centre_mm: grid.centre,
        body_semi_axes_mm: grid.semi,
    })
}

/// The phantom's grid and the body outline in it.
struct Grid {
    /// Voxels along i, j, k.
    dims: [usize; 3],
    /// Index to world (mm), LPS-like: i runs to the patient's left (-x), j posterior (-y).
    affine: Affine,
    /// Centre of the body ellipse (world x, y mm).
    centre: [f64; 2],
    /// Semi-axes of the body ellipse along world x and y (mm).
    semi: [f64; 2],
}

/// Fit the body outline around the tree (lungs 15 mm beyond it, then the chest wall) and the
/// grid around the body (6 mm of outside air), unless `opts.dims` fixes the grid.
fn lay_out_grid(opts: &CtPhantomOptions, tree: &AirwayTree) -> Result<Grid> {
    let sp = opts.spacing_mm;
    let (lo, hi) = tree.bounds();
    let centre = [(lo.x + hi.x) / 2.0, (lo.y + hi.y) / 2.0];
    let lung_margin = 15.0;
    let air_margin = 6.0;
    let fit_a = (hi.x - lo.x) / 2.0 + lung_margin + opts.chest_wall_mm;
    let fit_b = (hi.y - lo.y) / 2.0 + lung_margin + opts.chest_wall_mm;
    // The trachea leaves through the top slice, as in a chest CT that stops at the neck.
    let top = tree.branches[0].control[0].z - 5.0;
    let bottom = lo.z - 10.0;
    let (dims, semi) = match opts.dims {
        Some(d) => {
            let fov = [d[0] as f64 * sp[0], d[1] as f64 * sp[1]];
            (d, [(0.42 * fov[0]).max(fit_a), (0.32 * fov[1]).max(fit_b)])
        }
        None => {
            let ext = [
                2.0 * (fit_a + air_margin),
                2.0 * (fit_b + air_margin),
                top - bottom,
            ];
            let d = [0, 1, 2].map(|a| (ext[a] / sp[a]).ceil() as usize + 1);
            (d, [fit_a, fit_b])
        }
    };
    if dims.iter().any(|&d| d < 4) || dims[0] * dims[1] * dims[2] > 1 << 31 {
        return Err(Error::BadOptions {
            stage: "phantom CT",
            message: format!(
                "a {} x {} x {} grid is too small or too large",
                dims[0], dims[1], dims[2]
            ),
        });
    }
    // LPS-like sform: i runs to the patient's left (-x), j posterior (-y), k superior.
    let half = [0, 1, 2].map(|a| (dims[a] - 1) as f64 * sp[a] / 2.0);
    let zc = (top + bottom) / 2.0;
    let mut affine = Affine::identity();
    affine[(0, 0)] = -sp[0];
    affine[(1, 1)] = -sp[1];
    affine[(2, 2)] = sp[2];
    affine[(0, 3)] = centre[0] + half[0];
    affine[(1, 3)] = centre[1] + half[1];
    affine[(2, 3)] = if opts.dims.is_some() {
        zc - half[2]
    } else {
        bottom
    };
    Ok(Grid {
        dims,
        affine,
        centre,
        semi,
    })
}

/// Side of the square tiles (voxels) a slice is cut into: each tile looks up the branches
/// near it once.
const TILE: usize = 16;

/// What every slice needs to voxelise the tree.
struct Voxeliser<'a> {
    opts: &'a CtPhantomOptions,
    tree: &'a AirwayTree,
    grid: &'a Grid,
    texture: Texture,
    /// Mean voxel size (mm): the width of the outer wall's partial-volume ramp.
    mean_sp: f64,
    /// Half the voxel diagonal (mm): a surface farther than this does not cut the voxel.
    half_diag: f64,
    /// Sub-sample width (mm): the width of the lumen's partial-volume ramp.
    sub_w: f64,
    /// Height of the carina (world z, mm): the mediastinum ends 10 mm below it.
    carina_z: f64,
}

impl<'a> Voxeliser<'a> {
    fn new(opts: &'a CtPhantomOptions, tree: &'a AirwayTree, grid: &'a Grid) -> Self {
        let sp = opts.spacing_mm;
        let mean_sp = (sp[0] + sp[1] + sp[2]) / 3.0;
        Voxeliser {
            opts,
            tree,
            grid,
            texture: Texture::new(opts.seed),
            mean_sp,
            half_diag: 0.5 * (sp[0] * sp[0] + sp[1] * sp[1] + sp[2] * sp[2]).sqrt(),
            sub_w: mean_sp / opts.supersample as f64,
            carina_z: tree.carina().z,
        }
    }

    /// World position (mm) of the fractional voxel index (i, j, k); the affine is diagonal.
    #[inline]
    fn world(&self, i: f64, j: f64, k: f64) -> Point3<f64> {
        let a = &self.grid.affine;
        Point3::new(
            a[(0, 0)] * i + a[(0, 3)],
            a[(1, 1)] * j + a[(1, 3)],
            a[(2, 2)] * k + a[(2, 3)],
        )
    }

    /// Fill slice `k` of the CT (`cts`, HU with noise) and of the lumen fraction (`frs`), tile
    /// by tile; the noise of a slice has its own stream, so slices run in any order.
    fn fill_slice(&self, k: usize, cts: &mut [f32], frs: &mut [f32]) {
        let [nx, ny, _] = self.grid.dims;
        let mut rng = Pcg32::new(self.opts.seed, k as u64 + 1);
        let z = self.world(0.0, 0.0, k as f64).z;
        let tr_xy = self.trachea_axis_at(z);
        for tj in (0..ny).step_by(TILE) {
            for ti in (0..nx).step_by(TILE) {
                let (i1, j1) = ((ti + TILE).min(nx), (tj + TILE).min(ny));
                let cands = self.branches_near_tile([ti, tj], [i1, j1], k, z);
                for j in tj..j1 {
                    for i in ti..i1 {
                        let (hu, fl) = self.voxel([i, j, k], z, &tr_xy, &cands);
                        let n = i + nx * j;
                        cts[n] = hu + self.opts.noise_sigma_hu * rng.normal() as f32;
                        frs[n] = fl as f32;
                    }
                }
            }
        }
    }

    /// The trachea's centreline sample nearest in height to `z` (mm): the mediastinum's axis.
    fn trachea_axis_at(&self, z: f64) -> Point3<f64> {
        let c = &self.tree.branches[0].centreline;
        let mut best = c[0];
        for p in c {
            if (p.z - z).abs() < (best.z - z).abs() {
                best = *p;
            }
        }
        best
    }

    /// Branches whose wall can reach the tile of voxels [i0, i1) x [j0, j1) in slice `k`.
    fn branches_near_tile(&self, t0: [usize; 2], t1: [usize; 2], k: usize, z: f64) -> Vec<usize> {
        let sp = self.opts.spacing_mm;
        let a = self.world(t0[0] as f64, t0[1] as f64, k as f64);
        let b = self.world((t1[0] - 1) as f64, (t1[1] - 1) as f64, k as f64);
        let tlo = Point3::new(a.x.min(b.x), a.y.min(b.y), z - sp[2]);
        let thi = Point3::new(a.x.max(b.x), a.y.max(b.y), z + sp[2]);
        let margin = self.opts.wall_thickness_mm + 2.0 * self.half_diag;
        self.tree
            .branches_near(&tlo, &thi, margin + self.tree.junction_smoothing_mm)
    }

    /// HU (without noise) and lumen fraction of voxel (i, j, k): the background, then the
    /// airway's lumen and wall over it with their partial volumes.
    fn voxel(
        &self,
        [i, j, k]: [usize; 3],
        z: f64,
        tr_xy: &Point3<f64>,
        cands: &[usize],
    ) -> (f32, f64) {
        let opts = self.opts;
        let wall = opts.wall_thickness_mm;
        let p = self.world(i as f64, j as f64, k as f64);
        let bg = self.background_hu(&p, z, tr_xy);
        if !cands.is_empty() {
            let d = self.tree.sdf_among(&p, cands.iter().copied());
            if d < wall + self.half_diag + self.mean_sp {
                let fl = if d.abs() < self.half_diag + self.sub_w {
                    self.lumen_fraction([i, j, k], cands)
                } else if d < 0.0 {
                    1.0
                } else {
                    0.0
                };
                let fo = (0.5 - (d - wall) / self.mean_sp).clamp(0.0, 1.0).max(fl);
                let hu = (fl * opts.hu_air as f64
                    + (fo - fl) * opts.hu_tissue as f64
                    + (1.0 - fo) * bg as f64) as f32;
                return (hu, fl);
            }
        }
        (bg, 0.0)
    }

    /// Outside air, chest wall, mediastinum around the trachea above the carina, or textured
    /// lung at `p` (HU).
    fn background_hu(&self, p: &Point3<f64>, z: f64, tr_xy: &Point3<f64>) -> f32 {
        let opts = self.opts;
        let (centre, semi) = (self.grid.centre, self.grid.semi);
        let qx = (p.x - centre[0]) / semi[0];
        let qy = (p.y - centre[1]) / semi[1];
        let ia = semi[0] - opts.chest_wall_mm;
        let ib = semi[1] - opts.chest_wall_mm;
        if qx * qx + qy * qy > 1.0 {
            opts.hu_air
        } else if ((p.x - centre[0]) / ia).powi(2) + ((p.y - centre[1]) / ib).powi(2) > 1.0
            || (z > self.carina_z - 10.0
                && ((p.x - tr_xy.x).powi(2) + (p.y - tr_xy.y).powi(2)).sqrt()
                    < self.tree.branches[0].radius_start_mm + 12.0)
        {
            // Chest wall, or mediastinum around the trachea.
            opts.hu_tissue
        } else {
            opts.hu_lung + opts.lung_texture_hu * self.texture.at(p) as f32
        }
    }

    /// Fraction of voxel (i, j, k) inside the lumen: the mean over `supersample`³ sub-samples
    /// of a linear ramp one sub-sample wide across the surface.
    fn lumen_fraction(&self, [i, j, k]: [usize; 3], cands: &[usize]) -> f64 {
        let ss = self.opts.supersample;
        let o = |u: usize| (u as f64 + 0.5) / ss as f64 - 0.5;
        let mut acc = 0.0;
        for c in 0..ss {
            for bb in 0..ss {
                for aa in 0..ss {
                    let q = self.world(i as f64 + o(aa), j as f64 + o(bb), k as f64 + o(c));
                    let dq = self.tree.sdf_among(&q, cands.iter().copied());
                    acc += (0.5 - dq / self.sub_w).clamp(0.0, 1.0);
                }
            }
        }
        acc / (ss * ss * ss) as f64
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn coarse_phantom_has_the_expected_hu_and_truth() {
        let ph = make_ct_phantom(&CtPhantomOptions::coarse()).unwrap();
        let ct = &ph.ct;
        assert_eq!(ct.orientation(), "LPS");
        // Trachea: a centreline point well inside the grid is air.
        let tr = &ph.tree.branches[0];
        let p = tr.centreline[tr.centreline.len() / 2];
        let v = ct.voxel_at_world(p).unwrap();
        assert!(ct.get(v[0], v[1], v[2]) < -900.0);
        // Corner of the grid: outside air; the truth volume matches the mask's voxel count.
        assert!(ct.get(0, 0, 0) < -900.0);
        let sp = ct.spacing();
        let count = ph.truth_mask.data.iter().filter(|&&m| m == 1).count() as f64;
        let mask_ml = count * sp[0] * sp[1] * sp[2] / 1000.0;
        assert!(
            (mask_ml / ph.truth_volume_ml - 1.0).abs() < 0.05,
            "{mask_ml} vs {}",
            ph.truth_volume_ml
        );
        // Trachea volume alone is about pi r^2 L inside the grid: the total must exceed ~15 ml.
        assert!(
            ph.truth_volume_ml > 15.0 && ph.truth_volume_ml < 80.0,
            "{}",
            ph.truth_volume_ml
        );
    }
}
