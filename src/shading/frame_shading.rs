//! The shading of one training frame, whichever model was fitted: what de-lighting divides by
//! and what fusion weighs with.
//!
//! - paper: the frame's own `Psi_p(gamma, z)` (Chung et al. 2004, eq. 2–5);
//! - calibrated: `g_f · rho(gamma) · s(theta) / z²` of the one light fitted to the whole
//!   video (DESIGN.md "Beyond the paper"), plus its specular term and `a_f` as an offset.

use super::calibrated::CalibratedModel;
use super::paper::PsiModel;

/// Luminance weights (Rec. 709) that turn an RGB shading into one weight.
pub const LUMA: [f64; 3] = [0.2126, 0.7152, 0.0722];

/// The sum of the luminance of the pixels of interleaved linear `rgb` whose `mask` flag is
/// set, and how many they are (a view's mean light, for the inter-reflection and the
/// auto-exposure).
pub fn masked_luminance_sum(rgb: &[f32], mask: &[bool]) -> (f64, usize) {
    rgb.chunks_exact(3)
        .zip(mask)
        .filter(|(_, &m)| m)
        .fold((0.0f64, 0usize), |(s, n), (px, _)| {
            let lum: f64 = (0..3).map(|c| LUMA[c] * f64::from(px[c])).sum();
            (s + lum, n + 1)
        })
}

/// The shading model of one training frame.
#[derive(Clone, Copy, Debug)]
pub enum FrameShading<'a> {
    /// The paper's per-viewpoint Psi.
    Paper(&'a PsiModel),
    /// The calibrated light at frame `frame`'s gain (and ambient term, if fitted).
    Calibrated {
        /// The model of the whole video.
        model: &'a CalibratedModel,
        /// The frame's index in the model's gains.
        frame: usize,
    },
}

/// A pixel's shading as `value = albedo · scale + offset`, per channel (linear intensity).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Shade {
    /// Multiplies the relative albedo.
    pub scale: [f64; 3],
    /// Added light that does not depend on the albedo (inter-reflection and the calibrated
    /// light's specular term; 0 for Psi).
    pub offset: [f64; 3],
}

impl Shade {
    /// Luminance of the scale: how well lit (and so how reliable) an observation is.
    pub fn luminance(&self) -> f64 {
        LUMA[0] * self.scale[0] + LUMA[1] * self.scale[1] + LUMA[2] * self.scale[2]
    }
}

impl FrameShading<'_> {
    /// The shading at a surface point seen at `gamma` (cos between the view ray and the normal),
    /// distance `z` (mm), with the ray at `cos_theta` off the optical axis.
    #[inline]
    pub fn shade(&self, gamma: f64, z: f64, cos_theta: f64) -> Shade {
        match self {
            FrameShading::Paper(p) => Shade {
                scale: p.eval_rgb(gamma, z),
                offset: [0.0; 3],
            },
            FrameShading::Calibrated { model, frame } => {
                let g = model.gains.get(*frame).copied().unwrap_or(f64::NAN);
                let a = model.ambient_of(*frame);
                let sp = model.specular_rgb(gamma, cos_theta, z, g);
                Shade {
                    scale: model.eval_rgb(gamma, cos_theta, z, g),
                    offset: std::array::from_fn(|c| a[c] + sp[c]),
                }
            }
        }
    }

    /// The gathered inter-reflection's part of the scale at normalised image coordinates
    /// (u, v) (see `IndirectField::at`): `g_f k_c E_c`, zeros for Psi, without the gathered term
    /// or without the frame's gathered light.
    #[inline]
    pub fn indirect_scale(&self, u: f64, v: f64) -> [f64; 3] {
        let FrameShading::Calibrated { model, frame } = self else {
            return [0.0; 3];
        };
        let (Some(g), Some(fields)) = (&model.gathered, &model.frame_indirect) else {
            return [0.0; 3];
        };
        let (Some(field), Some(gain)) = (fields.get(*frame), model.gains.get(*frame)) else {
            return [0.0; 3];
        };
        let e = field.at(u, v);
        std::array::from_fn(|c| gain * g.k[c] * f64::from(e[c]))
    }

    /// Check the model's numbers; the message says what is wrong.
    pub fn validate(&self) -> Result<(), String> {
        match self {
            FrameShading::Paper(p) => {
                let finite =
                    p.c.iter()
                        .flatten()
                        .chain(p.d.iter().flatten())
                        .all(|x| x.is_finite())
                        && p.z_min.is_finite()
                        && p.z_max.is_finite();
                if finite {
                    Ok(())
                } else {
                    Err("the shading model has non-finite coefficients".into())
                }
            }
            FrameShading::Calibrated { model, frame } => {
                model.validate()?;
                match model.gains.get(*frame) {
                    Some(g) if g.is_finite() && *g > 0.0 => Ok(()),
                    Some(g) => Err(format!("frame {frame} has gain {g}")),
                    None => Err(format!(
                        "frame {frame} is not one of the {} frames the light model was fitted to",
                        model.gains.len()
                    )),
                }
            }
        }
    }

    /// The brightest luminance the model predicts for this frame at gamma in [min_gamma, 1],
    /// on the optical axis, at depths in [z_near, z_far] (mm; the paper's Psi uses its own
    /// fitted depth range instead).
    pub fn peak_luminance(&self, min_gamma: f64, z_near: f64, z_far: f64) -> f64 {
        let (z0, z1) = match self {
            FrameShading::Paper(p) => (p.z_min, p.z_max),
            FrameShading::Calibrated { .. } => (z_near.max(1e-3), z_far.max(z_near)),
        };
        let mut best = 0.0f64;
        for i in 0..=16 {
            let gamma = min_gamma + (1.0 - min_gamma) * i as f64 / 16.0;
            for j in 0..=16 {
                let z = z0 + (z1 - z0) * j as f64 / 16.0;
                best = best.max(self.shade(gamma, z, 1.0).luminance());
            }
        }
        best
    }
}

/// Anything that gives each training frame its shading: the paper's Psi per frame, or the
/// calibrated light at each frame's gain. De-lighting and fusion stream frames through it.
pub trait FrameShaders: Sync {
    /// The shading of frame `frame` (poses order).
    fn frame_shading(&self, frame: usize) -> FrameShading<'_>;
}

impl FrameShaders for Vec<PsiModel> {
    fn frame_shading(&self, frame: usize) -> FrameShading<'_> {
        FrameShading::Paper(&self[frame])
    }
}

impl FrameShaders for CalibratedModel {
    fn frame_shading(&self, frame: usize) -> FrameShading<'_> {
        FrameShading::Calibrated { model: self, frame }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn calibrated_shade_follows_inverse_square_and_gain() {
        let m = CalibratedModel {
            gains: vec![1.0, 2.0],
            ambient: Some(vec![[0.0; 3], [0.1, 0.2, 0.3]]),
            ..CalibratedModel::new(
                [vec![0.0, 1.0], vec![0.0, 2.0], vec![0.0, 3.0]],
                vec![1.0, 0.5],
                0.5,
            )
        };
        let f = FrameShading::Calibrated {
            model: &m,
            frame: 1,
        };
        // rho linear in gamma; s = 1 on the axis, 0.75 halfway to the edge (cos 0.75).
        let a = f.shade(0.5, 10.0, 1.0);
        assert!((a.scale[1] - 2.0 * 2.0 * 0.5 / 100.0).abs() < 1e-12);
        let b = f.shade(0.5, 20.0, 0.75);
        assert!((b.scale[2] - 2.0 * 3.0 * 0.5 * 0.75 / 400.0).abs() < 1e-12);
        assert_eq!(b.offset, [0.1, 0.2, 0.3]);
        assert!(f.validate().is_ok());
        let missing = FrameShading::Calibrated {
            model: &m,
            frame: 5,
        };
        assert!(missing.validate().unwrap_err().contains("frame 5"));
    }
}
