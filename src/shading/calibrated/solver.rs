//! The calibrated fit's solver on the moments: exact block solves alternated over rho, s, the
//! gains (and ambient terms) and kappa, with the gauge fixed by the reference frame, then a
//! Levenberg–Marquardt polish over every parameter; bounds keep gains and ambient terms
//! positive and, in the constrained refit, every Bernstein coefficient.

#![allow(clippy::needless_range_loop)]
#![allow(clippy::neg_cmp_op_on_partial_ord)]

use super::fit::{CalibratedOptions, CalibratedReport};
use super::moments::{cost, normal_equations, Block, FrameMoments, Layout};
use crate::shading::bernstein::bernstein_eval;
use crate::shading::solve::solve_box;
use nalgebra::{DMatrix, DVector};

/// A typical intensity x mm² (sets the lower bound of the constrained rho coefficients):
/// the RMS green intensity (`G[d, d]` is the weight sum: feature d is the constant 1).
pub(super) fn rho_scale(lay: &Layout, m: &[FrameMoments]) -> f64 {
    let d = lay.d();
    let (s, w): (f64, f64) = m
        .iter()
        .map(|fm| (fm.s[1], fm.g(1)[(d, d)]))
        .fold((0.0, 0.0), |a, b| (a.0 + b.0, a.1 + b.1));
    (s / w.max(1e-300)).sqrt().max(1e-12) * 100.0
}

/// Lower bounds of the constrained fit: (every rho coefficient, every s coefficient).
pub(super) fn bounds(scale: f64) -> (f64, f64) {
    (scale * 1e-6, 1e-6)
}

/// Lower bound of parameter k: rho and s coefficients only when constrained; gains > 0 and
/// ambient >= 0 always.
fn lower(lay: &Layout, k: usize, b: Option<(f64, f64)>) -> f64 {
    if k >= lay.a_off() {
        0.0
    } else if k >= lay.g_off() {
        1e-9
    } else if k >= lay.e_off() {
        b.map_or(f64::NEG_INFINITY, |b| b.1)
    } else {
        b.map_or(f64::NEG_INFINITY, |b| b.0)
    }
}

pub(super) fn clamp_to(lay: &Layout, p: &mut [f64], b: Option<(f64, f64)>) {
    for k in 0..p.len() {
        p[k] = p[k].max(lower(lay, k, b));
    }
}

/// Smallest value of rho (any channel) and s on the positivity grids.
pub(super) fn min_positive(lay: &Layout, p: &[f64], grid: usize) -> f64 {
    let m = grid.max(2);
    let mut s = vec![1.0];
    s.extend_from_slice(&p[lay.e_off()..lay.e_off() + lay.ns - 1]);
    let mut lo = f64::INFINITY;
    for k in 0..m {
        let x = k as f64 / (m - 1) as f64;
        lo = lo.min(bernstein_eval(&s, x));
        for c in 0..3 {
            lo = lo.min(bernstein_eval(&p[lay.c_off(c)..lay.c_off(c) + lay.nr], x));
        }
    }
    lo
}

/// Gauge: the reference frame's gain is 1, its scale moves into rho.
fn fix_gauge(lay: &Layout, p: &mut [f64], reference: usize) {
    let k = p[lay.g_off() + reference];
    if !(k > 0.0) {
        return;
    }
    for f in 0..lay.frames {
        p[lay.g_off() + f] /= k;
    }
    for c in 0..3 {
        for j in 0..lay.nr {
            p[lay.c_off(c) + j] *= k;
        }
    }
    // The gathered light was gathered with the old rho: its factor g_f k_c is kept; so is
    // the specular term's g_f k_c.
    if lay.gathered {
        for c in 0..3 {
            p[lay.q_off() + c] *= k;
        }
    }
    if lay.specular.is_some() {
        for c in 0..lay.spec_colours {
            p[lay.p_off() + c] *= k;
        }
    }
}

/// Solve the block of parameters `idx` exactly (the model is linear in each block):
/// minimise `x^T H x - 2 (H x0 - grad)^T x` with bounds.
fn block_step(p: &mut [f64], h: &DMatrix<f64>, grad: &DVector<f64>, idx: &[usize], lb: &[f64]) {
    let n = idx.len();
    let a = DMatrix::from_fn(n, n, |r, c| h[(idx[r], idx[c])]);
    let x0 = DVector::from_fn(n, |r, _| p[idx[r]]);
    let b = &a * &x0 - DVector::from_fn(n, |r, _| grad[idx[r]]);
    let x = solve_box(&a, &b, &DVector::from_column_slice(lb));
    for (r, &k) in idx.iter().enumerate() {
        if x[r].is_finite() {
            p[k] = x[r];
        }
    }
}

/// Alternation then LM polish on the moments `m`, from `p`.
pub(super) fn solve(
    lay: &Layout,
    m: &[FrameMoments],
    mut p: Vec<f64>,
    opts: &CalibratedOptions,
    b: Option<(f64, f64)>,
    rep: &mut CalibratedReport,
) -> Vec<f64> {
    let lbs = |idx: &[usize]| -> Vec<f64> { idx.iter().map(|&k| lower(lay, k, b)).collect() };
    let mut last = f64::INFINITY;
    for _ in 0..opts.max_alternations.max(1) {
        rep.alternations += 1;
        // rho per channel (independent blocks).
        let (h, g, _) = normal_equations(lay, m, &p, Block::Rho);
        for c in 0..3 {
            let idx: Vec<usize> = (0..lay.nr).map(|j| lay.c_off(c) + j).collect();
            block_step(&mut p, &h, &g, &idx, &lbs(&idx));
        }
        if lay.ns > 1 {
            let (h, g, _) = normal_equations(lay, m, &p, Block::S);
            let idx: Vec<usize> = (1..lay.ns).map(|k| lay.e_off() + k - 1).collect();
            block_step(&mut p, &h, &g, &idx, &lbs(&idx));
        }
        let (h, g, _) = normal_equations(lay, m, &p, Block::Gains);
        for f in 0..lay.frames {
            let mut idx = vec![lay.g_off() + f];
            if lay.ambient {
                idx.extend((0..3).map(|c| lay.a_off() + 3 * f + c));
            }
            block_step(&mut p, &h, &g, &idx, &lbs(&idx));
        }
        if lay.interreflection {
            let (h, g, _) = normal_equations(lay, m, &p, Block::Kappa);
            let idx: Vec<usize> = (0..3).map(|c| lay.k_off() + c).collect();
            block_step(&mut p, &h, &g, &idx, &lbs(&idx));
        }
        if lay.gathered {
            let (h, g, _) = normal_equations(lay, m, &p, Block::Gathered);
            let idx: Vec<usize> = (0..3).map(|c| lay.q_off() + c).collect();
            block_step(&mut p, &h, &g, &idx, &lbs(&idx));
        }
        if lay.specular.is_some() {
            let (h, g, _) = normal_equations(lay, m, &p, Block::Specular);
            let idx: Vec<usize> = (0..lay.spec_colours).map(|c| lay.p_off() + c).collect();
            block_step(&mut p, &h, &g, &idx, &lbs(&idx));
        }
        fix_gauge(lay, &mut p, opts.reference_frame);
        let c = cost(lay, m, &p);
        let done = last - c <= opts.tolerance * c.max(1e-300);
        last = c;
        if done {
            break;
        }
    }
    if opts.lm_polish {
        p = lm_polish(lay, m, p, last, opts, b, rep);
    }
    p
}

/// Levenberg–Marquardt over all parameters but the reference gain, with Marquardt's diagonal
/// scaling; steps are projected onto the bounds.
fn lm_polish(
    lay: &Layout,
    m: &[FrameMoments],
    mut p: Vec<f64>,
    mut c0: f64,
    opts: &CalibratedOptions,
    b: Option<(f64, f64)>,
    rep: &mut CalibratedReport,
) -> Vec<f64> {
    let free: Vec<usize> = (0..lay.len())
        .filter(|&k| k != lay.g_off() + opts.reference_frame)
        .collect();
    let n = free.len();
    let mut lambda = 1e-6;
    for _ in 0..opts.max_lm_iterations {
        let (h, g, c) = normal_equations(lay, m, &p, Block::All);
        c0 = c0.min(c);
        let hf = DMatrix::from_fn(n, n, |r, cc| h[(free[r], free[cc])]);
        let gf = DVector::from_fn(n, |r, _| -g[free[r]]);
        let mut improved = false;
        for _ in 0..20 {
            let mut a = hf.clone();
            for k in 0..n {
                a[(k, k)] += lambda * hf[(k, k)].max(1e-300);
            }
            let Some(step) = a.cholesky().map(|ch| ch.solve(&gf)) else {
                lambda *= 10.0;
                continue;
            };
            let mut trial = p.clone();
            for (r, &k) in free.iter().enumerate() {
                trial[k] = (p[k] + step[r]).max(lower(lay, k, b));
            }
            let tc = cost(lay, m, &trial);
            if tc < c0 {
                let gain = c0 - tc;
                p = trial;
                c0 = tc;
                lambda = (lambda / 3.0).max(1e-12);
                rep.lm_steps += 1;
                improved = gain > opts.tolerance * c0.max(1e-300);
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
