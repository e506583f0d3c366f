//! The registration stage (issue 16): every frame's pose refined against the CT before the
//! model is fitted with them. Rounds alternate (a) the light and a consensus texture
//! fitted with the current poses and (b) every frame registered against that model
//! ([`crate::registration`]), until the poses stop moving or the rounds run out.
//!
//! The first round registers against the geometry's shading alone (each frame divided by the
//! albedo its colour predicts): a texture fused from the given poses follows their errors, and
//! frames registered against it stay where they were. Every `registration_geometry_every`-th
//! round does so again: the texture moves with the frames, so an error they all share (a turn
//! about the airway's axis, a shift along it) is measured by the geometry alone, and a second
//! look from poses the texture rounds made consistent halves it (BENCHMARKS.md). A geometry
//! round that leaves many frames outliers (far from the tracker's poses) is run again before
//! any texture is trusted. Late geometry rounds (`registration_shading_from`) also divide each
//! frame by the texture's albedo seen from its pose: by then the texture is close enough to
//! the truth that holding it in the image removes most of what pulls the geometry's turn and
//! shift, the albedo a frame's colour does not predict.
//!
//! The first round's light is fitted at the given poses, and follows their errors: from poses a
//! few millimetres off it may predict no frame well enough to register it. With a light
//! calibrated on another video of the same bronchoscope (`BuildOptions::scope_light`) the first
//! round registers against that light's shape instead, with this video's gains. Without one, a
//! first round that converges on too few frames is run again against a Lambertian lamp with a
//! uniform beam (`shading::calibrated::lambert_lamp`), with this video's gains: a light that
//! needs no poses, whose shape is not this scope's. A first round that still fails is run again
//! from the given poses corrected as each frame's neighbours agree (the median of their
//! corrections, [`consensus_poses`]), and again from where that run's frames agree, until the
//! agreement stops moving: from poses 4-6 mm off each frame finds its own wrong minimum, but
//! the tracker's drift is shared by neighbouring frames, and the median outvotes them.
//!
//! Frames that end flagged (a wrong given pose, too few comparable pixels, a cost far above the
//! video's) are left out of the model, never silently kept: [`PoseRegistration`] says which and
//! why, and model.json counts them.

use super::blur_check::{blurred_in, judge_sharpness};
use super::cross_validation::cross_validate;
use super::error::BuildError;
use super::fit_pass::{fit_pass, LightSamples};
use super::frames::DepthCache;
use super::light::{calibrated_light, Consensus};
use super::options::{BuildOptions, PosesMode};
use super::scene::BuildScene;
use super::selection::choose_tracked;
use super::tracking::track_poses;
use crate::camera::{Camera, Pose};
use crate::image::reduce::{reduce_frame, reduce_mask};
use crate::image::Frame;
use crate::io::poses::PoseEntry;
use crate::math::Affine;
use crate::model::registration::{FramePoseResult, PoseOverlay, PoseRegistration, RoundSummary};
use crate::model::selection::FrameSelection;
use crate::registration::{
    blocks::BlockOptions,
    consensus::consensus_poses,
    delta_between, interpolate_flagged,
    joint::{joint_windows, refine_jointly, JointOptions, JointRole},
    joint_shift::ShiftSearch,
    register_round,
    rounds::levels_below_reference,
    FrameRegistrar, FrameRegistration, FrameStatus, ModelParts, RegistrationOptions, RoundKind,
    RoundOptions, TrackState, VideoOptions, VideoRegistration,
};
use crate::render::{MipOptions, MipTexture};
use crate::shading::calibrated::{
    lambert_lamp, with_video_gains, CalibratedModel, CalibratedOptions, PooledSamples, ScopeLight,
    SpecularMode,
};
use crate::shading::{FittedShading, ShadingKind};
use crate::workflow::progress::Progress;
use crate::workflow::registration_overlays::{choose_overlay_frames, pose_overlays};
use crate::Result;
use rayon::prelude::*;
use std::time::Instant;

/// A frame whose registration is not to be trusted.
fn flagged(status: FrameStatus) -> bool {
    !matches!(status, FrameStatus::Converged | FrameStatus::NotConverged)
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v.get(v.len() / 2).copied().unwrap_or(0.0)
}

/// Refine the poses of `scene` (unless `opts.poses` is [`PosesMode::Fixed`]); flagged frames
/// are removed from the scene. `None` when the poses were trusted as given. Tracked from the
/// first pose, the frames of a `selection` that chose frames to track are chosen among once
/// tracked ([`choose_tracked`]).
pub fn register_poses(
    scene: &mut BuildScene,
    opts: &BuildOptions,
    selection: Option<&mut FrameSelection>,
    warnings: &mut Vec<String>,
) -> Result<Option<PoseRegistration>> {
    let first = opts.poses == PosesMode::First;
    if opts.poses == PosesMode::Fixed || (!first && opts.registration_rounds == 0) {
        if let Some(scope) = &opts.scope_light {
            warnings.push(format!(
                "the scope light {} serves the registration only, and the poses were not registered: it was not used",
                scope.source.display()
            ));
        }
        return Ok(None);
    }
    let mut view = RegistrationView::new(scene, opts.quiet)?;
    // Without a tracker the rounds start from the poses tracked from the first frame's.
    let (mut statuses, tracking, mut last_light) = if first {
        let (state, summary, light) = track_poses(scene, &view, opts, warnings)?;
        let mut statuses = tracked_statuses(&state);
        if let Some(record) = selection {
            let accepted: Vec<bool> = statuses.iter().map(|s| !s.1).collect();
            let keep = choose_tracked(scene, record, &accepted, opts);
            if keep.len() < scene.frame_count() {
                scene.keep_frames(&keep, opts.depth_cache_bytes);
                view = view.subset(&keep);
                statuses = keep.iter().map(|&i| statuses[i].clone()).collect();
            }
        }
        (statuses, Some(summary), Some(light))
    } else {
        (blank_statuses(&view), None, None)
    };
    // The tracker's verdicts, which stand when its poses are kept.
    let tracked = statuses.clone();
    let rejoined = match first {
        true => rejoin_blurred_between_kept(scene, &mut statuses, opts),
        false => Vec::new(),
    };
    let given = scene.poses.clone();
    let start_statuses = statuses.clone();
    let rounds_to_run = match first {
        true if !opts.tracking.refine_after => 0,
        _ => opts.registration_rounds,
    };
    // The rounds refine the frames the tracker kept, and those it found blurred between two
    // kept ones (placed between them above): a frame it lost sits at a predicted pose, often
    // outside the lumen, and is left out of the model anyway. On a real airway tree
    // (ATM_224) whose track was lost at frame 40 of 80, the rounds over all 80 frames failed
    // (5 converged) and refined none; over the 40 tracked frames they converged on all 40.
    let rounds_on: Vec<usize> = (0..scene.frame_count())
        .filter(|&i| statuses.get(i).is_none_or(|s| !s.1))
        .collect();
    let warnings_before = warnings.len();
    let mut on = rounds_on.clone();
    let mut blurred: Vec<usize> = Vec::new();
    let mut blur_check = None;
    let (run, refined_score) = loop {
        let (run, score) = rounds_on_frames(
            scene,
            &view,
            &on,
            rounds_to_run,
            opts,
            warnings,
            &mut statuses,
            &mut last_light,
        )?;
        let found = match &last_light {
            Some(light)
                if opts.leave_out_blurred
                    && blurred.is_empty()
                    && sharpness_can_be_judged(&run.rounds) =>
            {
                let sharp_so_far: Vec<usize> = on
                    .iter()
                    .copied()
                    .filter(|&i| statuses.get(i).is_none_or(|s| !s.1))
                    .collect();
                let check = judge_sharpness(scene, &view, &sharp_so_far, light, opts)?;
                let found = blurred_in(&check, &sharp_so_far);
                blur_check = Some(check);
                found
            }
            _ => Vec::new(),
        };
        if found.is_empty() {
            break (run, score);
        }
        // Fused into the registration's texture, blurred frames smear it for every frame: the
        // rounds run again without them, from the poses they started from (demo phantom, a
        // fifth of the frames blurred, a tracker's 1.5 mm / 2 deg: 0.125 mm / 0.550 deg with
        // them, 0.105 mm / 0.258 deg without; BENCHMARKS.md, session 35).
        warnings.truncate(warnings_before);
        warnings.push(format!(
            "registration: {} of {} frames are far less sharp than the model predicts them from their poses (motion blur or defocus): the rounds were run again without them, and they are left out of the model",
            found.len(),
            on.len()
        ));
        // A blurred frame keeps the pose the first rounds refined (written, not used;
        // without a tracker a flagged frame is then placed between its neighbours, below).
        let mut start = given.clone();
        for &i in &found {
            start[i] = scene.poses[i];
        }
        set_poses(scene, start, opts);
        statuses = match start_statuses.is_empty() {
            true => vec![("given".to_string(), false); scene.frame_count()],
            false => start_statuses.clone(),
        };
        for &i in &found {
            statuses[i] = (FrameStatus::Blurred.name().to_string(), true);
        }
        on.retain(|i| !found.contains(i));
        blurred = found;
    };
    if blur_check.is_none() {
        // No check judged the frames the tracker found blurred: its verdict stands.
        for &i in &rejoined {
            statuses[i] = (FrameStatus::Blurred.name().to_string(), true);
        }
    }
    let RoundsRun {
        rounds,
        joint,
        given_score,
        lambert_lamp,
        consensus_start,
    } = run;
    let margin = opts.registration_keep_margin_db;
    let kept_given = matches!((given_score, refined_score), (Some(g), Some(r)) if r <= g + margin);
    let registered = scene.poses.clone();
    if kept_given {
        set_poses(scene, given.clone(), opts);
        warnings.push(format!(
            "registration: the refined poses do not predict held-out frames more than {margin} dB better than the given ones (refined {:.2} dB, given {:.2} dB); the model is built with the given poses",
            refined_score.unwrap_or(f64::NAN),
            given_score.unwrap_or(f64::NAN)
        ));
    }
    if kept_given && first {
        // The tracked poses are kept: so are the tracker's verdicts on them.
        statuses = tracked;
        for &i in &blurred {
            statuses[i] = (FrameStatus::Blurred.name().to_string(), true);
        }
    }
    if first {
        // A flagged frame between two kept ones is placed between them, not left at the
        // tracker's prediction (it is left out of the model either way).
        let flagged: Vec<bool> = statuses.iter().map(|s| s.1).collect();
        interpolate_flagged(&mut scene.poses, &flagged, &scene.frame_numbers);
    }
    let results: Vec<FramePoseResult> = statuses
        .into_iter()
        .enumerate()
        .map(|(i, (status, is_flagged))| {
            let d = delta_between(&given[i], &scene.poses[i]);
            // Neither a frame that shows nothing nor a blurred one is used, whatever poses
            // are kept.
            let unusable =
                status == FrameStatus::Blank.name() || status == FrameStatus::Blurred.name();
            FramePoseResult {
                frame: scene.frame_numbers[i],
                correction_mm: d.mm(),
                correction_deg: d.deg(),
                status,
                // Kept given poses are all used, but not a frame the tracker lost, one that
                // shows nothing or a blurred one.
                used: !is_flagged || (kept_given && !first && !unusable),
            }
        })
        .collect();
    let entries = |poses: &[Affine]| -> Vec<PoseEntry> {
        scene
            .case
            .poses
            .iter()
            .zip(poses)
            .map(|(e, p)| PoseEntry {
                frame: e.frame.clone(),
                pose: Pose::new(*p),
            })
            .collect()
    };
    let (poses, refined) = (entries(&scene.poses), entries(&registered));
    let overlays = match &last_light {
        Some(light) => overlays(scene, &view, light, &given, &registered, &results)?,
        None => Vec::new(),
    };
    let keep: Vec<usize> = (0..results.len()).filter(|&i| results[i].used).collect();
    let left_out = results.len() - keep.len();
    if keep.len() < 2 {
        return Err(BuildError::Registration(format!(
            "only {} of {} frames registered to the CT; check the poses (or build with --poses fixed)",
            keep.len(),
            results.len()
        ))
        .into());
    }
    if left_out > 0 {
        let with = |status: &str| {
            results
                .iter()
                .filter(|r| !r.used && r.status == status)
                .count()
        };
        let (blank, blurred) = (
            with(FrameStatus::Blank.name()),
            with(FrameStatus::Blurred.name()),
        );
        let untrusted = left_out - blank - blurred;
        let why: Vec<String> = [
            (blank, "show next to nothing (dark or saturated)"),
            (blurred, "blurred"),
            (untrusted, "with a pose that could not be trusted"),
        ]
        .iter()
        .filter(|(n, _)| *n > 0)
        .map(|(n, what)| format!("{n} {what}"))
        .collect();
        warnings.push(format!(
            "registration left out {left_out} of {} frames: {} (registration.frames in model.json, or in register's registration.json, says which and why)",
            results.len(),
            why.join(", ")
        ));
        scene.keep_frames(&keep, opts.depth_cache_bytes);
    }
    let scope_light = opts
        .scope_light
        .as_ref()
        .filter(|_| !rounds.is_empty() || tracking.is_some())
        .map(|s| s.source.display().to_string());
    Ok(Some(PoseRegistration {
        frames: results,
        rounds,
        joint,
        left_out,
        kept: if kept_given { "given" } else { "refined" }.to_string(),
        held_out_psnr_given_db: given_score,
        held_out_psnr_refined_db: refined_score,
        tracking,
        scope_light,
        lambert_lamp,
        consensus_start,
        blur_check,
        overlays,
        given,
        poses,
        refined,
    }))
}

/// Up to `count` rounds ([`run_rounds`]) on the frames `on` of the scene (increasing; all of
/// them when fewer than two), the others left where they are, and the held-out PSNR at the
/// refined poses when the rounds scored the poses they started from. `statuses` (every
/// frame's, or empty) takes the rounds' statuses of the frames `on`.
#[allow(clippy::too_many_arguments)]
pub(super) fn rounds_on_frames(
    scene: &mut BuildScene,
    view: &RegistrationView,
    on: &[usize],
    count: usize,
    opts: &BuildOptions,
    warnings: &mut Vec<String>,
    statuses: &mut Vec<(String, bool)>,
    last_light: &mut Option<CalibratedModel>,
) -> Result<(RoundsRun, Option<f64>)> {
    let n = scene.frame_count();
    let on: Vec<usize> = match on.len() {
        0 | 1 => (0..n).collect(),
        _ => on.to_vec(),
    };
    let subset_view;
    let view = match on.len() == n {
        true => view,
        false => {
            subset_view = view.subset(&on);
            &subset_view
        }
    };
    let mut on_statuses: Vec<_> = match statuses.is_empty() {
        true => Vec::new(),
        false => on.iter().map(|&i| statuses[i].clone()).collect(),
    };
    let out = scene.on_frames(&on, opts.depth_cache_bytes, |scene| {
        let run = run_rounds(
            scene,
            view,
            count,
            opts,
            warnings,
            &mut on_statuses,
            last_light,
        )?;
        // Keep the refined poses only when they predict held-out frames clearly better than
        // the given ones (the same test, with the same held-out frames, as the shading
        // model's choice; `registration_keep_margin_db` says why clearly).
        let refined_score = match run.given_score {
            Some(_) => {
                // Refitted at the final poses, as the given poses' light was at theirs: the
                // last round's light (fitted a round or two earlier) saves 3.9 s but scored
                // the refined poses of the ATM_305 case 0.25 dB lower.
                let light = round_light(scene, opts, warnings)?;
                held_out_psnr(scene, &light, opts)?
            }
            None => None,
        };
        Ok::<_, crate::Error>((run, refined_score))
    })?;
    match statuses.is_empty() {
        true => *statuses = on_statuses,
        false => {
            for (&i, s) in on.iter().zip(on_statuses) {
                statuses[i] = s;
            }
        }
    }
    Ok(out)
}

/// The resolution frames are registered at: the working one, reduced further to at most
/// 400 pixels across. The registration's finest grid has ~80 points across (measured on the
/// 320-pixel demo), so more pixels add nothing but memory: every frame is held in memory for
/// the rounds (a 1280x720 video: 0.7 MB per frame at 320x180).
pub(super) struct RegistrationView {
    /// Every frame of the case, reduced.
    pub(super) frames: Vec<Frame>,
    /// The camera of the reduced frames.
    pub(super) camera: Camera,
    /// The case's image mask reduced like the frames.
    pub(super) mask: Option<Vec<bool>>,
}

impl RegistrationView {
    /// The model the frames are registered against: the scene's mesh in `light`, with
    /// `texture` (`None`: the geometry's shading alone), seen by the reduced frames' camera.
    pub(super) fn model_parts<'a>(
        &'a self,
        scene: &'a BuildScene,
        light: &'a CalibratedModel,
        texture: Option<&'a MipTexture>,
    ) -> ModelParts<'a> {
        ModelParts {
            scene: &scene.scene,
            tri_uv: &scene.tri_uv,
            texture,
            light,
            camera: &self.camera,
        }
    }

    pub(super) fn new(scene: &BuildScene, quiet: bool) -> Result<RegistrationView> {
        let full = &scene.case.camera;
        let level = (scene.level..=4)
            .find(|&l| full.width >> l <= 400 || full.width.min(full.height) >> (l + 1) < 64)
            .unwrap_or(scene.level);
        let mask = scene
            .case
            .mask
            .as_ref()
            .map(|m| reduce_mask(&m.image, full.width as usize, full.height as usize, level));
        let progress = Progress::new("read frames", scene.frame_count() as u64, quiet);
        let frames = scene
            .case
            .frame_source()?
            .map(|f| {
                progress.inc();
                f.map(|f| reduce_frame(&f, level, scene.saturation_level))
            })
            .collect::<std::result::Result<_, _>>()?;
        progress.finish();
        Ok(RegistrationView {
            frames,
            camera: full.at_level(level),
            mask,
        })
    }

    /// The view of the frames `keep` (indices into these).
    fn subset(&self, keep: &[usize]) -> RegistrationView {
        RegistrationView {
            frames: keep.iter().map(|&i| self.frames[i].clone()).collect(),
            camera: self.camera,
            mask: self.mask.clone(),
        }
    }
}

/// What [`run_rounds`] did.
pub(super) struct RoundsRun {
    /// The rounds, discarded ones included.
    pub(super) rounds: Vec<RoundSummary>,
    /// The joint stage after them ([`joint_stage`]).
    joint: Option<RoundSummary>,
    /// The held-out PSNR at the poses the rounds started from.
    given_score: Option<f64>,
    /// The first round was run again against the Lambertian lamp.
    lambert_lamp: bool,
    /// The first round was run again from the poses its frames agreed on.
    consensus_start: bool,
}

/// Up to `count` rounds of the alternation from the scene's poses (the first, every
/// `registration_geometry_every`-th and the one after an unsettled geometry round against the
/// geometry); each frame's status and the last round's light are updated. A first round that
/// fails against the light fitted at the given poses is run again against the Lambertian lamp
/// (`BuildOptions::registration_lambert_fallback`).
fn run_rounds(
    scene: &mut BuildScene,
    view: &RegistrationView,
    count: usize,
    opts: &BuildOptions,
    warnings: &mut Vec<String>,
    statuses: &mut Vec<(String, bool)>,
    last_light: &mut Option<CalibratedModel>,
) -> Result<RoundsRun> {
    let mut rounds = Vec::new();
    let mut given_score = None;
    let mut lamp = None;
    let mut lambert_lamp = false;
    let mut consensus_start = false;
    let every = opts.registration_geometry_every.max(1);
    let mut r = 0;
    let mut repeat_geometry = false;
    let later_opts = BuildOptions {
        max_pooled_samples: opts.registration_light_samples,
        ..opts.clone()
    };
    while r < count {
        let kind = match (
            repeat_geometry || r % every == 0,
            r >= opts.registration_shading_from,
        ) {
            (true, false) => RoundKind::Geometry,
            (true, true) => RoundKind::Shading,
            (false, _) => RoundKind::Texture,
        };
        // A texture round registers against the light of the round before it: the poses moved
        // a tenth of a degree, and refitting it changed nothing measurable (demo phantom,
        // 1.5 mm / 2 deg: 0.126 mm / 0.363 deg reused, 0.133 mm / 0.408 deg refitted) for 3.9 s
        // a round. A shading round refits it: reusing it gave the same new views on that case
        // (31.03 dB) but lost the round's gain at 3 mm / 4 deg (29.38 against 29.92 dB).
        // The lights of the first geometry round, which also scores the given poses against
        // the refined poses' full light, and of its repeat, fitted at poses still a millimetre
        // off, pool all the samples the build's does (the 24-frame phantom at 3 mm / 4 deg with
        // the repeat's light on fewer: 1.09 mm / 2.53 deg after the two rounds, against 1.11 mm
        // / 1.87 deg).
        let light = match (kind, last_light.take()) {
            (RoundKind::Texture, Some(l)) => l,
            _ if r == 0 => {
                let lights = first_light(scene, opts, warnings)?;
                given_score = held_out_psnr(scene, &lights.fitted, opts)?;
                lamp = lights.lamp;
                lights.scope.unwrap_or(lights.fitted)
            }
            _ if r < every => round_light(scene, opts, warnings)?,
            _ => round_light(scene, &later_opts, warnings)?,
        };
        let before = scene.poses.clone();
        let (mut summary, mut video) = run_round(scene, view, kind, &light, opts, r)?;
        let mut light = light;
        let min_share = opts.registration_min_converged_share;
        let failed = |v: &VideoRegistration| {
            let converged = v.frames.iter().filter(|f| !flagged(f.status)).count();
            round_failed(converged, v.frames.len(), min_share).then_some(converged)
        };
        if let Some((l, converged)) = lamp.take().zip(failed(&video)) {
            warnings.push(format!(
                "registration: round 1 (geometry) converged on {converged} of {} frames against the light fitted at the given poses; it was run again against a Lambertian lamp with this video's gains",
                video.frames.len()
            ));
            set_poses(scene, before.clone(), opts);
            summary.discarded = true;
            rounds.push(summary);
            (summary, video) = run_round(scene, view, kind, &l, opts, r)?;
            light = l;
            lambert_lamp = true;
        }
        if let Some(converged) = failed(&video).filter(|_| r == 0) {
            let agreement = rerun_from_agreement(
                scene,
                view,
                opts,
                warnings,
                &before,
                (&mut summary, &mut video, &mut light),
                &mut rounds,
            )?;
            if agreement.passes > 0 {
                consensus_start = true;
                warnings.push(format!(
                    "registration: round 1 (geometry) converged on {converged} of {} frames{}; it was run again {} from the given poses corrected as each frame's {} nearest frames agreed (the median of their corrections), with {} there, {}",
                    video.frames.len(),
                    if lambert_lamp { " against the Lambertian lamp" } else { "" },
                    match agreement.passes {
                        1 => "once".to_string(),
                        n => format!("{n} times"),
                    },
                    2 * CONSENSUS_HALF_WINDOW,
                    match opts.scope_light {
                        Some(_) => "the scope light's gains measured",
                        None => "the light fitted",
                    },
                    match agreement.settled {
                        true => "until that agreement settled",
                        false => "and the agreement had not settled when the runs ran out",
                    }
                ));
            }
        }
        let still_failed = failed(&video);
        let frames_done = video.frames;
        *last_light = Some(light);
        if let Some(converged) = still_failed {
            set_poses(scene, before, opts);
            warnings.push(format!(
                "registration: round {} ({}) converged on {converged} of {} frames; its poses are discarded and the rounds stop there (the poses it started from may be too far off for the photometric registration: check them, or build with --poses fixed)",
                r + 1,
                summary.against,
                frames_done.len()
            ));
            if statuses.is_empty() {
                // No round was kept: every frame stays at its given pose.
                *statuses = vec![("given".to_string(), false); frames_done.len()];
            }
            summary.discarded = true;
            rounds.push(summary);
            break;
        }
        let settled = kind == RoundKind::Texture
            && summary.median_step_mm < opts.registration_tolerance_mm
            && summary.median_step_deg < 0.1;
        repeat_geometry = kind == RoundKind::Geometry
            && !geometry_settled(&frames_done, opts.registration_geometry_repeat_share);
        rounds.push(summary);
        *statuses = frames_done
            .iter()
            .map(|f| (f.status.name().to_string(), flagged(f.status)))
            .collect();
        // Settled texture rounds go on with the next geometry round, if one is left.
        r = if settled {
            (r / every + 1) * every
        } else {
            r + 1
        };
    }
    let joint = match (last_light.as_ref(), rounds.iter().any(|r| !r.discarded)) {
        (Some(light), true) if opts.registration_joint => {
            joint_stage(scene, view, light, opts, statuses)?
        }
        _ => None,
    };
    Ok(RoundsRun {
        rounds,
        joint,
        given_score,
        lambert_lamp,
        consensus_start,
    })
}

/// The coarsest pyramid level of the texture rounds from round `LATER_TEXTURE_FROM_ROUND` on:
/// those after the first texture round, or every texture round when the first geometry round
/// was repeated (as on the 3 mm / 4 deg case below). They start from poses the rounds before
/// have made consistent to a few tenths of a degree, under a pixel at level 1, and the coarser
/// levels (a third of a round's renders) moved nothing: on the demo phantom with 3 mm / 4 deg
/// drift new views 30.10 -> 30.13 dB, 0.410 -> 0.338 deg median; 1.5 mm / 2 deg 30.92 ->
/// 30.98 dB, 0.317 -> 0.274 deg. On ATM_224 alone it gives the same poses, and with the texture
/// rounds' tolerances and the later rounds' light 25.53 -> 25.21 dB (BENCHMARKS.md).
const LATER_TEXTURE_COARSEST_LEVEL: usize = 1;
/// The round from which texture rounds start at `LATER_TEXTURE_COARSEST_LEVEL`.
const LATER_TEXTURE_FROM_ROUND: usize = 2;

/// The pyramid levels of the joint stage at the reference frame size (counted as the rounds'
/// are, [`levels_below_reference`]): level 1 gathers the move, level 0 places it (demo phantom,
/// the rounds' poses from a 1.5 mm / 2 deg tracker: new views 31.06 -> 32.94 dB; with the
/// mean shift along the view taken back after each level, levels 1, 0 gave 32.77 dB and
/// levels 2, 1, 0 32.74 dB; BENCHMARKS.md, session 38).
const JOINT_LEVELS: [usize; 2] = [1, 0];

/// Most renders on each of [`JOINT_LEVELS`] (a level ends early after a render that took no
/// step). The joint stage's cost is consistent from one render to the next once the points are
/// off the pixel centres ([`RegistrationOptions::ray_jitter`]), so a further render keeps
/// lowering it, and renders on level 1, where the move is gathered, do more than on level 0:
/// demo phantom, 3 mm / 4 deg tracker, new views 31.59 / 31.65 / 31.78 / 31.74 dB with 4 / 5
/// / 6 / 8 renders on level 1 and 4 on level 0, 31.50 dB with 4 and 7, 31.71 dB with 6 and 6;
/// from 4, 4 to 6, 4 seed 7 at 3 mm / 4 deg 29.82 -> 29.98 dB, 1.5 mm / 2 deg 32.68 -> 32.66
/// dB, and ATM_384 and `--poses first` the same to the bit (their fifth render took no step).
/// A render on level 1 costs about 1.8 s of the demo build (BENCHMARKS.md, session 41).
const JOINT_RENDERS: [usize; 2] = [6, 4];

/// Most frames the joint stage refines in one solve. Its normal equations are dense, seven
/// unknowns a frame (200 frames: 1400 x 1400, 16 MB, and a cell seen by k frames adds k^2
/// blocks): a longer video (`--max-frames` above the default) is refined in consecutive
/// windows of this many, each with the `JOINT_WINDOW_ANCHORS` frames refined just before it
/// held where they are.
const JOINT_WINDOW: usize = 200;
const JOINT_WINDOW_ANCHORS: usize = 20;

/// The joint stage after the rounds ([`BuildOptions::registration_joint`]): the frames not
/// flagged in `statuses`, and those flagged only for their cost, refined together against the
/// geometry in `light`, the albedo eliminated, after a search for runs of frames settled
/// along their views away from the rest ([`ShiftSearch`]); the frame a video without a
/// tracker starts from stays where it is. A frame flagged for its cost whose cost is now like
/// the others' is taken back. `None` when fewer than two frames are left to refine.
fn joint_stage(
    scene: &mut BuildScene,
    view: &RegistrationView,
    light: &CalibratedModel,
    opts: &BuildOptions,
    statuses: &mut [(String, bool)],
) -> Result<Option<RoundSummary>> {
    let started = Instant::now();
    let n = scene.frame_count();
    let anchored = anchored_frames(scene, opts);
    // A frame that fits worse than the rest often does so because the frames next to it sit
    // away from the truth (the end of the demo video at 3 mm / 4 deg: frames 74-75 flagged,
    // 76-79 kept 1 mm ahead along their views); with its neighbours moved it may fit.
    let high_cost = FrameStatus::HighCost.name();
    let roles: Vec<JointRole> = (0..n)
        .map(|i| match statuses.get(i) {
            Some((s, true)) if s != high_cost => JointRole::Skipped,
            _ if anchored.contains(&i) => JointRole::Anchor,
            _ => JointRole::Refined,
        })
        .collect();
    if roles.iter().filter(|&&r| r == JointRole::Refined).count() < 2 {
        return Ok(None);
    }
    let below = levels_below_reference(&view.camera);
    // Frames smaller than the reference have fewer levels: passes that fall on the same level
    // are one, the finest's.
    let mut passes: Vec<(usize, usize)> = JOINT_LEVELS
        .iter()
        .zip(JOINT_RENDERS)
        .map(|(l, renders)| (l.saturating_sub(below), renders))
        .collect();
    passes.reverse();
    passes.dedup_by_key(|p| p.0);
    passes.reverse();
    let reg = FrameRegistrar::new(
        view.model_parts(scene, light, None),
        RegistrationOptions {
            coarsest_level: passes[0].0,
            finest_level: 0,
            // Points off the pixel centres: the cost the solve lowers on the points held
            // between renders is then the cost the next render finds (see `ray_jitter`).
            ray_jitter: true,
            ..RegistrationOptions::default()
        },
    )?;
    let windows = joint_windows(&roles, JOINT_WINDOW, JOINT_WINDOW_ANCHORS);
    let progress = Progress::new(
        "register (all frames at once)",
        (windows.len() * passes.iter().map(|p| p.1).sum::<usize>()) as u64,
        opts.quiet,
    );
    let mut poses = scene.poses.clone();
    let mut costs: Vec<Option<f64>> = vec![None; n];
    let mut moved = std::collections::BTreeSet::new();
    for window_roles in &windows {
        for (l, &(level, renders)) in passes.iter().enumerate() {
            let result = refine_jointly(
                &reg,
                &view.frames,
                &light.gains,
                view.mask.as_deref(),
                &poses,
                window_roles,
                &JointOptions {
                    level,
                    renders,
                    shift_search: (l == 0).then(ShiftSearch::default),
                    progress: progress.bar(),
                    ..JointOptions::default()
                },
            )?;
            moved.extend(result.shifted.iter().flat_map(|s| s.frames.iter().copied()));
            for (i, c) in result.frame_costs.into_iter().enumerate() {
                if window_roles[i] == JointRole::Refined {
                    costs[i] = c;
                }
            }
            poses = result.poses;
        }
    }
    progress.finish();
    let fitting: Vec<f64> = (0..n)
        .filter(|&i| roles[i] == JointRole::Refined && !statuses[i].1)
        .filter_map(|i| costs[i])
        .collect();
    let gate = VideoOptions::default().cost_ratio * median(fitting);
    for i in 0..n {
        if statuses[i].1 && statuses[i].0 == high_cost && costs[i].is_some_and(|c| c <= gate) {
            statuses[i] = (FrameStatus::Converged.name().to_string(), false);
        }
    }
    let steps: Vec<_> = (0..n)
        .filter(|&i| roles[i] == JointRole::Refined)
        .map(|i| delta_between(&scene.poses[i], &poses[i]))
        .collect();
    let mut counts = std::collections::BTreeMap::new();
    for (status, _) in statuses.iter() {
        *counts.entry(status.clone()).or_insert(0) += 1;
    }
    set_poses(scene, poses, opts);
    Ok(Some(RoundSummary {
        against: "all frames at once".to_string(),
        median_step_mm: median(steps.iter().map(|d| d.mm()).collect()),
        median_step_deg: median(steps.iter().map(|d| d.deg()).collect()),
        counts,
        realigned: moved.len(),
        seconds: started.elapsed().as_secs_f64(),
        discarded: false,
    }))
}

/// Put the scene's frames at `poses`: the depths cached at the old ones are dropped.
fn set_poses(scene: &mut BuildScene, poses: Vec<Affine>, opts: &BuildOptions) {
    scene.poses = poses;
    scene.cache = DepthCache::new(scene.frame_count(), opts.depth_cache_bytes, scene.level);
}

/// The frames whose given pose is exact ([`first_frame_held`]).
fn anchored_frames(scene: &BuildScene, opts: &BuildOptions) -> Vec<usize> {
    // A held frame's zero correction may leave rounding in its pose; a refinement kept moved
    // it far more (it fitted the frame 10 % better).
    let at_given = match (scene.poses.first(), scene.case.poses.first()) {
        (Some(p), Some(given)) => {
            let moved = delta_between(&given.pose.camera_to_world, p);
            moved.mm() < 1e-6 && moved.deg() < 1e-6
        }
        _ => false,
    };
    first_frame_held(&scene.frame_numbers, at_given, opts)
}

/// Without a tracker (`--poses first`), the video's first frame when it is among the scene's
/// (`frame_numbers`) and still at the pose the case gives (`at_given`): given exactly
/// (`--trust-first-pose`), or agreeing with the CT as far as that frame alone can tell (the
/// tracking's refinement of it did not fit 10 % better). Held, the first pose anchors the video
/// (session 29: ATM_224 / 305 / 384 from their exact first poses, 28.95 / 28.87 / 25.00 dB ->
/// 29.22 / 29.63 / 25.35 dB). A first pose the refinement moved is one frame's estimate, and
/// the rounds refine it with the others: held, it pulled its neighbours to it (`phantom --seed
/// 7`, first pose 1.7 mm / 1.8 deg off, refined to 1.0 mm / 3.3 deg: frames 0-2 ended 0.4-1.0
/// mm / 1.1-3.3 deg off and new views scored 30.12 dB; refined with the others, frames 0-75
/// within 1 mm and 1 deg, 30.62 dB; BENCHMARKS.md, session 46).
fn first_frame_held(frame_numbers: &[usize], at_given: bool, opts: &BuildOptions) -> Vec<usize> {
    match (opts.poses, frame_numbers.first()) {
        (PosesMode::First, Some(0)) if at_given => vec![0],
        _ => Vec::new(),
    }
}

/// The poses a tracker gave (the case's, with `--poses refine`), from which the rounds judge
/// the jumps of runs of frames as well as from the poses each starts at (see
/// `registration::blocks`); none without a tracker (`--poses first`: the case's poses are the
/// first frame's, repeated).
fn tracker_poses(scene: &BuildScene, opts: &BuildOptions) -> Vec<Affine> {
    match opts.poses {
        PosesMode::Refine => scene
            .case
            .poses
            .iter()
            .map(|p| p.pose.camera_to_world)
            .collect(),
        PosesMode::First | PosesMode::Fixed => Vec::new(),
    }
}

/// Frames on each side whose corrections a failed first round's restart takes the median of
/// (see [`consensus_poses`]): a tracker's drift changes little over seven frames, and three
/// outliers of seven are outvoted.
const CONSENSUS_HALF_WINDOW: usize = 3;

/// The runs from the agreement stop when the agreed poses moved less than this from the last
/// run's (median over the frames; mm and degrees).
const CONSENSUS_TOLERANCE_MM: f64 = 0.1;
const CONSENSUS_TOLERANCE_DEG: f64 = 0.1;

/// What [`rerun_from_agreement`] did.
struct AgreementRuns {
    /// Runs of the first round from agreed poses.
    passes: usize,
    /// The agreed poses stopped moving before the runs ran out.
    settled: bool,
}

/// A first round that failed, run again from the poses its frames agree on: the given poses
/// corrected by the median correction of each frame's nearest frames
/// ([`consensus_poses`] of where they registered), with the light fitted there (or the scope
/// light's gains measured there), until the agreed poses stop moving or
/// `opts.registration_consensus_passes` runs are spent. The round (`summary`, `video`,
/// `light`) becomes the last run's; every run before it is pushed to `rounds`, discarded.
/// On ATM_224 from 4 mm / 5 deg the agreement moved 1.0 mm / 2.8 deg, then 0.20 / 0.81, 0.015 /
/// 0.11 and 0.015 / 0.075 (BENCHMARKS.md, session 27).
fn rerun_from_agreement(
    scene: &mut BuildScene,
    view: &RegistrationView,
    opts: &BuildOptions,
    warnings: &mut Vec<String>,
    given: &[Affine],
    round: (
        &mut RoundSummary,
        &mut VideoRegistration,
        &mut CalibratedModel,
    ),
    rounds: &mut Vec<RoundSummary>,
) -> Result<AgreementRuns> {
    let (summary, video, light) = round;
    let mut previous: Option<Vec<Affine>> = None;
    let mut passes = 0;
    while passes < opts.registration_consensus_passes {
        let usable: Vec<bool> = video
            .frames
            .iter()
            .map(|f| reached_a_cost(f.status))
            .collect();
        let Some(start) = consensus_poses(given, &video.measured, &usable, CONSENSUS_HALF_WINDOW)
        else {
            break;
        };
        if let Some(p) = &previous {
            let (mm, deg) = median_move(p, &start);
            if mm < CONSENSUS_TOLERANCE_MM && deg < CONSENSUS_TOLERANCE_DEG {
                return Ok(AgreementRuns {
                    passes,
                    settled: true,
                });
            }
        }
        set_poses(scene, start.clone(), opts);
        summary.discarded = true;
        rounds.push(summary.clone());
        *light = registration_light(scene, opts, warnings)?;
        (*summary, *video) = run_round(scene, view, RoundKind::Geometry, light, opts, 0)?;
        previous = Some(start);
        passes += 1;
    }
    Ok(AgreementRuns {
        passes,
        settled: false,
    })
}

/// The median over the frames of the move from `a` to `b` (mm, degrees).
fn median_move(a: &[Affine], b: &[Affine]) -> (f64, f64) {
    let d: Vec<_> = a.iter().zip(b).map(|(a, b)| delta_between(a, b)).collect();
    (
        median(d.iter().map(|d| d.mm()).collect()),
        median(d.iter().map(|d| d.deg()).collect()),
    )
}

/// A frame's registration reached a cost: it converged, or it ended somewhere its neighbours
/// disagree with. The others were not compared with the model and stayed where they started.
fn reached_a_cost(status: FrameStatus) -> bool {
    matches!(
        status,
        FrameStatus::Converged | FrameStatus::NotConverged | FrameStatus::Outlier
    )
}

/// Whether a round on which `converged` of `frames` frames converged has failed (fewer than
/// `min_share` of them): the drift the video's smoother fits to so few frames would move all
/// the others.
fn round_failed(converged: usize, frames: usize, min_share: f64) -> bool {
    (converged as f64) < min_share * frames as f64
}

/// Whether a geometry round left the video consistent enough for a texture round: at most
/// `max_share` of its frames are outliers. From tracker poses 3 mm / 4 deg off, the texture
/// fused after one geometry round follows its outliers' errors (demo phantom: 1.00 mm /
/// 3.03 deg median, 6 of 80 frames within 1 mm and 1 deg, against 0.29 mm / 0.74 deg, 51 of
/// 80, with the geometry round repeated).
fn geometry_settled(frames: &[FrameRegistration], max_share: f64) -> bool {
    let outliers = frames
        .iter()
        .filter(|f| f.status == FrameStatus::Outlier)
        .count();
    outliers as f64 <= max_share * frames.len() as f64
}

/// One round: light and consensus texture at the scene's current poses, then every frame
/// registered against them as a round of `kind`; the scene's poses are moved to the result.
fn run_round(
    scene: &mut BuildScene,
    view: &RegistrationView,
    kind: RoundKind,
    light: &CalibratedModel,
    opts: &BuildOptions,
    round_index: usize,
) -> Result<(RoundSummary, VideoRegistration)> {
    let started = Instant::now();
    // A geometry round still needs the texture: the colour–albedo relation it divides
    // the frames by is fitted on it.
    let texture = consensus_texture(scene, light, opts)?;
    let parts = view.model_parts(scene, light, Some(&texture));
    let mask = view.mask.as_deref();
    let label = match kind {
        RoundKind::Geometry => "register (CT)",
        RoundKind::Shading => "register (CT, texture held)",
        RoundKind::Texture => "register",
    };
    let mut frame = RegistrationOptions::default();
    if kind == RoundKind::Texture && round_index >= LATER_TEXTURE_FROM_ROUND {
        frame.coarsest_level = LATER_TEXTURE_COARSEST_LEVEL;
    }
    let progress = Progress::new(label, scene.frame_count() as u64, opts.quiet);
    let video = register_round(
        parts,
        &view.frames,
        &light.gains,
        mask,
        &scene.poses,
        kind,
        &RoundOptions {
            video: VideoOptions {
                frame_numbers: scene.frame_numbers.clone(),
                progress: progress.bar(),
                // Not in the first round: from the tracker's poses a third of the frames or more
                // end as outliers and the runs are fragments with none to trust (demo phantom,
                // 3 mm / 4 deg: realigning from the first round 25.87 dB new views, from the
                // second 29.43 dB, never 26.85 dB; BENCHMARKS.md).
                blocks: (round_index > 0).then(BlockOptions::default),
                anchored: anchored_frames(scene, opts),
                tracker_poses: tracker_poses(scene, opts),
                ..VideoOptions::default()
            },
            frame,
            ..RoundOptions::default()
        },
    )?;
    progress.finish();
    let steps: Vec<(f64, f64)> = video
        .frames
        .iter()
        .zip(&scene.poses)
        .map(|(f, p)| {
            let d = delta_between(p, &f.pose);
            (d.mm(), d.deg())
        })
        .collect();
    set_poses(scene, video.frames.iter().map(|f| f.pose).collect(), opts);
    let (step_mm, step_deg) = (
        median(steps.iter().map(|s| s.0).collect()),
        median(steps.iter().map(|s| s.1).collect()),
    );
    let summary = RoundSummary {
        against: match kind {
            RoundKind::Geometry => "geometry",
            RoundKind::Shading => "shading",
            RoundKind::Texture => "texture",
        }
        .to_string(),
        median_step_mm: step_mm,
        median_step_deg: step_deg,
        counts: video.counts.clone(),
        realigned: video.realigned,
        seconds: started.elapsed().as_secs_f64(),
        discarded: false,
    };
    Ok((summary, video))
}

/// The calibrated light's mean PSNR on held-out frames at the scene's current poses (the
/// build's cross-validation, calibrated light only); `None` when cross-validation is off.
fn held_out_psnr(
    scene: &BuildScene,
    light: &CalibratedModel,
    opts: &BuildOptions,
) -> Result<Option<f64>> {
    if opts.cross_validate_every == 0 {
        return Ok(None);
    }
    let shading = FittedShading::new(ShadingKind::Calibrated, Vec::new(), Some(light.clone()));
    let cv = cross_validate(scene, &shading, opts)?;
    Ok(cv.models.first().and_then(|m| m.mean_psnr_db))
}

/// The first round's lights, their gains fitted at the given poses.
struct FirstLights {
    /// Fitted there: it scores the given poses, and the round registers against it unless
    /// `scope` is set.
    fitted: CalibratedModel,
    /// The scope's light (`opts.scope_light`).
    scope: Option<CalibratedModel>,
    /// The Lambertian lamp, for a round that fails against `fitted`
    /// (`opts.registration_lambert_fallback`, without a scope light).
    lamp: Option<CalibratedModel>,
}

/// The first round's lights at the given poses.
fn first_light(
    scene: &mut BuildScene,
    opts: &BuildOptions,
    warnings: &mut Vec<String>,
) -> Result<FirstLights> {
    let (_, samples) = fit_pass(scene, opts)?;
    let scope = match &opts.scope_light {
        Some(scope) => Some(scope_light_with_gains(scope, &samples.pooled, None)?),
        None => None,
    };
    let wants_lamp = scope.is_none() && opts.registration_lambert_fallback;
    let pooled = wants_lamp.then(|| samples.pooled.clone());
    let fitted = light_from_samples(scene, samples, opts, warnings)?;
    // The inter-reflection's kappa is the fitted light's: a share of each frame's own light,
    // which a few millimetres move little.
    let lamp = pooled.and_then(|p| {
        lambert_lamp(&p, fitted.interreflection, fitted.cos_theta_edge)
            .and_then(|lamp| with_video_gains(&lamp, &p, None))
    });
    Ok(FirstLights {
        fitted,
        scope,
        lamp,
    })
}

/// `scope`'s light with the gains of the frames of `samples` ([`with_video_gains`]; the
/// reference frame `reference` or the median one).
fn scope_light_with_gains(
    scope: &ScopeLight,
    samples: &PooledSamples,
    reference: Option<usize>,
) -> Result<CalibratedModel> {
    with_video_gains(&scope.light, samples, reference).ok_or_else(|| {
        BuildError::Registration(format!(
            "{}: no frame has enough samples to fit its gain in the scope light",
            scope.source.display()
        ))
        .into()
    })
}

/// The light to register against at the scene's current poses: the scope's
/// (`opts.scope_light`) with the frames' gains measured there (`opts.calibrated_reference`
/// the frame whose gain is 1, else the median one), or one fitted there ([`round_light`]).
/// The scope's light needs only the frames' gains, which a few frames fix as well as many.
pub(super) fn registration_light(
    scene: &mut BuildScene,
    opts: &BuildOptions,
    warnings: &mut Vec<String>,
) -> Result<CalibratedModel> {
    match &opts.scope_light {
        Some(scope) => {
            let (_, samples) = fit_pass(scene, opts)?;
            scope_light_with_gains(scope, &samples.pooled, opts.calibrated_reference)
        }
        None => round_light(scene, opts, warnings),
    }
}

/// The calibrated light fitted with the scene's current poses (a first pass and the pooled
/// fit with its refinements).
pub(super) fn round_light(
    scene: &mut BuildScene,
    opts: &BuildOptions,
    warnings: &mut Vec<String>,
) -> Result<CalibratedModel> {
    let (_, samples) = fit_pass(scene, opts)?;
    light_from_samples(scene, samples, opts, warnings)
}

/// The calibrated light fitted to `samples` of the scene's frames at their current poses.
fn light_from_samples(
    scene: &BuildScene,
    samples: LightSamples,
    opts: &BuildOptions,
    warnings: &mut Vec<String>,
) -> Result<CalibratedModel> {
    let mut round_warnings = Vec::new();
    let light_opts = BuildOptions {
        refine_gains: opts.registration_light_refinements,
        refine_light: 0,
        // The photometric registration predicts with the uniform inter-reflection.
        interreflection: crate::shading::indirect::InterreflectionMode::Uniform,
        // Without the lobe's search: the rounds' light (no gain corrections or refits) finds no
        // lobe, and fitting with it anyway moved the registration on the demo phantom with
        // 1.5 mm / 2 deg drift from 0.755 to 1.272 deg median (BENCHMARKS.md).
        calibrated: CalibratedOptions {
            specular: SpecularMode::None,
            ..opts.calibrated.clone()
        },
        ..opts.clone()
    };
    let light = calibrated_light(scene, samples, &light_opts, &mut round_warnings)?;
    warnings.extend(
        round_warnings
            .into_iter()
            .map(|w| format!("registration: {w}")),
    );
    light.map(|l| l.model).ok_or_else(|| {
        BuildError::Registration(
            "no calibrated light could be fitted to register against (build with --poses fixed)"
                .to_string(),
        )
        .into()
    })
}

/// The consensus albedo of every frame de-lit with `light` at the current poses, with its
/// mip chain: what the texture rounds register against.
pub(super) fn consensus_texture(
    scene: &BuildScene,
    light: &CalibratedModel,
    opts: &BuildOptions,
) -> Result<MipTexture> {
    let fused = Consensus::new(scene, opts).fuse(light, "registration texture")?;
    let rgb = fused.filled(&scene.texels)?;
    let image = Frame {
        width: fused.width,
        height: fused.height,
        rgb,
    };
    MipTexture::new(&image, None, opts.atlas.texel_mm, &MipOptions::default())
}

/// The reports' before/after overlays of the 3 frames with the largest corrections and a
/// typical one, on the geometry shaded by `light`.
fn overlays(
    scene: &BuildScene,
    view: &RegistrationView,
    light: &CalibratedModel,
    given: &[Affine],
    registered: &[Affine],
    results: &[FramePoseResult],
) -> Result<Vec<PoseOverlay>> {
    let parts = view.model_parts(scene, light, None);
    let chosen = choose_overlay_frames(results, 3);
    pose_overlays(
        parts,
        &view.frames,
        given,
        registered,
        &chosen,
        results,
        160,
    )
}

/// Whether the rounds `rounds` left poses and a texture consistent enough to judge a frame's
/// sharpness against the model: at least two rounds kept, and three quarters of the last
/// one's frames converged. After one kept round from 3 mm / 4 deg off (0.5-0.7 mm / 1.7-2.5
/// deg after it), or at the given poses when every round was discarded, 1-5 of 24 sharp
/// frames scored as blurred.
fn sharpness_can_be_judged(rounds: &[RoundSummary]) -> bool {
    let kept: Vec<&RoundSummary> = rounds.iter().filter(|r| !r.discarded).collect();
    kept.last().is_some_and(|r| {
        let count = |k: &str| r.counts.get(k).copied().unwrap_or(0);
        let converged = count("converged") + count("not_converged");
        kept.len() >= 2 && 4 * converged >= 3 * r.counts.values().sum::<usize>()
    })
}

/// With a tracker's poses, every frame's status before the rounds: `blank` (flagged) for a
/// frame that shows nothing ([`RegistrationOptions::shows_nothing`]), `given` for the others;
/// none when no frame is blank. A build's frame selection leaves such frames out before this;
/// `register` and `build --max-frames 0` run none, and one black frame used to stop them at
/// the light's first fit.
fn blank_statuses(view: &RegistrationView) -> Vec<(String, bool)> {
    let opts = RegistrationOptions::default();
    let mask = view.mask.as_deref();
    let blank: Vec<bool> = view
        .frames
        .par_iter()
        .map(|f| opts.shows_nothing(f, mask))
        .collect();
    if !blank.contains(&true) {
        return Vec::new();
    }
    blank
        .into_iter()
        .map(|b| match b {
            true => (FrameStatus::Blank.name().to_string(), true),
            false => ("given".to_string(), false),
        })
        .collect()
}

/// Each frame's status after tracking (`given` for the first) and whether it is flagged.
/// Frames from where the track was lost on are flagged (`track_lost`) even when the tracker
/// accepted them: they were tracked from poses extrapolated past the loss. On ATM_307 (80
/// frames) the track was lost at frame 14 and 14 frames after it were accepted 65-118 mm and
/// 34-68 deg off; the rounds over them and the 14 good ones were not kept, and they went
/// into the texture.
fn tracked_statuses(state: &TrackState) -> Vec<(String, bool)> {
    let lost = state.first_lost.unwrap_or(usize::MAX);
    state
        .status
        .iter()
        .zip(&state.accepted)
        .enumerate()
        .map(|(i, (s, &ok))| match s {
            None => ("given".to_string(), false),
            Some(_) if ok && i >= lost => ("track_lost".to_string(), true),
            Some(s) => (s.name().to_string(), !ok),
        })
        .collect()
}

/// The frames the tracker flagged `blurred` between two frames it kept
/// ([`blurred_between_kept`]): they join the rounds, each placed on the motion between those
/// two ([`interpolate_flagged`]), and the build's blur check after the rounds decides whether
/// they are left out.
///
/// The tracker judges a frame against a model of the last few frames it kept, and a
/// bronchus's smooth wall seen from a few millimetres holds as little detail against that
/// model as a motion-blurred frame. On the phantom of the real airway tree ATM_384 (no frame
/// blurred) it flagged frames 71-78 so: kept at their predictions, 2-10 deg off, out of the
/// rounds, and frame 79 after them was tracked 7 deg off and used. Refined with the others,
/// frames 71-79 end within 0.2 mm and 2.4 deg, the check leaves out 73, 74 and 77 (the frames
/// it leaves out from the exact poses too), and new views go from 28.00 to 29.23 dB
/// (BENCHMARKS.md, session 47). Frames after the last kept one are not placed: from their
/// predictions (the blurred ATM_384 video's frames 72-79) they took the whole registration
/// off (21.7 dB).
fn rejoin_blurred_between_kept(
    scene: &mut BuildScene,
    statuses: &mut [(String, bool)],
    opts: &BuildOptions,
) -> Vec<usize> {
    let rejoined = blurred_between_kept(statuses);
    if rejoined.is_empty() {
        return rejoined;
    }
    // Each run lies between two kept frames, the nearest frames not rejoined around it.
    let mut placing = vec![false; statuses.len()];
    for &i in &rejoined {
        placing[i] = true;
        statuses[i].1 = false;
    }
    let mut poses = scene.poses.clone();
    interpolate_flagged(&mut poses, &placing, &scene.frame_numbers);
    set_poses(scene, poses, opts);
    rejoined
}

/// The frames of `statuses` in runs of flagged frames, all `blurred`, between two frames not
/// flagged. A run with a frame flagged for another reason (an outlier, a lost track) may span
/// a motion the frames around it do not say.
fn blurred_between_kept(statuses: &[(String, bool)]) -> Vec<usize> {
    let kept: Vec<usize> = (0..statuses.len()).filter(|&i| !statuses[i].1).collect();
    let blurred = |i: usize| statuses[i].0 == FrameStatus::Blurred.name();
    kept.windows(2)
        .filter(|w| (w[0] + 1..w[1]).all(blurred))
        .flat_map(|w| w[0] + 1..w[1])
        .collect()
}

/// The notes poses.json carries per frame after a registration: correction and status.
pub fn pose_notes(
    registration: &PoseRegistration,
) -> Vec<serde_json::Map<String, serde_json::Value>> {
    registration
        .frames
        .iter()
        .map(|f| {
            let mut m = serde_json::Map::new();
            m.insert("correction_mm".into(), round3(f.correction_mm).into());
            m.insert("correction_deg".into(), round3(f.correction_deg).into());
            m.insert("status".into(), f.status.clone().into());
            m.insert("used".into(), f.used.into());
            m
        })
        .collect()
}

fn round3(x: f64) -> f64 {
    (x * 1000.0).round() / 1000.0
}

#[cfg(test)]
mod tests {
    use super::{blurred_between_kept, first_frame_held, round_failed, tracked_statuses};
    use crate::math::Affine;
    use crate::registration::{FrameStatus, TrackState};
    use crate::workflow::build::{BuildOptions, PosesMode};

    #[test]
    fn the_tracker_s_blurred_frames_between_kept_ones_are_judged_again() {
        let s = |name: &str, flagged: bool| (name.to_string(), flagged);
        let statuses = [
            s("given", false),
            s("blurred", true),
            s("blurred", true),
            s("converged", false),
            s("blurred", true),
            s("outlier", true),
            s("not_converged", false),
            s("blurred", true),
        ];
        // Frames 4-5 are a run with an outlier in it; frame 7 has no kept frame after it.
        assert_eq!(blurred_between_kept(&statuses), [1, 2]);
        assert!(blurred_between_kept(&statuses[4..]).is_empty());
    }

    #[test]
    fn a_first_frame_at_its_given_pose_is_held_by_the_rounds() {
        let first = BuildOptions {
            poses: PosesMode::First,
            ..Default::default()
        };
        let video: Vec<usize> = (0..10).collect();
        assert_eq!(first_frame_held(&video, true, &first), [0]);
        // Moved by the tracking's refinement against the CT: one frame's estimate.
        assert!(first_frame_held(&video, false, &first).is_empty());
        // The video's first frame left out: no frame's pose is given.
        assert!(first_frame_held(&video[2..], true, &first).is_empty());
        let tracker = BuildOptions {
            poses: PosesMode::Refine,
            ..Default::default()
        };
        assert!(first_frame_held(&video, true, &tracker).is_empty());
    }

    #[test]
    fn frames_accepted_after_the_track_was_lost_are_flagged() {
        // Frames 1-2 tracked, 3-5 flagged (the track lost at 3), 6 accepted again from poses
        // extrapolated past the loss.
        let numbers: Vec<usize> = (0..7).collect();
        let mut state = TrackState::new(&numbers, Affine::identity(), 1.0);
        for f in 1..7 {
            let ok = !(3..6).contains(&f);
            state.accepted[f] = ok;
            state.status[f] = Some(match ok {
                true => FrameStatus::Converged,
                false => FrameStatus::Outlier,
            });
        }
        state.first_lost = Some(3);
        let statuses = tracked_statuses(&state);
        let flagged: Vec<bool> = statuses.iter().map(|s| s.1).collect();
        assert_eq!(
            flagged,
            [false, false, false, true, true, true, true],
            "{statuses:?}"
        );
        assert_eq!(statuses[0].0, "given");
        assert_eq!(statuses[6].0, "track_lost");
        assert_eq!(statuses[3].0, "outlier");
    }

    #[test]
    fn a_round_that_converged_on_few_frames_has_failed() {
        // ATM_224 from 3 mm / 4 deg: 4 of 30 converged; the demo phantom from 3 mm / 4 deg
        // leaves 37 of 80 outliers, which the repeated geometry round mends.
        assert!(round_failed(4, 30, 0.25));
        assert!(!round_failed(43, 80, 0.25));
        assert!(!round_failed(8, 30, 0.25));
        assert!(round_failed(7, 30, 0.25));
    }
}
