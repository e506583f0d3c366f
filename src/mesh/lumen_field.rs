//! The scalar field whose iso-surface is the lumen: the CT where the airway wall is resolved,
//! the segmentation's boundary (pushed out by a narrow band) where it is not.
//!
//! On real CT, bronchial walls are often thinner than a voxel: partial volume averages them
//! with the air on both sides, the CT never reaches the wall's iso level there, and an
//! iso-surface of the CT alone runs on into the lung parenchyma (about −850 HU) behind the
//! wall. The segmentation does not leak there (its threshold was chosen to stop before the
//! parenchyma), so its boundary is the best estimate of the lumen where the CT has none.
//!
//! The field is the CSG intersection of two solids, `F = max(CT, iso + s·(φ − band))`, with φ
//! the signed distance (mm) to the mask's boundary (negative inside) and `s` a slope in HU/mm
//! comparable to the CT's own gradient across a wall. `F < iso` holds where the CT is below the
//! level *and* the point lies less than `band` mm outside the mask: where the wall is
//! resolved within the band the surface is the CT's sub-voxel iso-surface, unchanged; where
//! it is not, the surface is the offset `φ = band` of the mask, a smooth surface at most
//! `band` mm from the segmentation. Air below the level that is not 6-connected to the
//! segmented lumen (parenchyma behind a wall that is resolved, within the band) is set to
//! tissue, so it cannot add a second surface.
//!
//! Non-finite CT values (NaN, ±inf) count as tissue (the wall's +40 HU at the default level),
//! and values are clamped to ±4000 HU around the level, so every interpolation stays finite.

use crate::mesh::error::GeometryError;
use crate::volume::morphology::distance_transform_sq;
use crate::volume::region_grow::flood_fill;
use crate::volume::segment::{bounding_box, crop};
use crate::volume::Volume;
use crate::volume::VolumeError;
use crate::Result;
use rayon::prelude::*;

/// Where the CT is not a number, the field holds `iso + WALL_ABOVE_ISO_HU` (soft tissue,
/// +40 HU, at the default level of −500 HU).
pub const WALL_ABOVE_ISO_HU: f32 = 540.0;

/// Field values are clamped to this far (HU) on either side of the level: enough for bone
/// and contrast, and it keeps huge or infinite inputs from turning interpolations into NaN.
const CLAMP_HU: f32 = 4000.0;

/// Parameters of [`lumen_field`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LumenFieldOptions {
    /// Iso level (HU) of the lumen surface.
    pub iso_hu: f32,
    /// How far (mm) beyond the mask's boundary the CT's iso-surface may lie; where the CT has
    /// no crossing that close, the surface is this offset of the mask.
    pub band_mm: f64,
    /// Slope (HU/mm) of the band's ramp, about the CT's gradient across a resolved wall.
    pub slope_hu_per_mm: f32,
}

/// The lumen field on the mask's bounding box grown by the band and two voxels (the affine
/// keeps world positions), or an error when the mask is empty.
pub fn lumen_field(
    ct: &Volume<f32>,
    mask: &Volume<u8>,
    opts: &LumenFieldOptions,
) -> Result<Volume<f32>> {
    if mask.dims != ct.dims {
        return Err(VolumeError::GridMismatch {
            stage: "lumen mesh",
            what: "mask",
            got: mask.dims,
            expected: ct.dims,
        }
        .into());
    }
    if !(opts.band_mm >= 0.0 && opts.band_mm.is_finite() && opts.slope_hu_per_mm > 0.0) {
        return Err(GeometryError::BadOptions {
            stage: "lumen mesh",
            message: format!(
                "band {} mm must be >= 0 and the slope {} HU/mm > 0",
                opts.band_mm, opts.slope_hu_per_mm
            ),
        }
        .into());
    }
    if !opts.iso_hu.is_finite() {
        return Err(VolumeError::BadIsoLevel(opts.iso_hu).into());
    }
    let (lo, hi) = bounding_box(mask).ok_or(VolumeError::Empty {
        stage: "lumen mesh",
        what: "airway mask",
    })?;
    let sp = ct.spacing();
    let pad = [0, 1, 2].map(|a| (opts.band_mm / sp[a]).ceil() as usize + 2);
    let lo = [0, 1, 2].map(|a| lo[a].saturating_sub(pad[a]));
    let hi = [0, 1, 2].map(|a| (hi[a] + pad[a]).min(ct.dims[a] - 1));
    let ct = crop(ct, lo, hi);
    let mask = crop(mask, lo, hi);
    let phi = signed_distance(&mask);
    let iso = opts.iso_hu;
    let tissue = iso + WALL_ABOVE_ISO_HU;
    let (band, slope) = (opts.band_mm as f32, opts.slope_hu_per_mm);
    let mut field: Vec<f32> = ct
        .data
        .par_iter()
        .zip(phi.par_iter())
        .map(|(&v, &d)| {
            let v = if v.is_finite() { v } else { tissue };
            v.max(iso + slope * (d - band))
                .clamp(iso - CLAMP_HU, iso + CLAMP_HU)
        })
        .collect();
    // Keep the air that is 6-connected to the segmented lumen; other air becomes tissue.
    let seeds: Vec<u32> = (0..field.len())
        .filter(|&i| mask.data[i] != 0 && field[i] < iso)
        .map(|i| i as u32)
        .collect();
    let mut lumen = vec![0u8; field.len()];
    flood_fill(
        ct.dims,
        &mut lumen,
        &seeds,
        1,
        |i| field[i] < iso,
        None,
        usize::MAX,
    );
    field
        .par_iter_mut()
        .zip(lumen.par_iter())
        .for_each(|(f, &l)| {
            if l == 0 && *f < iso {
                *f = tissue;
            }
        });
    Ok(Volume {
        dims: ct.dims,
        affine: ct.affine,
        data: field,
    })
}

/// Signed distance (mm) from every voxel centre to the mask's boundary, negative inside: the
/// exact Euclidean distance to the nearest voxel of the other kind, less half a voxel (the
/// boundary lies half-way between the two voxel centres). The outside of the grid counts as
/// neither, so a lumen that leaves the grid stays open there.
pub fn signed_distance(mask: &Volume<u8>) -> Vec<f32> {
    let sp = mask.spacing();
    let m = &mask.data;
    let to_mask = distance_transform_sq(mask.dims, sp, |i| m[i] != 0);
    let to_outside = distance_transform_sq(mask.dims, sp, |i| m[i] == 0);
    // Half a voxel: the geometric mean spacing stands in for the axis the distance runs along.
    let half = (0.5 * (sp[0] * sp[1] * sp[2]).cbrt()) as f32;
    to_mask
        .par_iter()
        .zip(to_outside.par_iter())
        .map(|(&a, &b)| {
            if a > 0.0 {
                a.sqrt() - half
            } else {
                // Infinite when the mask fills the grid: clamp to a finite distance.
                -(b.sqrt() - half).min(1e6)
            }
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::math::Affine;

    fn grid(spacing: f64) -> Affine {
        let mut a = Affine::identity();
        for k in 0..3 {
            a[(k, k)] = spacing;
        }
        a
    }

    #[test]
    fn signed_distance_of_a_slab_is_the_distance_to_its_faces() {
        // A slab x in 4..=7 (voxels, 0.5 mm): faces at x = 3.5 and 7.5 voxels.
        let dims = [12, 3, 3];
        let mut m = Volume::filled(dims, grid(0.5), 0u8);
        for k in 0..3 {
            for j in 0..3 {
                for i in 4..=7 {
                    m.set(i, j, k, 1);
                }
            }
        }
        let phi = signed_distance(&m);
        for i in 0..12 {
            let want = 0.5 * ((i as f64 - 3.5).abs().min((i as f64 - 7.5).abs()));
            let want = if (4..=7).contains(&i) { -want } else { want };
            let got = phi[m.index(i, 1, 1)] as f64;
            assert!((got - want).abs() < 1e-6, "x {i}: {got} vs {want}");
        }
    }

    #[test]
    fn field_follows_the_ct_in_the_band_and_the_mask_beyond_it() {
        // One line of voxels (1 mm): lumen x <= 4, then a wall the CT does not resolve
        // (-800 HU, above the mask's threshold but far below the -500 level), then parenchyma.
        let dims = [20, 1, 1];
        let ct_vals: Vec<f32> = (0..20)
            .map(|i| match i {
                0..=4 => -1000.0,
                5 => -800.0,
                _ => -850.0,
            })
            .collect();
        let ct = Volume::from_data(dims, grid(1.0), ct_vals).unwrap();
        let mask = ct.map(|v| u8::from(v < -875.0));
        let opts = LumenFieldOptions {
            iso_hu: -500.0,
            band_mm: 1.0,
            slope_hu_per_mm: 500.0,
        };
        let f = lumen_field(&ct, &mask, &opts).unwrap();
        // The crop keeps x 0..=7 (mask 0..=4 plus band/spacing + 2 voxels).
        assert_eq!(f.dims, [8, 1, 1]);
        // Mask boundary at 4.5: the iso crossing must be band = 1 mm beyond it, at 5.5.
        let crossing = (0..7)
            .find_map(|i| {
                let (a, b) = (f.data[i] + 500.0, f.data[i + 1] + 500.0);
                (a < 0.0 && b >= 0.0).then(|| i as f32 + a / (a - b))
            })
            .unwrap();
        assert!((crossing - 5.5).abs() < 1e-5, "crossing {crossing}");
        // Deep in the lumen the CT is kept.
        assert_eq!(f.data[0], -1000.0);
    }

    #[test]
    fn disconnected_air_and_non_finite_values_become_tissue() {
        // Lumen x <= 3, a resolved wall at 4, air behind it at 5 (inside the band), NaN at 6.
        let dims = [12, 1, 1];
        let mut vals = vec![-1000.0f32; 12];
        vals[4] = 40.0;
        vals[6] = f32::NAN;
        vals[7] = f32::NEG_INFINITY;
        let ct = Volume::from_data(dims, grid(1.0), vals).unwrap();
        let mut mask = Volume::filled(dims, ct.affine, 0u8);
        for i in 0..=3 {
            mask.data[i] = 1;
        }
        let opts = LumenFieldOptions {
            iso_hu: -500.0,
            band_mm: 3.0,
            slope_hu_per_mm: 500.0,
        };
        let f = lumen_field(&ct, &mask, &opts).unwrap();
        assert_eq!(f.data[4], 40.0);
        assert_eq!(f.data[5], 40.0, "air behind a resolved wall");
        assert_eq!(f.data[6], 40.0, "NaN");
        assert!(f.data[7] >= 40.0, "-inf: {}", f.data[7]);
        assert!(f.data.iter().all(|v| v.is_finite()));
        let empty = Volume::filled(dims, ct.affine, 0u8);
        let e = lumen_field(&ct, &empty, &opts).unwrap_err().to_string();
        assert!(e.contains("empty"), "{e}");
    }
}
