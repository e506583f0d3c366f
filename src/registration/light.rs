//! The calibrated light seen from a moving camera: `S_c = rho_c(gamma) s(theta) / z^2` of a
//! surface point and its derivative with respect to the camera's motion (the shading changes
//! when the camera, which carries the light, moves).

use crate::math::Vector3;
use crate::shading::bernstein::bernstein_eval;
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
        }
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
        let mut value = [0.0; 3];
        let mut grad = [[0.0; 6]; 3];
        for c in 0..3 {
            let rho = bernstein_eval(&self.rho[c], gamma);
            let drho = eval_or_zero(&self.drho[c], gamma);
            value[c] = rho * s * inv_z2;
            let gv = (dgamma_dv * (drho * s) + dcos_dv * (rho * ds_dcos)
                - dz_dv * (2.0 * rho * s / z))
                * inv_z2;
            let gw = dcos_dw * (rho * ds_dcos * inv_z2);
            grad[c] = [gv.x, gv.y, gv.z, gw.x, gw.y, gw.z];
        }
        ShadeGrad { value, grad }
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

    #[test]
    fn gradient_matches_finite_differences() {
        let light = LightEval::new(&model());
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
        let h = 1e-6;
        for k in 0..6 {
            let mut xi = [0.0; 6];
            xi[k] = h;
            let (pp, np) = cam(&perturb(&pose, &xi));
            xi[k] = -h;
            let (pm, nm) = cam(&perturb(&pose, &xi));
            let (a, b) = (light.shade(&pp, &np), light.shade(&pm, &nm));
            for c in 0..3 {
                let fd = (a[c] - b[c]) / (2.0 * h);
                assert!(
                    (fd - g.grad[c][k]).abs() < 1e-6 * (1.0 + fd.abs()),
                    "channel {c} axis {k}: finite difference {fd}, analytic {}",
                    g.grad[c][k]
                );
            }
        }
    }
}
