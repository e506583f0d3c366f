//! Albedo refinement of the calibrated fit: the same surface point seen in several frames has
//! one albedo, which makes the light identifiable without assuming a uniform albedo.
//!
//! Round k: de-light every sample with the current model, `q = (I - a_f) / (g_f rho s / z^2)`;
//! average q per texel and channel over the samples of that texel (texels seen in fewer than
//! `min_frames` frames carry no cross-frame information and are left out); normalise so the
//! weighted mean albedo is 1 per channel (its scale belongs to rho); refit the light with that
//! per-sample albedo, starting from the current model.

// Indexing several parallel arrays (struct of arrays, channels) by one index reads clearer than zips.
#![allow(clippy::needless_range_loop)]

use super::calibrated::CalibratedModel;
use super::calibrated_fit::{
    fit_calibrated, fit_calibrated_with_albedo, CalibratedFit, CalibratedOptions,
};
use super::calibrated_samples::PooledSamples;
use crate::{Error, Result};

/// What one refinement round did.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RefineRound {
    /// Samples whose texel was seen in at least `min_frames` frames (they enter the refit).
    pub samples_used: usize,
    /// Texels with an albedo estimate.
    pub texels: usize,
    /// Largest relative change of any gain against the previous round.
    pub max_gain_change: f64,
    /// Weighted RMS residual per channel after the refit (linear intensity).
    pub rms_residual: [f64; 3],
}

/// The refined fit, the per-sample albedo it ended with (NaN: none), and one record per round.
#[derive(Debug, Clone)]
pub struct RefinedFit {
    /// The last fit.
    pub fit: CalibratedFit,
    /// The uniform-albedo fit the refinement started from.
    pub initial: CalibratedModel,
    /// Albedo per channel and sample used in the last refit (relative, mean 1; NaN: none).
    pub albedo: [Vec<f32>; 3],
    /// One record per round.
    pub rounds: Vec<RefineRound>,
}

/// Uniform-albedo fit, then `rounds` rounds of albedo refinement over the samples' texel ids
/// (`samples.texel` must be present). `min_frames`: fewest distinct frames a texel must be
/// seen in (2 or more).
pub fn refine_with_texels(
    samples: &PooledSamples,
    density: &[f32],
    opts: &CalibratedOptions,
    rounds: usize,
    min_frames: usize,
) -> Result<RefinedFit> {
    let Some(texel) = samples.texel.as_ref() else {
        return Err(Error::Other(
            "calibrated refinement: the samples carry no texel ids".into(),
        ));
    };
    let mut fit = fit_calibrated(samples, density, opts)?;
    let initial = fit.model.clone();
    let mut albedo: [Vec<f32>; 3] = std::array::from_fn(|_| vec![f32::NAN; samples.len()]);
    let mut recs = Vec::new();
    // Samples sorted by texel once: each round's averages are one sweep.
    let mut order: Vec<u32> = (0..samples.len() as u32)
        .filter(|&i| texel[i as usize] != u32::MAX)
        .collect();
    order.sort_unstable_by_key(|&i| texel[i as usize]);
    for _ in 0..rounds {
        let m = &fit.model;
        let q: [Vec<f64>; 3] = std::array::from_fn(|c| {
            (0..samples.len())
                .map(|i| {
                    m.delight(
                        c,
                        f64::from(samples.rgb[c][i]),
                        f64::from(samples.gamma[i]),
                        f64::from(samples.cos_theta[i]),
                        f64::from(samples.z[i]),
                        samples.frame[i] as usize,
                    )
                    .unwrap_or(f64::NAN)
                })
                .collect()
        });
        for a in albedo.iter_mut() {
            a.fill(f32::NAN);
        }
        let (mut used, mut texels) = (0usize, 0usize);
        let mut k = 0;
        while k < order.len() {
            let tx = texel[order[k] as usize];
            let mut e = k;
            while e < order.len() && texel[order[e] as usize] == tx {
                e += 1;
            }
            let group = &order[k..e];
            k = e;
            // Samples are grouped by frame, so distinct frames are counted by changes.
            let mut frames = 0;
            let mut last = u32::MAX;
            for &i in group {
                let f = samples.frame[i as usize];
                if f != last {
                    frames += 1;
                    last = f;
                }
            }
            if frames < min_frames.max(2) {
                continue;
            }
            // Weighted by the last fit's weights: outliers (highlights) do not set the albedo.
            let mut acc = [0.0f64; 3];
            let mut ws = 0.0;
            for &i in group {
                let i = i as usize;
                let w = f64::from(fit.weights[i]);
                if w > 0.0 && (0..3).all(|c| q[c][i].is_finite()) {
                    for c in 0..3 {
                        acc[c] += w * q[c][i];
                    }
                    ws += w;
                }
            }
            if !(ws > 0.0) {
                continue;
            }
            texels += 1;
            for &i in group {
                for c in 0..3 {
                    albedo[c][i as usize] = (acc[c] / ws) as f32;
                }
                used += 1;
            }
        }
        if used == 0 {
            return Err(Error::Other(format!(
                "calibrated refinement: no texel is seen in {} frames",
                min_frames.max(2)
            )));
        }
        // Relative albedo: weighted mean 1 per channel.
        for c in 0..3 {
            let (s, w) = albedo[c]
                .iter()
                .zip(density)
                .filter(|(a, _)| a.is_finite())
                .fold((0.0f64, 0.0f64), |(s, w), (&a, &d)| {
                    (s + f64::from(a) * f64::from(d), w + f64::from(d))
                });
            let mean = (s / w.max(1e-300)) as f32;
            if mean > 0.0 {
                for a in albedo[c].iter_mut() {
                    *a /= mean;
                }
            }
        }
        let prev = fit.model.gains.clone();
        fit = fit_calibrated_with_albedo(samples, density, &albedo, Some(&fit.model), opts)?;
        let max_gain_change = fit
            .model
            .gains
            .iter()
            .zip(&prev)
            .map(|(a, b)| (a / b - 1.0).abs())
            .fold(0.0, f64::max);
        recs.push(RefineRound {
            samples_used: used,
            texels,
            max_gain_change,
            rms_residual: fit.model.rms_residual,
        });
    }
    Ok(RefinedFit {
        fit,
        initial,
        albedo,
        rounds: recs,
    })
}
