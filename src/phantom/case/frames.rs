//! The phantom's video: every frame rendered, exposed (auto gain, sensor noise, the scope's
//! overlay if asked) and written, a few frames at a time in parallel (each render is parallel
//! too; encoding and writing a PNG is not, and is most of an HD frame's time otherwise).
//! Blurred frames ([`MotionBlur`]) average sub-renders along the exposure's motion, rendered
//! at half size from 1280 px wide up.

use rayon::prelude::*;
use serde::Serialize;
use std::path::Path;

use super::{PhantomSummary, Stage};
use crate::camera::{Camera, Pose};
use crate::image::reduce::expand_frame;
use crate::image::Frame;
use crate::io::camera_file::write_camera_json;
use crate::io::image_mask::MASK_FILE;
use crate::io::png::write_png_srgb8;
use crate::io::poses::{write_poses, FrameRef, PoseEntry};
use crate::math::Affine;
use crate::phantom::motion_blur::MotionBlur;
use crate::phantom::overlay::ScopeOverlay;
use crate::phantom::pose_noise::tracker_poses;
use crate::phantom::render::{auto_gain, expose, render_radiance, SubpixelRays};
use crate::rng::Pcg32;
use crate::workflow::progress::Progress;
use crate::{Error, Result};

/// Frames rendered at once: enough to keep both the renders and the PNG encoders busy, few
/// enough that their buffers stay small (about 80 MB per 1280 x 720 frame in flight).
const FRAMES_IN_FLIGHT: usize = 4;

/// What truth/gains.json records of one frame.
#[derive(Serialize)]
pub(super) struct FrameGain {
    pub image: String,
    pub gain: f64,
    pub mean_linear: f64,
    pub saturated_fraction: f64,
    /// Averaged over the exposure's motion (truth.json `motion_blur.frames`).
    pub blurred: bool,
}

/// Render, expose and write a frame per pose, then poses.json, camera.json and mask.png (with
/// the overlay). Records each frame's statistics in `sm` and returns each frame's gain.
pub(super) fn write_frames(
    dir: &Path,
    stage: &Stage,
    camera: &Camera,
    poses: &[Affine],
    sm: &mut PhantomSummary,
) -> Result<Vec<FrameGain>> {
    let opts = stage.opts;
    let rays = SubpixelRays::new(camera, opts.supersample);
    let blur_level = MotionBlur::sub_render_level(camera.width);
    let blur_rays =
        (blur_level > 0).then(|| SubpixelRays::new(&camera.at_level(blur_level), opts.supersample));
    let frames_dir = dir.join("frames");
    std::fs::create_dir_all(&frames_dir).map_err(|e| Error::io(&frames_dir, e))?;
    // What a tracker would report (the frames are rendered from the true poses).
    let reported = tracker_poses(
        poses,
        &opts.pose_noise,
        opts.seed.wrapping_mul(613).wrapping_add(29),
    );
    let overlay = opts
        .scope_overlay
        .then(|| ScopeOverlay::new(opts.width, opts.height));
    if let Some(o) = &overlay {
        write_png_srgb8(&dir.join(MASK_FILE), &o.mask())?;
    }
    let blur_seed = opts.seed.wrapping_mul(977).wrapping_add(13);
    let blurred = opts.motion_blur.blurred_frames(poses.len(), blur_seed);
    let ctx = FrameContext {
        stage,
        camera,
        rays: &rays,
        blur_rays: blur_rays.as_ref().map(|r| (blur_level, r)),
        poses,
        blurred: &blurred,
        overlay: overlay.as_ref(),
        frames_dir: &frames_dir,
        blur_seed,
    };
    let mut gains = Vec::with_capacity(poses.len());
    let progress = Progress::new("render frames", poses.len() as u64, opts.quiet);
    for chunk in (0..poses.len())
        .collect::<Vec<_>>()
        .chunks(FRAMES_IN_FLIGHT)
    {
        let done: Vec<FrameGain> = chunk
            .par_iter()
            .map(|&i| ctx.write_frame(i))
            .collect::<Result<_>>()?;
        done.iter().for_each(|_| progress.inc());
        gains.extend(done);
    }
    progress.finish();
    for (i, g) in gains.iter().enumerate() {
        if g.blurred {
            sm.blurred_frames.push(i);
        }
        sm.frame_mean_linear.push(g.mean_linear);
        sm.frame_saturated_fraction.push(g.saturated_fraction);
    }
    let entry = |i: usize, pose: &Affine| PoseEntry {
        frame: FrameRef::Image(frames_dir.join(format!("{i:06}.png"))),
        pose: Pose::new(*pose),
    };
    let entries: Vec<PoseEntry> = reported
        .iter()
        .enumerate()
        .map(|(i, p)| entry(i, p))
        .collect();
    let true_entries: Vec<PoseEntry> = poses.iter().enumerate().map(|(i, p)| entry(i, p)).collect();
    write_poses(&dir.join("poses.json"), &entries, dir)?;
    let truth = dir.join("truth");
    std::fs::create_dir_all(&truth).map_err(|e| Error::io(&truth, e))?;
    write_poses(&truth.join("poses.json"), &true_entries, dir)?;
    write_camera_json(&dir.join("camera.json"), camera)?;
    sm.frames = entries.len();
    Ok(gains)
}

/// What every frame is rendered with.
struct FrameContext<'a> {
    stage: &'a Stage<'a>,
    camera: &'a Camera,
    rays: &'a SubpixelRays,
    /// The reduced rays blurred frames' sub-renders use, and their level (see
    /// [`MotionBlur::sub_render_level`]); `None` when they are rendered at full size.
    blur_rays: Option<(usize, &'a SubpixelRays)>,
    poses: &'a [Affine],
    blurred: &'a [bool],
    overlay: Option<&'a ScopeOverlay>,
    frames_dir: &'a Path,
    blur_seed: u64,
}

impl FrameContext<'_> {
    /// Render, expose and write frame `i`.
    fn write_frame(&self, i: usize) -> Result<FrameGain> {
        let opts = self.stage.opts;
        let radiance = if self.blurred[i] {
            self.blurred_radiance(i, &opts.motion_blur)
        } else {
            self.radiance(&self.poses[i])
        };
        let gain = auto_gain(&radiance, &opts.sensor);
        let noise_seed = opts.seed.wrapping_mul(7919).wrapping_add(1);
        let mut img = expose(&radiance, gain, &opts.sensor, true, noise_seed, i as u64);
        if let Some(o) = self.overlay {
            o.apply(&mut img, i, 25.0);
        }
        write_png_srgb8(&self.frames_dir.join(format!("{i:06}.png")), &img)?;
        let (mean, sat) = super::frame_stats(&img);
        Ok(FrameGain {
            image: format!("frames/{i:06}.png"),
            gain,
            mean_linear: mean,
            saturated_fraction: sat,
            blurred: self.blurred[i],
        })
    }

    fn radiance(&self, pose: &Affine) -> Frame {
        self.radiance_with(self.rays, pose)
    }

    fn radiance_with(&self, rays: &SubpixelRays, pose: &Affine) -> Frame {
        let s = self.stage;
        render_radiance(&s.scene, rays, pose, &s.albedo, &s.opts.light).frame
    }

    /// The mean radiance over the exposure's poses of frame `i`, rendered at the sub-render
    /// level and expanded to the frame's size.
    fn blurred_radiance(&self, i: usize, blur: &MotionBlur) -> Frame {
        let mut rng = Pcg32::new(self.blur_seed, i as u64);
        let sub = blur.exposure_poses(self.poses, i, self.camera.width, self.camera.fx, &mut rng);
        let (level, rays) = self.blur_rays.unwrap_or((0, self.rays));
        let mut sum = Frame::new(rays.width, rays.height);
        for p in &sub {
            let r = self.radiance_with(rays, p);
            sum.rgb.iter_mut().zip(&r.rgb).for_each(|(a, b)| *a += b);
        }
        let k = 1.0 / sub.len() as f32;
        sum.rgb.iter_mut().for_each(|v| *v *= k);
        expand_frame(&sum, level, self.camera.width, self.camera.height)
    }
}
