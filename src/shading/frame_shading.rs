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

    /// A distance (mm) beyond which every surface point's [`Shade::luminance`] (with the
    /// gathered inter-reflection of [`FrameShading::indirect_scale`]) is below `luminance`,
    /// at any gamma in [0, 1] and any angle off the axis: de-lighting can drop what lies
    /// farther without evaluating it. Infinity when the model gives no such bound (the
    /// paper's Psi is a polynomial in z, not a falling function of it).
    pub fn dimmer_than_beyond(&self, luminance: f64) -> f64 {
        let FrameShading::Calibrated { model, frame } = self else {
            return f64::INFINITY;
        };
        let gain = model.gains.get(*frame).copied().unwrap_or(f64::NAN);
        if !(luminance > 0.0 && gain > 0.0 && gain.is_finite()) {
            return f64::INFINITY;
        }
        let range = |values: &mut dyn Iterator<Item = f64>| {
            values.fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), x| {
                (lo.min(x), hi.max(x))
            })
        };
        // A Bernstein polynomial on [0, 1] lies within its coefficients' range.
        let (s_lo, s_hi) = range(&mut model.s.iter().copied());
        let (r_lo, r_hi) = (0..3).fold((0.0, 0.0), |(lo, hi), c| {
            let (a, b) = range(&mut model.rho[c].iter().copied());
            (lo + LUMA[c] * a, hi + LUMA[c] * b)
        });
        // Largest luminance of g s(theta) rho(gamma) at 1 mm: falls as 1 / z^2.
        let direct = [s_lo * r_lo, s_lo * r_hi, s_hi * r_lo, s_hi * r_hi]
            .into_iter()
            .fold(0.0f64, f64::max)
            * gain;
        // The gathered term interpolates its field's nodes: within their range.
        let indirect = match (&model.gathered, &model.frame_indirect) {
            (Some(g), Some(fields)) => match fields.get(*frame) {
                Some(field) => (0..3)
                    .map(|c| {
                        let (lo, hi) = range(&mut field.values.iter().map(|v| f64::from(v[c])));
                        LUMA[c] * (gain * g.k[c] * lo).max(gain * g.k[c] * hi)
                    })
                    .sum::<f64>(),
                None => 0.0,
            },
            _ => 0.0,
        };
        if !(direct.is_finite() && indirect.is_finite()) {
            return f64::INFINITY;
        }
        // A relative margin far above the rounding of the shading's evaluation.
        let room = luminance * (1.0 - 1e-6) - indirect.max(0.0) * (1.0 + 1e-6);
        if room.is_nan() || room <= 0.0 {
            return f64::INFINITY;
        }
        (direct * (1.0 + 1e-6) / room).sqrt()
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

    /// Beyond the distance, no gamma, angle or image position gives the luminance; well
    /// short of it some point does (a bound that is safe and not loose: the green rho here
    /// peaks at 0.8 between coefficients up to 1.4).
    #[test]
    fn nothing_beyond_the_dim_distance_reaches_the_luminance() {
        use crate::shading::indirect::{GatheredInterreflection, IndirectField};
        use std::sync::Arc;
        let m = CalibratedModel {
            gains: vec![1.5, 3.0],
            gathered: Some(GatheredInterreflection {
                k: [0.5, 0.4, 0.3],
                nodes_across: 2,
                rays: 8,
                visibility: false,
            }),
            frame_indirect: Some(Arc::new(vec![
                IndirectField {
                    nx: 1,
                    ny: 1,
                    values: vec![[0.0; 3]],
                },
                IndirectField {
                    nx: 2,
                    ny: 2,
                    values: vec![[1e-4, 2e-4, 0.0], [3e-4, 1e-4, 1e-4], [0.0; 3], [2e-4; 3]],
                },
            ])),
            // rho peaks inside (0, 1) for green; s falls off the axis.
            ..CalibratedModel::new(
                [
                    vec![0.2, 1.0, 0.6],
                    vec![0.1, 1.4, 0.3],
                    vec![0.05, 0.2, 0.4],
                ],
                vec![1.0, 0.8, 0.3, 0.1],
                0.4,
            )
        };
        let f = FrameShading::Calibrated {
            model: &m,
            frame: 1,
        };
        let lum = 0.02;
        let d = f.dimmer_than_beyond(lum);
        assert!(d.is_finite() && d > 1.0, "{d}");
        let brightest = |z: f64| {
            let mut best = 0.0f64;
            for i in 0..=40 {
                for j in 0..=10 {
                    for (u, v) in [(0.0, 0.0), (0.3, 0.8), (1.0, 0.0), (0.5, 0.5)] {
                        let mut sh = f.shade(i as f64 / 40.0, z, 1.0 - 0.06 * j as f64);
                        for (s, e) in sh.scale.iter_mut().zip(f.indirect_scale(u, v)) {
                            *s += e;
                        }
                        best = best.max(sh.luminance());
                    }
                }
            }
            best
        };
        assert!(brightest(d * 1.000001) < lum);
        assert!(brightest(d * 0.6) > lum, "{}", brightest(d * 0.6));
        // The paper's Psi and a frame without a gain give no bound.
        let none = FrameShading::Calibrated {
            model: &m,
            frame: 7,
        };
        assert_eq!(none.dimmer_than_beyond(lum), f64::INFINITY);
        assert_eq!(f.dimmer_than_beyond(0.0), f64::INFINITY);
    }
}
