//! Direct alignment of one pyramid level: the model's surface points are fixed in the world,
//! the camera moves. Residual per point and channel:
//! `e_c = (I_c(project(P)) - k (A_c S_c(P) + a_c)) / sigma_c`, P the point in the moving camera,
//! I the frame divided by its gain, k a gain correction (optional), sigma_c the expected error
//! (`relative` x the prediction + the noise floor). Huber-robust Gauss–Newton normal equations
//! over the six pose parameters of [`super::pose::perturb`] and log k.

use super::light::LightEval;
use super::photometric::ModelPoint;
use super::pose::rotation_of;
use super::pyramid::ImageLevel;
use crate::camera::pose::camera_centre;
use crate::math::{Affine, Matrix3, Point3, Vector2, Vector3};
use nalgebra::{SMatrix, SVector};

/// 7x7 normal matrix (pose, then log gain).
pub type Mat7 = SMatrix<f64, 7, 7>;
/// 7-vector.
pub type Vec7 = SVector<f64, 7>;

/// The fixed parts of one level's problem.
pub struct LevelProblem<'a> {
    /// The frame's pyramid level (divided by its gain).
    pub image: &'a ImageLevel,
    /// The light.
    pub light: &'a LightEval,
    /// The model's surface points.
    pub points: Vec<ModelPoint>,
    /// Light added to every point (unit gain), per channel.
    pub offset: [f64; 3],
    /// 1 / sigma per point and channel, fixed when the points were rendered.
    pub inv_sigma: Vec<[f32; 3]>,
    /// Huber threshold (units of sigma).
    pub huber: f64,
    /// Observed pixels whose brightest channel is under this carry no shading (gain-divided).
    pub dark: f32,
    /// Each point's cost where it was rendered (all channels; NaN where it could not be
    /// compared there). Points that could not are left out while the points are held fixed,
    /// and a point that a move takes off the usable pixels is charged this cost: the set of
    /// compared points never changes between two renders, so the cost stays continuous.
    /// Empty: every point counts, unusable ones at the Huber threshold's cost.
    pub ref_cost: Vec<f32>,
    /// Gradient of the model's own image at each point where it was rendered (d/dx, d/dy
    /// per channel, per level pixel); empty: not used.
    pub model_grad: Vec<[[f32; 3]; 2]>,
    /// Weight of `model_grad` in the Jacobian's image gradient (0: the frame's gradient at
    /// the moved point, forward alignment; 1: the model's, the gradient of the re-rendered
    /// cost; 0.5: both averaged, efficient second-order minimisation).
    pub grad_blend: f32,
}

/// Cost and normal equations at one pose.
#[derive(Clone, Debug)]
pub struct Linearised {
    /// Sum of the robust costs (unused points cost the Huber threshold's).
    pub cost: f64,
    /// Gauss–Newton matrix `J^T W J`.
    pub h: Mat7,
    /// Gradient `J^T W e`.
    pub b: Vec7,
    /// Points that projected onto usable pixels.
    pub used: usize,
    /// Sum of squared normalised residuals of the used points (for an RMS).
    pub sum_sq: f64,
}

/// Huber cost and IRLS weight of a normalised residual.
#[inline]
pub(crate) fn huber(e: f64, k: f64) -> (f64, f64) {
    let a = e.abs();
    if a <= k {
        (0.5 * e * e, 1.0)
    } else {
        (k * (a - 0.5 * k), k / a)
    }
}

/// The frame at each of a level's points, at the pose they were rendered from (where their
/// [`ModelPoint::radiance`] holds): what [`LevelProblem::set_reference`],
/// [`LevelProblem::set_model_gradient`] and the first normal equations all read, so that each
/// point is projected and sampled there once.
pub struct AtRendered {
    /// The frame's value and gradient where the point projects, when usable.
    obs: Vec<Option<super::pyramid::Sample>>,
    /// Distance of the point from the camera (mm).
    depth: Vec<f64>,
}

impl LevelProblem<'_> {
    /// The frame at each point at `pose`, the pose the points were rendered from.
    pub fn at_rendered(&self, pose: &Affine) -> AtRendered {
        let (r, c) = (rotation_of(pose).transpose(), camera_centre(pose).coords);
        let (obs, depth) = self
            .points
            .iter()
            .map(|q| {
                let p = r * (q.x - c);
                (self.observe(&p), p.norm())
            })
            .unzip();
        AtRendered { obs, depth }
    }

    /// Fix the points' expected errors and reference costs where they were rendered (`at`,
    /// gain `log_k`): `sigma = (relative x observed + floor) / weight` per channel, from the
    /// frame's value there. From the observation, not the prediction: a sigma that grew with
    /// the prediction would reward poses that predict the frame brighter.
    pub fn set_reference(
        &mut self,
        at: &AtRendered,
        log_k: f64,
        relative: f64,
        floor: f64,
        channel_weights: [f32; 3],
    ) {
        self.inv_sigma = at
            .obs
            .iter()
            .map(|obs| match obs {
                Some((obs, _, _)) => std::array::from_fn(|ch| {
                    let v = f64::from(obs[ch]).max(0.0);
                    channel_weights[ch] / (relative * v + floor) as f32
                }),
                None => [0.0; 3],
            })
            .collect();
        self.ref_cost = self.point_costs(at, log_k);
    }

    /// Fix the gradient of the model's image at each point, from its neighbours on the
    /// render grid (`index`: point per grid ray, `grid_width` rays per row, `stride` level
    /// pixels apart), where the points were rendered (`at`, gain `log_k`). A neighbour across
    /// a depth step of more than a tenth is not used (an occluding edge does not move with the
    /// surface); a point without neighbours on an axis has no gradient along it.
    pub fn set_model_gradient(
        &mut self,
        at: &AtRendered,
        index: &[u32],
        grid_width: usize,
        stride: usize,
        log_k: f64,
    ) {
        let k = log_k.exp();
        let values: Vec<([f64; 3], f64)> = self
            .points
            .iter()
            .zip(&at.depth)
            .map(|(q, &z)| {
                let s = q.radiance;
                (std::array::from_fn(|ch| k * (s[ch] + self.offset[ch])), z)
            })
            .collect();
        let rows = index.len() / grid_width.max(1);
        let neighbour = |ray: usize, dx: isize, dy: isize, z: f64| -> Option<usize> {
            let (x, y) = (
                (ray % grid_width) as isize + dx,
                (ray / grid_width) as isize + dy,
            );
            if x < 0 || y < 0 || x >= grid_width as isize || y >= rows as isize {
                return None;
            }
            let j = index[y as usize * grid_width + x as usize];
            (j != u32::MAX && (values[j as usize].1 - z).abs() < 0.1 * z).then_some(j as usize)
        };
        let h = stride as f64;
        self.model_grad = self
            .points
            .iter()
            .enumerate()
            .map(|(i, q)| {
                let (m, z) = values[i];
                let ray = q.ray as usize;
                let axis = |dx: isize, dy: isize| -> [f32; 3] {
                    let (a, b) = (neighbour(ray, -dx, -dy, z), neighbour(ray, dx, dy, z));
                    let (lo, hi, span) = match (a, b) {
                        (Some(a), Some(b)) => (values[a].0, values[b].0, 2.0 * h),
                        (None, Some(b)) => (m, values[b].0, h),
                        (Some(a), None) => (values[a].0, m, h),
                        (None, None) => return [0.0; 3],
                    };
                    std::array::from_fn(|ch| ((hi[ch] - lo[ch]) / span) as f32)
                };
                [axis(1, 0), axis(0, 1)]
            })
            .collect();
    }

    /// The frame's value and gradient where camera-frame point `p` projects, when usable.
    #[inline]
    fn observe(&self, p: &Vector3<f64>) -> Option<super::pyramid::Sample> {
        if p.z <= 1e-3 {
            return None;
        }
        let px = self.image.camera.project(&Point3::from(*p))?;
        self.image
            .sample(px.x, px.y)
            .filter(|(obs, _, _)| obs.iter().fold(0.0f32, |a, &v| a.max(v)) >= self.dark)
    }

    /// Each point's robust cost over its channels where it was rendered (`at`, gain `log_k`;
    /// NaN where it is not usable): the reference for [`LevelProblem::ref_cost`].
    fn point_costs(&self, at: &AtRendered, log_k: f64) -> Vec<f32> {
        let k = log_k.exp();
        at.obs
            .iter()
            .zip(&self.points)
            .zip(&self.inv_sigma)
            .map(|((obs, q), inv_sigma)| {
                let Some((obs, _, _)) = obs else {
                    return f32::NAN;
                };
                let s = q.radiance;
                (0..3)
                    .map(|ch| {
                        let m = k * (s[ch] + self.offset[ch]);
                        huber((obs[ch] as f64 - m) * inv_sigma[ch] as f64, self.huber).0
                    })
                    .sum::<f64>() as f32
            })
            .collect()
    }

    /// Cost and (when `with_normal_equations`) the normal equations at `pose` with gain
    /// factor `exp(log_k)`.
    pub fn evaluate(&self, pose: &Affine, log_k: f64, with_normal_equations: bool) -> Linearised {
        self.evaluate_with(pose, log_k, with_normal_equations, None)
    }

    /// [`LevelProblem::evaluate`] with normal equations at the pose the points were rendered
    /// from, reading the frame's samples already taken there (`at`).
    pub fn evaluate_at_rendered(&self, at: &AtRendered, pose: &Affine, log_k: f64) -> Linearised {
        self.evaluate_with(pose, log_k, true, Some(at))
    }

    fn evaluate_with(
        &self,
        pose: &Affine,
        log_k: f64,
        with_normal_equations: bool,
        at: Option<&AtRendered>,
    ) -> Linearised {
        let cam = &self.image.camera;
        let (r, c) = (rotation_of(pose).transpose(), camera_centre(pose).coords);
        let k = log_k.exp();
        let penalty = 3.0 * 0.5 * self.huber * self.huber;
        let mut out = Linearised {
            cost: 0.0,
            h: Mat7::zeros(),
            b: Vec7::zeros(),
            used: 0,
            sum_sq: 0.0,
        };
        let pinhole = cam.is_pinhole();
        let mut normal = NormalSums::default();
        for (i, (q, inv_sigma)) in self.points.iter().zip(&self.inv_sigma).enumerate() {
            let reference = self.ref_cost.get(i).map(|&c| f64::from(c));
            if reference.is_some_and(f64::is_nan) {
                continue;
            }
            let p = r * (q.x - c);
            let observed = match at {
                Some(at) => at.obs[i],
                None => self.observe(&p),
            };
            let Some((obs, gx, gy)) = observed else {
                out.cost += reference.unwrap_or(penalty);
                continue;
            };
            let n = r * q.n;
            out.used += 1;
            if !with_normal_equations {
                let s = self.light.radiance(&p, &n, q.albedo);
                for ch in 0..3 {
                    let m = k * (s[ch] + self.offset[ch]);
                    let e = (obs[ch] as f64 - m) * inv_sigma[ch] as f64;
                    out.cost += huber(e, self.huber).0;
                    out.sum_sq += e * e;
                }
                continue;
            }
            let sg = self.light.shade_grad(&p, &n);
            let dpix = projection_jacobian(cam, &p, pinhole);
            for ch in 0..3 {
                let a = q.albedo[ch] as f64;
                let m = k * (a * sg.value[ch] + sg.specular[ch] + self.offset[ch]);
                let w_sigma = inv_sigma[ch] as f64;
                let e = (obs[ch] as f64 - m) * w_sigma;
                let (cost, w) = huber(e, self.huber);
                out.cost += cost;
                out.sum_sq += e * e;
                // d I / d P through the projection, then dP/dxi = [-I | [P]x].
                let (mut gxc, mut gyc) = (gx[ch], gy[ch]);
                if let Some(mg) = self.model_grad.get(i) {
                    let b = self.grad_blend;
                    gxc += b * (mg[0][ch] - gxc);
                    gyc += b * (mg[1][ch] - gyc);
                }
                let gq = dpix.0 * gxc as f64 + dpix.1 * gyc as f64;
                let gw = gq.cross(&p);
                let mut j = Vec7::zeros();
                for i in 0..3 {
                    j[i] = -gq[i] - k * (a * sg.grad[ch][i] + sg.specular_grad[ch][i]);
                    j[3 + i] = gw[i] - k * (a * sg.grad[ch][3 + i] + sg.specular_grad[ch][3 + i]);
                }
                j[6] = -m;
                j *= w_sigma;
                normal.add(w, e, &j);
            }
        }
        if with_normal_equations {
            (out.h, out.b) = normal.finish();
        }
        out
    }
}

/// One point's residual in one channel with the parts of its Jacobian that scale with the
/// point's albedo kept apart, so that the albedo can be a shared unknown of many frames
/// ([`super::joint`]). All are divided by the residual's sigma. With albedo `a` the residual
/// is `obs - a per_albedo - fixed` and its Jacobian over the pose step and log k is
/// `image - a shade - specular`, then `-(a per_albedo + fixed)`.
#[derive(Clone, Copy, Debug)]
pub struct PointRow {
    /// Index of the point in [`LevelProblem::points`].
    pub point: u32,
    /// Colour channel.
    pub channel: u8,
    /// The frame's value.
    pub obs: f32,
    /// The prediction per unit albedo (`k S_c`).
    pub per_albedo: f32,
    /// The prediction that does not scale with the albedo (`k (P_c + a_c)`).
    pub fixed: f32,
    /// Derivative through the frame's image gradient.
    pub image: [f32; 6],
    /// Derivative of `k S_c` (the light's part per unit albedo).
    pub shade: [f32; 6],
    /// Derivative of `k P_c`.
    pub specular: [f32; 6],
}

impl PointRow {
    /// The prediction with albedo `albedo`.
    #[inline]
    pub fn predicted(&self, albedo: f64) -> f64 {
        albedo * f64::from(self.per_albedo) + f64::from(self.fixed)
    }

    /// The residual (observed minus predicted) with albedo `albedo`.
    #[inline]
    pub fn residual(&self, albedo: f64) -> f64 {
        f64::from(self.obs) - self.predicted(albedo)
    }

    /// The residual's derivative over the pose step and log k with albedo `albedo`.
    #[inline]
    pub fn jacobian(&self, albedo: f64) -> [f64; 7] {
        std::array::from_fn(|i| match i {
            6 => -self.predicted(albedo),
            _ => {
                f64::from(self.image[i])
                    - albedo * f64::from(self.shade[i])
                    - f64::from(self.specular[i])
            }
        })
    }
}

impl LevelProblem<'_> {
    /// The residual rows of the points usable where they were rendered, projected from `pose`
    /// with gain factor `exp(log_k)`: the pieces [`LevelProblem::evaluate`] sums, per point
    /// and channel of non-zero weight.
    pub fn point_rows(&self, pose: &Affine, log_k: f64) -> Vec<PointRow> {
        let cam = &self.image.camera;
        let (r, c) = (rotation_of(pose).transpose(), camera_centre(pose).coords);
        let k = log_k.exp();
        let pinhole = cam.is_pinhole();
        let mut rows = Vec::with_capacity(3 * self.points.len());
        for (i, (q, inv_sigma)) in self.points.iter().zip(&self.inv_sigma).enumerate() {
            if self.ref_cost.get(i).is_some_and(|c| c.is_nan()) {
                continue;
            }
            let p = r * (q.x - c);
            let Some((obs, gx, gy)) = self.observe(&p) else {
                continue;
            };
            let n = r * q.n;
            let sg = self.light.shade_grad(&p, &n);
            let dpix = projection_jacobian(cam, &p, pinhole);
            for ch in 0..3 {
                let ws = inv_sigma[ch] as f64;
                if ws == 0.0 {
                    continue;
                }
                let gq = dpix.0 * gx[ch] as f64 + dpix.1 * gy[ch] as f64;
                let gw = gq.cross(&p);
                let mut row = PointRow {
                    point: i as u32,
                    channel: ch as u8,
                    obs: (obs[ch] as f64 * ws) as f32,
                    per_albedo: (k * sg.value[ch] * ws) as f32,
                    fixed: (k * (sg.specular[ch] + self.offset[ch]) * ws) as f32,
                    image: [0.0; 6],
                    shade: [0.0; 6],
                    specular: [0.0; 6],
                };
                for a in 0..3 {
                    row.image[a] = (-gq[a] * ws) as f32;
                    row.image[3 + a] = (gw[a] * ws) as f32;
                }
                for a in 0..6 {
                    row.shade[a] = (k * sg.grad[ch][a] * ws) as f32;
                    row.specular[a] = (k * sg.specular_grad[ch][a] * ws) as f32;
                }
                rows.push(row);
            }
        }
        rows
    }
}

/// Running sums of the weighted normal equations `J^T W J` and `J^T W e`, the matrix's upper
/// triangle only (it is symmetric: 28 products per residual instead of 49).
#[derive(Default)]
struct NormalSums {
    h: [[f64; 7]; 7],
    b: [f64; 7],
}

impl NormalSums {
    /// Add one residual `e` with IRLS weight `w` and Jacobian row `j`.
    #[inline(always)]
    fn add(&mut self, w: f64, e: f64, j: &Vec7) {
        let j: [f64; 7] = (*j).into();
        for a in 0..7 {
            let wj = w * j[a];
            for (h, &jb) in self.h[a][a..].iter_mut().zip(&j[a..]) {
                *h += wj * jb;
            }
            self.b[a] += w * e * j[a];
        }
    }

    /// The full matrix and the vector.
    fn finish(&self) -> (Mat7, Vec7) {
        let h = Mat7::from_fn(|r, c| self.h[r.min(c)][r.max(c)]);
        (h, Vec7::from(self.b))
    }
}

/// Derivatives of the pixel coordinates (u, v) with respect to the camera-frame point `p`.
#[inline]
fn projection_jacobian(
    cam: &crate::camera::Camera,
    p: &Vector3<f64>,
    pinhole: bool,
) -> (Vector3<f64>, Vector3<f64>) {
    let iz = 1.0 / p.z;
    let (x, y) = (p.x * iz, p.y * iz);
    // d(x, y)/dP of the normalised coordinates.
    let dx = Vector3::new(iz, 0.0, -x * iz);
    let dy = Vector3::new(0.0, iz, -y * iz);
    let d: Matrix3<f64> = if pinhole {
        Matrix3::identity()
    } else {
        cam.distortion_jacobian(Vector2::new(x, y))
    };
    (
        (dx * d[(0, 0)] + dy * d[(0, 1)]) * cam.fx,
        (dx * d[(1, 0)] + dy * d[(1, 1)]) * cam.fy,
    )
}
