//! `--poses first` in the build (issue 16 item 5): the video's poses tracked from the first
//! frame's alone. The light and a consensus texture are fitted on the frames tracked so far
//! (at first the trusted frame alone), the next `refit_every` frames are tracked against
//! them ([`crate::registration::track`]), and the light is fitted again on the last
//! `fit_frames` accepted frames, until the video ends. With a scope light
//! (`BuildOptions::scope_light`) only the frames' gains are fitted, in that light.

use super::fit_pass::fit_pass;
use super::options::BuildOptions;
use super::registration::{
    consensus_texture, round_light, scope_light_with_gains, RegistrationView,
};
use super::scene::BuildScene;
use crate::model::registration::TrackingSummary;
use crate::registration::{ModelParts, TrackOptions, TrackState, Tracker};
use crate::shading::calibrated::CalibratedModel;
use crate::Result;
use std::time::Instant;

/// Options of the tracking stage of `--poses first`.
#[derive(Clone, Debug)]
pub struct TrackingOptions {
    /// Frames tracked against one fit of the light before it is fitted again.
    pub refit_every: usize,
    /// Most accepted frames (the latest) the light and texture are fitted on.
    pub fit_frames: usize,
    /// The per-frame tracking.
    pub track: TrackOptions,
    /// Run the registration's rounds from the tracked poses. Off: measured on the demo
    /// phantom (BENCHMARKS.md, "Tracking"), rounds from poses tracked 1-2 degrees off in
    /// view direction and lost after frame 56 flag most frames as outliers and predict
    /// held-out frames worse (15.2 vs 18.1 dB; the check kept the tracked poses).
    pub refine_after: bool,
}

impl Default for TrackingOptions {
    fn default() -> Self {
        TrackingOptions {
            refit_every: 8,
            fit_frames: 8,
            track: TrackOptions::default(),
            refine_after: false,
        }
    }
}

/// Run `f` on `scene` reduced to the frames `keep` (increasing), then restore every frame.
fn on_frames<T>(
    scene: &mut BuildScene,
    keep: &[usize],
    opts: &BuildOptions,
    f: impl FnOnce(&mut BuildScene) -> Result<T>,
) -> Result<T> {
    let (case_poses, poses) = (scene.case.poses.clone(), scene.poses.clone());
    let numbers = scene.frame_numbers.clone();
    scene.keep_frames(keep, opts.depth_cache_bytes);
    let out = f(scene);
    scene.case.poses = case_poses;
    scene.poses = poses;
    scene.frame_numbers = numbers;
    scene.cache =
        super::frames::DepthCache::new(scene.frame_count(), opts.depth_cache_bytes, scene.level);
    out
}

/// The light and consensus texture fitted on the frames `fit_on` at their tracked poses (the
/// latest frame's gain is 1 in the light: the next frames are tracked from it).
fn fit_model(
    scene: &mut BuildScene,
    state: &TrackState,
    fit_on: &[usize],
    opts: &BuildOptions,
    warnings: &mut Vec<String>,
) -> Result<(CalibratedModel, crate::render::MipTexture)> {
    for &i in fit_on {
        scene.poses[i] = state.poses[i];
    }
    let fit_opts = BuildOptions {
        calibrated_reference: Some(fit_on.len() - 1),
        quiet: true,
        ..opts.clone()
    };
    on_frames(scene, fit_on, opts, |s| {
        let light = match &opts.scope_light {
            // The scope's light needs only the frames' gains, which a few frames fix as well
            // as many; a light fitted on the first frames sees few distances and angles.
            Some(scope) => {
                let (_, samples) = fit_pass(s, &fit_opts)?;
                scope_light_with_gains(scope, &samples.pooled, Some(fit_on.len() - 1))?
            }
            None => round_light(s, &fit_opts, warnings)?,
        };
        let texture = consensus_texture(s, &light, &fit_opts)?;
        Ok((light, texture))
    })
}

/// Track every frame of `scene` (decoded `frames`) from the first frame's pose; the scene's
/// poses become the tracked ones (flagged frames: their predicted pose). Returns the state
/// and its summary, and the last light the frames were tracked against.
pub(super) fn track_poses(
    scene: &mut BuildScene,
    view: &RegistrationView,
    opts: &BuildOptions,
    warnings: &mut Vec<String>,
) -> Result<(TrackState, TrackingSummary, CalibratedModel)> {
    let started = Instant::now();
    let t = &opts.tracking;
    let n = scene.frame_count();
    let mut state = TrackState::new(n, scene.poses[0], 1.0);
    let mask = view.mask.as_deref();
    let mut next = 1;
    let mut fits = 0;
    let mut last_light = None;
    while next < n {
        let fit_on: Vec<usize> = {
            let ok = state.accepted_before(next);
            ok[ok.len().saturating_sub(t.fit_frames.max(1))..].to_vec()
        };
        let (light, texture) = fit_model(scene, &state, &fit_on, opts, warnings)?;
        fits += 1;
        for (k, &i) in fit_on.iter().enumerate() {
            state.gains[i] = light.gains[k];
        }
        let parts = ModelParts {
            scene: &scene.scene,
            tri_uv: &scene.tri_uv,
            texture: Some(&texture),
            light: &light,
            camera: &view.camera,
        };
        let seen: Vec<_> = fit_on.iter().map(|&i| state.poses[i]).collect();
        let tracker = Tracker::new(parts, &seen, &t.track)?;
        let fitted_at = next;
        while next < n && next - fitted_at < t.refit_every.max(1) {
            let attempt = tracker.try_frame(&view.frames, mask, &state, next)?;
            // A frame the model no longer predicts is tried again against a model fitted on
            // the frames up to it (new surface comes into view as the scope moves).
            let newer = state.accepted_before(next).last() > fit_on.last();
            if !attempt.accepted && newer {
                break;
            }
            state.commit(next, &attempt, t.track.lost_after);
            next += 1;
        }
        drop(tracker);
        last_light = Some(light);
    }
    scene.poses.clone_from(&state.poses);
    let tracked = state.accepted.iter().filter(|&&a| a).count();
    if let Some(f) = state.first_lost {
        warnings.push(format!(
            "tracking from the first pose was lost at frame {f} of {n} ({tracked} frames tracked)"
        ));
    }
    let seconds = started.elapsed().as_secs_f64();
    let summary = TrackingSummary {
        frames_tracked: tracked,
        frames: n,
        first_lost: state.first_lost,
        light_fits: fits,
        seconds,
        seconds_per_frame: seconds / (n.max(2) - 1) as f64,
    };
    let light = match last_light {
        Some(l) => l,
        None => round_light(scene, opts, warnings)?,
    };
    Ok((state, summary, light))
}
