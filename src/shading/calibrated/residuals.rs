//! The calibrated fit's residuals: each sample's prediction, the robust weights of the IRLS
//! and the weighted RMS residual.

// Indexing several parallel arrays (struct of arrays, channels) by one index reads clearer than zips.
#![allow(clippy::needless_range_loop)]

use super::fit::CalibratedOptions;
use super::moments::Layout;
use super::samples::PooledSamples;
use super::specular::lobe;
use crate::parallel::{add_channel_sums, ordered_block_sum};
use crate::shading::bernstein::bernstein_eval;
use rayon::prelude::*;

/// The model's prediction per channel for sample i (albedo included when given).
#[inline]
fn predict(
    lay: &Layout,
    p: &[f64],
    s_coeffs: &[f64],
    samples: &PooledSamples,
    t: &[f32],
    albedo: Option<&[Vec<f32>; 3]>,
    i: usize,
) -> [f64; 3] {
    let f = samples.frame[i] as usize;
    let z = f64::from(samples.z[i]);
    let gam = f64::from(samples.gamma[i]);
    let k = p[lay.g_off() + f] * bernstein_eval(s_coeffs, f64::from(t[i])) / (z * z);
    let spec = lay.specular.map_or(0.0, |alpha| k * lobe(alpha, gam));
    std::array::from_fn(|c| {
        let alb = albedo.map_or(1.0, |a| f64::from(a[c][i]));
        let light = samples.frame_light.get(f).copied().unwrap_or(0.0);
        let mut amb = super::moments::ambient_of(lay, p, light, f, c);
        if let (true, Some(e)) = (lay.gathered, &samples.indirect) {
            amb += super::moments::gathered_of(lay, p, f, c) * alb * f64::from(e[c][i]);
        }
        if lay.specular.is_some() {
            amb += spec * p[lay.k_idx(c)];
        }
        k * alb * bernstein_eval(&p[lay.c_off(c)..lay.c_off(c) + lay.nr], gam) + amb
    })
}

fn s_coeffs(lay: &Layout, p: &[f64]) -> Vec<f64> {
    let mut s = vec![1.0];
    s.extend_from_slice(&p[lay.e_off()..lay.e_off() + lay.ns - 1]);
    s
}

/// New weights: `base x robust(u / sigma)` with u the RMS over channels of the relative
/// residual `(I - pred) / (|pred| + floor)` and sigma its robust scale.
pub(super) fn robust_weights(
    samples: &PooledSamples,
    t: &[f32],
    base: &[f32],
    albedo: Option<&[Vec<f32>; 3]>,
    lay: &Layout,
    p: &[f64],
    opts: &CalibratedOptions,
) -> Vec<f32> {
    let sc = s_coeffs(lay, p);
    let u: Vec<f32> = (0..samples.len())
        .into_par_iter()
        .with_min_len(4096)
        .map(|i| {
            if base[i] == 0.0 {
                return f32::NAN;
            }
            let pr = predict(lay, p, &sc, samples, t, albedo, i);
            let ss: f64 = (0..3)
                .map(|c| {
                    let e = (f64::from(samples.rgb[c][i]) - pr[c])
                        / (pr[c].abs() + opts.relative_floor);
                    e * e
                })
                .sum();
            (ss / 3.0).sqrt() as f32
        })
        .collect();
    let mut v: Vec<f32> = u.iter().copied().filter(|x| x.is_finite()).collect();
    if v.is_empty() {
        return base.to_vec();
    }
    let mid = v.len() / 2;
    let med = f64::from(*v.select_nth_unstable_by(mid, |a, b| a.total_cmp(b)).1);
    // The median of sqrt(chi²_3 / 3) is 0.888 sigma.
    let sigma = (med / 0.888).max(1e-9);
    u.iter()
        .zip(base)
        .map(|(&ui, &bi)| {
            if !ui.is_finite() {
                return 0.0;
            }
            (f64::from(bi) * opts.robust.weight(f64::from(ui) / sigma)) as f32
        })
        .collect()
}

/// Weighted RMS residual per channel and the weight sum.
pub(super) fn residual_rms(
    samples: &PooledSamples,
    t: &[f32],
    w: &[f32],
    albedo: Option<&[Vec<f32>; 3]>,
    lay: &Layout,
    p: &[f64],
) -> ([f64; 3], f64) {
    let sc = s_coeffs(lay, p);
    let (sums, ws) = ordered_block_sum(
        samples.len(),
        4096,
        ([0.0f64; 3], 0.0f64),
        |range| {
            let (mut acc, mut ws) = ([0.0f64; 3], 0.0f64);
            for i in range {
                let wi = f64::from(w[i]);
                if wi == 0.0 {
                    continue;
                }
                let pr = predict(lay, p, &sc, samples, t, albedo, i);
                for c in 0..3 {
                    let e = f64::from(samples.rgb[c][i]) - pr[c];
                    acc[c] += wi * e * e;
                }
                ws += wi;
            }
            (acc, ws)
        },
        add_channel_sums,
    );
    (
        std::array::from_fn(|c| (sums[c] / ws.max(1e-300)).sqrt()),
        ws,
    )
}
