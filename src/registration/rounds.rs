//! One round of the alternation between the model and the poses (issue 16 item 1): the caller
//! fits the light and fuses the texture with the current poses, then every frame is
//! registered against that model.
//!
//! The first round cannot trust the texture: fused from the given poses, it follows their
//! errors, and frames registered against it stay where they were (measured on the demo
//! phantom with 1.5 mm / 2 degree drift: median error 1.41 mm -> 1.42 mm). It registers against
//! the geometry's shading alone instead, each frame divided by the albedo its colour predicts
//! ([`super::chroma`]), red weighed most; later rounds use the texture, fused from better poses
//! each time, and the caller may go back to the geometry after some of them. A geometry round's
//! smoother weighs each frame by its own information ([`RoundOptions::geometry_noise`]).

use super::chroma::ChromaAlbedo;
use super::frame::{FrameRegistrar, RegistrationOptions};
use super::photometric::{ModelParts, RayGrid};
use super::prior::MeasurementNoise;
use super::video::{refine_video, VideoOptions, VideoRegistration};
use crate::camera::Camera;
use crate::image::Frame;
use crate::math::Affine;
use crate::Result;
use rayon::prelude::*;

/// What a round registers against.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum RoundKind {
    /// The geometry's shading with each frame's albedo predicted from its colour (first round).
    Geometry,
    /// The model's texture and light (later rounds).
    Texture,
    /// The geometry's shading, each frame divided by the albedo its colour predicts and by the
    /// albedo the texture shows from the frame's current pose beyond that
    /// ([`ChromaAlbedo::divide_texture_albedo`]). The texture's pattern stays where it is in the
    /// image, so only the shading moves the pose: where the texture rounds have made the poses
    /// consistent, the albedo the colour misses no longer pulls the geometry's turn and shift
    /// (demo phantom with the shared error of the registration alone, 0.213 deg median: mean
    /// pitch / yaw +0.15 / -0.08 deg -> +0.07 / -0.01 deg; a geometry round leaves +0.23 /
    /// -0.20 deg). From poorly registered frames the texture follows their errors and it sees
    /// little (BENCHMARKS.md).
    Shading,
}

/// Options of [`register_round`].
#[derive(Clone, Debug)]
pub struct RoundOptions {
    /// Per-frame registration (its `uniform_albedo_from_level` and
    /// `uniform_channel_weights` are set by the round's kind).
    pub frame: RegistrationOptions,
    /// The video's continuity.
    pub video: VideoOptions,
    /// Channel weights of a geometry round (R, G, B).
    pub geometry_channel_weights: [f32; 3],
    /// The colour–albedo relation is fitted on the texture seen from every n-th pose.
    pub chroma_every: usize,
    /// Finest pyramid level of a geometry round (at least the frame options' own).
    pub geometry_finest_level: usize,
    /// How a geometry round's smoother models each frame's registration noise (texture
    /// rounds use the video's `smooth` as given).
    pub geometry_noise: MeasurementNoise,
    /// A texture round's step tolerance (mm at level 0; the frame options' own when larger).
    pub texture_step_tolerance: f64,
    /// A texture round's smallest trust region before a level ends (the frame options' own
    /// when larger).
    pub texture_min_radius: f64,
    /// A texture round's trust region shrinks to half the step that failed
    /// ([`RegistrationOptions::shrink_to_failed_step`]).
    pub texture_shrink_to_failed_step: bool,
}

impl Default for RoundOptions {
    fn default() -> Self {
        RoundOptions {
            frame: RegistrationOptions::default(),
            video: VideoOptions::default(),
            // Measured on the demo phantom (1.5 mm / 2 deg): red alone 0.32 mm / 1.05 deg median
            // after the round, all channels 0.35 mm / 1.05 deg (forward error 0.25 vs 0.38 mm).
            geometry_channel_weights: [1.0, 0.0, 0.0],
            chroma_every: 4,
            // The geometry round's accuracy is set by its albedo, not its resolution (measured on
            // the demo phantom with 1.5 mm / 2 deg drift: finest level 1 0.338 mm / 1.068 deg,
            // level 0 0.337 mm / 1.069 deg), and one level less saves a quarter of its time.
            geometry_finest_level: 1,
            // Against the geometry a frame fixes its roll only where the airway is not round,
            // and coupled with a sideways shift: each frame's own information says where (demo
            // phantom, 1.5 mm / 2 deg: 0.75 deg median after the round, 1.18 deg with one noise
            // per camera axis).
            geometry_noise: MeasurementNoise::Information { deflation: 200.0 },
            // Against the texture a frame's pose is well fixed and the rounds start where the
            // last one left it, so the last steps and failed renders of a tight tolerance
            // buy nothing measurable: on the demo phantom with 3 mm / 4 deg drift new views
            // 29.90 -> 29.81 dB and 69 -> 70 of 80 frames within 1 mm and 1 deg, 1.5 mm / 2 deg
            // 31.07 -> 30.97 dB, with 30 % fewer renders per texture round. Geometry rounds
            // keep the tight ones: there roll is weakly fixed and creeps in small steps (3 mm /
            // 4 deg with every round loosened: mean roll error -0.78 deg, 28.62 dB).
            texture_step_tolerance: 0.01,
            texture_min_radius: 0.5,
            texture_shrink_to_failed_step: true,
        }
    }
}

/// The size of the frames the rounds' pyramid levels are set for (the demo phantom's 320x320
/// frames).
const REFERENCE_SIDE_PX: f64 = 320.0;

/// How many pyramid levels a camera's size (the geometric mean of its sides) lies below
/// [`REFERENCE_SIDE_PX`] (rounded, 0 when larger): the rounds' levels are counted from there,
/// so that a level shows the airway at about the same scale whatever the frames' size.
/// Registered at the reference's levels, 160x160 frames stopped their geometry rounds at 80
/// pixels across and began them at 20, and the demo phantom's path at 160x160 with a 1.5 mm /
/// 2 deg tracker's error ended at 0.755 deg median, 50 of 80 frames within 1 mm and 1 deg,
/// its round trachea turned 1.3 deg off at the top (at 320x320: 0.284 deg, 78); counted from
/// here, 0.572 deg and 78 (BENCHMARKS.md, session 31).
pub fn levels_below_reference(camera: &Camera) -> usize {
    let side = (f64::from(camera.width) * f64::from(camera.height))
        .sqrt()
        .max(1.0);
    (REFERENCE_SIDE_PX / side).log2().round().max(0.0) as usize
}

/// Register `frames` (linear RGB, gains `gains` in the model's light, optional pixel `mask`)
/// starting from `poses` against the model `parts`, as a round of `kind`. The pyramid levels
/// of `opts` are counted from the reference frame size ([`levels_below_reference`]).
pub fn register_round(
    parts: ModelParts,
    frames: &[Frame],
    gains: &[f64],
    mask: Option<&[bool]>,
    poses: &[Affine],
    kind: RoundKind,
    opts: &RoundOptions,
) -> Result<VideoRegistration> {
    let mut frame_opts = opts.frame.clone();
    if kind == RoundKind::Texture {
        frame_opts.step_tolerance = frame_opts.step_tolerance.max(opts.texture_step_tolerance);
        frame_opts.min_radius = frame_opts.min_radius.max(opts.texture_min_radius);
        frame_opts.shrink_to_failed_step = opts.texture_shrink_to_failed_step;
    } else {
        frame_opts.uniform_albedo_from_level = 0;
        frame_opts.uniform_channel_weights = opts.geometry_channel_weights;
        frame_opts.finest_level = frame_opts
            .finest_level
            .max(opts.geometry_finest_level)
            .min(frame_opts.coarsest_level);
    }
    let below = levels_below_reference(parts.camera);
    frame_opts.coarsest_level = frame_opts.coarsest_level.saturating_sub(below);
    frame_opts.finest_level = frame_opts.finest_level.saturating_sub(below);
    let reg = FrameRegistrar::new(parts, frame_opts)?;
    match kind {
        RoundKind::Texture => refine_video(&reg, frames, gains, mask, poses, &opts.video),
        RoundKind::Geometry | RoundKind::Shading => {
            let grid = RayGrid::new(parts.camera, 2, 1);
            let some: Vec<Affine> = poses
                .iter()
                .step_by(opts.chroma_every.max(1))
                .copied()
                .collect();
            let rel = ChromaAlbedo::fit(&reg.model, &grid, &some)?;
            let level = reg.opts.saturation_level;
            // A shading round reads the texture on the frames' own pixel grid.
            let full = (kind == RoundKind::Shading).then(|| RayGrid::new(parts.camera, 0, 1));
            let normalised: Vec<Frame> = frames
                .par_iter()
                .zip(poses)
                .map(|(f, pose)| {
                    let n = rel.normalise(f, level);
                    match &full {
                        Some(grid) => rel.divide_texture_albedo(&n, &reg.model, grid, pose, level),
                        None => n,
                    }
                })
                .collect();
            let mut video = opts.video.clone();
            if let Some(prior) = &mut video.smooth {
                prior.noise = opts.geometry_noise;
            }
            refine_video(&reg, &normalised, gains, mask, poses, &video)
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::phantom::case::phantom_camera;

    #[test]
    fn levels_are_counted_from_the_reference_frame_size() {
        let below = |w, h| levels_below_reference(&phantom_camera(w, h));
        // The demo's frames, and larger ones (registered reduced to ~320 across anyway).
        assert_eq!(below(320, 320), 0);
        assert_eq!(below(640, 640), 0);
        // A 720p video registered at 320x180: 240 pixels' worth, nearer 320 than 160.
        assert_eq!(below(320, 180), 0);
        assert_eq!(below(256, 256), 0);
        // The tests' small phantoms.
        assert_eq!(below(160, 160), 1);
        assert_eq!(below(128, 128), 1);
        assert_eq!(below(80, 80), 2);
        assert_eq!(below(1, 1), 8);
    }
}
