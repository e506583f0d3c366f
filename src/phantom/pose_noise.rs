//! Tracker-like pose errors for the phantom (issue 16 item 4): a smooth drift (an
//! electromagnetic tracker's field distortion and breathing, a registration offset) plus
//! per-frame jitter, scaled to a chosen RMS error.
//!
//! Each of the six components (centre x, y, z; rotation about world x, y, z) drifts as a
//! constant offset plus three sinusoids of 0.25 to 1.5 cycles over the video with random
//! phases; the jitter is independent per frame. Errors are applied as in
//! [`crate::registration::pose`]: the centre moves, the camera turns about its centre.

use crate::math::{Affine, Vector3};
use crate::registration::pose::{apply_delta, PoseDelta};
use crate::rng::Pcg32;
use serde::Serialize;

/// Size of the error (RMS over frames of the centre distance and of the rotation angle).
#[derive(Clone, Debug, Serialize, PartialEq)]
pub struct PoseNoise {
    /// RMS distance between the noisy and the true camera centre (mm).
    pub rms_mm: f64,
    /// RMS rotation angle between the noisy and the true camera (degrees).
    pub rms_deg: f64,
    /// RMS of the per-frame jitter inside the total (mm); at most half of `rms_mm`.
    pub jitter_mm: f64,
    /// RMS of the per-frame jitter inside the total (degrees); at most half of `rms_deg`.
    pub jitter_deg: f64,
}

impl PoseNoise {
    /// A total error of `rms_mm` and `rms_deg` with the default jitter (0.3 mm, 0.3 degrees).
    pub fn new(rms_mm: f64, rms_deg: f64) -> PoseNoise {
        PoseNoise {
            rms_mm,
            rms_deg,
            jitter_mm: 0.3,
            jitter_deg: 0.3,
        }
    }

    /// True when there is no error to add.
    pub fn is_zero(&self) -> bool {
        self.rms_mm <= 0.0 && self.rms_deg <= 0.0
    }
}

/// One component's error over the video: offset + three sinusoids (unit RMS before scaling).
fn drift(rng: &mut Pcg32, n: usize) -> Vec<f64> {
    let offset = rng.normal();
    let waves: Vec<(f64, f64, f64)> = (0..3)
        .map(|_| {
            let cycles = rng.range(0.25, 1.5);
            let phase = rng.range(0.0, std::f64::consts::TAU);
            (rng.normal(), cycles, phase)
        })
        .collect();
    (0..n)
        .map(|i| {
            let t = i as f64 / n.max(2).saturating_sub(1) as f64;
            offset
                + waves
                    .iter()
                    .map(|(a, c, p)| a * (std::f64::consts::TAU * c * t + p).sin())
                    .sum::<f64>()
        })
        .collect()
}

/// RMS of the norms of 3-vectors.
fn rms(v: &[Vector3<f64>]) -> f64 {
    (v.iter().map(|x| x.norm_squared()).sum::<f64>() / v.len().max(1) as f64).sqrt()
}

/// Drift + jitter of one kind (translation or rotation) with a total RMS of `total` and a
/// jitter of RMS `jitter` (capped at half the total).
fn error_series(rng: &mut Pcg32, n: usize, total: f64, jitter: f64) -> Vec<Vector3<f64>> {
    if total <= 0.0 || n == 0 {
        return vec![Vector3::zeros(); n];
    }
    let d: Vec<Vec<f64>> = (0..3).map(|_| drift(rng, n)).collect();
    let drift_v: Vec<Vector3<f64>> = (0..n)
        .map(|i| Vector3::new(d[0][i], d[1][i], d[2][i]))
        .collect();
    let jit: Vec<Vector3<f64>> = (0..n)
        .map(|_| Vector3::new(rng.normal(), rng.normal(), rng.normal()))
        .collect();
    let j = jitter.min(0.5 * total);
    let drift_rms = (total * total - j * j).sqrt();
    let (sd, sj) = (drift_rms / rms(&drift_v), j / rms(&jit));
    let sum: Vec<Vector3<f64>> = drift_v
        .iter()
        .zip(&jit)
        .map(|(a, b)| a * sd + b * sj)
        .collect();
    // The two parts are not exactly uncorrelated over a short video: scale to the exact total.
    let k = total / rms(&sum);
    sum.into_iter().map(|v| v * k).collect()
}

/// Tracker-like versions of the true `poses` with the error `noise`, seeded.
pub fn tracker_poses(poses: &[Affine], noise: &PoseNoise, seed: u64) -> Vec<Affine> {
    if noise.is_zero() {
        return poses.to_vec();
    }
    let n = poses.len();
    let mut rng = Pcg32::new(seed, 0x7AC);
    let t = error_series(&mut rng, n, noise.rms_mm, noise.jitter_mm);
    let r = error_series(
        &mut rng,
        n,
        noise.rms_deg.to_radians(),
        noise.jitter_deg.to_radians(),
    );
    poses
        .iter()
        .zip(t.iter().zip(&r))
        .map(|(p, (t, r))| {
            apply_delta(
                p,
                &PoseDelta {
                    translation_mm: *t,
                    rotation: *r,
                },
            )
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::registration::pose::pose_error;

    #[test]
    fn the_error_has_the_requested_rms_and_is_mostly_smooth() {
        let truth: Vec<Affine> = (0..80)
            .map(|i| {
                let mut m = Affine::identity();
                m[(2, 3)] = i as f64 * 1.7;
                m
            })
            .collect();
        let noisy = tracker_poses(&truth, &PoseNoise::new(1.5, 2.0), 9);
        let errs: Vec<(f64, f64)> = noisy
            .iter()
            .zip(&truth)
            .map(|(a, b)| pose_error(a, b))
            .collect();
        let rms_mm = (errs.iter().map(|e| e.0 * e.0).sum::<f64>() / 80.0).sqrt();
        let rms_deg = (errs.iter().map(|e| e.1 * e.1).sum::<f64>() / 80.0).sqrt();
        assert!((rms_mm - 1.5).abs() < 1e-9, "{rms_mm}");
        assert!((rms_deg - 2.0).abs() < 1e-6, "{rms_deg}");
        // Consecutive errors differ by about the jitter (sqrt 2 x 0.3 mm), far less than the
        // total: the error is a drift, not white noise.
        let steps: Vec<f64> = noisy
            .windows(2)
            .zip(truth.windows(2))
            .map(|(a, b)| {
                let ea = a[0].fixed_view::<3, 1>(0, 3) - b[0].fixed_view::<3, 1>(0, 3);
                let eb = a[1].fixed_view::<3, 1>(0, 3) - b[1].fixed_view::<3, 1>(0, 3);
                (ea - eb).norm()
            })
            .collect();
        let step_rms = (steps.iter().map(|s| s * s).sum::<f64>() / steps.len() as f64).sqrt();
        assert!(step_rms > 0.2 && step_rms < 0.8, "{step_rms}");
        // Seeded: same seed, same poses; another seed, other poses.
        assert_eq!(noisy, tracker_poses(&truth, &PoseNoise::new(1.5, 2.0), 9));
        assert_ne!(noisy, tracker_poses(&truth, &PoseNoise::new(1.5, 2.0), 10));
    }
}
