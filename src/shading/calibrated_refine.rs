//! Albedo refinement of the calibrated fit: the same surface point seen in several frames has
//! one albedo, which makes the light identifiable without assuming a uniform albedo.
//!
//! Round k: with the current light shape (rho, s, a_f) fixed, the gains and a per-texel albedo
//! are solved exactly in the log domain, `log((I - a_f) / (rho s / z^2)) = log g_f + log A_x`:
//! a weighted least-squares problem whose texel unknowns eliminate in closed form, leaving an
//! F x F system in the log gains (alternating gains and albedo instead converges like diffusion
//! along the video, far too slowly: the albedo's slow variation along the airway and the
//! gains of the frames that see it are tied only through overlaps). Texels seen in fewer than
//! `min_frames` frames carry no cross-frame information and are left out. The albedo is
//! normalised to a weighted mean of 1 per channel (its scale belongs to rho) and the light is
//! refitted with that per-sample albedo, starting from the solved gains.

// Indexing several parallel arrays (struct of arrays, channels) by one index reads clearer than zips.
#![allow(clippy::needless_range_loop)]
// `!(x > t)` on floats is deliberate: it also rejects NaN.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

use super::calibrated::CalibratedModel;
use super::calibrated_fit::{
    fit_calibrated, fit_calibrated_with_albedo, CalibratedFit, CalibratedOptions,
};
use super::calibrated_samples::PooledSamples;
use crate::{Error, Result};
use nalgebra::{DMatrix, DVector};

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
    // Stable: within a texel the samples stay in frame order.
    order.sort_by_key(|&i| texel[i as usize]);
    for _ in 0..rounds {
        let (log_gain, log_albedo, texels) = gains_and_albedo(
            samples,
            &order,
            texel,
            &fit,
            opts.reference_frame,
            min_frames,
        )?;
        for c in 0..3 {
            for i in 0..samples.len() {
                albedo[c][i] = log_albedo[c][i].exp() as f32;
            }
        }
        let used = albedo[0].iter().filter(|a| a.is_finite()).count();
        // Relative albedo: weighted mean 1 per channel (its scale belongs to rho).
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
        // Start the refit from the exact gains of the log-domain solve.
        let mut start = fit.model.clone();
        for (g, l) in start.gains.iter_mut().zip(&log_gain) {
            *g = l.exp();
        }
        let prev = fit.model.gains.clone();
        fit = fit_calibrated_with_albedo(samples, density, &albedo, Some(&start), opts)?;
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

/// Per-channel log albedo per sample (NaN where its texel is left out).
type LogAlbedo = [Vec<f64>; 3];

/// The exact log-domain solve of the gains (log, reference 0) and the per-texel albedo given
/// the light shape of `fit`. Returns (log gains, log albedo per sample, texels used).
fn gains_and_albedo(
    samples: &PooledSamples,
    order: &[u32],
    texel: &[u32],
    fit: &CalibratedFit,
    reference: usize,
    min_frames: usize,
) -> Result<(Vec<f64>, LogAlbedo, usize)> {
    let m = &fit.model;
    let nf = samples.frames();
    let floor = 0.01;
    // Per sample and channel: y = log((I - a) / (rho s / z^2)) and its weight (fit weight x
    // (I / (I + floor))^2: the log of a dark pixel is noise).
    let yw = |i: usize, c: usize| -> Option<(f64, f64)> {
        let w = f64::from(fit.weights[i]);
        let f = samples.frame[i] as usize;
        let v = f64::from(samples.rgb[c][i]) - m.ambient_of(f)[c];
        let shade = m.eval(
            c,
            f64::from(samples.gamma[i]),
            f64::from(samples.cos_theta[i]),
            f64::from(samples.z[i]),
            1.0,
        );
        (w > 0.0 && v > floor && shade > 0.0).then(|| ((v / shade).ln(), w * v * v))
    };
    let mut mat = DMatrix::<f64>::zeros(nf, nf);
    let mut rhs = DVector::<f64>::zeros(nf);
    // Per texel: (start, end) in `order` and whether it is used.
    let mut groups = Vec::new();
    let mut k = 0;
    while k < order.len() {
        let tx = texel[order[k] as usize];
        let mut e = k;
        while e < order.len() && texel[order[e] as usize] == tx {
            e += 1;
        }
        groups.push((k, e));
        k = e;
    }
    let mut used_groups = Vec::new();
    for &(b, e) in &groups {
        let group = &order[b..e];
        // Per frame within the texel (samples are in frame order): (frame, W_c, Y_c).
        let mut per: Vec<(usize, [f64; 3], [f64; 3])> = Vec::new();
        for &i in group {
            let i = i as usize;
            let f = samples.frame[i] as usize;
            let vals: Vec<Option<(f64, f64)>> = (0..3).map(|c| yw(i, c)).collect();
            if vals.iter().any(|v| v.is_none()) {
                continue;
            }
            if per.last().is_none_or(|p| p.0 != f) {
                per.push((f, [0.0; 3], [0.0; 3]));
            }
            let p = per.last_mut().expect("pushed above");
            for (c, v) in vals.iter().enumerate() {
                let (y, w) = v.expect("checked above");
                p.1[c] += w;
                p.2[c] += w * y;
            }
        }
        if per.len() < min_frames.max(2) {
            continue;
        }
        used_groups.push((b, e));
        for c in 0..3 {
            let wt: f64 = per.iter().map(|p| p.1[c]).sum();
            let yt: f64 = per.iter().map(|p| p.2[c]).sum();
            if !(wt > 0.0) {
                continue;
            }
            for a in &per {
                mat[(a.0, a.0)] += a.1[c];
                rhs[a.0] += a.2[c] - a.1[c] * yt / wt;
                for bb in &per {
                    mat[(a.0, bb.0)] -= a.1[c] * bb.1[c] / wt;
                }
            }
        }
    }
    if used_groups.is_empty() {
        return Err(Error::Other(format!(
            "calibrated refinement: no texel is seen in {} frames",
            min_frames.max(2)
        )));
    }
    // Fix log g_ref = 0: solve on the other frames (a frame sharing no texel keeps its gain).
    let free: Vec<usize> = (0..nf).filter(|&f| f != reference).collect();
    let n = free.len();
    let mut a = DMatrix::from_fn(n, n, |r, c| mat[(free[r], free[c])]);
    let scale = (0..n).map(|i| a[(i, i)]).fold(0.0, f64::max).max(1e-300);
    let current: Vec<f64> = m.gains.iter().map(|g| g.ln()).collect();
    let mut b = DVector::from_fn(n, |r, _| rhs[free[r]]);
    for r in 0..n {
        // A tiny ridge towards the current gains keeps an unconnected frame determined.
        a[(r, r)] += scale * 1e-9;
        b[r] += scale * 1e-9 * current[free[r]];
    }
    let sol = a
        .cholesky()
        .ok_or_else(|| Error::Other("calibrated refinement: singular gain system".into()))?
        .solve(&b);
    let mut log_gain = vec![0.0; nf];
    for (r, &f) in free.iter().enumerate() {
        log_gain[f] = sol[r];
    }
    // Texel albedo in closed form given the gains.
    let mut log_albedo: LogAlbedo = std::array::from_fn(|_| vec![f64::NAN; samples.len()]);
    for &(b, e) in &used_groups {
        let group = &order[b..e];
        for c in 0..3 {
            let (mut wy, mut ws) = (0.0, 0.0);
            for &i in group {
                let i = i as usize;
                if let Some((y, w)) = yw(i, c) {
                    wy += w * (y - log_gain[samples.frame[i] as usize]);
                    ws += w;
                }
            }
            if ws > 0.0 {
                for &i in group {
                    log_albedo[c][i as usize] = wy / ws;
                }
            }
        }
    }
    Ok((log_gain, log_albedo, used_groups.len()))
}
