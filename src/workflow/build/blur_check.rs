//! Frames far less sharp than the model predicts them (motion blur, defocus), found against the
//! model's prediction from their poses and left out of it.
//!
//! A blurred frame fused into the texture smears it for every view: on the demo phantom with a
//! fifth of its frames motion-blurred, new views from the true poses score 31.69 dB with them
//! and 33.10 dB without (BENCHMARKS.md, session 35). Within the frame budget the selection keeps
//! every frame: its own test, sharpness against the frame's neighbours in time, judged 17 of a
//! real airway tree's 80 sharp frames blurred. Against the model a frame's wall is compared
//! with the same wall, so only the blur is left.
//!
//! The registration runs the check after its rounds ([`super::registration`]); a build whose
//! poses are trusted as given (`--poses fixed`) runs it here, at those poses
//! ([`leave_out_blurred`]).

use super::options::BuildOptions;
use super::registration::{consensus_texture, registration_light, RegistrationView};
use super::scene::BuildScene;
use crate::model::blur_check::{BlurCheck, FrameSharpness};
use crate::registration::blur::sharpness_at_pose;
use crate::registration::photometric::{PhotometricModel, RayGrid};
use crate::registration::RegistrationOptions;
use crate::shading::calibrated::CalibratedModel;
use crate::workflow::progress::Progress;
use crate::Result;
use rayon::prelude::*;

/// Fewest frames whose median sharpness against the model is a reference for blur.
const MIN_FRAMES_FOR_BLUR: usize = 8;

/// Share of the video's median sharpness against the model's prediction
/// ([`crate::registration::blur::sharpness_against`]) under which a frame is blurred. On the
/// demo phantom with a fifth of its frames motion-blurred (`phantom --motion-blur-share 0.2`)
/// blurred frames scored 0.26-0.67 of the median and sharp ones 0.79 and up; a real airway
/// tree's sharp frames (ATM_307) 0.92 and up (BENCHMARKS.md, session 35).
const BLURRED_BELOW: f64 = 0.7;

/// With the poses trusted as given: the frames far less sharp than the model predicts them
/// from those poses (the light fitted there and a texture fused there) are removed from the
/// scene, said in `warnings`. `None` when fewer than [`MIN_FRAMES_FOR_BLUR`] frames were
/// there to judge.
pub(super) fn leave_out_blurred(
    scene: &mut BuildScene,
    opts: &BuildOptions,
    warnings: &mut Vec<String>,
) -> Result<Option<BlurCheck>> {
    if scene.frame_count() < MIN_FRAMES_FOR_BLUR {
        return Ok(None);
    }
    let view = RegistrationView::new(scene, opts.quiet)?;
    // Without a light at the given poses the frames are used unjudged: the build fits its own
    // light next and says there when it cannot.
    let Ok(light) = registration_light(scene, opts, &mut Vec::new()) else {
        warnings.push(
            "no light could be fitted at the given poses to check the frames for blur: every frame is used".to_string(),
        );
        return Ok(None);
    };
    let all: Vec<usize> = (0..scene.frame_count()).collect();
    let check = judge_sharpness(scene, &view, &all, &light, opts)?;
    let blurred = blurred_in(&check, &all);
    if !blurred.is_empty() {
        warnings.push(format!(
            "{} of {} frames are far less sharp than the model predicts them from their poses (motion blur or defocus): they are left out of the model (blur_check in model.json says which)",
            blurred.len(),
            all.len()
        ));
        let keep: Vec<usize> = all.into_iter().filter(|i| !blurred.contains(i)).collect();
        scene.keep_frames(&keep, opts.depth_cache_bytes);
    }
    Ok(Some(check))
}

/// The frames `on` of `scene` (increasing indices) judged against the model's prediction
/// from their poses ([`relative_sharpness`]); empty with fewer than [`MIN_FRAMES_FOR_BLUR`].
pub(super) fn judge_sharpness(
    scene: &mut BuildScene,
    view: &RegistrationView,
    on: &[usize],
    light: &CalibratedModel,
    opts: &BuildOptions,
) -> Result<BlurCheck> {
    let mut check = BlurCheck {
        blurred_below: BLURRED_BELOW,
        frames: Vec::new(),
    };
    if on.len() < MIN_FRAMES_FOR_BLUR {
        return Ok(check);
    }
    let relative = scene.on_frames(on, opts.depth_cache_bytes, |scene| {
        relative_sharpness(scene, view, on, light, opts)
    })?;
    check.frames = on
        .iter()
        .zip(relative)
        .map(|(&i, r)| FrameSharpness {
            frame: scene.frame_numbers[i],
            relative_sharpness: r,
            blurred: r.is_some_and(|r| r < BLURRED_BELOW),
        })
        .collect();
    Ok(check)
}

/// The frames of `on` (scene indices, the frames `check` judged in that order) it found blurred.
pub(super) fn blurred_in(check: &BlurCheck, on: &[usize]) -> Vec<usize> {
    on.iter()
        .zip(&check.frames)
        .filter(|(_, f)| f.blurred)
        .map(|(&i, _)| i)
        .collect()
}

/// Each frame of `scene`'s sharpness against the model's prediction from its pose over the
/// video's median: the light `light` and a texture fused from the frames at their poses,
/// rendered where the view's frames are compared (`view`, reduced; frame `i` of the scene is
/// the view's `in_view[i]`), on the pixels neither dark nor saturated, away from the
/// prediction's edges.
fn relative_sharpness(
    scene: &BuildScene,
    view: &RegistrationView,
    in_view: &[usize],
    light: &CalibratedModel,
    opts: &BuildOptions,
) -> Result<Vec<Option<f64>>> {
    let texture = consensus_texture(scene, light, opts)?;
    let model = PhotometricModel::new(view.model_parts(scene, light, Some(&texture)))?;
    let grid = RayGrid::new(&view.camera, 0, 1);
    let ro = RegistrationOptions::default();
    let progress = Progress::new("sharpness", scene.frame_count() as u64, opts.quiet);
    let ratios: Vec<Option<f64>> = (0..scene.frame_count())
        .into_par_iter()
        .map(|i| {
            let frame = &view.frames[in_view[i]];
            let mask = view.mask.as_deref();
            progress.inc();
            sharpness_at_pose(&model, &grid, &scene.poses[i], frame, mask, &ro)
        })
        .collect();
    progress.finish();
    let mut judged: Vec<f64> = ratios.iter().flatten().copied().collect();
    judged.sort_by(f64::total_cmp);
    let median = judged.get(judged.len() / 2).copied().unwrap_or(0.0);
    Ok(ratios
        .into_iter()
        .map(|r| r.filter(|_| median > 0.0).map(|r| r / median))
        .collect())
}
