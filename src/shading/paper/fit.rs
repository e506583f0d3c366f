//! The weighted fit of Psi (paper, eq. 5), per colour channel.
//!
//! Steps per channel: (1) one pass over the samples builds the cost's quadratic form
//! (see `moments`); (2) alternate the exact c-step (4x4) and d-step (3x3) weighted linear
//! least-squares solves from varrho ≡ 1 until the cost stops falling; (3) polish jointly
//! over all 7 parameters with Levenberg–Marquardt; (4) optionally, robust IRLS: Huber or
//! Tukey weights on the residuals multiply the density weights and steps 1–3 repeat;
//! (5) check Psi > 0 on a grid over gamma, r in [0, 1]; if not, refit with all Bernstein
//! coefficients >= a small positive bound (then rho, varrho and Psi are positive).
//!
//! The LM polish is hand-written on the 7x7 system: it runs on the 16x16 moment matrix, not
//! on per-sample residuals, so the `levenberg-marquardt` crate (which wants an N x 7 residual
//! Jacobian, N ~ 80k) would only make it slower.

// Indexing several parallel arrays (struct of arrays, channels) by one index reads clearer than zips.
#![allow(clippy::needless_range_loop)]
// `!(x > t)` on floats is deliberate: it also rejects NaN.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

use super::moments::{accumulate, Quadratic};
use super::psi::PsiModel;
use crate::parallel::{add_channel_sums, ordered_block_sum};
use crate::shading::bernstein::eval3;
use crate::shading::error::check_weights;
use crate::shading::robust::Robust;
use crate::shading::samples::SampleSet;
use crate::shading::solve::{solve_box_fixed, solve_spd};
use crate::shading::ShadingError;
use crate::Result;
use nalgebra::SVector;
use serde::{Deserialize, Serialize};

/// The name errors give this fit.
const FIT: &str = "shading fit";

/// Options of [`fit_psi`].
#[derive(Debug, Clone, PartialEq)]
pub struct FitOptions {
    /// Most c-step/d-step alternations (each is two tiny solves). Default 500.
    pub max_alternations: usize,
    /// Stop alternating (and polishing) when the cost falls by less than this fraction of
    /// itself in one iteration. Default 1e-12.
    pub tolerance: f64,
    /// Joint Levenberg–Marquardt polish over all 7 parameters after the alternation. Default true.
    pub lm_polish: bool,
    /// Most LM iterations. Default 100.
    pub max_lm_iterations: usize,
    /// Robust loss on top of the density weights. Default `Robust::None` (the paper).
    pub robust: Robust,
    /// Most IRLS re-weightings when `robust` is not `None`; they stop earlier once no
    /// parameter moves by more than 1e-5 of itself. Default 10.
    pub max_irls_iterations: usize,
    /// Grid points per axis over gamma, r in [0, 1] for the positivity check. Default 65.
    pub positivity_grid: usize,
    /// Refit with non-negative Bernstein coefficients when the fit goes non-positive on the
    /// grid (the texture divides by Psi). Default true; false gives the plain least-squares
    /// optimum (still checked and reported in [`ChannelFit::unconstrained_min_psi`]).
    pub enforce_positivity: bool,
}

impl Default for FitOptions {
    fn default() -> Self {
        FitOptions {
            max_alternations: 500,
            tolerance: 1e-12,
            lm_polish: true,
            max_lm_iterations: 100,
            robust: Robust::None,
            max_irls_iterations: 10,
            positivity_grid: 65,
            enforce_positivity: true,
        }
    }
}

/// How one channel's fit went.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct ChannelFit {
    /// c/d alternations performed (summed over IRLS rounds).
    pub alternations: usize,
    /// Accepted LM steps (summed over IRLS rounds).
    pub lm_steps: usize,
    /// IRLS re-weightings performed (0 without robust fitting).
    pub irls_iterations: usize,
    /// Smallest Psi on the positivity grid of the unconstrained fit (linear intensity).
    pub unconstrained_min_psi: f64,
    /// True when the unconstrained fit went non-positive and the constrained fit replaced it.
    pub constrained: bool,
    /// `C_p = sum w_i (Psi - P_i)^2` with the density weights given to [`fit_psi`].
    pub cost: f64,
    /// Smallest Psi on the positivity grid of the final fit (> 0 unless positivity is not enforced).
    pub min_psi: f64,
}

/// The fitted Psi of one frame and how each channel's fit went.
#[derive(Debug, Clone, PartialEq)]
pub struct PsiFit {
    /// The model; `camera_to_world` is the identity until the caller sets the frame's pose.
    pub model: PsiModel,
    /// Per channel R, G, B.
    pub channels: [ChannelFit; 3],
}

/// Fit Psi to `samples` with per-sample `weights` (density weights, or ones for an unweighted fit).
pub fn fit_psi(samples: &SampleSet, weights: &[f32], opts: &FitOptions) -> Result<PsiFit> {
    let n = samples.len();
    if n < 7 {
        return Err(ShadingError::TooFewSamples {
            fit: FIT,
            got: n,
            needed: 7,
        }
        .into());
    }
    check_weights(FIT, weights, n)?;
    if !(samples.z_max > samples.z_min) {
        return Err(ShadingError::EmptyDepthRange {
            z_min: samples.z_min,
            z_max: samples.z_max,
        }
        .into());
    }
    // r per sample once: the passes below read it many times.
    let r: Vec<f64> = (0..n).map(|i| samples.r(i)).collect();
    let gamma_r = |i: usize| (f64::from(samples.gamma[i]), r[i]);
    let w = |i: usize| f64::from(weights[i]);
    let quads = accumulate::<3>(
        n,
        &gamma_r,
        &w,
        [&samples.rgb[0], &samples.rgb[1], &samples.rgb[2]],
    );

    let mut params = [[0.0; 7]; 3];
    let mut reports = [ChannelFit {
        alternations: 0,
        lm_steps: 0,
        irls_iterations: 0,
        unconstrained_min_psi: 0.0,
        constrained: false,
        cost: 0.0,
        min_psi: 0.0,
    }; 3];
    for ch in 0..3 {
        let values = &samples.rgb[ch];
        let mut rep = reports[ch];
        let mut p = fit_channel(&quads[ch], values, &gamma_r, &w, opts, false, &mut rep);
        rep.unconstrained_min_psi = min_on_grid(&p, opts.positivity_grid);
        rep.min_psi = rep.unconstrained_min_psi;
        if opts.enforce_positivity && !(rep.min_psi > 0.0) {
            // Psi must be positive (the texture divides by it): constrained refit.
            rep.constrained = true;
            p = fit_channel(&quads[ch], values, &gamma_r, &w, opts, true, &mut rep);
            rep.min_psi = min_on_grid(&p, opts.positivity_grid);
        }
        params[ch] = p;
        reports[ch] = rep;
    }

    // Cost and RMS straight from the samples (the moment form loses digits near a perfect fit).
    let (sums, wsum) = ordered_block_sum(
        n,
        4096,
        ([0.0f64; 3], 0.0f64),
        |range| {
            let (mut acc, mut ws) = ([0.0f64; 3], 0.0f64);
            for i in range {
                let (g, ri) = gamma_r(i);
                let wi = w(i);
                for ch in 0..3 {
                    let e = psi_at(&params[ch], g, ri) - f64::from(samples.rgb[ch][i]);
                    acc[ch] += wi * e * e;
                }
                ws += wi;
            }
            (acc, ws)
        },
        add_channel_sums,
    );
    for ch in 0..3 {
        reports[ch].cost = sums[ch];
    }
    let model = PsiModel {
        camera_to_world: identity16(),
        z_min: samples.z_min,
        z_max: samples.z_max,
        c: std::array::from_fn(|ch| [params[ch][0], params[ch][1], params[ch][2], params[ch][3]]),
        d: std::array::from_fn(|ch| [params[ch][4], params[ch][5], params[ch][6]]),
        rms_residual: std::array::from_fn(|ch| (sums[ch] / wsum.max(1e-300)).sqrt()),
        samples_used: n,
        excluded: samples.excluded,
    };
    Ok(PsiFit {
        model,
        channels: reports,
    })
}

/// 4x4 identity, row-major.
fn identity16() -> [f64; 16] {
    std::array::from_fn(|i| if i % 5 == 0 { 1.0 } else { 0.0 })
}

/// Psi at (gamma, r) for parameters `p = (c_0..c_3, d_1..d_3)`.
#[inline]
pub(crate) fn psi_at(p: &[f64; 7], gamma: f64, r: f64) -> f64 {
    eval3(&[p[0], p[1], p[2], p[3]], gamma) * eval3(&[1.0, p[4], p[5], p[6]], r)
}

/// Smallest Psi over an `m` x `m` grid of (gamma, r) in [0, 1]².
fn min_on_grid(p: &[f64; 7], m: usize) -> f64 {
    let m = m.max(2);
    let t = |k: usize| k as f64 / (m - 1) as f64;
    let rho_min_max = (0..m).map(|k| eval3(&[p[0], p[1], p[2], p[3]], t(k)));
    let varrho: Vec<f64> = (0..m)
        .map(|k| eval3(&[1.0, p[4], p[5], p[6]], t(k)))
        .collect();
    rho_min_max
        .flat_map(|a| varrho.iter().map(move |b| a * b))
        .fold(f64::INFINITY, f64::min)
}

/// Fit one channel: least squares from `quad`, then IRLS rounds if robust.
fn fit_channel(
    quad: &Quadratic,
    values: &[f32],
    gamma_r: &(dyn Fn(usize) -> (f64, f64) + Sync),
    w: &(dyn Fn(usize) -> f64 + Sync),
    opts: &FitOptions,
    constrained: bool,
    rep: &mut ChannelFit,
) -> [f64; 7] {
    // Bounds for the constrained fit: positive Bernstein coefficients make Psi positive.
    let scale = (quad.s / quad.wsum.max(1e-300)).sqrt().max(1e-12);
    let bounds = (scale * 1e-6, 1e-6);
    let start = [0.0, 0.0, 0.0, 0.0, 1.0, 1.0, 1.0];
    let mut p = solve_quadratic(quad, start, opts, constrained.then_some(bounds), rep);
    if opts.robust == Robust::None {
        return p;
    }
    let n = values.len();
    for _ in 0..opts.max_irls_iterations {
        rep.irls_iterations += 1;
        let resid: Vec<f64> = (0..n)
            .map(|i| {
                let (g, r) = gamma_r(i);
                f64::from(values[i]) - psi_at(&p, g, r)
            })
            .collect();
        // Robust scale: 1.4826 x median |residual| (a standard deviation under Gaussian noise).
        let mut abs: Vec<f64> = resid.iter().map(|e| e.abs()).collect();
        let mid = n / 2;
        let (_, med, _) = abs.select_nth_unstable_by(mid, |a, b| a.total_cmp(b));
        let sigma = (1.4826 * *med).max(1e-12 * scale);
        let robust_w = |i: usize| w(i) * opts.robust.weight((resid[i] / sigma).abs());
        let [q] = accumulate::<1>(n, gamma_r, &robust_w, [values]);
        let next = solve_quadratic(&q, p, opts, constrained.then_some(bounds), rep);
        let change = (0..7)
            .map(|k| (next[k] - p[k]).abs() / (p[k].abs() + 1e-3 * scale))
            .fold(0.0, f64::max);
        p = next;
        if change < 1e-5 {
            break;
        }
    }
    p
}

/// Minimise the quadratic-form cost from `p`: alternation, then (unconstrained) LM polish.
/// `bounds` = (lower bound of every c_i, of every d_i) for the constrained fit.
fn solve_quadratic(
    quad: &Quadratic,
    mut p: [f64; 7],
    opts: &FitOptions,
    bounds: Option<(f64, f64)>,
    rep: &mut ChannelFit,
) -> [f64; 7] {
    let mut cost = f64::INFINITY;
    for _ in 0..opts.max_alternations.max(1) {
        rep.alternations += 1;
        let (a, b) = quad.c_system(&p);
        let c = match bounds {
            Some((lc, _)) => Some(solve_box_fixed(&a, &b, &SVector::<f64, 4>::repeat(lc))),
            None => solve_spd(&a, &b),
        };
        if let Some(c) = c {
            p[..4].copy_from_slice(c.as_slice());
        }
        let (a, b) = quad.d_system(&p);
        let d = match bounds {
            Some((_, ld)) => Some(solve_box_fixed(&a, &b, &SVector::<f64, 3>::repeat(ld))),
            None => solve_spd(&a, &b),
        };
        if let Some(d) = d {
            p[4..].copy_from_slice(d.as_slice());
        }
        let next = quad.cost(&p);
        let done = cost - next <= opts.tolerance * next.max(1e-300 * quad.s);
        cost = next;
        if done {
            break;
        }
    }
    if bounds.is_none() && opts.lm_polish {
        p = lm_polish(quad, p, cost, opts, rep);
    }
    p
}

/// Levenberg–Marquardt on the 7 parameters (Gauss–Newton Hessian `J^T G J`, Marquardt's
/// diagonal scaling): the alternation zig-zags when gamma and depth are correlated, the
/// joint step does not.
fn lm_polish(
    quad: &Quadratic,
    mut p: [f64; 7],
    mut cost: f64,
    opts: &FitOptions,
    rep: &mut ChannelFit,
) -> [f64; 7] {
    let mut lambda = 1e-6;
    for _ in 0..opts.max_lm_iterations {
        let j = Quadratic::jacobian(&p);
        let x = Quadratic::x(&p);
        let grad = j.transpose() * (quad.g * x - quad.h);
        let h = j.transpose() * quad.g * j;
        let mut improved = false;
        for _ in 0..20 {
            let mut a = h;
            for k in 0..7 {
                a[(k, k)] += lambda * h[(k, k)].max(1e-300);
            }
            let Some(step) = solve_spd::<7>(&a, &(-grad)) else {
                lambda *= 10.0;
                continue;
            };
            let mut trial = p;
            for k in 0..7 {
                trial[k] += step[k];
            }
            let tc = quad.cost(&trial);
            if tc < cost {
                let gain = cost - tc;
                p = trial;
                cost = tc;
                lambda = (lambda / 3.0).max(1e-12);
                rep.lm_steps += 1;
                improved = gain > opts.tolerance * cost.max(1e-300 * quad.s);
                break;
            }
            lambda *= 4.0;
        }
        if !improved {
            break;
        }
    }
    p
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn noise_free_psi_is_recovered_exactly() {
        let truth = [0.05, 0.4, 0.7, 0.9, 0.85, 0.6, 0.45];
        let mut s = SampleSet {
            z_min: 5.0,
            z_max: 25.0,
            ..Default::default()
        };
        for a in 0..40 {
            for b in 0..40 {
                let g = 0.05 + 0.95 * a as f64 / 39.0;
                let z = 5.0 + 20.0 * b as f64 / 39.0;
                let v = psi_at(&truth, g, (z - 5.0) / 20.0) as f32;
                s.gamma.push(g as f32);
                s.z.push(z as f32);
                for ch in 0..3 {
                    s.rgb[ch].push(v * (1.0 - 0.2 * ch as f32));
                }
            }
        }
        let w = vec![1.0; s.len()];
        let fit = fit_psi(&s, &w, &FitOptions::default()).unwrap();
        for k in 0..4 {
            assert!(
                (fit.model.c[0][k] - truth[k]).abs() < 1e-5,
                "{:?}",
                fit.model.c[0]
            );
        }
        for k in 0..3 {
            assert!(
                (fit.model.d[2][k] - truth[4 + k]).abs() < 1e-5,
                "{:?}",
                fit.model.d[2]
            );
        }
        assert!(fit.model.rms_residual[1] < 1e-6);
        assert!(!fit.channels[0].constrained);
    }
}
