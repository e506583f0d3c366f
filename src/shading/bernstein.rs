//! Bernstein polynomials `B_i^n(t) = C(n,i) (1-t)^(n-i) t^i` (paper, eq. 2), the basis of Psi.

/// `B_i^n(t)` for any degree `n` and `0 <= i <= n` (0 when `i > n`). `t` is unitless.
pub fn bernstein(n: u32, i: u32, t: f64) -> f64 {
    if i > n {
        return 0.0;
    }
    binomial(n, i) * (1.0 - t).powi((n - i) as i32) * t.powi(i as i32)
}

/// The binomial coefficient `C(n, k)` as a float (exact for the small degrees used here).
fn binomial(n: u32, k: u32) -> f64 {
    let k = k.min(n - k);
    (0..k).fold(1.0, |acc, j| acc * f64::from(n - j) / f64::from(j + 1))
}

/// The four cubic basis values `[B_0^3(t), B_1^3(t), B_2^3(t), B_3^3(t)]`; they sum to 1.
#[inline]
pub fn basis3(t: f64) -> [f64; 4] {
    let s = 1.0 - t;
    [s * s * s, 3.0 * s * s * t, 3.0 * s * t * t, t * t * t]
}

/// The cubic `sum_i coeffs[i] B_i^3(t)`.
#[inline]
pub fn eval3(coeffs: &[f64; 4], t: f64) -> f64 {
    let b = basis3(t);
    coeffs[0] * b[0] + coeffs[1] * b[1] + coeffs[2] * b[2] + coeffs[3] * b[3]
}

/// The cubic basis for every `t` in `ts`, written into `out` (same length): the per-sample
/// basis vectors the fit accumulates, computed once per frame.
pub fn basis3_into(ts: &[f64], out: &mut [[f64; 4]]) {
    for (o, &t) in out.iter_mut().zip(ts) {
        *o = basis3(t);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cubic_basis_matches_general_formula_and_sums_to_one() {
        for k in 0..=20 {
            let t = f64::from(k) / 20.0;
            let b = basis3(t);
            for (i, bi) in b.iter().enumerate() {
                assert!((bi - bernstein(3, i as u32, t)).abs() < 1e-14);
            }
            assert!((b.iter().sum::<f64>() - 1.0).abs() < 1e-14);
        }
        // C(5,2) (1-t)^3 t^2 at t = 0.5 is 10/32.
        assert!((bernstein(5, 2, 0.5) - 10.0 / 32.0).abs() < 1e-15);
        assert_eq!(bernstein(3, 4, 0.5), 0.0);
    }

    #[test]
    fn eval3_reproduces_linear_function() {
        // Coefficients i/3 give t exactly (linear precision of the Bernstein basis).
        let c = [0.0, 1.0 / 3.0, 2.0 / 3.0, 1.0];
        for k in 0..=10 {
            let t = f64::from(k) / 10.0;
            assert!((eval3(&c, t) - t).abs() < 1e-14);
        }
    }
}
