//! The small linear solves every shading fit is made of: a ridge-regularised symmetric
//! positive semi-definite solve and an exact bound-constrained quadratic minimisation.

use nalgebra::{DMatrix, DVector, SMatrix, SVector};

/// Solve the symmetric positive semi-definite `A y = b`; a relative ridge of 1e-12 keeps a
/// rank-deficient system (e.g. all samples at one depth) solvable with the minimum-change answer.
pub fn solve_spd<const N: usize>(
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

/// Minimise `y^T A y - 2 b^T y` subject to `y >= lb` (A symmetric PSD). Unbounded entries have
/// `lb = -inf`. Exact by enumerating active sets for n <= 10 (the blocks here are tiny).
pub fn solve_box(a: &DMatrix<f64>, b: &DVector<f64>, lb: &DVector<f64>) -> DVector<f64> {
    let n = a.nrows();
    let bounded: Vec<usize> = (0..n).filter(|&i| lb[i].is_finite()).collect();
    let q = |y: &DVector<f64>| y.dot(&(a * y)) - 2.0 * b.dot(y);
    let solve_with = |fixed: &[usize]| -> Option<DVector<f64>> {
        let free: Vec<usize> = (0..n).filter(|i| !fixed.contains(i)).collect();
        let mut y = DVector::from_fn(n, |i, _| if fixed.contains(&i) { lb[i] } else { 0.0 });
        if free.is_empty() {
            return Some(y);
        }
        let m = free.len();
        let mut ar = DMatrix::from_fn(m, m, |r, c| a[(free[r], free[c])]);
        let br = DVector::from_fn(m, |r, _| {
            b[free[r]] - fixed.iter().map(|&j| a[(free[r], j)] * lb[j]).sum::<f64>()
        });
        let scale = (0..m)
            .map(|i| ar[(i, i)].abs())
            .fold(0.0, f64::max)
            .max(1e-300);
        for i in 0..m {
            ar[(i, i)] += scale * 1e-12;
        }
        let yr = ar.cholesky()?.solve(&br);
        for (r, &i) in free.iter().enumerate() {
            y[i] = yr[r];
        }
        Some(y)
    };
    if let Some(y) = solve_with(&[]) {
        if bounded.iter().all(|&i| y[i] >= lb[i]) {
            return y;
        }
    }
    if bounded.len() > 10 {
        // Not expected here: clamp the unconstrained answer.
        let mut y = solve_with(&[]).unwrap_or_else(|| lb.map(|v| v.max(0.0)));
        for &i in &bounded {
            y[i] = y[i].max(lb[i]);
        }
        return y;
    }
    let mut best: Option<(f64, DVector<f64>)> = None;
    for mask in 1u32..(1 << bounded.len()) {
        let fixed: Vec<usize> = (0..bounded.len())
            .filter(|k| mask & (1 << k) != 0)
            .map(|k| bounded[k])
            .collect();
        let Some(y) = solve_with(&fixed) else {
            continue;
        };
        if bounded.iter().all(|&i| y[i] >= lb[i]) {
            let qy = q(&y);
            if best.as_ref().is_none_or(|(bq, _)| qy < *bq) {
                best = Some((qy, y));
            }
        }
    }
    best.map(|(_, y)| y)
        .unwrap_or_else(|| lb.map(|v| if v.is_finite() { v } else { 0.0 }))
}

/// [`solve_box`] on fixed-size matrices.
pub fn solve_box_fixed<const N: usize>(
    a: &SMatrix<f64, N, N>,
    b: &SVector<f64, N>,
    lb: &SVector<f64, N>,
) -> SVector<f64, N> {
    let y = solve_box(
        &DMatrix::from_column_slice(N, N, a.as_slice()),
        &DVector::from_column_slice(b.as_slice()),
        &DVector::from_column_slice(lb.as_slice()),
    );
    SVector::from_column_slice(y.as_slice())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn box_qp_matches_hand_solution() {
        // min (y0-1)^2 + (y1+2)^2 with y >= 0  →  y = (1, 0).
        let a = SMatrix::<f64, 2, 2>::identity();
        let b = SVector::<f64, 2>::new(1.0, -2.0);
        let y = solve_box_fixed(&a, &b, &SVector::<f64, 2>::zeros());
        assert!((y[0] - 1.0).abs() < 1e-9 && y[1] == 0.0, "{y}");
    }

    #[test]
    fn unbounded_entries_stay_free() {
        // min (y0+1)^2 + (y1+2)^2 with y0 >= 0 only  →  y = (0, -2).
        let a = DMatrix::<f64>::identity(2, 2);
        let b = DVector::from_column_slice(&[-1.0, -2.0]);
        let lb = DVector::from_column_slice(&[0.0, f64::NEG_INFINITY]);
        let y = solve_box(&a, &b, &lb);
        assert!(y[0] == 0.0 && (y[1] + 2.0).abs() < 1e-9, "{y}");
    }
}
