//! The shading of a new view (paper §2.4): what the renderer multiplies the albedo by.
//!
//! - paper: the Psi of the nearest (or k nearest) fitted viewpoints, evaluated with the new
//!   view's gamma and z (the light moves with the camera);
//! - calibrated: `rho(gamma) s(theta) / z²` of the one light, at the reference gain, plus its
//!   specular term and the inter-reflection of the view's own light.

use super::calibrated::CalibratedModel;
use super::frame_shading::masked_luminance_sum;
use super::paper::BlendedPsi;
use crate::image::Frame;

/// The shader of one new view.
#[derive(Clone, Debug)]
pub enum ViewShader<'a> {
    /// Psi of the nearest (or k nearest) fitted viewpoints.
    Paper(BlendedPsi<'a>),
    /// The calibrated light model.
    Calibrated {
        /// The model.
        model: &'a CalibratedModel,
        /// Its ambient term for new views (per channel, linear intensity).
        ambient: [f32; 3],
    },
}

impl ViewShader<'_> {
    /// Intensity of unit albedo seen at `gamma`, distance `z` (mm), along a ray `cos_theta` off
    /// the optical axis: (scale, offset) per channel, pixel = albedo · scale + offset.
    #[inline]
    pub fn eval_rgb(&self, gamma: f32, z: f32, cos_theta: f32) -> ([f32; 3], [f32; 3]) {
        match self {
            ViewShader::Paper(b) => (b.eval_rgb(gamma, z), [0.0; 3]),
            ViewShader::Calibrated { model, ambient } => {
                let (g, ct, z) = (f64::from(gamma), f64::from(cos_theta), f64::from(z));
                let s = model.eval_rgb(g, ct, z, 1.0);
                let sp = model.specular_rgb(g, ct, z, 1.0);
                (
                    s.map(|v| v as f32),
                    std::array::from_fn(|c| ambient[c] + sp[c] as f32),
                )
            }
        }
    }

    /// What depends on the whole shaded view, added once every pixel is shaded: the calibrated
    /// light's inter-reflection (`kappa_c` times the view's own mean luminance over its surface
    /// pixels) on every pixel that sees the surface; nothing for Psi. `gain` is the exposure the
    /// frame was rendered at.
    pub fn finish(&self, frame: &mut Frame, mask: &[bool], gain: f32) {
        let ViewShader::Calibrated { model, .. } = self else {
            return;
        };
        if model.interreflection.is_none() || gain <= 0.0 {
            return;
        }
        let (sum, hits) = masked_luminance_sum(&frame.rgb, mask);
        if hits == 0 {
            return;
        }
        let light_without = sum / hits as f64 / f64::from(gain);
        let extra = model
            .view_interreflection(light_without)
            .map(|a| (a * f64::from(gain)) as f32);
        for (px, _) in frame.rgb.chunks_exact_mut(3).zip(mask).filter(|(_, &m)| m) {
            for c in 0..3 {
                px[c] += extra[c];
            }
        }
    }
}
