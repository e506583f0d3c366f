//! Motion blur for a share of the phantom's frames (issue 21): the scope turns fast during the
//! exposure, so the frame is the average of sub-renders from poses along that motion — the
//! camera's own path from halfway to the previous frame to halfway to the next, plus a turn
//! about an axis across the optical axis, symmetric about the frame's pose. The pose written
//! to poses.json is the mid pose, the centre of the exposure, so the truth stays exact.

use crate::camera::pose::camera_centre;
use crate::math::{Affine, Vector3};
use crate::registration::pose::{apply_delta, rotation_of, PoseDelta};
use crate::rng::Pcg32;
use serde::Serialize;

/// Sub-renders of blurred frames are rendered at a reduced size no narrower than this
/// (pixels); frames up to twice as wide are rendered at full size.
pub const SUB_RENDER_MIN_WIDTH: u32 = 640;

/// How many frames are blurred and how much.
#[derive(Clone, Debug, Serialize, PartialEq)]
pub struct MotionBlur {
    /// Share of the frames blurred (0..=1).
    pub share: f64,
    /// Length of the smear at the image centre, as a share of the image width.
    pub length_share: f64,
    /// Most sub-renders averaged per blurred frame (about one per 3 pixels of smear).
    pub max_sub_renders: u32,
}

impl Default for MotionBlur {
    fn default() -> Self {
        MotionBlur {
            share: 0.0,
            length_share: 0.03,
            max_sub_renders: 8,
        }
    }
}

impl MotionBlur {
    /// Sub-renders of a blurred frame `width` pixels wide: one per 3 pixels of smear, at
    /// least 3.
    pub fn sub_renders(&self, width: u32) -> u32 {
        let px = self.length_share * width as f64;
        ((px / 3.0).ceil() as u32).clamp(3, self.max_sub_renders.max(3))
    }

    /// Pyramid level the sub-renders of a frame `width` pixels wide are rendered at: halved
    /// while they stay at least [`SUB_RENDER_MIN_WIDTH`] wide, then expanded back (the smear
    /// spans tens of pixels at those sizes; a blurred HD frame would cost 8 full renders).
    pub fn sub_render_level(width: u32) -> usize {
        let mut level = 0;
        while width >> (level + 1) >= SUB_RENDER_MIN_WIDTH {
            level += 1;
        }
        level
    }

    /// Which of `frames` frames are blurred: `round(share · frames)` of them, drawn with `seed`.
    pub fn blurred_frames(&self, frames: usize, seed: u64) -> Vec<bool> {
        let count = ((self.share.clamp(0.0, 1.0) * frames as f64).round() as usize).min(frames);
        let mut order: Vec<usize> = (0..frames).collect();
        let mut rng = Pcg32::new(seed, 0xB1A);
        // Partial Fisher-Yates: the first `count` of a seeded permutation.
        for k in 0..count {
            let j = k + (rng.uniform() * (frames - k) as f64) as usize;
            order.swap(k, j.min(frames - 1));
        }
        let mut out = vec![false; frames];
        order[..count].iter().for_each(|&i| out[i] = true);
        out
    }

    /// The exposure's poses of frame `i` of `poses` (`width` pixels wide, focal length `fx`
    /// pixels), symmetric about `poses[i]`; `rng` draws the turn's axis.
    pub fn exposure_poses(
        &self,
        poses: &[Affine],
        i: usize,
        width: u32,
        fx: f64,
        rng: &mut Pcg32,
    ) -> Vec<Affine> {
        let k = self.sub_renders(width);
        let pose = &poses[i];
        let prev = camera_centre(&poses[i.saturating_sub(1)]).coords;
        let next = camera_centre(&poses[(i + 1).min(poses.len() - 1)]).coords;
        // Half the way to each neighbour: the path the camera travels in one frame time.
        let travel: Vector3<f64> = (next - prev) * 0.5;
        let phi = rng.uniform() * std::f64::consts::TAU;
        let axis_cam = Vector3::new(phi.cos(), phi.sin(), 0.0);
        let axis = rotation_of(pose) * axis_cam;
        // A turn by `a` about an axis across the optical axis moves the centre by fx · a pixels.
        let angle = self.length_share * width as f64 / fx;
        (0..k)
            .map(|s| {
                let t = (s as f64 + 0.5) / k as f64 - 0.5;
                let delta = PoseDelta {
                    translation_mm: travel * t,
                    rotation: axis * (angle * t),
                };
                apply_delta(pose, &delta)
            })
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::registration::pose::delta_between;

    #[test]
    fn blurred_share_and_symmetric_exposure() {
        let mb = MotionBlur {
            share: 0.2,
            ..Default::default()
        };
        let b = mb.blurred_frames(300, 5);
        assert_eq!(b.iter().filter(|&&x| x).count(), 60);
        assert_eq!(b, mb.blurred_frames(300, 5));
        assert_ne!(b, mb.blurred_frames(300, 6));
        // 320 px wide: a smear of 9.6 px in 4 sub-renders; 1280 px: 38.4 px, capped at 8.
        assert_eq!(mb.sub_renders(320), 4);
        assert_eq!(mb.sub_renders(1280), 8);
        assert_eq!(MotionBlur::sub_render_level(320), 0);
        assert_eq!(MotionBlur::sub_render_level(1279), 0);
        assert_eq!(MotionBlur::sub_render_level(1280), 1);
        assert_eq!(MotionBlur::sub_render_level(1920), 1);
        let poses: Vec<Affine> = (0..3)
            .map(|k| {
                let mut m = Affine::identity();
                m[(0, 3)] = k as f64;
                m
            })
            .collect();
        let mut rng = Pcg32::new(1, 2);
        let sub = mb.exposure_poses(&poses, 1, 320, 160.0, &mut rng);
        assert_eq!(sub.len(), 4);
        // Symmetric about the mid pose: the first and last sub-poses are opposite deltas, the
        // whole turn is 9.6 px / 160 px (0.06 rad) and the whole shift one frame's travel less
        // a sub-step (1 mm · 3/4).
        let (d0, d3) = (
            delta_between(&poses[1], &sub[0]),
            delta_between(&poses[1], &sub[3]),
        );
        assert!((d0.rotation + d3.rotation).norm() < 1e-12);
        assert!((d3.rotation.norm() * 2.0 - 0.06 * 0.75).abs() < 1e-9);
        assert!((d3.translation_mm.x * 2.0 - 0.75).abs() < 1e-12);
        // The turn is about an axis across the optical axis (camera z = world z here).
        assert!(d3.rotation.z.abs() < 1e-12);
    }
}
