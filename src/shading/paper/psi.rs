//! `PsiModel`: the fitted shading of one viewpoint (paper, eq. 2–4), as stored in `shading.json`.

use crate::shading::bernstein::{basis3, eval3};
use crate::shading::samples::{normalised_depth, ExclusionCounts};
use serde::{Deserialize, Serialize};

/// `Psi_p(gamma, z) = rho(gamma) * varrho(z)` per colour channel for one viewpoint p.
///
/// `rho(gamma) = sum_i c[ch][i] B_i^3(gamma)`;
/// `varrho(z) = B_0^3(r) + sum_i d[ch][i-1] B_i^3(r)`, `r = (z - z_min)/(z_max - z_min)`
/// clamped to [0, 1]. Output is linear intensity (same scale as the fitted pixels).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PsiModel {
    /// The viewpoint's camera → world transform, 4x4 row-major (world mm, OpenCV camera axes).
    pub camera_to_world: [f64; 16],
    /// Depth (mm) mapped to r = 0.
    pub z_min: f64,
    /// Depth (mm) mapped to r = 1.
    pub z_max: f64,
    /// `c_0..c_3` of rho, per channel R, G, B (linear intensity).
    pub c: [[f64; 4]; 3],
    /// `d_1..d_3` of varrho, per channel R, G, B (unitless; `d_0` is fixed at 1).
    pub d: [[f64; 3]; 3],
    /// Weighted RMS residual `sqrt(sum w (Psi - P)^2 / sum w)` per channel (linear intensity),
    /// with the density weights of the fit.
    pub rms_residual: [f64; 3],
    /// Samples the fit used.
    pub samples_used: usize,
    /// Pixels excluded from the fit, by reason.
    pub excluded: ExclusionCounts,
}

impl PsiModel {
    /// Normalised depth of `z` (mm), clamped to [0, 1].
    #[inline]
    pub fn r(&self, z: f64) -> f64 {
        normalised_depth(z, self.z_min, self.z_max)
    }

    /// `rho(gamma)` of channel `ch` (0 = R, 1 = G, 2 = B).
    #[inline]
    pub fn rho(&self, ch: usize, gamma: f64) -> f64 {
        eval3(&self.c[ch], gamma)
    }

    /// `varrho(r)` of channel `ch` at normalised depth `r` (clamped to [0, 1]).
    #[inline]
    pub fn varrho_r(&self, ch: usize, r: f64) -> f64 {
        let b = basis3(r.clamp(0.0, 1.0));
        let d = &self.d[ch];
        b[0] + d[0] * b[1] + d[1] * b[2] + d[2] * b[3]
    }

    /// `Psi(gamma, z)` of channel `ch`, z in mm (r clamped to [0, 1], never extrapolated).
    #[inline]
    pub fn eval(&self, ch: usize, gamma: f64, z: f64) -> f64 {
        self.rho(ch, gamma) * self.varrho_r(ch, self.r(z))
    }

    /// `Psi(gamma, z)` for R, G, B.
    #[inline]
    pub fn eval_rgb(&self, gamma: f64, z: f64) -> [f64; 3] {
        let r = self.r(z);
        let bg = basis3(gamma);
        let br = basis3(r);
        std::array::from_fn(|ch| {
            let c = &self.c[ch];
            let d = &self.d[ch];
            let rho = c[0] * bg[0] + c[1] * bg[1] + c[2] * bg[2] + c[3] * bg[3];
            rho * (br[0] + d[0] * br[1] + d[1] * br[2] + d[2] * br[3])
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn model() -> PsiModel {
        PsiModel {
            camera_to_world: [0.0; 16],
            z_min: 10.0,
            z_max: 30.0,
            c: [[0.1, 0.3, 0.6, 0.9]; 3],
            d: [[0.8, 0.5, 0.3]; 3],
            rms_residual: [0.0; 3],
            samples_used: 0,
            excluded: ExclusionCounts::default(),
        }
    }

    #[test]
    fn eval_clamps_depth_and_matches_the_formula() {
        let m = model();
        // At z_min varrho = B_0(0) = 1, so Psi = rho(gamma); at gamma = 1 rho = c_3.
        assert!((m.eval(0, 1.0, 10.0) - 0.9).abs() < 1e-15);
        // Beyond z_max: clamped to r = 1, varrho = d_3.
        assert!((m.eval(1, 1.0, 99.0) - 0.9 * 0.3).abs() < 1e-15);
        assert_eq!(m.eval(2, 0.5, 5.0), m.eval(2, 0.5, 10.0));
        // Midpoint by hand: r = 0.5 → basis [1,3,3,1]/8.
        let varrho = (1.0 + 3.0 * 0.8 + 3.0 * 0.5 + 0.3) / 8.0;
        let rho = (0.1 + 3.0 * 0.3 + 3.0 * 0.6 + 0.9) / 8.0;
        assert!((m.eval(0, 0.5, 20.0) - rho * varrho).abs() < 1e-15);
        assert_eq!(m.eval_rgb(0.5, 20.0)[1], m.eval(1, 0.5, 20.0));
    }
}
