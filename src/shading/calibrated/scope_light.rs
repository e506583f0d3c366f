//! A bronchoscope's light carried from a model built with it to another video of the same
//! scope: its shape (rho, s, the specular lobe, the inter-reflection's kappa) is the scope's
//! and its light guides', the same from patient to patient; only the per-frame gains (the
//! auto-exposure, and the mean albedo of this patient's mucosa) belong to the video.
//!
//! It serves registration: a light fitted at tracker poses a few millimetres off follows their
//! errors (every sample's distance and angle is wrong), and frames registered against it do not
//! converge (BENCHMARKS.md, session 25). The gains alone are robust to those errors: each is
//! one number per frame, the median over its samples of observed over predicted luminance.

use std::path::PathBuf;

use super::model::CalibratedModel;
use super::samples::PooledSamples;
use crate::shading::frame_shading::LUMA;

/// A calibrated light read from another model (`build --scope-light`).
#[derive(Clone, Debug)]
pub struct ScopeLight {
    /// Where it was read from (the model's shading.json).
    pub source: PathBuf,
    /// The light as that model fitted it (its own video's gains).
    pub light: CalibratedModel,
}

/// Fewest samples a frame needs for its own gain; frames with fewer take the video's median.
const MIN_FRAME_SAMPLES: usize = 20;

/// `scope`'s light with gains fitted to `samples` (this video's frames at their current
/// poses), its inter-reflection `kappa_c L_f` from the frames' own light and without the
/// terms that belonged to the scope's video alone (free ambient, gathered inter-reflection,
/// auto-exposure). The reference frame (gain 1) is `reference`, or else the one with the
/// median gain; rho and the specular lobe carry the scale. `None` when no frame has enough
/// samples.
pub fn with_video_gains(
    scope: &CalibratedModel,
    samples: &PooledSamples,
    reference: Option<usize>,
) -> Option<CalibratedModel> {
    let frames = samples.frames();
    let kappa_lum: Option<f64> = scope
        .interreflection
        .map(|k| (0..3).map(|c| LUMA[c] * k[c]).sum());
    let mut light = CalibratedModel {
        gains: vec![1.0; frames],
        reference_frame: 0,
        ambient: None,
        frame_light: None,
        gathered: None,
        frame_indirect: None,
        auto_exposure: None,
        ..scope.clone()
    };
    let lum = |rgb: [f64; 3]| -> f64 { (0..3).map(|c| LUMA[c] * rgb[c]).sum() };
    let fitted: Vec<Option<f64>> = (0..frames)
        .map(|f| {
            let range = samples.frame_start[f]..samples.frame_start[f + 1];
            let inter = kappa_lum.map_or(0.0, |k| k * samples.frame_light[f]);
            let mut ratios: Vec<f64> = range
                .filter_map(|i| {
                    let (g, c, z) = (
                        f64::from(samples.gamma[i]),
                        f64::from(samples.cos_theta[i]),
                        f64::from(samples.z[i]),
                    );
                    let diffuse = light.eval_rgb(g, c, z, 1.0);
                    let spec = light.specular_rgb(g, c, z, 1.0);
                    let predicted = lum(std::array::from_fn(|ch| diffuse[ch] + spec[ch]));
                    let observed = lum(std::array::from_fn(|ch| f64::from(samples.rgb[ch][i])));
                    (predicted > 0.0).then(|| (observed - inter) / predicted)
                })
                .filter(|r| r.is_finite())
                .collect();
            if ratios.len() < MIN_FRAME_SAMPLES {
                return None;
            }
            let mid = ratios.len() / 2;
            let g = *ratios.select_nth_unstable_by(mid, f64::total_cmp).1;
            (g > 0.0).then_some(g)
        })
        .collect();
    let mut known: Vec<f64> = fitted.iter().flatten().copied().collect();
    if known.is_empty() {
        return None;
    }
    let mid = known.len() / 2;
    let median = *known.select_nth_unstable_by(mid, f64::total_cmp).1;
    let gains: Vec<f64> = fitted.iter().map(|g| g.unwrap_or(median)).collect();
    // The reference frame's gain is 1: the median frame's scale moves into rho (and the lobe).
    let reference = reference.filter(|&r| r < frames).unwrap_or_else(|| {
        (0..frames)
            .min_by(|&a, &b| {
                (gains[a] - median)
                    .abs()
                    .total_cmp(&(gains[b] - median).abs())
            })
            .unwrap_or(0)
    });
    let scale = gains[reference];
    light.gains = gains.iter().map(|g| g / scale).collect();
    light.reference_frame = reference;
    for rho in &mut light.rho {
        rho.iter_mut().for_each(|v| *v *= scale);
    }
    if let Some(sp) = &mut light.specular {
        sp.k.iter_mut().for_each(|v| *v *= scale);
    }
    if let Some(k) = scope.interreflection {
        let frame_light = samples.frame_light.clone();
        light.ambient = Some(frame_light.iter().map(|l| k.map(|k| k * l)).collect());
        light.frame_light = Some(frame_light);
    }
    Some(light)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::SplitMix64;

    /// A scope light with a lobe and inter-reflection, as a build fits one.
    fn scope() -> CalibratedModel {
        let mut m = CalibratedModel::new(
            [
                vec![2.0, 30.0, 57.0, 84.0],
                vec![0.9, 14.0, 25.0, 37.0],
                vec![0.7, 11.7, 21.0, 31.0],
            ],
            vec![1.0, 0.83, 0.66, 0.5],
            0.5,
        );
        m.interreflection = Some([0.07, 0.03, 0.024]);
        m.frame_light = Some(vec![0.3]);
        m.ambient = Some(vec![[0.02, 0.01, 0.007]]);
        m.specular = Some(crate::shading::calibrated::SpecularLobe {
            k: [19.6; 3],
            alpha: 0.2,
        });
        m
    }

    #[test]
    fn gains_of_another_video_are_recovered_under_a_varied_albedo() {
        let truth = scope();
        let true_gains = [0.4, 1.3, 2.0, 0.9, 5.5];
        let frame_light = [0.1, 0.25, 0.4, 0.2, 0.6];
        let mut rng = SplitMix64::new(7);
        let mut s = PooledSamples::default();
        s.frame_start.push(0);
        for (f, (&g, &l)) in true_gains.iter().zip(&frame_light).enumerate() {
            for _ in 0..2000 {
                let gamma = 0.2 + 0.8 * rng.uniform();
                let cos_theta = 0.55 + 0.45 * rng.uniform();
                let z = 3.0 + 20.0 * rng.uniform();
                // Mucosa: albedo 0.6..1.4 of the mean, vessels darker in green and blue.
                let albedo = 0.6 + 0.8 * rng.uniform();
                let d = truth.eval_rgb(gamma, cos_theta, z, g);
                let sp = truth.specular_rgb(gamma, cos_theta, z, g);
                for ch in 0..3 {
                    let a = if ch == 0 { albedo } else { albedo * 0.9 };
                    let inter = truth.interreflection.unwrap()[ch] * l;
                    let noisy = (a * d[ch] + sp[ch] + inter) * (1.0 + 0.02 * rng.normal());
                    s.rgb[ch].push(noisy as f32);
                }
                s.gamma.push(gamma as f32);
                s.cos_theta.push(cos_theta as f32);
                s.z.push(z as f32);
                s.frame.push(f as u32);
                s.pixel.push(0);
            }
            s.frame_start.push(s.gamma.len());
            s.frame_light.push(l);
        }
        let fitted = with_video_gains(&truth, &s, None).expect("gains");
        // Relative gains are the video's: against frame 2's, within 3 % (the albedo's median
        // is not its mean, which the common scale absorbs).
        for f in 0..true_gains.len() {
            let got = fitted.gains[f] / fitted.gains[2];
            let want = true_gains[f] / true_gains[2];
            assert!(
                (got / want - 1.0).abs() < 0.03,
                "frame {f}: {got} vs {want}"
            );
        }
        assert_eq!(fitted.gains[fitted.reference_frame], 1.0);
        // The light's shape is the scope's; its scale moved into rho.
        let k = fitted.rho[0][3] / truth.rho[0][3];
        assert!((fitted.rho[1][2] / truth.rho[1][2] / k - 1.0).abs() < 1e-12);
        assert_eq!(fitted.s, truth.s);
        // The frames' own inter-reflection, none of the scope video's.
        assert_eq!(fitted.frame_light.as_deref(), Some(&frame_light[..]));
        let a = fitted.ambient_of(4);
        assert!((a[0] - 0.07 * 0.6).abs() < 1e-12);
        assert!(fitted.validate().is_ok());
    }

    #[test]
    fn frames_without_samples_take_the_median_gain() {
        let truth = scope();
        let mut s = PooledSamples {
            frame_start: vec![0, 0, 0],
            frame_light: vec![0.1, 0.2],
            ..Default::default()
        };
        assert!(with_video_gains(&truth, &s, None).is_none());
        for i in 0..30 {
            let (gamma, cos_theta, z) = (0.9f64, 0.9f64, 5.0 + i as f64 * 0.1);
            let d = truth.eval_rgb(gamma, cos_theta, z, 2.0);
            let sp = truth.specular_rgb(gamma, cos_theta, z, 2.0);
            for ch in 0..3 {
                let inter = truth.interreflection.unwrap()[ch] * 0.2;
                s.rgb[ch].push((d[ch] + sp[ch] + inter) as f32);
            }
            s.gamma.push(gamma as f32);
            s.cos_theta.push(cos_theta as f32);
            s.z.push(z as f32);
            s.frame.push(1);
            s.pixel.push(0);
        }
        s.frame_start = vec![0, 0, 30];
        let fitted = with_video_gains(&truth, &s, None).expect("gains");
        assert_eq!(fitted.gains, vec![1.0, 1.0]);
        assert_eq!(
            with_video_gains(&truth, &s, Some(0))
                .unwrap()
                .reference_frame,
            0
        );
        let k = fitted.rho[0][0] / truth.rho[0][0];
        assert!((k - 2.0).abs() < 1e-4, "scale {k}");
    }
}
