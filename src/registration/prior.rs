//! The video's continuity as a prior on the corrections: a tracker's error is a smooth drift
//! plus per-frame jitter, so the correction of frame f is `d_f + j_f`, d a random walk with
//! small steps, j independent. Each frame's measured correction `m_f = d_f + j_f + n_f` has a
//! registration noise n. The smoother solves for the drift (a block-tridiagonal least-squares
//! problem over the video) and keeps from each frame's own measurement the share its jitter
//! explains: where registration is precise the measured correction stands, where it is weakly
//! constrained (roll about a straight airway, translation along it) the neighbours decide.
//!
//! The noise n is modelled per camera axis from the video, or per frame from its own
//! registration ([`MeasurementNoise`]): the Gauss–Newton information of its pose says which
//! combinations of axes the frame's image fixes. In a tube the weak direction is not an axis
//! but a roll coupled with a sideways shift (the turn about the airway's axis), and it changes
//! with what the frame sees: measured on the demo phantom's geometry round (1.5 mm / 2 deg
//! drift), smoothing with each frame's information leaves roll 0.43 deg RMS where one noise per
//! camera axis leaves 0.87 deg (the information's diagonal alone: 1.34 deg).

use super::pose::PoseDelta;
use crate::math::Matrix3;
use nalgebra::{SMatrix, SVector};

type M6 = SMatrix<f64, 6, 6>;
type V6 = SVector<f64, 6>;

/// The tracker's error model (all per frame, RMS along each axis).
#[derive(Clone, Debug)]
pub struct DriftPrior {
    /// Jitter of the camera centre (mm, 3-D RMS).
    pub jitter_mm: f64,
    /// Jitter of the orientation (degrees, RMS angle).
    pub jitter_deg: f64,
    /// Change of the drift from one frame to the next (mm, 3-D RMS).
    pub drift_step_mm: f64,
    /// Change of the drift's rotation from one frame to the next (degrees).
    pub drift_step_deg: f64,
    /// How each frame's registration noise is modelled.
    pub noise: MeasurementNoise,
}

/// The registration noise of a frame's measured correction.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum MeasurementNoise {
    /// One size per camera axis for every frame, estimated from the scatter of the video's
    /// second differences.
    PerAxis,
    /// Each frame's Gauss–Newton information of its pose divided by `deflation`: the
    /// residuals' model error is smooth across the image, so neighbouring pixels are far from
    /// independent and the information overstates the precision by about that factor in
    /// variance. Measured on the demo phantom against its truth: the chi-square of the
    /// geometry round's true errors under the undeflated information has a median of
    /// 2,100-2,500 (6 for a calibrated one); smoothing the round with deflation 50 / 200 /
    /// 500 / 1,000 leaves 1.45 / 0.75 / 0.83 / 0.86 deg median from 1.5 mm / 2 deg drift and
    /// 0.87 / 0.45 / 0.42 / 0.41 deg from the true poses. The texture rounds gain nothing from
    /// it (within 0.02 deg on the demo phantom, 0.36 against 0.3 deg on a 24-frame 160x160 one).
    Information {
        /// Factor the information is divided by.
        deflation: f64,
    },
}

impl Default for DriftPrior {
    fn default() -> Self {
        DriftPrior {
            jitter_mm: 0.3,
            jitter_deg: 0.3,
            drift_step_mm: 0.1,
            drift_step_deg: 0.1,
            noise: MeasurementNoise::PerAxis,
        }
    }
}

/// What the smoother found.
#[derive(Clone, Debug)]
pub struct Smoothed {
    /// The corrections to use, per frame.
    pub corrections: Vec<PoseDelta>,
    /// The registration noise estimated per camera axis: x, y, z (mm), rotation about x, y,
    /// z (degrees).
    pub noise: [f64; 6],
}

fn to_v6(d: &PoseDelta) -> V6 {
    V6::from(d.to_array())
}

fn diag(v: [f64; 6]) -> M6 {
    M6::from_diagonal(&V6::from(v))
}

/// Camera-to-world rotation of both halves of a correction.
fn block_rot(r: &Matrix3<f64>) -> M6 {
    let mut b = M6::zeros();
    b.fixed_view_mut::<3, 3>(0, 0).copy_from(r);
    b.fixed_view_mut::<3, 3>(3, 3).copy_from(r);
    b
}

/// The registration noise per camera axis: robust variance of the second differences of the
/// corrections (`6 (jitter^2 + noise^2)` for white parts) minus the jitter's share.
fn estimate_noise(m: &[V6], rot: &[Matrix3<f64>], usable: &[bool], jitter: &[f64; 6]) -> [f64; 6] {
    let mut per_axis: [Vec<f64>; 6] = Default::default();
    for f in 1..m.len().saturating_sub(1) {
        if !(usable[f - 1] && usable[f] && usable[f + 1]) {
            continue;
        }
        let d2 = block_rot(&rot[f]).transpose() * (m[f - 1] - 2.0 * m[f] + m[f + 1]);
        for (k, v) in per_axis.iter_mut().enumerate() {
            v.push(d2[k].abs());
        }
    }
    std::array::from_fn(|k| {
        let v = &mut per_axis[k];
        if v.len() < 5 {
            return 0.0;
        }
        let mid = v.len() / 2;
        let mad = *v.select_nth_unstable_by(mid, f64::total_cmp).1;
        // Median absolute value of a normal deviate is 0.6745 sigma.
        let var = (mad / 0.6745).powi(2) / 6.0 - jitter[k] * jitter[k];
        var.max(0.0).sqrt()
    })
}

/// Smooth the measured corrections `measured` (relative to the given poses) of a video whose
/// frames have camera → world rotations `rot` and registered with Gauss–Newton `information`
/// (camera-frame step of [`super::pose::perturb`]; read with [`MeasurementNoise::Information`]);
/// frames not `usable` (not converged) take the drift alone. `frame_numbers` are the frames'
/// positions in the video (increasing; empty: consecutive): the drift walks one step per video
/// frame, so after a frame selection two kept frames `k` apart are `k` steps apart. See the
/// module docs. `anchored` frames (missing: none) are known exactly: their correction is
/// zero, and their neighbours' drift is pinned there.
pub fn smooth_corrections(
    measured: &[PoseDelta],
    rot: &[Matrix3<f64>],
    information: &[[[f64; 6]; 6]],
    usable: &[bool],
    anchored: &[bool],
    frame_numbers: &[usize],
    prior: &DriftPrior,
) -> Smoothed {
    let anchored: Vec<bool> = (0..measured.len())
        .map(|f| anchored.get(f) == Some(&true))
        .collect();
    let m: Vec<V6> = measured
        .iter()
        .zip(&anchored)
        .map(|(d, &a)| if a { V6::zeros() } else { to_v6(d) })
        .collect();
    let noise = estimate_noise(&m, rot, usable, &jitter_of(prior));
    let mut smoothed = match prior.noise {
        MeasurementNoise::PerAxis => {
            smooth_with_noise(&m, rot, usable, &anchored, frame_numbers, prior, noise)
        }
        MeasurementNoise::Information { deflation } => {
            // The jitter's own precision, shared by every frame (zero jitter: nothing to add).
            let sj_inv = jitter_covariance(prior).try_inverse();
            let info: Vec<M6> = (0..m.len())
                .map(|f| match (usable[f], information.get(f), &sj_inv) {
                    (true, Some(i), Some(sj_inv)) => {
                        registered_information(&rot[f], i, deflation, sj_inv)
                    }
                    _ => M6::zeros(),
                })
                .collect();
            smooth_with_information(&m, &info, &anchored, frame_numbers, prior, noise)
        }
    };
    for (c, _) in smoothed
        .corrections
        .iter_mut()
        .zip(&anchored)
        .filter(|(_, &a)| a)
    {
        *c = PoseDelta::default();
    }
    smoothed
}

/// The precision of an anchored frame's zero correction (per mm², per rad²): far above any
/// registration's and the drift's (a step of 0.01 mm: 10⁴).
const ANCHOR_PRECISION: f64 = 1e12;

/// The jitter per axis (mm, mm, mm, rad, rad, rad) of `prior`.
fn jitter_of(prior: &DriftPrior) -> [f64; 6] {
    let jt = prior.jitter_mm / 3f64.sqrt();
    let jr = prior.jitter_deg.to_radians() / 3f64.sqrt();
    [jt, jt, jt, jr, jr, jr]
}

fn jitter_covariance(prior: &DriftPrior) -> M6 {
    diag(jitter_of(prior).map(|v| v * v))
}

/// A frame's precision for the drift, `(jitter + noise)^-1`, with the noise's information the
/// frame's own (camera frame) divided by `deflation`: in world terms `Iw = B I B^T / deflation`,
/// and `(S + Iw^-1)^-1 = Iw (Iw + S^-1)^-1 S^-1` (`sj_inv` = `S^-1`, the jitter's precision),
/// which stays finite where the image fixes nothing (`Iw` singular).
fn registered_information(
    rot: &Matrix3<f64>,
    information: &[[f64; 6]; 6],
    deflation: f64,
    sj_inv: &M6,
) -> M6 {
    let b = block_rot(rot);
    let i_cam = M6::from_fn(|r, c| information[r][c]);
    let iw = b * i_cam * b.transpose() / deflation.max(f64::MIN_POSITIVE);
    let Some(mid) = (iw + sj_inv).try_inverse() else {
        return M6::zeros();
    };
    let info = iw * mid * sj_inv;
    (info + info.transpose()) * 0.5
}

/// [`smooth_corrections`] with one registration noise per camera axis for every frame (mm,
/// radians).
fn smooth_with_noise(
    m: &[V6],
    rot: &[Matrix3<f64>],
    usable: &[bool],
    anchored: &[bool],
    frame_numbers: &[usize],
    prior: &DriftPrior,
    noise: [f64; 6],
) -> Smoothed {
    let sj = jitter_covariance(prior);
    // Each frame's precision for the drift: (jitter + noise)^-1, the noise along its camera axes.
    let info: Vec<M6> = (0..m.len())
        .map(|f| {
            if !usable[f] {
                return M6::zeros();
            }
            let b = block_rot(&rot[f]);
            let cov = sj + b * diag(noise.map(|v| v * v)) * b.transpose();
            cov.try_inverse().unwrap_or_else(M6::zeros)
        })
        .collect();
    smooth_with_information(m, &info, anchored, frame_numbers, prior, noise)
}

/// The smoother itself, given each frame's precision `info` for the drift (zero: the frame
/// was not measured; `anchored`: the drift is pinned at its measurement); `noise` is passed
/// through to the result.
fn smooth_with_information(
    m: &[V6],
    info: &[M6],
    anchored: &[bool],
    frame_numbers: &[usize],
    prior: &DriftPrior,
    noise: [f64; 6],
) -> Smoothed {
    let n = m.len();
    let pinned = M6::identity() * ANCHOR_PRECISION;
    let info: Vec<M6> = (0..n)
        .map(|f| match anchored.get(f) {
            Some(true) => pinned,
            _ => info[f],
        })
        .collect();
    let sj = jitter_covariance(prior);
    // Random-walk precision of the drift.
    let (dt, dr) = (
        prior.drift_step_mm / 3f64.sqrt(),
        prior.drift_step_deg.to_radians() / 3f64.sqrt(),
    );
    let p = diag([dt, dt, dt, dr, dr, dr].map(|v| 1.0 / (v * v)));
    // links[f]: the precision of the drift's change from frame f - 1 to f (a random walk of
    // `steps` steps has `steps` times the variance of one); links[0] is unused.
    let links: Vec<M6> = (0..n)
        .map(|f| {
            let steps = match (f, frame_numbers.len() == n) {
                (0, _) | (_, false) => 1,
                (_, true) => frame_numbers[f].saturating_sub(frame_numbers[f - 1]).max(1),
            };
            p / steps as f64
        })
        .collect();
    // Block-tridiagonal system:
    // (J_f + P_f + P_{f+1}) d_f - P_f d_{f-1} - P_{f+1} d_{f+1} = J_f m_f.
    let mut diag_b: Vec<M6> = (0..n)
        .map(|f| {
            let mut b = info[f];
            if f > 0 {
                b += links[f];
            }
            if f + 1 < n {
                b += links[f + 1];
            }
            b
        })
        .collect();
    let mut rhs: Vec<V6> = (0..n).map(|f| info[f] * m[f]).collect();
    // Forward elimination (block Thomas); the off-diagonal blocks are -P_f.
    for f in 1..n {
        let Some(inv) = diag_b[f - 1].try_inverse() else {
            continue;
        };
        let l = links[f] * inv;
        diag_b[f] -= l * links[f];
        rhs[f] = rhs[f] + l * rhs[f - 1];
    }
    let mut d = vec![V6::zeros(); n];
    for f in (0..n).rev() {
        let r = if f + 1 < n {
            rhs[f] + links[f + 1] * d[f + 1]
        } else {
            rhs[f]
        };
        d[f] = diag_b[f].try_inverse().map_or(V6::zeros(), |inv| inv * r);
    }
    let corrections = (0..n)
        .map(|f| {
            // The frame's own jitter: its share of the measured departure from the drift.
            let v = d[f] + sj * info[f] * (m[f] - d[f]);
            PoseDelta::from_array(&v.into())
        })
        .collect();
    Smoothed {
        corrections,
        noise: [
            noise[0],
            noise[1],
            noise[2],
            noise[3].to_degrees(),
            noise[4].to_degrees(),
            noise[5].to_degrees(),
        ],
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::math::Vector3;
    use crate::rng::Pcg32;

    /// Camera → world rotation of a camera looking along world +x (camera z = world x).
    fn looking_along_x() -> Matrix3<f64> {
        Matrix3::new(0.0, 0.0, 1.0, 0.0, 1.0, 0.0, -1.0, 0.0, 0.0)
    }

    /// RMS over the frames of `f(a) - f(truth)`.
    fn rms_against(a: &[PoseDelta], truth: &[PoseDelta], f: &dyn Fn(&PoseDelta) -> f64) -> f64 {
        let sum: f64 = a
            .iter()
            .zip(truth)
            .map(|(x, t)| (f(x) - f(t)).powi(2))
            .sum();
        (sum / a.len() as f64).sqrt()
    }

    /// `truth` measured with `deg` degrees RMS of noise on the roll of a camera looking along
    /// world +x (about world x), nothing elsewhere.
    fn with_roll_noise(truth: &[PoseDelta], deg: f64, rng: &mut Pcg32) -> Vec<PoseDelta> {
        truth
            .iter()
            .map(|d| PoseDelta {
                rotation: d.rotation
                    + Vector3::new(1.0, 0.0, 0.0) * deg.to_radians() * rng.normal(),
                ..*d
            })
            .collect()
    }

    #[test]
    fn noisy_roll_is_smoothed_and_precise_axes_are_kept() {
        // 120 frames looking along world +x (camera z = world x), a smooth drift plus jitter as
        // the true correction; measurements add 2 degrees of noise to the roll (about camera
        // z) and nothing elsewhere.
        let n = 120;
        let r = looking_along_x();
        let mut rng = Pcg32::new(3, 1);
        let truth: Vec<PoseDelta> = (0..n)
            .map(|f| {
                let t = f as f64 / n as f64;
                PoseDelta {
                    translation_mm: Vector3::new(1.0 + t, (6.0 * t).sin(), 0.5)
                        + Vector3::new(rng.normal(), rng.normal(), rng.normal()) * 0.17,
                    rotation: Vector3::new(0.02 * (4.0 * t).cos(), 0.01, -0.02)
                        + Vector3::new(rng.normal(), rng.normal(), rng.normal()) * 0.003,
                }
            })
            .collect();
        let measured = with_roll_noise(&truth, 2.0, &mut rng);
        let s = smooth_corrections(
            &measured,
            &vec![r; n],
            &[],
            &vec![true; n],
            &[],
            &[],
            &DriftPrior {
                noise: MeasurementNoise::PerAxis,
                ..DriftPrior::default()
            },
        );
        // The roll noise is found (about 2 degrees), the other axes are clean.
        assert!((s.noise[5] - 2.0).abs() < 0.5, "{:?}", s.noise);
        assert!(s.noise[0] < 0.05 && s.noise[3] < 0.1, "{:?}", s.noise);
        let rms = |a: &[PoseDelta], f: &dyn Fn(&PoseDelta) -> f64| rms_against(a, &truth, f);
        let roll = |d: &PoseDelta| d.rotation.x.to_degrees();
        let (before, after) = (rms(&measured, &roll), rms(&s.corrections, &roll));
        assert!(
            after < 0.3 * before,
            "roll error {before:.3} -> {after:.3} deg"
        );
        // Translations were measured exactly: they stay within a hundredth of a mm.
        let tx = |d: &PoseDelta| d.translation_mm.y;
        assert!(
            rms(&s.corrections, &tx) < 0.01,
            "{}",
            rms(&s.corrections, &tx)
        );
    }

    #[test]
    fn an_anchored_frame_pins_the_drift_of_its_neighbours() {
        // A drift that is zero at the first frame (its pose is given exactly) and grows along
        // the video; the roll measured with 2 degrees of noise. Anchoring the first frame
        // keeps it at zero and pulls its neighbours' roll onto the truth (free, the stiff drift
        // leaves them at the video's mean error).
        let n = 60;
        let r = looking_along_x();
        let mut rng = Pcg32::new(5, 2);
        let truth: Vec<PoseDelta> = (0..n)
            .map(|f| {
                let t = f as f64 / n as f64;
                PoseDelta {
                    translation_mm: Vector3::new(0.8 * t, 0.3 * t, 0.0),
                    rotation: Vector3::new(0.03 * t, 0.0, 0.01 * t),
                }
            })
            .collect();
        let measured = with_roll_noise(&truth, 2.0, &mut rng);
        let prior = DriftPrior {
            noise: MeasurementNoise::PerAxis,
            ..DriftPrior::default()
        };
        let mut anchored = vec![false; n];
        anchored[0] = true;
        let smooth = |anchored: &[bool]| {
            smooth_corrections(
                &measured,
                &vec![r; n],
                &[],
                &vec![true; n],
                anchored,
                &[],
                &prior,
            )
            .corrections
        };
        let (free, pinned) = (smooth(&[]), smooth(&anchored));
        assert_eq!(pinned[0], PoseDelta::default());
        let roll = |d: &PoseDelta| d.rotation.x.to_degrees();
        let near = 0..10;
        let (e_free, e_pinned) = (
            rms_against(&free[near.clone()], &truth[near.clone()], &roll),
            rms_against(&pinned[near.clone()], &truth[near], &roll),
        );
        // Measured: 0.576 deg free, 0.051 deg anchored (seeds 6-8: 0.641 / 0.032, 0.958 / 0.020,
        // 0.297 / 0.097).
        assert!(e_pinned < 0.3 * e_free, "{e_free:.3} -> {e_pinned:.3} deg");
    }

    #[test]
    fn kept_frames_far_apart_are_linked_by_as_many_drift_steps() {
        // Frames 0, 3, 4, 9, 15, 16 of a 17-frame video kept: smoothing them with their frame
        // numbers must equal smoothing the whole video with only those frames measured (the
        // others carry no information, so k steps through them are one link of k steps).
        let kept = [0usize, 3, 4, 9, 15, 16];
        let mut rng = Pcg32::new(11, 3);
        let mut draw = || {
            let mut v = || Vector3::new(rng.normal(), rng.normal(), rng.normal());
            PoseDelta {
                translation_mm: v() * 0.4,
                rotation: v() * 0.4f64.to_radians(),
            }
        };
        let measured: Vec<PoseDelta> = kept.iter().map(|_| draw()).collect();
        let r = Matrix3::identity();
        let prior = DriftPrior::default();
        // Registration noise on every axis, so that the drift matters (without it each frame
        // keeps its own measurement).
        let noise = [0.3, 0.3, 0.3, 0.01, 0.01, 0.01];
        let m: Vec<V6> = measured.iter().map(to_v6).collect();
        let sub = smooth_with_noise(&m, &vec![r; 6], &[true; 6], &[], &kept, &prior, noise);
        let mut full_m = vec![V6::zeros(); 17];
        let mut usable = vec![false; 17];
        for (k, &f) in kept.iter().enumerate() {
            full_m[f] = m[k];
            usable[f] = true;
        }
        let full = smooth_with_noise(&full_m, &vec![r; 17], &usable, &[], &[], &prior, noise);
        let far = |a: &PoseDelta, b: &PoseDelta| {
            (a.translation_mm - b.translation_mm).norm() + (a.rotation - b.rotation).norm()
        };
        for (k, &f) in kept.iter().enumerate() {
            let d = far(&sub.corrections[k], &full.corrections[f]);
            assert!(d < 1e-9, "frame {f}: {d}");
        }
        // The smoother moved the measurements, and taken as consecutive frames they are
        // smoothed harder.
        let off: f64 = (0..6).map(|k| far(&sub.corrections[k], &measured[k])).sum();
        assert!(off > 1e-3, "{off}");
        let consecutive = smooth_with_noise(&m, &vec![r; 6], &[true; 6], &[], &[], &prior, noise);
        let moved: f64 = (0..6)
            .map(|k| far(&consecutive.corrections[k], &sub.corrections[k]))
            .sum();
        assert!(moved > 1e-3, "{moved}");
    }

    #[test]
    fn coupled_weak_direction_is_smoothed_by_each_frames_information() {
        // Frames looking along world +x inside a tube whose axis passes `r` mm beside the
        // camera (r changes along the video): a turn about the axis (a roll coupled with a
        // sideways shift of r x the angle) is what the image cannot fix. Each frame's
        // measurement noise is large along that direction and small elsewhere; its information
        // says so. No single noise per camera axis can describe the coupling.
        let n = 160;
        let r_cam = looking_along_x();
        let mut rng = Pcg32::new(7, 5);
        let truth: Vec<PoseDelta> = (0..n)
            .map(|f| {
                let t = f as f64 / n as f64;
                PoseDelta {
                    translation_mm: Vector3::new(0.5 * t, 0.3 * (5.0 * t).sin(), -0.2),
                    rotation: Vector3::new(0.015 * (3.0 * t).cos(), 0.005, 0.01 * t),
                }
            })
            .collect();
        let deflation = 50.0;
        let weak = 2f64.to_radians();
        let strong = V6::from([0.02, 0.02, 0.02, 1e-3, 1e-3, 1e-3]);
        let mut information = Vec::new();
        let measured: Vec<PoseDelta> = truth
            .iter()
            .enumerate()
            .map(|(f, d)| {
                let r = 3.0 * (f as f64 / 20.0).sin();
                // Camera-frame step (v, w) of a turn about the axis: roll w_z, the centre
                // moving r w_z along y.
                let a = V6::from([0.0, r, 0.0, 0.0, 0.0, 1.0]);
                let cov = M6::from_diagonal(&strong.component_mul(&strong))
                    + a * a.transpose() * weak * weak;
                let info = cov.try_inverse().unwrap() * deflation;
                information.push(std::array::from_fn(|i| {
                    std::array::from_fn(|j| info[(i, j)])
                }));
                let e = a * (weak * rng.normal()) + V6::from_fn(|i, _| strong[i] * rng.normal());
                let w = block_rot(&r_cam) * e;
                PoseDelta {
                    translation_mm: d.translation_mm + Vector3::new(w[0], w[1], w[2]),
                    rotation: d.rotation + Vector3::new(w[3], w[4], w[5]),
                }
            })
            .collect();
        let rms = |a: &[PoseDelta], f: &dyn Fn(&PoseDelta) -> f64| rms_against(a, &truth, f);
        let roll = |d: &PoseDelta| d.rotation.x.to_degrees();
        let side = |d: &PoseDelta| d.translation_mm.y;
        let smooth = |noise| {
            let prior = DriftPrior {
                noise,
                ..DriftPrior::default()
            };
            smooth_corrections(
                &measured,
                &vec![r_cam; n],
                &information,
                &vec![true; n],
                &[],
                &[],
                &prior,
            )
            .corrections
        };
        let by_info = smooth(MeasurementNoise::Information { deflation });
        let by_axis = smooth(MeasurementNoise::PerAxis);
        let (m, i, a) = (
            rms(&measured, &roll),
            rms(&by_info, &roll),
            rms(&by_axis, &roll),
        );
        // Roll is smoothed as well as one noise per axis does it...
        assert!(
            i < 0.25 * m && i < 1.1 * a,
            "roll RMS: measured {m:.3}, information {i:.3}, per axis {a:.3} deg"
        );
        let (m, i, a) = (
            rms(&measured, &side),
            rms(&by_info, &side),
            rms(&by_axis, &side),
        );
        // ...and the sideways shift coupled with it is too, which the per-axis noise takes for
        // precise (the centre's y is measured to 0.02 mm but for the turn).
        assert!(
            i < 0.4 * m && i < 0.4 * a,
            "sideways RMS: measured {m:.3}, information {i:.3}, per axis {a:.3} mm"
        );
    }
}
