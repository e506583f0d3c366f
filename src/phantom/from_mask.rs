//! A CT-like volume (HU) made from a binary airway mask (e.g. the ATM'22 trees): lumen air,
//! a soft-tissue wall, parenchyma with texture, partial volume, noise, the mask's own affine,
//! and a body outline with outside air when the grid has room for one.

use crate::io::nifti::read_nifti;
use crate::math::Vector4;
use crate::rng::Pcg32;
use crate::volume::filter::gaussian_blur;
use crate::volume::morphology::dilate;
use crate::volume::segment::{bounding_box, crop};
use crate::volume::Volume;
use crate::volume::VolumeError;
use crate::{Error, Result};
use rayon::prelude::*;
use std::path::Path;

/// Options of [`ct_from_mask`]. HU are Hounsfield units, lengths mm.
#[derive(Clone, Debug)]
pub struct FromMaskOptions {
    /// Crop to the mask's bounding box plus this margin (mm); `None` keeps the whole grid.
    pub crop_margin_mm: Option<f64>,
    /// Average blocks of `downsample`³ voxels (1 keeps the resolution). The lumen fraction of
    /// each block is its partial volume; the truth is where it reaches one half.
    pub downsample: usize,
    /// Airway wall thickness (mm), measured in world units on the anisotropic grid.
    pub wall_thickness_mm: f64,
    /// Standard deviation of the Gaussian point-spread blur (voxels).
    pub blur_sigma_voxels: f64,
    /// Standard deviation of the additive noise (HU).
    pub noise_sigma_hu: f32,
    /// Lumen and outside air (HU).
    pub hu_air: f32,
    /// Airway wall and chest wall (HU).
    pub hu_tissue: f32,
    /// Mean lung parenchyma (HU).
    pub hu_lung: f32,
    /// Amplitude of the smooth parenchyma texture (HU).
    pub lung_texture_hu: f32,
    /// Seed of the noise and texture.
    pub seed: u64,
}

impl Default for FromMaskOptions {
    fn default() -> Self {
        FromMaskOptions {
            crop_margin_mm: None,
            downsample: 1,
            wall_thickness_mm: 2.0,
            blur_sigma_voxels: 0.6,
            noise_sigma_hu: 20.0,
            hu_air: -1000.0,
            hu_tissue: 40.0,
            hu_lung: -850.0,
            lung_texture_hu: 30.0,
            seed: 11,
        }
    }
}

/// A CT-like volume and the truth it was made from.
#[derive(Clone, Debug)]
pub struct MaskPhantom {
    /// CT in HU on the (cropped, downsampled) mask grid, with the mask's affine.
    pub ct: Volume<f32>,
    /// Truth lumen on the same grid (1 where at least half of the voxel is lumen).
    pub truth_mask: Volume<u8>,
    /// True when a body outline with outside air was drawn.
    pub has_body: bool,
}

/// Read a binary airway mask (NIfTI) and make a CT-like volume from it.
pub fn ct_from_mask_file(path: &Path, opts: &FromMaskOptions) -> Result<MaskPhantom> {
    let mask = read_nifti(path)?;
    ct_from_mask(&mask, opts).map_err(|e| Error::invalid(path, e.to_string()))
}

/// Make a CT-like volume from a mask (lumen where the value exceeds 0.5).
///
/// Steps: binarise and crop; average blocks into the lumen fraction (its half-threshold is the
/// truth); dilate the truth into the wall; fit a body outline if the grid has room; mix air,
/// wall and background by the lumen fraction; blur; add noise.
pub fn ct_from_mask(mask: &Volume<f32>, opts: &FromMaskOptions) -> Result<MaskPhantom> {
    // Written negated so NaN options are rejected too.
    #[allow(clippy::neg_cmp_op_on_partial_ord)]
    let bad = opts.downsample == 0
        || !(opts.wall_thickness_mm >= 0.0)
        || !(opts.blur_sigma_voxels >= 0.0);
    if bad {
        return Err(Error::BadOptions {
            stage: "mask phantom",
            message: format!(
                "need downsample >= 1, wall and blur >= 0 (got downsample {}, wall {} mm, blur {} voxels)",
                opts.downsample, opts.wall_thickness_mm, opts.blur_sigma_voxels
            ),
        });
    }
    let bin = mask.map(|v| u8::from(v > 0.5));
    let (blo, bhi) = bounding_box(&bin).ok_or(VolumeError::Empty {
        stage: "mask phantom",
        what: "mask (no voxel above 0.5)",
    })?;
    let sp0 = bin.spacing();
    let bin = match opts.crop_margin_mm {
        Some(m) => {
            let lo = [0, 1, 2].map(|a| blo[a].saturating_sub((m / sp0[a]).ceil() as usize));
            let hi =
                [0, 1, 2].map(|a| (bhi[a] + (m / sp0[a]).ceil() as usize).min(bin.dims[a] - 1));
            crop(&bin, lo, hi)
        }
        None => bin,
    };
    let frac = block_average(&bin, opts.downsample);
    let truth = frac.map(|f| u8::from(f >= 0.5));
    let wall = dilate(&truth, opts.wall_thickness_mm);
    let body = fit_body(&frac, &truth);
    let mixed = mix_tissues(&frac, &wall, &body, opts);
    let mut ct = Volume::from_data(frac.dims, frac.affine, mixed)?;
    if opts.blur_sigma_voxels > 0.0 {
        gaussian_blur(&mut ct, [opts.blur_sigma_voxels; 3]);
    }
    let slice = frac.dims[0] * frac.dims[1];
    ct.data
        .par_chunks_mut(slice)
        .enumerate()
        .for_each(|(k, s)| {
            let mut rng = Pcg32::new(opts.seed, k as u64 + 1);
            for v in s.iter_mut() {
                *v += opts.noise_sigma_hu * rng.normal() as f32;
            }
        });
    Ok(MaskPhantom {
        ct,
        truth_mask: truth,
        has_body: body.fits,
    })
}

/// The body outline: an axis-aligned ellipse in every axial slice, around the grid centre.
struct BodyOutline {
    /// True when the outline is drawn.
    fits: bool,
    /// Semi-axes along i and j (mm).
    semi: [f64; 2],
    /// Centre (voxel indices i, j).
    centre: [f64; 2],
}

/// A body outline fits when an ellipse of 45 % x 38 % of the field of view around the grid
/// centre keeps 25 mm between the airway (`truth`'s box) and a 10 mm chest wall; only for
/// axial grids.
fn fit_body(frac: &Volume<f32>, truth: &Volume<u8>) -> BodyOutline {
    let [nx, ny, _] = frac.dims;
    let sp = frac.spacing();
    let axial = frac.affine[(2, 2)].abs() > 0.9 * sp[2];
    let semi = [0.45 * nx as f64 * sp[0], 0.38 * ny as f64 * sp[1]];
    let centre = [(nx - 1) as f64 / 2.0, (ny - 1) as f64 / 2.0];
    let (tlo, thi) = bounding_box(truth).unwrap_or(([0; 3], [0; 3]));
    let fits = axial
        && [tlo, thi, [tlo[0], thi[1], 0], [thi[0], tlo[1], 0]]
            .iter()
            .all(|c| {
                let qx = (c[0] as f64 - centre[0]) * sp[0] / (semi[0] - 35.0);
                let qy = (c[1] as f64 - centre[1]) * sp[1] / (semi[1] - 35.0);
                semi[1] > 60.0 && qx * qx + qy * qy < 1.0
            });
    BodyOutline { fits, semi, centre }
}

/// HU before blur and noise: lumen air by the lumen fraction `frac`, over the wall's tissue
/// where `wall` is set and over the background elsewhere (outside air or chest wall when the
/// body outline is drawn, textured lung inside it).
fn mix_tissues(
    frac: &Volume<f32>,
    wall: &Volume<u8>,
    body: &BodyOutline,
    opts: &FromMaskOptions,
) -> Vec<f32> {
    let [nx, ny, _] = frac.dims;
    let sp = frac.spacing();
    let (semi, centre) = (body.semi, body.centre);
    let mut r = Pcg32::new(opts.seed, 0xBEEF);
    let waves: Vec<([f64; 3], f64)> = (0..6)
        .map(|_| {
            (
                [r.range(-0.5, 0.5), r.range(-0.5, 0.5), r.range(-0.5, 0.5)],
                r.range(0.0, 6.3),
            )
        })
        .collect();
    let affine = frac.affine;
    let slice = nx * ny;
    // The outline's HU at (i, j): outside air, chest wall, or `None` inside the chest wall.
    let outline_hu = |i: usize, j: usize| {
        let qx = (i as f64 - centre[0]) * sp[0];
        let qy = (j as f64 - centre[1]) * sp[1];
        let outer = (qx / semi[0]).powi(2) + (qy / semi[1]).powi(2);
        let inner = (qx / (semi[0] - 10.0)).powi(2) + (qy / (semi[1] - 10.0)).powi(2);
        if outer > 1.0 {
            Some(opts.hu_air)
        } else if inner > 1.0 {
            Some(opts.hu_tissue)
        } else {
            None
        }
    };
    let lung_hu = |i: usize, j: usize, k: usize| {
        let w = affine * Vector4::new(i as f64, j as f64, k as f64, 1.0);
        let t: f64 = waves
            .iter()
            .map(|(q, ph)| (q[0] * w.x + q[1] * w.y + q[2] * w.z + ph).sin())
            .sum::<f64>()
            / (waves.len() as f64).sqrt();
        opts.hu_lung + opts.lung_texture_hu * t as f32
    };
    let mut ct = vec![0f32; frac.len()];
    ct.par_chunks_mut(slice).enumerate().for_each(|(k, out)| {
        for j in 0..ny {
            for i in 0..nx {
                let n = i + nx * j;
                let g = n + slice * k;
                let outline = if body.fits { outline_hu(i, j) } else { None };
                let bg = outline.unwrap_or_else(|| lung_hu(i, j, k));
                let f = frac.data[g];
                let around = if wall.data[g] != 0 {
                    opts.hu_tissue
                } else {
                    bg
                };
                out[n] = f * opts.hu_air + (1.0 - f) * around;
            }
        }
    });
    ct
}

/// Mean of each `f`³ block of a 0/1 mask (partial blocks at the far edges are dropped); the
/// affine is scaled and moved to the block centres.
fn block_average(m: &Volume<u8>, f: usize) -> Volume<f32> {
    if f == 1 {
        return m.map(|v| v as f32);
    }
    let dims = m.dims.map(|d| (d / f).max(1));
    let [nx, ny, nz] = dims;
    let mut data = vec![0f32; nx * ny * nz];
    let norm = 1.0 / (f * f * f) as f32;
    data.par_chunks_mut(nx * ny)
        .enumerate()
        .for_each(|(k, out)| {
            for kk in k * f..((k + 1) * f).min(m.dims[2]) {
                for j in 0..ny {
                    for jj in j * f..((j + 1) * f).min(m.dims[1]) {
                        let row = m.index(0, jj, kk);
                        for i in 0..nx {
                            let s: u32 = m.data[row + i * f..row + ((i + 1) * f).min(m.dims[0])]
                                .iter()
                                .map(|&v| v as u32)
                                .sum();
                            out[i + nx * j] += s as f32 * norm;
                        }
                    }
                }
            }
        });
    let mut affine = m.affine;
    let c = (f as f64 - 1.0) / 2.0;
    let o = m.affine * Vector4::new(c, c, c, 1.0);
    for a in 0..3 {
        for r in 0..3 {
            affine[(r, a)] *= f as f64;
        }
    }
    affine.fixed_view_mut::<4, 1>(0, 3).copy_from(&o);
    Volume { dims, affine, data }
}
