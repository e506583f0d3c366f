//! Bernstein polynomials `B_i^n(t) = C(n,i) (1-t)^(n-i) t^i` (paper, eq. 2): the basis of the
//! paper's Psi (cubic) and of the calibrated light's rho and s (any degree).

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

/// The Bernstein basis `B_i^n(t)`, `i = 0..=n`, of degree `n = out.len() - 1`, written into `out`.
#[inline]
pub fn basis_into(t: f64, out: &mut [f64]) {
    let n = out.len() - 1;
    let s = 1.0 - t;
    let mut tp = 1.0;
    for o in out.iter_mut() {
        *o = tp;
        tp *= t;
    }
    let mut sp = 1.0;
    for o in out.iter_mut().rev() {
        *o *= sp;
        sp *= s;
    }
    let mut binom = 1.0;
    for (i, o) in out.iter_mut().enumerate() {
        *o *= binom;
        binom = binom * (n - i) as f64 / (i + 1) as f64;
    }
}

/// `sum_i coeffs[i] B_i^n(t)` with `n = coeffs.len() - 1` (de Casteljau: stable, allocation free
/// for degrees up to 15).
#[inline]
pub fn bernstein_eval(coeffs: &[f64], t: f64) -> f64 {
    // The light's polynomials are evaluated per pixel and per texel: the common lengths get
    // a fully unrolled copy (the same operations in the same order, so the same values).
    match coeffs.len() {
        1 => coeffs[0],
        2 => casteljau::<2>(coeffs, t),
        3 => casteljau::<3>(coeffs, t),
        4 => casteljau::<4>(coeffs, t),
        5 => casteljau::<5>(coeffs, t),
        6 => casteljau::<6>(coeffs, t),
        _ => casteljau::<16>(coeffs, t),
    }
}

/// de Casteljau on the first `coeffs.len() <= N` entries of an `N`-array.
#[inline(always)]
fn casteljau<const N: usize>(coeffs: &[f64], t: f64) -> f64 {
    let n = coeffs.len();
    debug_assert!((1..=N).contains(&n));
    let mut b = [0.0f64; N];
    b[..n].copy_from_slice(coeffs);
    for k in (1..n).rev() {
        for i in 0..k {
            b[i] = b[i] * (1.0 - t) + b[i + 1] * t;
        }
    }
    b[0]
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

    #[test]
    fn general_basis_matches_formula_and_eval() {
        for n in 0..7usize {
            let mut b = vec![0.0; n + 1];
            let coeffs: Vec<f64> = (0..=n).map(|i| 0.3 + 0.1 * i as f64).collect();
            for k in 0..=10 {
                let t = f64::from(k) / 10.0;
                basis_into(t, &mut b);
                let mut direct = 0.0;
                for i in 0..=n {
                    let e = bernstein(n as u32, i as u32, t);
                    assert!((b[i] - e).abs() < 1e-14, "n {n} i {i} t {t}");
                    direct += coeffs[i] * e;
                }
                assert!((bernstein_eval(&coeffs, t) - direct).abs() < 1e-14);
            }
        }
    }
}
