//! The calibrated light seen from a moving camera: `S_c = rho_c(gamma) s(theta) / z^2` of a
//! surface point, the specular term `P_c = k_c spec(gamma) s(theta) / z^2` that is added to
//! `albedo S_c` without the albedo, and their derivatives with respect to the camera's motion
//! (the shading changes when the camera, which carries the light, moves).

use crate::math::Vector3;
use crate::shading::bernstein::bernstein_eval;
use crate::shading::calibrated::specular::{lobe, SpecularLobe};
use crate::shading::CalibratedModel;

/// The light of a [`CalibratedModel`] with the derivative polynomials tabulated once.
#[derive(Clone, Debug)]
pub struct LightEval {
    rho: [Vec<f64>; 3],
    drho: [Vec<f64>; 3],
    s: Vec<f64>,
    ds: Vec<f64>,
    /// d t / d cos(theta) inside the fitted range (t is held constant outside it).
    dt_dcos: f64,
    cos_edge: f64,
    specular: Option<SpecularLobe>,
}

/// Coefficients of the derivative of a Bernstein polynomial (degree one less; empty for a
/// constant, whose derivative is 0).
fn derivative(c: &[f64]) -> Vec<f64> {
    let n = c.len() as f64 - 1.0;
    c.windows(2).map(|w| n * (w[1] - w[0])).collect()
}

fn eval_or_zero(c: &[f64], t: f64) -> f64 {
    if c.is_empty() {
        0.0
    } else {
        bernstein_eval(c, t)
    }
}

/// One point's shading per channel and its gradient with respect to the camera-frame step
/// `xi = (v, w)` of [`super::pose::perturb`].
#[derive(Clone, Copy, Debug)]
pub struct ShadeGrad {
    /// `S_c` (linear intensity at unit gain and albedo).
    pub value: [f64; 3],
    /// `dS_c / dxi`.
    pub grad: [[f64; 6]; 3],
    /// The specular term `P_c` (linear intensity at unit gain; zero without one).
    pub specular: [f64; 3],
    /// `dP_c / dxi`.
    pub specular_grad: [[f64; 6]; 3],
}

impl LightEval {
    /// Tabulate `model`'s light.
    pub fn new(model: &CalibratedModel) -> LightEval {
        LightEval {
            drho: std::array::from_fn(|c| derivative(&model.rho[c])),
            rho: model.rho.clone(),
            ds: derivative(&model.s),
            s: model.s.clone(),
            dt_dcos: -1.0 / (1.0 - model.cos_theta_edge),
            cos_edge: model.cos_theta_edge,
            specular: model.specular,
        }
    }

    /// The specular lobe times its colour at `gamma`, and its derivative in gamma (zero
    /// without a specular term).
    fn specular_lobe(&self, gamma: f64) -> ([f64; 3], [f64; 3]) {
        let Some(sp) = &self.specular else {
            return ([0.0; 3], [0.0; 3]);
        };
        let h = 1e-6;
        let value = lobe(sp.alpha, gamma);
        let slope = (lobe(sp.alpha, (gamma + h).min(1.0)) - lobe(sp.alpha, (gamma - h).max(0.0)))
            / ((gamma + h).min(1.0) - (gamma - h).max(0.0));
        (sp.k.map(|k| k * value), sp.k.map(|k| k * slope))
    }

    /// What the surface at camera-frame point `p` (normal `n`) with `albedo` sends back at
    /// unit gain: `albedo_c S_c + P_c`.
    #[inline]
    pub fn radiance(&self, p: &Vector3<f64>, n: &Vector3<f64>, albedo: [f32; 3]) -> [f64; 3] {
        let s = self.shade(p, n);
        if self.specular.is_none() {
            return std::array::from_fn(|c| albedo[c] as f64 * s[c]);
        }
        let (gamma, cos_theta, z) = Self::geometry(p, n);
        let k = bernstein_eval(&self.s, self.t(cos_theta)) / (z * z);
        let (spec, _) = self.specular_lobe(gamma);
        std::array::from_fn(|c| albedo[c] as f64 * s[c] + k * spec[c])
    }

    fn t(&self, cos_theta: f64) -> f64 {
        ((1.0 - cos_theta) / (1.0 - self.cos_edge)).clamp(0.0, 1.0)
    }

    /// gamma (clamped to [0, 1]), cos(theta) and z of camera-frame point `p` (mm) with unit
    /// normal `n` facing the camera.
    #[inline]
    fn geometry(p: &Vector3<f64>, n: &Vector3<f64>) -> (f64, f64, f64) {
        let z = p.norm();
        ((-n.dot(p) / z).clamp(0.0, 1.0), p.z / z, z)
    }

    /// `S_c` of camera-frame point `p` (mm) with normal `n`.
    #[inline]
    pub fn shade(&self, p: &Vector3<f64>, n: &Vector3<f64>) -> [f64; 3] {
        let (gamma, cos_theta, z) = Self::geometry(p, n);
        let k = bernstein_eval(&self.s, self.t(cos_theta)) / (z * z);
        std::array::from_fn(|c| k * bernstein_eval(&self.rho[c], gamma))
    }

    /// `S_c` and its gradient. With u = p / z: translation changes z (`dz/dv = -u`), gamma
    /// (`dgamma/dv = (n + gamma u) / z`) and theta; rotation about the light changes theta
    /// alone.
    pub fn shade_grad(&self, p: &Vector3<f64>, n: &Vector3<f64>) -> ShadeGrad {
        let (gamma_raw, cos_theta, z) = (-n.dot(p) / p.norm(), p.z / p.norm(), p.norm());
        let gamma = gamma_raw.clamp(0.0, 1.0);
        let u = p / z;
        let t = self.t(cos_theta);
        let s = bernstein_eval(&self.s, t);
        let inside = t > 0.0 && t < 1.0;
        let ds_dcos = if inside {
            eval_or_zero(&self.ds, t) * self.dt_dcos
        } else {
            0.0
        };
        let dgamma_dv = if gamma_raw > 0.0 && gamma_raw < 1.0 {
            (n + u * gamma) / z
        } else {
            Vector3::zeros()
        };
        let dcos_dv = (u * cos_theta - Vector3::z()) / z;
        let dcos_dw = Vector3::new(-p.y, p.x, 0.0) / z;
        let dz_dv = -u;
        let inv_z2 = 1.0 / (z * z);
        // A function of gamma times s(theta) / z^2, and its gradient.
        let term = |f: f64, df: f64| -> (f64, [f64; 6]) {
            let gv = (dgamma_dv * (df * s) + dcos_dv * (f * ds_dcos) - dz_dv * (2.0 * f * s / z))
                * inv_z2;
            let gw = dcos_dw * (f * ds_dcos * inv_z2);
            (f * s * inv_z2, [gv.x, gv.y, gv.z, gw.x, gw.y, gw.z])
        };
        let (spec, dspec) = self.specular_lobe(gamma);
        let mut out = ShadeGrad {
            value: [0.0; 3],
            grad: [[0.0; 6]; 3],
            specular: [0.0; 3],
            specular_grad: [[0.0; 6]; 3],
        };
        for c in 0..3 {
            let rho = bernstein_eval(&self.rho[c], gamma);
            let drho = eval_or_zero(&self.drho[c], gamma);
            (out.value[c], out.grad[c]) = term(rho, drho);
            if self.specular.is_some() {
                (out.specular[c], out.specular_grad[c]) = term(spec[c], dspec[c]);
            }
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::math::Affine;
    use crate::registration::pose::{perturb, rotation_of};

    fn model() -> CalibratedModel {
        CalibratedModel::new(
            [
                vec![0.1, 0.5, 0.9, 1.2],
                vec![0.2, 0.4, 0.6, 0.7],
                vec![0.05, 0.3, 0.2, 0.9],
            ],
            vec![1.0, 0.7, 0.3],
            0.3,
        )
    }

    fn model_with_highlights() -> CalibratedModel {
        CalibratedModel {
            specular: Some(SpecularLobe {
                k: [0.4, 0.5, 0.6],
                alpha: 0.3,
            }),
            ..model()
        }
    }

    #[test]
    fn gradient_matches_finite_differences() {
        for m in [model(), model_with_highlights()] {
            gradient_matches_finite_differences_of(&m);
        }
    }

    fn gradient_matches_finite_differences_of(m: &CalibratedModel) {
        let light = LightEval::new(m);
        let albedo = [0.9f32, 0.5, 0.3];
        // A world point and normal seen from the identity pose, moved by small steps.
        let x = Vector3::new(2.0, -1.5, 7.0);
        let nw = Vector3::new(-0.3, 0.4, -0.8).normalize();
        let pose = Affine::identity();
        let cam = |m: &Affine| {
            let r = rotation_of(m).transpose();
            let c = Vector3::new(m[(0, 3)], m[(1, 3)], m[(2, 3)]);
            (r * (x - c), r * nw)
        };
        let (p, n) = cam(&pose);
        let g = light.shade_grad(&p, &n);
        assert_eq!(g.value, light.shade(&p, &n));
        let r = light.radiance(&p, &n, albedo);
        for c in 0..3 {
            let from_grad = albedo[c] as f64 * g.value[c] + g.specular[c];
            assert!((r[c] - from_grad).abs() < 1e-12 * r[c].abs().max(1.0));
        }
        assert_eq!(m.specular.is_some(), g.specular[0] > 0.0);
        let h = 1e-6;
        for k in 0..6 {
            let mut xi = [0.0; 6];
            xi[k] = h;
            let (pp, np) = cam(&perturb(&pose, &xi));
            xi[k] = -h;
            let (pm, nm) = cam(&perturb(&pose, &xi));
            let (a, b) = (
                light.radiance(&pp, &np, albedo),
                light.radiance(&pm, &nm, albedo),
            );
            for c in 0..3 {
                let fd = (a[c] - b[c]) / (2.0 * h);
                let analytic = albedo[c] as f64 * g.grad[c][k] + g.specular_grad[c][k];
                assert!(
                    (fd - analytic).abs() < 1e-5 * (1.0 + fd.abs()),
                    "channel {c} axis {k}: finite difference {fd}, analytic {analytic}"
                );
            }
        }
    }
}
