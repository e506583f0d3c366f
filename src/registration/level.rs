//! One pyramid level of a frame's registration: Levenberg–Marquardt steps on the model's
//! points held fixed (cheap), inside a trust region, each batch verified by rendering the
//! model again from the new pose (the true cost: visibility and the points change with the
//! pose) and undone when that cost rose.

use super::align::{LevelProblem, Linearised, Mat7, Vec7};
use super::frame::{FrameRegistrar, FrameStatus};
use super::pose::{delta_between, perturb};
use super::pyramid::ObservedPyramid;
use crate::math::Affine;

/// The optimiser's state across levels.
pub(crate) struct State {
    pub pose: Affine,
    pub log_k: f64,
    pub iterations: usize,
    pub converged: bool,
}

/// The model rendered from one pose at one level, with the frame's cost there.
pub(crate) struct Snapshot<'p> {
    pub pose: Affine,
    pub log_k: f64,
    pub prob: LevelProblem<'p>,
    pub lin: Linearised,
    /// Mean robust cost per residual (unused points at the Huber threshold's cost).
    pub mean_cost: f64,
    /// Median distance of the rendered points (mm), for the trust region.
    pub median_depth: f64,
}

impl FrameRegistrar<'_> {
    /// Render the model from `pose` at `level` and evaluate the frame against it.
    pub(crate) fn snapshot<'p>(
        &'p self,
        pyr: &'p ObservedPyramid,
        level: usize,
        pose: &Affine,
        log_k: f64,
        floor: f64,
    ) -> Result<Snapshot<'p>, FrameStatus> {
        let o = &self.opts;
        let view = self
            .model_at(level)
            .view(&self.grids[level], pose, o.min_gamma);
        if view.inside_fraction < 0.5 {
            return Err(FrameStatus::OutsideLumen);
        }
        if view.points.len() < o.min_points {
            return Err(FrameStatus::TooFewPoints);
        }
        let light = &self.model.light;
        let centre = crate::camera::pose::camera_centre(pose).coords;
        let super::photometric::ModelView {
            points,
            index,
            grid_width,
            offset,
            ..
        } = view;
        let mut depth: Vec<f64> = points.iter().map(|q| (q.x - centre).norm()).collect();
        // Levels against the geometry's shading and levels against the texture differ in
        // which image gradient serves them best ([`super::frame::RegistrationOptions`]).
        let grad_blend = match level >= o.uniform_albedo_from_level {
            true => o.geometry_grad_blend,
            false => o.grad_blend,
        };
        let mid = depth.len() / 2;
        let median_depth = *depth.select_nth_unstable_by(mid, |a, b| a.total_cmp(b)).1;
        let mut prob = LevelProblem {
            image: &pyr.levels[level],
            light,
            points,
            offset,
            inv_sigma: Vec::new(),
            huber: o.huber,
            dark: floor as f32,
            ref_cost: Vec::new(),
            model_grad: Vec::new(),
            grad_blend,
        };
        let weights = if level >= o.uniform_albedo_from_level {
            o.uniform_channel_weights
        } else {
            [1.0; 3]
        };
        let at = prob.at_rendered(pose);
        prob.set_reference(&at, log_k, o.relative_sigma, floor, weights);
        if grad_blend > 0.0 {
            let stride = self.grids[level].stride;
            prob.set_model_gradient(&at, &index, grid_width, stride, log_k);
        }
        let lin = prob.evaluate_at_rendered(&at, pose, log_k);
        if lin.used < o.min_points {
            return Err(FrameStatus::TooFewPoints);
        }
        // Pixels that cannot be compared count at the Huber threshold's cost, so that renders
        // with different visible points compare fairly.
        let unused = prob.points.len() - lin.used;
        let penalty = 3.0 * 0.5 * o.huber * o.huber;
        let mean_cost = (lin.cost + unused as f64 * penalty) / (3 * prob.points.len()) as f64;
        Ok(Snapshot {
            pose: *pose,
            log_k,
            prob,
            lin,
            mean_cost,
            median_depth,
        })
    }

    /// Refine `st` at `level`; returns the model rendered at the pose it ends at, `Err` when the
    /// model cannot be compared with the frame.
    pub(crate) fn refine_level<'p>(
        &'p self,
        pyr: &'p ObservedPyramid,
        level: usize,
        st: &mut State,
        floor: f64,
    ) -> Result<Snapshot<'p>, FrameStatus> {
        let o = &self.opts;
        let scale = (1u32 << level) as f64;
        let tol = o.step_tolerance * scale;
        let mut cur = self.snapshot(pyr, level, &st.pose, st.log_k, floor)?;
        // Trust region: `trust_px` level pixels of image motion.
        let px_angle = scale / self.model.parts.camera.fx;
        let base = (
            o.trust_px * px_angle * cur.median_depth,
            o.trust_px * px_angle,
        );
        let mut radius = 1.0;
        let mut lambda = 1e-3;
        st.converged = false;
        for _ in 0..o.max_renders.max(1) {
            let region = (base.0 * radius, base.1 * radius);
            let (pose, log_k, steps, small, reach) = if o.max_inner == 0 {
                let (pose, log_k, steps, small, used) =
                    single_step(&cur, region, lambda, tol, o.estimate_gain);
                (pose, log_k, steps, small, radius * used)
            } else {
                let (pose, log_k, steps, small) =
                    inner_steps(&cur, region, o.max_inner, tol, o.estimate_gain);
                (pose, log_k, steps, small, radius)
            };
            st.iterations += steps;
            // A step under the tolerance is not worth a render.
            if steps == 0 || pose == cur.pose || (o.max_inner == 0 && small) {
                st.converged = true;
                break;
            }
            let next = match self.snapshot(pyr, level, &pose, log_k, floor) {
                Ok(n) if n.mean_cost < cur.mean_cost => n,
                _ => {
                    radius = 0.5
                        * if o.shrink_to_failed_step {
                            reach
                        } else {
                            radius
                        };
                    lambda *= 4.0;
                    if radius < o.min_radius {
                        st.converged = true;
                        break;
                    }
                    continue;
                }
            };
            let moved = delta_between(&cur.pose, &next.pose);
            cur = next;
            radius = (radius * 2.0).min(4.0);
            lambda = (lambda / 3.0).max(1e-7);
            if small && moved.mm() < 0.05 * scale && moved.rotation.norm() < 5e-4 * scale {
                st.converged = true;
                break;
            }
        }
        st.pose = cur.pose;
        st.log_k = cur.log_k;
        Ok(cur)
    }
}

/// One damped Gauss–Newton step from `cur`, kept within `radius` (mm, radians), to be
/// verified by a new render. Returns the pose, log gain, 1, whether the step was under the
/// tolerance and the fraction of `radius` the step used (its larger part).
fn single_step(
    cur: &Snapshot,
    radius: (f64, f64),
    lambda: f64,
    tol: f64,
    with_gain: bool,
) -> (Affine, f64, usize, bool, f64) {
    let Some(step) = solve(&cur.lin, lambda, with_gain) else {
        return (cur.pose, cur.log_k, 0, true, 0.0);
    };
    let (xi, dk, size, used) = within_radius(step, radius);
    (perturb(&cur.pose, &xi), cur.log_k + dk, 1, size < tol, used)
}

/// A solver step scaled down to stay within `radius` (mm, radians): the camera-frame pose step,
/// the log-gain step, the step's size (translation mm, or rotation radians x 100 mm,
/// whichever is larger) for the convergence test, and the fraction of `radius` it uses.
fn within_radius(mut step: Vec7, radius: (f64, f64)) -> ([f64; 6], f64, f64, f64) {
    let t = (step[0] * step[0] + step[1] * step[1] + step[2] * step[2]).sqrt();
    let r = (step[3] * step[3] + step[4] * step[4] + step[5] * step[5]).sqrt();
    let shrink = (radius.0 / t.max(1e-300))
        .min(radius.1 / r.max(1e-300))
        .min(1.0);
    step *= shrink;
    let xi = [step[0], step[1], step[2], step[3], step[4], step[5]];
    let used = (shrink * t / radius.0.max(1e-300)).max(shrink * r / radius.1.max(1e-300));
    (
        xi,
        step[6],
        (shrink * t).max(shrink * r * 1e2),
        used.min(1.0),
    )
}

/// Levenberg–Marquardt on `cur`'s fixed points, the motion from `cur.pose` kept within
/// `radius` (mm, radians). Returns the pose, log gain, steps taken and whether the last step
/// was under the tolerance.
fn inner_steps(
    cur: &Snapshot,
    radius: (f64, f64),
    max_steps: usize,
    tol: f64,
    with_gain: bool,
) -> (Affine, f64, usize, bool) {
    let (mut pose, mut log_k) = (cur.pose, cur.log_k);
    let mut lin = cur.lin.clone();
    let mut lambda = 1e-3;
    let mut steps = 0;
    for _ in 0..max_steps {
        let Some(step) = solve(&lin, lambda, with_gain) else {
            break;
        };
        steps += 1;
        let (xi, dk, size, _) = within_radius(step, radius);
        let cand = perturb(&pose, &xi);
        let cand_k = log_k + dk;
        let trial = cur.prob.evaluate(&cand, cand_k, false);
        if trial.cost < lin.cost {
            pose = cand;
            log_k = cand_k;
            lambda = (lambda / 3.0).max(1e-7);
            // Rotation weighed by 100 mm: 0.02 mrad moves a pixel about 0.003 px.
            if size < tol {
                return (pose, log_k, steps, true);
            }
            let total = delta_between(&cur.pose, &pose);
            if total.mm() >= radius.0 || total.rotation.norm() >= radius.1 {
                break;
            }
            lin = cur.prob.evaluate(&pose, log_k, true);
        } else {
            lambda *= 5.0;
            if lambda > 1e6 {
                return (pose, log_k, steps, true);
            }
        }
    }
    (pose, log_k, steps, false)
}

/// The damped Gauss–Newton step `-(H + lambda diag H)^-1 b` (the gain column dropped when not
/// estimated); `None` when singular.
fn solve(lin: &Linearised, lambda: f64, with_gain: bool) -> Option<Vec7> {
    let n = if with_gain { 7 } else { 6 };
    let mut h = lin.h;
    for i in 0..7 {
        h[(i, i)] += lambda * h[(i, i)].max(1e-9);
    }
    let hn = h.view((0, 0), (n, n)).into_owned();
    let bn = lin.b.rows(0, n).into_owned();
    let x = hn.cholesky()?.solve(&bn);
    let mut out = Vec7::zeros();
    for i in 0..n {
        out[i] = -x[i];
    }
    Some(out)
}

/// The information of the six pose parameters with the gain eliminated (Schur complement).
pub(crate) fn pose_information(h: &Mat7) -> [[f64; 6]; 6] {
    let hkk = h[(6, 6)];
    std::array::from_fn(|i| {
        std::array::from_fn(|j| {
            let s = if hkk > 0.0 {
                h[(i, 6)] * h[(j, 6)] / hkk
            } else {
                0.0
            };
            h[(i, j)] - s
        })
    })
}
