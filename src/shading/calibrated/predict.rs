//! Predicting whole frames with the calibrated model (new views, held-out frames for
//! cross-validation) and the scores used to compare shading models.

// `!(x > t)` on floats is deliberate: it also rejects NaN.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

use super::model::CalibratedModel;
use crate::raycast::{GBuffer, RayTable};
use rayon::prelude::*;

/// The albedo a prediction multiplies the shading by.
#[derive(Debug, Clone, Copy)]
pub enum Albedo<'a> {
    /// Uniform: the mean albedo is already in rho.
    Uniform,
    /// Per pixel, interleaved RGB, relative to the mean albedo folded into rho (e.g. the
    /// de-lit texture sampled at each pixel's surface point).
    PerPixel(&'a [f32]),
}

/// cos theta per pixel (the ray's angle off the optical axis) from a camera's ray table.
pub fn cos_theta_of(rays: &RayTable) -> Vec<f32> {
    rays.dirs.iter().map(|d| d[2]).collect()
}

/// Linear RGB (interleaved) of a view:
/// `gain * (albedo * rho(gamma) + k spec(gamma)) s(theta) / z^2 + ambient`,
/// per pixel; 0 where there is no hit (`z` not finite or <= 0). For a new view use
/// `gain = 1` (the reference gain) and `model.new_view_ambient()`.
pub fn predict_pixels(
    model: &CalibratedModel,
    gamma: &[f32],
    z: &[f32],
    cos_theta: &[f32],
    albedo: Albedo,
    gain: f64,
    ambient: [f64; 3],
) -> Vec<f32> {
    let n = gamma.len().min(z.len()).min(cos_theta.len());
    let mut out = vec![0f32; 3 * n];
    out.par_chunks_mut(3)
        .enumerate()
        .with_min_len(1024)
        .for_each(|(i, px)| {
            let zi = f64::from(z[i]);
            if !(zi.is_finite() && zi > 0.0) {
                return;
            }
            let (g, ct) = (f64::from(gamma[i]).clamp(0.0, 1.0), f64::from(cos_theta[i]));
            let v = model.eval_rgb(g, ct, zi, gain);
            let sp = model.specular_rgb(g, ct, zi, gain);
            for c in 0..3 {
                let a = match albedo {
                    Albedo::Uniform => 1.0,
                    Albedo::PerPixel(a) => f64::from(a[3 * i + c]),
                };
                px[c] = (a * v[c] + sp[c] + ambient[c]) as f32;
            }
        });
    out
}

/// [`predict_pixels`] for a ray-cast frame (pixels without a hit are 0).
pub fn predict_frame(
    model: &CalibratedModel,
    gbuffer: &GBuffer,
    cos_theta: &[f32],
    albedo: Albedo,
    gain: f64,
    ambient: [f64; 3],
) -> Vec<f32> {
    let z: Vec<f32> = (0..gbuffer.z.len())
        .map(|i| if gbuffer.hit(i) { gbuffer.z[i] } else { 0.0 })
        .collect();
    predict_pixels(model, &gbuffer.gamma, &z, cos_theta, albedo, gain, ambient)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::image::quality::{fit_gain, psnr_masked, PSNR_CAP_DB};

    fn psnr(pred: &[f32], obs: &[f32], mask: &[bool], k: f64) -> f64 {
        let scaled: Vec<f32> = pred.iter().map(|&v| (k * f64::from(v)) as f32).collect();
        psnr_masked(&scaled, obs, mask).unwrap()
    }

    #[test]
    fn prediction_gain_and_psnr() {
        let m = CalibratedModel::new(
            [vec![50.0; 4], vec![25.0; 4], vec![10.0; 4]],
            vec![1.0, 1.0],
            0.5,
        );
        let pred = predict_pixels(
            &m,
            &[0.5, 0.5],
            &[10.0, 0.0],
            &[1.0, 1.0],
            Albedo::PerPixel(&[2.0, 1.0, 1.0, 1.0, 1.0, 1.0]),
            1.0,
            [0.0, 0.0, 0.01],
        );
        assert_eq!(pred, vec![1.0, 0.25, 0.11, 0.0, 0.0, 0.0]);
        let obs: Vec<f32> = pred.iter().map(|v| 0.5 * v).collect();
        let mask = [true, false];
        let k = fit_gain(&pred, &obs, &mask);
        assert!((k - 0.5).abs() < 1e-7);
        assert_eq!(psnr(&pred, &obs, &mask, k), PSNR_CAP_DB);
        // Unscaled: errors 0.5, 0.125, 0.055 → MSE 0.08955 → 10.479 dB.
        assert!((psnr(&pred, &obs, &mask, 1.0) - 10.479).abs() < 0.005);
    }
}
