//! Airway segmentation: trachea seed, adaptive region growing with explosion control,
//! morphological clean-up, and a summary (volume, branches, thresholds).

use super::branches::{count_branches, BranchCountOptions};
use super::error::VolumeError;
use super::morphology::{close, component_of, fill_holes};
use super::region_grow::{grow_adaptive, AdaptiveOptions, ThresholdStep};
use super::seed::{find_trachea_seed, SeedOptions};
use super::Volume;
use crate::math::{Point3, Vector4};
use crate::Result;
use rayon::prelude::*;
use std::borrow::Cow;

/// Options of [`segment_airway`]. The steps, in order:
/// 0. non-finite voxels (NaN, ±inf) are read as +inf, i.e. tissue (see [`non_finite_as_tissue`]);
/// 1. the seed: `seed_world` if given, else [`find_trachea_seed`] with `seed`;
/// 2. region growing from it, 6-connected, below an upper threshold raised by `growth`'s
///    schedule until the region explodes (see [`grow_adaptive`]);
/// 3. closing with a ball of `closing_radius_mm`, 3-D hole filling, and keeping the
///    6-connected component of the seed;
/// 4. the summary: volume and the branch count with `branches`.
#[derive(Clone, Debug)]
pub struct SegmentOptions {
    /// Seed position in world mm (RAS+); `None` finds the trachea automatically.
    pub seed_world: Option<Point3<f64>>,
    /// Automatic trachea seed search.
    pub seed: SeedOptions,
    /// Adaptive threshold schedule and explosion control (HU, ml).
    pub growth: AdaptiveOptions,
    /// Radius of the closing ball (mm); 0 skips the closing.
    pub closing_radius_mm: f64,
    /// Branch counting (mm).
    pub branches: BranchCountOptions,
}

impl Default for SegmentOptions {
    fn default() -> Self {
        SegmentOptions {
            seed_world: None,
            seed: SeedOptions::default(),
            growth: AdaptiveOptions::default(),
            closing_radius_mm: 1.0,
            branches: BranchCountOptions::default(),
        }
    }
}

/// The airway segmentation and its summary.
#[derive(Clone, Debug)]
pub struct Segmentation {
    /// Airway lumen, 0/1 on the CT's grid with the CT's affine.
    pub mask: Volume<u8>,
    /// Seed voxel (i, j, k).
    pub seed_voxel: [usize; 3],
    /// Seed position (world mm, RAS+).
    pub seed_world: Point3<f64>,
    /// True when the seed was found automatically.
    pub seed_automatic: bool,
    /// Thresholds tried with their region sizes; the last may be the explosion.
    pub thresholds: Vec<ThresholdStep>,
    /// The threshold kept (HU).
    pub threshold_hu: f32,
    /// True when growing stopped on an explosion (rather than at the schedule's end).
    pub exploded: bool,
    /// Lumen volume (ml).
    pub volume_ml: f64,
    /// Number of airway branches (see [`super::branches`]).
    pub branch_count: usize,
    /// Voxels of the CT that were NaN or ±inf, counted as tissue.
    pub non_finite_voxels: usize,
}

/// `ct` with every non-finite voxel (NaN, ±inf) set to +inf, and their count; borrowed
/// unchanged when there are none.
///
/// The rule: a voxel that is not a number was not measured (resampling pads the space outside
/// the scanner's field of view with NaN in common tools), so it cannot be shown to be airway;
/// as tissue it is never grown into and the lumen surface closes against it, while the rest of
/// the scan stays usable. −inf is not a plausible attenuation either and gets the same rule,
/// so no threshold can take it for air.
pub fn non_finite_as_tissue(ct: &Volume<f32>) -> (Cow<'_, Volume<f32>>, usize) {
    let n = ct.data.par_iter().filter(|v| !v.is_finite()).count();
    if n == 0 {
        return (Cow::Borrowed(ct), 0);
    }
    let data = ct
        .data
        .par_iter()
        .map(|&v| if v.is_finite() { v } else { f32::INFINITY })
        .collect();
    let clean = Volume {
        dims: ct.dims,
        affine: ct.affine,
        data,
    };
    (Cow::Owned(clean), n)
}

/// Segment the airway lumen of a chest CT (HU). See [`SegmentOptions`] for the steps.
pub fn segment_airway(ct: &Volume<f32>, opts: &SegmentOptions) -> Result<Segmentation> {
    let (ct, non_finite_voxels) = non_finite_as_tissue(ct);
    let ct = ct.as_ref();
    let (seed_voxel, seed_automatic) = match opts.seed_world {
        Some(w) => {
            let v = ct.voxel_at_world(w).ok_or_else(|| {
                let (lo, hi) = ct.world_bounds();
                VolumeError::SeedOutsideCt {
                    seed: w.coords.into(),
                    lo: lo.coords.into(),
                    hi: hi.coords.into(),
                }
            })?;
            (v, false)
        }
        None => (find_trachea_seed(ct, &opts.seed)?.voxel, true),
    };
    let g = grow_adaptive(ct, seed_voxel, &opts.growth)?;
    // Clean up inside the region's bounding box (plus the ball) only: airways fill a few
    // percent of a chest CT, so this keeps morphology fast and memory small.
    let margin = opts.closing_radius_mm.max(0.0);
    let sp = ct.spacing();
    let pad = [0, 1, 2].map(|a| (margin / sp[a]).ceil() as usize + 2);
    let (lo, hi) = bounding_box(&g.mask).ok_or(VolumeError::Empty {
        stage: "segmentation",
        what: "grown region",
    })?;
    let lo = [0, 1, 2].map(|a| lo[a].saturating_sub(pad[a]));
    let hi = [0, 1, 2].map(|a| (hi[a] + pad[a]).min(ct.dims[a] - 1));
    let mut sub = crop(&g.mask, lo, hi);
    if opts.closing_radius_mm > 0.0 {
        sub = close(&sub, opts.closing_radius_mm);
    }
    sub = fill_holes(&sub);
    let local_seed = [0, 1, 2].map(|a| seed_voxel[a] - lo[a]);
    sub = component_of(&sub, local_seed);
    let branch_count = count_branches(&sub, &opts.branches);
    let count = sub.data.iter().filter(|&&m| m != 0).count();
    let mut mask = Volume::filled(ct.dims, ct.affine, 0u8);
    paste(&mut mask, &sub, lo);
    let chosen = &g.steps[g.chosen];
    Ok(Segmentation {
        mask,
        seed_voxel,
        seed_world: ct.index_to_world(Point3::new(
            seed_voxel[0] as f64,
            seed_voxel[1] as f64,
            seed_voxel[2] as f64,
        )),
        seed_automatic,
        threshold_hu: chosen.hu,
        thresholds: g.steps.clone(),
        exploded: g.exploded,
        volume_ml: count as f64 * sp[0] * sp[1] * sp[2] / 1000.0,
        branch_count,
        non_finite_voxels,
    })
}

/// Inclusive voxel bounding box of the non-zero voxels.
pub fn bounding_box(mask: &Volume<u8>) -> Option<([usize; 3], [usize; 3])> {
    let [nx, ny, _] = mask.dims;
    let mut lo = [usize::MAX; 3];
    let mut hi = [0usize; 3];
    for (n, &m) in mask.data.iter().enumerate() {
        if m != 0 {
            let c = [n % nx, (n / nx) % ny, n / (nx * ny)];
            for a in 0..3 {
                lo[a] = lo[a].min(c[a]);
                hi[a] = hi[a].max(c[a]);
            }
        }
    }
    (lo[0] != usize::MAX).then_some((lo, hi))
}

/// The sub-volume `lo..=hi` (voxels) with its affine shifted so world positions are kept.
pub fn crop<T: Copy>(v: &Volume<T>, lo: [usize; 3], hi: [usize; 3]) -> Volume<T> {
    let dims = [0, 1, 2].map(|a| hi[a] - lo[a] + 1);
    let mut data = Vec::with_capacity(dims[0] * dims[1] * dims[2]);
    for k in lo[2]..=hi[2] {
        for j in lo[1]..=hi[1] {
            let s = v.index(lo[0], j, k);
            data.extend_from_slice(&v.data[s..s + dims[0]]);
        }
    }
    let mut affine = v.affine;
    let o = v.affine * Vector4::new(lo[0] as f64, lo[1] as f64, lo[2] as f64, 1.0);
    affine.fixed_view_mut::<4, 1>(0, 3).copy_from(&o);
    Volume { dims, affine, data }
}

/// Write `sub` into `dst` with its voxel (0, 0, 0) at `lo`.
pub fn paste<T: Copy>(dst: &mut Volume<T>, sub: &Volume<T>, lo: [usize; 3]) {
    let [sx, sy, sz] = sub.dims;
    for k in 0..sz {
        for j in 0..sy {
            let d = dst.index(lo[0], lo[1] + j, lo[2] + k);
            let s = sub.index(0, j, k);
            dst.data[d..d + sx].copy_from_slice(&sub.data[s..s + sx]);
        }
    }
}
