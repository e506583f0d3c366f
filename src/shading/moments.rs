//! Sufficient statistics of the weighted Psi fit, and the small linear algebra on them.
//!
//! `Psi(gamma, r) = sum_jk c_j dfull_k B_j(gamma) B_k(r)` with `dfull = (1, d_1, d_2, d_3)`:
//! a rank-1 bicubic tensor-product surface with coefficient vector `x = vec(c dfull^T)`.
//! With `g_i = B(gamma_i) ⊗ B(r_i)` (16 values) the cost is exactly
//! `C = x^T G x - 2 h^T x + s`, `G = sum w g g^T`, `h = sum w P g`, `s = sum w P^2`,
//! so one pass over the samples gives everything the alternation and the Gauss–Newton
//! polish need; their iterations then cost microseconds regardless of the sample count.

// Indexing several parallel arrays (struct of arrays, channels) by one index reads clearer than zips.
#![allow(clippy::needless_range_loop)]

use super::bernstein::basis3;
use nalgebra::{SMatrix, SVector};
use rayon::prelude::*;

pub(crate) type Mat16 = SMatrix<f64, 16, 16>;
pub(crate) type Vec16 = SVector<f64, 16>;

/// The quadratic form of one channel's weighted cost.
#[derive(Debug, Clone)]
pub(crate) struct Quadratic {
    pub g: Mat16,
    pub h: Vec16,
    pub s: f64,
    pub wsum: f64,
}

/// Accumulators for one pass: G (shared by the channels) and h, s per channel.
#[derive(Clone)]
struct Acc<const C: usize> {
    g: [[f64; 16]; 16],
    h: [[f64; 16]; C],
    s: [f64; C],
    wsum: f64,
}

impl<const C: usize> Acc<C> {
    fn zero() -> Self {
        Acc {
            g: [[0.0; 16]; 16],
            h: [[0.0; 16]; C],
            s: [0.0; C],
            wsum: 0.0,
        }
    }

    fn add(mut self, o: Self) -> Self {
        for (a, b) in self.g.iter_mut().zip(o.g.iter()) {
            for (x, y) in a.iter_mut().zip(b) {
                *x += y;
            }
        }
        for c in 0..C {
            for k in 0..16 {
                self.h[c][k] += o.h[c][k];
            }
            self.s[c] += o.s[c];
        }
        self.wsum += o.wsum;
        self
    }
}

/// The 16-vector `B(gamma) ⊗ B(r)`, index `j * 4 + k` for gamma basis j, r basis k.
#[inline]
pub(crate) fn tensor_basis(gamma: f64, r: f64) -> [f64; 16] {
    let bg = basis3(gamma);
    let br = basis3(r);
    std::array::from_fn(|i| bg[i / 4] * br[i % 4])
}

/// One pass: the quadratic forms of `C` channels sharing the weights `w(i)`.
/// `gamma_r(i)` gives sample i's (gamma, r); `values[c][i]` its intensity in channel c.
pub(crate) fn accumulate<const C: usize>(
    n: usize,
    gamma_r: &(dyn Fn(usize) -> (f64, f64) + Sync),
    w: &(dyn Fn(usize) -> f64 + Sync),
    values: [&[f32]; C],
) -> [Quadratic; C] {
    const CHUNK: usize = 4096;
    let acc = (0..n.div_ceil(CHUNK))
        .into_par_iter()
        .map(|chunk| {
            let mut a = Acc::<C>::zero();
            for i in chunk * CHUNK..((chunk + 1) * CHUNK).min(n) {
                let wi = w(i);
                if wi == 0.0 {
                    continue;
                }
                let (gm, r) = gamma_r(i);
                let g = tensor_basis(gm, r);
                let wg: [f64; 16] = std::array::from_fn(|k| wi * g[k]);
                // Upper triangle only (G is symmetric; mirrored after the pass).
                for (j, (row, &wgj)) in a.g.iter_mut().zip(wg.iter()).enumerate() {
                    for (x, &gk) in row[j..].iter_mut().zip(g[j..].iter()) {
                        *x += wgj * gk;
                    }
                }
                for c in 0..C {
                    let p = f64::from(values[c][i]);
                    for (x, &wgk) in a.h[c].iter_mut().zip(wg.iter()) {
                        *x += p * wgk;
                    }
                    a.s[c] += wi * p * p;
                }
                a.wsum += wi;
            }
            a
        })
        .reduce(Acc::zero, Acc::add);
    let g = Mat16::from_fn(|r, c| if r <= c { acc.g[r][c] } else { acc.g[c][r] });
    std::array::from_fn(|c| Quadratic {
        g,
        h: Vec16::from_column_slice(&acc.h[c]),
        s: acc.s[c],
        wsum: acc.wsum,
    })
}

impl Quadratic {
    /// `x = vec(c dfull^T)` for parameters `p = (c_0..c_3, d_1..d_3)`.
    pub fn x(p: &[f64; 7]) -> Vec16 {
        let df = [1.0, p[4], p[5], p[6]];
        Vec16::from_fn(|i, _| p[i / 4] * df[i % 4])
    }

    /// The weighted cost `sum w (Psi - P)^2` at `p` (from the moments).
    pub fn cost(&self, p: &[f64; 7]) -> f64 {
        let x = Self::x(p);
        (x.dot(&(self.g * x)) - 2.0 * self.h.dot(&x) + self.s).max(0.0)
    }

    /// Jacobian `dx/dp` (16 x 7).
    pub fn jacobian(p: &[f64; 7]) -> SMatrix<f64, 16, 7> {
        let df = [1.0, p[4], p[5], p[6]];
        let mut j = SMatrix::<f64, 16, 7>::zeros();
        for a in 0..4 {
            for k in 0..4 {
                j[(a * 4 + k, a)] = df[k];
                if k > 0 {
                    j[(a * 4 + k, 3 + k)] = p[a];
                }
            }
        }
        j
    }

    /// Normal equations of the c-step (d fixed): `A c = b`, 4x4.
    pub fn c_system(&self, p: &[f64; 7]) -> (SMatrix<f64, 4, 4>, SVector<f64, 4>) {
        let j = Self::jacobian(p);
        let k = j.fixed_view::<16, 4>(0, 0);
        (k.transpose() * self.g * k, k.transpose() * self.h)
    }

    /// Normal equations of the d-step (c fixed): `A d = b`, 3x3.
    pub fn d_system(&self, p: &[f64; 7]) -> (SMatrix<f64, 3, 3>, SVector<f64, 3>) {
        let j = Self::jacobian(p);
        let l = j.fixed_view::<16, 3>(0, 4);
        // x = x0 + L d with x0 the B_0(r) column scaled by c.
        let x0 = Vec16::from_fn(|i, _| if i % 4 == 0 { p[i / 4] } else { 0.0 });
        (
            l.transpose() * self.g * l,
            l.transpose() * (self.h - self.g * x0),
        )
    }
}

/// Solve the symmetric positive semi-definite `A y = b`; a relative ridge of 1e-12 keeps a
/// rank-deficient system (e.g. all samples at one depth) solvable with the minimum-change answer.
pub(crate) fn solve_spd<const N: usize>(
    a: &SMatrix<f64, N, N>,
    b: &SVector<f64, N>,
) -> Option<SVector<f64, N>> {
    let scale = (0..N)
        .map(|i| a[(i, i)].abs())
        .fold(0.0, f64::max)
        .max(1e-300);
    let ridge = SMatrix::<f64, N, N>::identity() * (scale * 1e-12);
    (a + ridge).cholesky().map(|c| c.solve(b))
}

/// Minimise `y^T A y - 2 b^T y` subject to `y >= lb` (A symmetric PSD, N <= 4): every active
/// set is tried and the best feasible candidate kept, which is exact for a convex problem
/// this small (at most 16 tiny solves).
pub(crate) fn solve_box<const N: usize>(
    a: &SMatrix<f64, N, N>,
    b: &SVector<f64, N>,
    lb: &SVector<f64, N>,
) -> SVector<f64, N> {
    let q = |y: &SVector<f64, N>| y.dot(&(a * y)) - 2.0 * b.dot(y);
    let mut best = *lb;
    let mut best_q = q(lb);
    for mask in 1u32..(1 << N) {
        let free: Vec<usize> = (0..N).filter(|i| mask & (1 << i) != 0).collect();
        let m = free.len();
        // Reduced system on the free variables, the others held at their bound.
        let mut ar = nalgebra::DMatrix::<f64>::zeros(m, m);
        let mut br = nalgebra::DVector::<f64>::zeros(m);
        for (ri, &i) in free.iter().enumerate() {
            br[ri] = b[i];
            for j in 0..N {
                if mask & (1 << j) == 0 {
                    br[ri] -= a[(i, j)] * lb[j];
                }
            }
            for (ci, &j) in free.iter().enumerate() {
                ar[(ri, ci)] = a[(i, j)];
            }
        }
        let scale = (0..m)
            .map(|i| ar[(i, i)].abs())
            .fold(0.0, f64::max)
            .max(1e-300);
        for i in 0..m {
            ar[(i, i)] += scale * 1e-12;
        }
        let Some(ch) = ar.cholesky() else { continue };
        let yr = ch.solve(&br);
        let mut y = *lb;
        for (ri, &i) in free.iter().enumerate() {
            y[i] = yr[ri];
        }
        if free.iter().all(|&i| y[i] >= lb[i]) {
            let qy = q(&y);
            if qy < best_q {
                best_q = qy;
                best = y;
            }
        }
    }
    best
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn moment_cost_equals_direct_cost() {
        let n = 500;
        let gam: Vec<f64> = (0..n)
            .map(|i| 0.05 + 0.9 * ((i * 37) % n) as f64 / n as f64)
            .collect();
        let r: Vec<f64> = (0..n).map(|i| ((i * 91) % n) as f64 / n as f64).collect();
        let p: Vec<f32> = (0..n)
            .map(|i| 0.2 + 0.5 * gam[i] as f32 * (1.0 - 0.4 * r[i] as f32))
            .collect();
        let w = |i: usize| 0.5 + (i % 3) as f64;
        let [q] = accumulate::<1>(n, &|i| (gam[i], r[i]), &w, [&p]);
        let th = [0.1, 0.3, 0.5, 0.7, 0.9, 0.8, 0.6];
        let direct: f64 = (0..n)
            .map(|i| {
                let psi = crate::shading::bernstein::eval3(&[th[0], th[1], th[2], th[3]], gam[i])
                    * crate::shading::bernstein::eval3(&[1.0, th[4], th[5], th[6]], r[i]);
                w(i) * (psi - f64::from(p[i])).powi(2)
            })
            .sum();
        assert!(
            (q.cost(&th) - direct).abs() < 1e-10 * direct.max(1.0),
            "{} {}",
            q.cost(&th),
            direct
        );
    }

    #[test]
    fn box_qp_matches_hand_solution() {
        // min (y0-1)^2 + (y1+2)^2 with y >= 0  →  y = (1, 0).
        let a = SMatrix::<f64, 2, 2>::identity();
        let b = SVector::<f64, 2>::new(1.0, -2.0);
        let y = solve_box(&a, &b, &SVector::<f64, 2>::zeros());
        assert!((y[0] - 1.0).abs() < 1e-9 && y[1] == 0.0, "{y}");
    }
}
