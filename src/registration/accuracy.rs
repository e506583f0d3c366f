//! How far poses are from known true ones (issue 16 item 4: `build` and `register` report it
//! when the case comes with its truth, as the phantom's does). Besides the median, the error
//! along each of the true camera's axes, averaged and RMS over the frames: a mean close to the
//! RMS is an error the frames share (the whole video off the same way), which held-out frames
//! cannot show and new views pay for.

use super::pose::{pose_error, pose_error_axes};
use crate::math::Affine;
use serde::{Deserialize, Serialize};

/// Pose errors of a set of frames against their true poses. Axes are the true camera's (x
/// right, y down, z along the view); rotations are the rotation vector of `R_true^T R` (pitch
/// about x, yaw about y, roll about z).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct PoseAccuracy {
    /// Frames compared.
    pub frames: usize,
    /// Median camera-centre error (mm).
    pub median_mm: f64,
    /// Median rotation error (degrees).
    pub median_deg: f64,
    /// Frames within 1 mm and 1 degree of their true pose.
    pub within_1mm_1deg: usize,
    /// Mean centre error along x, y, z (mm).
    pub mean_mm: [f64; 3],
    /// RMS centre error along x, y, z (mm).
    pub rms_mm: [f64; 3],
    /// Mean rotation error about x, y, z (degrees).
    pub mean_deg: [f64; 3],
    /// RMS rotation error about x, y, z (degrees).
    pub rms_deg: [f64; 3],
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    let n = v.len();
    match n {
        0 => f64::NAN,
        _ if n % 2 == 1 => v[n / 2],
        _ => 0.5 * (v[n / 2 - 1] + v[n / 2]),
    }
}

impl PoseAccuracy {
    /// The errors of `poses` against `truth` (pairwise; `None` when there is no pair).
    pub fn of(poses: &[Affine], truth: &[Affine]) -> Option<PoseAccuracy> {
        let n = poses.len().min(truth.len());
        if n == 0 {
            return None;
        }
        let pairs = || poses.iter().zip(truth);
        let errors: Vec<(f64, f64)> = pairs().map(|(p, t)| pose_error(p, t)).collect();
        let (mut mean_mm, mut rms_mm, mut mean_deg, mut rms_deg) =
            ([0.0; 3], [0.0; 3], [0.0; 3], [0.0; 3]);
        for (p, t) in pairs() {
            let (dt, dr) = pose_error_axes(p, t);
            for k in 0..3 {
                mean_mm[k] += dt[k] / n as f64;
                rms_mm[k] += dt[k] * dt[k] / n as f64;
                mean_deg[k] += dr[k] / n as f64;
                rms_deg[k] += dr[k] * dr[k] / n as f64;
            }
        }
        Some(PoseAccuracy {
            frames: n,
            median_mm: median(errors.iter().map(|e| e.0).collect()),
            median_deg: median(errors.iter().map(|e| e.1).collect()),
            within_1mm_1deg: errors.iter().filter(|e| e.0 <= 1.0 && e.1 <= 1.0).count(),
            mean_mm,
            rms_mm: rms_mm.map(f64::sqrt),
            mean_deg,
            rms_deg: rms_deg.map(f64::sqrt),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::registration::pose::perturb;

    #[test]
    fn a_shared_turn_and_shift_are_measured_on_their_axes() {
        // Four camera poses looking different ways; each estimate turned 0.5 deg about its own
        // camera's x axis and moved 0.2 mm along its own z, plus a frame-to-frame +-0.1 mm in y.
        let truth: Vec<Affine> = (0..4)
            .map(|k| {
                let a = 0.7 * k as f64;
                perturb(&Affine::identity(), &[k as f64, 2.0, -1.0, 0.3 * a, a, 0.2])
            })
            .collect();
        let est: Vec<Affine> = truth
            .iter()
            .enumerate()
            .map(|(k, t)| {
                let dy = if k % 2 == 0 { 0.1 } else { -0.1 };
                perturb(t, &[0.0, dy, 0.2, 0.5f64.to_radians(), 0.0, 0.0])
            })
            .collect();
        let acc = PoseAccuracy::of(&est, &truth).unwrap();
        assert_eq!((acc.frames, acc.within_1mm_1deg), (4, 4));
        assert!((acc.mean_deg[0] - 0.5).abs() < 1e-6, "{acc:?}");
        assert!((acc.rms_deg[0] - 0.5).abs() < 1e-6, "{acc:?}");
        assert!(
            acc.mean_deg[1].abs() < 1e-6 && acc.mean_deg[2].abs() < 1e-6,
            "{acc:?}"
        );
        assert!((acc.median_deg - 0.5).abs() < 1e-6, "{acc:?}");
        assert!(
            acc.mean_mm[1].abs() < 1e-9 && (acc.rms_mm[1] - 0.1).abs() < 1e-9,
            "{acc:?}"
        );
        assert!((acc.mean_mm[2] - 0.2).abs() < 1e-9, "{acc:?}");
        assert!((acc.median_mm - (0.2f64.powi(2) + 0.1f64.powi(2)).sqrt()).abs() < 1e-9);
        assert!(PoseAccuracy::of(&[], &truth).is_none());
    }
}
