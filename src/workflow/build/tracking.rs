//! `--poses first` in the build (issue 16 item 5): the video's poses tracked from the first
//! frame's alone. The light and a consensus texture are fitted on the frames tracked so far
//! (at first the trusted frame alone), the next `refit_every` frames are tracked against
//! them ([`crate::registration::track`]), the last `window_geometry` accepted frames are
//! registered again against the geometry, and the light is fitted again on the last
//! `fit_frames` accepted frames, until the video ends. With a scope light
//! (`BuildOptions::scope_light`) only the frames' gains are fitted, in that light. The
//! registration's rounds then refine the tracked poses (`refine_after`).

use super::options::BuildOptions;
use super::registration::{
    consensus_texture, registration_light, round_light, rounds_on_frames, RegistrationView,
};
use super::scene::BuildScene;
use crate::camera::Camera;
use crate::math::Affine;
use crate::model::registration::{FirstPoseRefinement, TrackingSummary};
use crate::registration::pose::rotation_of;
use crate::registration::{
    apply_delta, delta_between, register_round, FrameStatus, RoundKind, RoundOptions, TrackOptions,
    TrackState, Tracker, VideoOptions,
};
use crate::render::MipTexture;
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
    /// Run the registration's rounds from the tracked poses (off: the tracked poses are the
    /// model's). Measured on the demo phantom (BENCHMARKS.md, sessions 28 and 29): from poses
    /// tracked to 0.33 mm / 1.41 deg median the rounds, the first frame anchored, end at
    /// 0.095 mm / 0.223 deg, new views 30.75 dB (a tracker 1.5 mm / 2 deg off: 30.54 dB); the
    /// tracked poses alone (the window's roll kept) scored 28.17 dB.
    pub refine_after: bool,
    /// Before each fit of the light, the last this many accepted frames (the trusted first
    /// frame aside) are registered again against the geometry's shading alone, as one
    /// geometry round of the registration with its smoother, against the model they were
    /// tracked with (0: never). Against a texture fused from tracked frames the view direction
    /// drifts with them (demo phantom: pitch 0.3 deg off after 7 frames, 5 deg after 27, the
    /// track lost at frame 52); the geometry does not follow.
    pub window_geometry: usize,
    /// Times the tracking resumes after it was lost: the last `resume_frames` frames accepted
    /// before the loss are refined by the registration's rounds, and the lost frames are
    /// tracked again from them (0: the track stays lost). On a real airway tree (ATM_224,
    /// 2 mm and up to 13 deg between frames) the track was lost at frame 40 with its frames
    /// within 0.55 mm / 1.8 deg; refined, they were within 0.32 mm / 0.75 deg, and the track
    /// resumed from them held to frame 79 (BENCHMARKS.md, session 29).
    pub resumes: usize,
    /// Accepted frames refined before the tracking resumes.
    pub resume_frames: usize,
    /// Rounds of the registration that refine them (the build's own rounds may be none).
    pub resume_rounds: usize,
    /// A video over the frame selection's budget is tracked on up to this many times the
    /// budget, evenly spaced in time, and the budget's frames are chosen among them once
    /// tracked (their coverage needs their poses). The tracker needs frames close together,
    /// and each costs 0.3-0.75 s: tracking the budget's frames alone lost a real airway tree
    /// at 2 mm between them (ATM_307, 160 frames, budget 80: lost at frame 80) that twice as
    /// many held to its end (BENCHMARKS.md, session 30).
    pub tracked_per_used: usize,
    /// Refine the first frame's given pose against the CT's geometry before tracking from it
    /// ([`refine_first_pose`]; off: trusted exactly, `--trust-first-pose`). The rounds after
    /// the tracking hold the first frame only where it is still at its given pose. A first pose
    /// aligned by hand is rarely better than a millimetre and a degree, and tracking follows
    /// its error. Demo phantom's video, first pose 1 mm / 1 deg off: trusted 0.53 deg median,
    /// 62 of 80 frames within 1 mm and 1 deg, new views 28.49 dB; refined 0.41 deg, 71, 29.24
    /// dB. 2 mm / 2 deg off: trusted, lost at frame 20 (17.10 dB); refined, 0.83 deg, 28.29 dB
    /// (BENCHMARKS.md, session 33).
    pub refine_first: bool,
    /// The refined first pose is kept when it lowers the frame's cost against the geometry by
    /// at least this share; else the given pose agrees with the CT as far as one frame's
    /// geometry can tell, and is kept. From the exact pose the refinement lowered the cost by
    /// 2-3 % (demo phantom and its path at 160x160) and cost 1.2 dB of new views on the demo
    /// (30.75 -> 29.53 dB); from 0.5 mm / 0.5 deg off by 29 %, from 1 mm / 1 deg off by 31-45 %
    /// (BENCHMARKS.md, session 33).
    pub first_pose_min_cost_drop: f64,
}

impl Default for TrackingOptions {
    fn default() -> Self {
        TrackingOptions {
            refit_every: 8,
            fit_frames: 8,
            track: TrackOptions::default(),
            refine_after: true,
            window_geometry: 16,
            resumes: 4,
            resume_frames: 32,
            resume_rounds: 9,
            tracked_per_used: 2,
            refine_first: true,
            first_pose_min_cost_drop: 0.1,
        }
    }
}

/// The light and consensus texture fitted on the frames `fit_on` at `poses` (one per frame of
/// the scene; the latest frame's gain is 1 in the light: the next frames are tracked from it).
fn fit_model(
    scene: &mut BuildScene,
    poses: &[Affine],
    fit_on: &[usize],
    opts: &BuildOptions,
    warnings: &mut Vec<String>,
) -> Result<(CalibratedModel, MipTexture)> {
    for &i in fit_on {
        scene.poses[i] = poses[i];
    }
    let fit_opts = BuildOptions {
        calibrated_reference: Some(fit_on.len() - 1),
        quiet: true,
        ..opts.clone()
    };
    scene.on_frames(fit_on, opts.depth_cache_bytes, |s| {
        // With a scope, only the frames' gains are fitted: a light fitted on the first
        // frames sees few distances and angles.
        let light = registration_light(s, &fit_opts, warnings)?;
        let texture = consensus_texture(s, &light, &fit_opts)?;
        Ok((light, texture))
    })
}

/// Track every frame of `scene` (decoded `frames`) from the first frame's pose; the scene's
/// poses become the tracked ones (flagged frames: their predicted pose). When the track is
/// lost, the accepted frames before it are refined by the registration's rounds and tracking
/// resumes from them (up to `TrackingOptions::resumes` times, while each resume gets further).
/// Returns the state and its summary, and the last light the frames were tracked against.
pub(super) fn track_poses(
    scene: &mut BuildScene,
    view: &RegistrationView,
    opts: &BuildOptions,
    warnings: &mut Vec<String>,
) -> Result<(TrackState, TrackingSummary, CalibratedModel)> {
    let started = Instant::now();
    let t = &opts.tracking;
    let n = scene.frame_count();
    let first_pose = match t.refine_first && scene.frame_numbers.first() == Some(&0) {
        true => Some(refine_first_pose(scene, view, opts, warnings)?),
        false => None,
    };
    let mut state = TrackState::new(&scene.frame_numbers, scene.poses[0], 1.0);
    if let Some(kept) = first_pose.as_ref().filter(|r| r.summary.kept) {
        state.status[0] = Some(kept.status);
    }
    let mut fits = 0;
    let mut resumed_at: Vec<usize> = Vec::new();
    let mut light = None;
    loop {
        let resumable = resumed_at.len() < t.resumes;
        light = track_from(
            scene, view, opts, warnings, &mut state, &mut fits, resumable,
        )?
        .or(light);
        let Some(lost) = state.first_lost.filter(|_| resumable) else {
            break;
        };
        if resumed_at.last().is_some_and(|&r| lost <= r)
            || !refine_tracked(scene, view, opts, &state, lost)?
        {
            // No further than the last resume, or the frames before it did not refine: the
            // rest of the video is tracked on as it was lost.
            light =
                track_from(scene, view, opts, warnings, &mut state, &mut fits, false)?.or(light);
            break;
        }
        state.resume_at(lost, &scene.poses);
        resumed_at.push(lost);
    }
    scene.poses.clone_from(&state.poses);
    let tracked = state.accepted.iter().filter(|&&a| a).count();
    // Reported as frames of the video (poses.json order), which the frames tracked may skip.
    let first_lost = state.first_lost.map(|f| scene.frame_numbers[f]);
    let resumed_at: Vec<usize> = resumed_at.iter().map(|&f| scene.frame_numbers[f]).collect();
    if let Some(f) = first_lost {
        warnings.push(format!(
            "tracking from the first pose was lost at frame {f} ({tracked} of {n} frames tracked{})",
            match resumed_at.len() {
                0 => String::new(),
                _ => format!(", resumed at frames {resumed_at:?} after refining the frames before"),
            }
        ));
    }
    let seconds = started.elapsed().as_secs_f64();
    let summary = TrackingSummary {
        frames_tracked: tracked,
        frames: n,
        first_lost,
        resumed_at,
        light_fits: fits,
        seconds,
        seconds_per_frame: seconds / (n.max(2) - 1) as f64,
        first_pose: first_pose.map(|r| r.summary),
    };
    let light = match light {
        Some(l) => l,
        None => round_light(scene, opts, warnings)?,
    };
    Ok((state, summary, light))
}

/// The first frame's refinement and how its registration ended.
struct FirstPose {
    summary: FirstPoseRefinement,
    status: FrameStatus,
}

/// The first frame's given pose registered against the CT's geometry (its shading under the
/// light fitted on that frame at the given pose, the frame divided by the albedo its colour
/// predicts, as the tracker registers the frames before any texture exists); the scene's first
/// pose becomes the refined one when it converged and lowered the cost by
/// `TrackingOptions::first_pose_min_cost_drop` or more.
///
/// Alone, one frame's geometry is ambiguous where a turn and a shift move its image alike
/// (about 0.3 mm / 0.9 deg from the exact pose on the demo phantom), and a round airway does
/// not fix the roll: the refinement is coarse. The roll is refined all the same: kept as
/// given, from a first pose 1 mm / 1 deg off about a skew axis, the demo's video ended at
/// 0.57 deg median, refined 0.41 (BENCHMARKS.md, session 33).
fn refine_first_pose(
    scene: &mut BuildScene,
    view: &RegistrationView,
    opts: &BuildOptions,
    warnings: &mut Vec<String>,
) -> Result<FirstPose> {
    let given = scene.poses[0];
    let poses = scene.poses.clone();
    let (light, texture) = fit_model(scene, &poses, &[0], opts, warnings)?;
    let parts = view.model_parts(scene, &light, Some(&texture));
    let geometry = TrackOptions {
        against_texture: false,
        ..opts.tracking.track.clone()
    };
    let tracker = Tracker::new(parts, &[given], &geometry)?;
    let r = tracker.register_alone(&view.frames, view.mask.as_deref(), 0, &given, 1.0)?;
    let converged = matches!(r.status, FrameStatus::Converged | FrameStatus::NotConverged)
        && r.cost_after.is_finite();
    let drop = opts.tracking.first_pose_min_cost_drop;
    let kept = converged && r.cost_after < (1.0 - drop) * r.cost_before;
    let moved = delta_between(&given, &r.pose);
    if kept {
        scene.poses[0] = r.pose;
    } else if !converged {
        warnings.push(format!(
            "the first frame's pose could not be refined against the CT ({}); tracking starts from it as given",
            r.status.name()
        ));
    }
    Ok(FirstPose {
        summary: FirstPoseRefinement {
            status: r.status.name().to_string(),
            kept,
            correction_mm: if kept { moved.mm() } else { 0.0 },
            correction_deg: if kept { moved.deg() } else { 0.0 },
            cost_given: r.cost_before,
            cost_refined: r.cost_after,
        },
        status: r.status,
    })
}

/// The registration's rounds on the last `TrackingOptions::resume_frames` frames accepted
/// before `lost` (the scene's poses at the tracked ones first); whether a round was kept.
/// Their warnings are the tracking's business, not the build's: the rounds that count run
/// after the tracking.
fn refine_tracked(
    scene: &mut BuildScene,
    view: &RegistrationView,
    opts: &BuildOptions,
    state: &TrackState,
    lost: usize,
) -> Result<bool> {
    scene.poses.clone_from(&state.poses);
    let ok = state.accepted_before(lost);
    let on = &ok[ok.len().saturating_sub(opts.tracking.resume_frames)..];
    if on.len() < opts.tracking.fit_frames.max(2) {
        return Ok(false);
    }
    // No held-out frames and no joint stage: the build's rounds decide on the poses, after
    // the tracking.
    let quiet = BuildOptions {
        quiet: true,
        cross_validate_every: 0,
        registration_joint: false,
        ..opts.clone()
    };
    let (run, _) = rounds_on_frames(
        scene,
        view,
        on,
        opts.tracking.resume_rounds,
        &quiet,
        &mut Vec::new(),
        &mut Vec::new(),
        &mut None,
    )?;
    // The tracked roll is kept, as after a window's geometry round: the rounds turned 32
    // frames of a round trachea 6.5 deg about their view axes together (none of them the
    // trusted first frame), which neither the geometry nor a texture fused from them shows.
    // The first frame's pose is given, not refined.
    for &i in on {
        scene.poses[i] = match i {
            0 => state.poses[0],
            _ => without_roll(&state.poses[i], &scene.poses[i]),
        };
    }
    Ok(run.rounds.iter().any(|r| !r.discarded))
}

/// Track the frames of `scene` from the first one `state` has not tracked, to the video's
/// end or, when `stop_when_lost`, until the track is lost. Returns the last light the frames
/// were tracked against (`None` when no frame was left).
fn track_from(
    scene: &mut BuildScene,
    view: &RegistrationView,
    opts: &BuildOptions,
    warnings: &mut Vec<String>,
    state: &mut TrackState,
    fits: &mut usize,
    stop_when_lost: bool,
) -> Result<Option<CalibratedModel>> {
    let t = &opts.tracking;
    let n = scene.frame_count();
    let mask = view.mask.as_deref();
    let mut next = state.next_untracked();
    let mut last_model: Option<(CalibratedModel, MipTexture)> = None;
    let track_opts = TrackOptions {
        blurred_below: match opts.leave_out_blurred {
            true => t.track.blurred_below,
            false => 0.0,
        },
        ..t.track.clone()
    };
    while next < n && !(stop_when_lost && state.first_lost.is_some()) {
        let fit_on: Vec<usize> = {
            let ok = state.accepted_before(next);
            ok[ok.len().saturating_sub(t.fit_frames.max(1))..].to_vec()
        };
        if let Some((light, texture)) = &last_model {
            correct_window(scene, view, state, next, light, texture, t.window_geometry)?;
        }
        let (light, texture) = fit_model(scene, &state.poses, &fit_on, opts, warnings)?;
        *fits += 1;
        for (k, &i) in fit_on.iter().enumerate() {
            state.gains[i] = light.gains[k];
        }
        let parts = view.model_parts(scene, &light, Some(&texture));
        let seen: Vec<_> = fit_on.iter().map(|&i| state.poses[i]).collect();
        let tracker = Tracker::new(parts, &seen, &track_opts)?;
        let fitted_at = next;
        while next < n && next - fitted_at < t.refit_every.max(1) {
            let attempt = tracker.try_frame(&view.frames, mask, state, next)?;
            // A frame the model no longer predicts is tried again against a model fitted on
            // the frames up to it (new surface comes into view as the scope moves).
            let newer = state.accepted_before(next).last() > fit_on.last();
            if !attempt.accepted && newer {
                break;
            }
            state.commit(next, &attempt, t.track.lost_after);
            next += 1;
            if stop_when_lost && state.first_lost.is_some() {
                break;
            }
        }
        drop(tracker);
        last_model = Some((light, texture));
    }
    Ok(last_model.map(|(l, _)| l))
}

/// The finest pyramid level of the window's geometry round: the coarser one (1) while it
/// keeps 160 pixels across the frame, else the frames' own. Measured on the demo phantom
/// (320x320), the window's roll kept: level 1 kept 80 of 80 frames within 1 mm, 33 within
/// 1 mm and 1 deg, level 0 64 and 16; on 20 frames at 128x128 level 1 turned them 1.6 deg
/// median (2 of 20 within 1 mm and 1 deg), level 0 0.98 deg (11; 10 without the window).
fn window_finest_level(camera: &Camera) -> usize {
    match camera.width.min(camera.height) >> 1 >= 160 {
        true => 1,
        false => 0,
    }
}

/// The last `window` accepted frames before `next` (not the trusted first frame) registered
/// again against the geometry's shading, as a geometry round with its smoother, against the
/// model (`light`, `texture`) they were tracked with; the frames it converged on take its
/// poses, less their roll ([`without_roll`]).
fn correct_window(
    scene: &BuildScene,
    view: &RegistrationView,
    state: &mut TrackState,
    next: usize,
    light: &CalibratedModel,
    texture: &MipTexture,
    window: usize,
) -> Result<()> {
    let ok: Vec<usize> = state
        .accepted_before(next)
        .into_iter()
        .filter(|&i| i > 0)
        .collect();
    let frames_in: Vec<usize> = ok[ok.len().saturating_sub(window)..].to_vec();
    // The round's outlier test and smoother compare each frame with its neighbours.
    if window == 0 || frames_in.len() < 4 {
        return Ok(());
    }
    let parts = view.model_parts(scene, light, Some(texture));
    let frames: Vec<_> = frames_in.iter().map(|&i| view.frames[i].clone()).collect();
    let gains: Vec<f64> = frames_in.iter().map(|&i| state.gains[i]).collect();
    let poses: Vec<_> = frames_in.iter().map(|&i| state.poses[i]).collect();
    let round = register_round(
        parts,
        &frames,
        &gains,
        view.mask.as_deref(),
        &poses,
        RoundKind::Geometry,
        &RoundOptions {
            video: VideoOptions {
                frame_numbers: frames_in.iter().map(|&i| scene.frame_numbers[i]).collect(),
                ..VideoOptions::default()
            },
            geometry_finest_level: window_finest_level(&view.camera),
            ..RoundOptions::default()
        },
    )?;
    for (&i, r) in frames_in.iter().zip(&round.frames) {
        if matches!(r.status, FrameStatus::Converged | FrameStatus::NotConverged) {
            state.poses[i] = without_roll(&state.poses[i], &r.pose);
        }
    }
    Ok(())
}

/// `to` with the roll about `from`'s view axis taken out of the turn from `from`. A round
/// airway does not fix the roll against the geometry, and the tracked frames hold it against
/// their texture: with the window's roll kept, 20 frames at 128x128 tracked in a scope light
/// ended 1.74 deg median off (3 of 20 within 1 mm and 1 deg), without it 0.39 deg (20 of 20);
/// on the demo phantom's seed 11 1.77 and 1.07 deg (BENCHMARKS.md, "Tracking").
fn without_roll(from: &Affine, to: &Affine) -> Affine {
    let mut d = delta_between(from, to);
    let r = rotation_of(from);
    let mut w = r.transpose() * d.rotation;
    w.z = 0.0;
    d.rotation = r * w;
    apply_delta(from, &d)
}
