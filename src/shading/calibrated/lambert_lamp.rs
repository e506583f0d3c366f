//! A light that needs no poses: a Lambertian wall under a lamp at the camera centre with a
//! uniform beam, `I = g_f · c · cos(gamma) / z²` (+ the inter-reflection), the textbook light of
//! endoscopic shape from shading. Only its colour `c` and the per-frame gains are measured.
//!
//! It serves the registration's first round when the light fitted at the given poses cannot:
//! from tracker poses a few millimetres off in a narrow airway, every sample's distance and angle
//! is wrong, the fitted rho and s follow those errors, and the round converges on too few
//! frames (ATM_224 from 3 mm / 4 deg: 4 of 30). A fixed shape has no errors to follow; its
//! colour and gains are medians over the samples, which a wrong distance moves little. Its
//! shape is wrong wherever the scope's lamp is not uniform, so it is a fallback, not the first
//! choice: as the first light of every build it lost on the demo phantom, whose lamp falls to
//! half at 60 deg off axis (BENCHMARKS.md, session 26).

use super::model::CalibratedModel;
use super::samples::PooledSamples;

/// The Lambertian lamp's shape: rho per channel `c_ch · gamma` (Bernstein coefficients `[0,
/// c_ch]`), `c_ch` the median over `samples` of `I_ch z² / gamma`, and s = 1 up to
/// `cos_theta_edge`; the inter-reflection's `kappa`, when given, is kept for
/// [`super::with_video_gains`] to scale by each frame's light. The gains are left at 1: fit them
/// with `with_video_gains`. `None` without a usable sample.
pub fn lambert_lamp(
    samples: &PooledSamples,
    kappa: Option<[f64; 3]>,
    cos_theta_edge: f64,
) -> Option<CalibratedModel> {
    let colour: Vec<f64> = (0..3)
        .map(|ch| {
            let mut v: Vec<f64> = (0..samples.len())
                .filter(|&i| samples.gamma[i] > 0.0)
                .map(|i| {
                    let z = f64::from(samples.z[i]);
                    f64::from(samples.rgb[ch][i]) * z * z / f64::from(samples.gamma[i])
                })
                .filter(|c| c.is_finite() && *c > 0.0)
                .collect();
            if v.is_empty() {
                return f64::NAN;
            }
            let mid = v.len() / 2;
            *v.select_nth_unstable_by(mid, f64::total_cmp).1
        })
        .collect();
    if colour.iter().any(|c| !c.is_finite()) {
        return None;
    }
    let rho = std::array::from_fn(|ch| vec![0.0, colour[ch]]);
    let mut lamp = CalibratedModel::new(rho, vec![1.0], cos_theta_edge);
    lamp.interreflection = kappa;
    Some(lamp)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::SplitMix64;
    use crate::shading::calibrated::with_video_gains;

    /// Samples of frames seen under a Lambertian lamp of colour `colour`, gains `gains`, an
    /// albedo varying +-40 % and 2 % noise.
    fn lamp_samples(colour: [f64; 3], gains: &[f64]) -> PooledSamples {
        let mut rng = SplitMix64::new(11);
        let mut s = PooledSamples::default();
        s.frame_start.push(0);
        for (f, &g) in gains.iter().enumerate() {
            for _ in 0..1500 {
                let gamma = 0.2 + 0.8 * rng.uniform();
                let z = 3.0 + 20.0 * rng.uniform();
                let albedo = 0.6 + 0.8 * rng.uniform();
                for (rgb, c) in s.rgb.iter_mut().zip(colour) {
                    let i = g * albedo * c * gamma / (z * z);
                    rgb.push((i * (1.0 + 0.02 * rng.normal())) as f32);
                }
                s.gamma.push(gamma as f32);
                s.cos_theta.push((0.6 + 0.4 * rng.uniform()) as f32);
                s.z.push(z as f32);
                s.frame.push(f as u32);
                s.pixel.push(0);
            }
            s.frame_start.push(s.gamma.len());
            s.frame_light.push(0.2);
        }
        s
    }

    #[test]
    fn a_lambertian_video_is_predicted_by_the_lamp_with_its_gains() {
        let colour = [40.0, 22.0, 18.0];
        let gains = [0.3, 1.0, 2.5, 0.8];
        let s = lamp_samples(colour, &gains);
        let lamp = lambert_lamp(&s, None, 0.5).expect("lamp");
        // The colour's ratios are the lamp's and the mucosa's (the scale is the gains').
        let c: Vec<f64> = lamp.rho.iter().map(|r| r[1]).collect();
        assert!((c[1] / c[0] - 22.0 / 40.0).abs() < 0.01, "{c:?}");
        assert!((c[2] / c[0] - 18.0 / 40.0).abs() < 0.01, "{c:?}");
        assert_eq!(lamp.s, vec![1.0]);
        let fitted = with_video_gains(&lamp, &s, Some(1)).expect("gains");
        for (f, &g) in gains.iter().enumerate() {
            assert!((fitted.gains[f] - g).abs() < 0.02 * g, "{:?}", fitted.gains);
        }
        // Predicted against observed over the reference frame's samples: the median albedo's.
        let i = s.frame_start[1];
        let p = fitted.eval_rgb(f64::from(s.gamma[i]), 0.9, f64::from(s.z[i]), 1.0);
        let albedo = f64::from(s.rgb[0][i]) / p[0];
        assert!((0.5..1.5).contains(&albedo), "{albedo}");
    }

    #[test]
    fn no_usable_sample_gives_no_lamp() {
        let s = PooledSamples {
            frame_start: vec![0, 0],
            frame_light: vec![0.1],
            ..Default::default()
        };
        assert!(lambert_lamp(&s, Some([0.1; 3]), 0.5).is_none());
    }
}
