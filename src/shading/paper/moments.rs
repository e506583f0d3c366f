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

use crate::parallel::ordered_block_sum;
use crate::shading::bernstein::basis3;
use nalgebra::{SMatrix, SVector};

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
    let acc = ordered_block_sum(
        n,
        4096,
        Acc::<C>::zero(),
        |range| {
            let mut a = Acc::<C>::zero();
            for i in range {
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
        },
        Acc::add,
    );
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
}
