//! `bronchosim build CASE --out MODEL`: the whole pipeline of the paper (Fig. 1) and beyond, as
//! a sequence of stages that meet at plain data types:
//!
//! ```text
//! read, segment, mesh, atlas ─► BuildScene        (scene.rs)
//! choose the frames          ─► FrameSelection    (selection.rs: scores, coverage, budget;
//!                                                  frames not chosen are left out)
//! register the poses to CT   ─► PoseRegistration  (registration.rs: rounds of light, texture,
//!                                                  every frame's pose; flagged frames left out)
//! poses trusted as given     ─► BlurCheck         (blur_check.rs: blurred frames left out)
//! first pass over the frames ─► FitPass + pooled samples   (fit_pass.rs: ray cast, Psi per frame)
//! calibrated light           ─► CalibratedLight   (light.rs, gain_correction.rs, light_refit.rs)
//! cross-validation           ─► the shading model in use   (cross_validation.rs)
//! de-light and fuse          ─► Textures          (textures.rs)
//! model folder and report    ─► ModelManifest     (write.rs)
//! ```
//!
//! A new stage is a file here that takes the [`BuildScene`] and earlier stages' outputs and
//! returns its own plain output, and one line in [`build_model`].

mod blur_check;
mod cross_validation;
mod error;
mod fit_pass;
pub mod frames;
mod gain_correction;
mod light;
mod light_refit;
mod options;
mod pose_truth;
mod registration;
mod scene;
pub mod selection;
mod textures;
mod tracking;
mod write;

pub use cross_validation::held_out_frames;
pub use error::BuildError;
pub use fit_pass::{FitPass, LightSamples};
pub use gain_correction::refine_gains_against_texture;
pub use light::CalibratedLight;
pub use light_refit::{refit_light_with_albedo, sample_albedo, sample_uvs};
pub use options::{BuildOptions, PosesMode};
pub use pose_truth::{check_truth_dir, poses_against_truth};
pub use registration::{pose_notes, register_poses};
pub use scene::BuildScene;
pub use textures::{FusedAlbedo, Textures};
pub use tracking::TrackingOptions;

use std::path::Path;
use std::time::Instant;

use crate::io::output_dir::OutputDir;
use crate::model::manifest::{BuildTimings, CrossValidation, ModelManifest};
use crate::shading::{FittedShading, ShadingKind};
use crate::Result;

/// Build the model of the case in `case_dir` into `out` (atomically).
pub fn build_model(case_dir: &Path, out: &Path, opts: &BuildOptions) -> Result<ModelManifest> {
    let started = Instant::now();
    check_truth_dir(opts.truth.as_deref(), true)?;
    let out_dir = OutputDir::create(out, opts.force)?;
    let mut timings = BuildTimings::default();
    let mut warnings = Vec::new();
    let mut scene = BuildScene::prepare(case_dir, opts, &mut timings)?;
    let non_finite = scene.segmentation.non_finite_voxels;
    if non_finite > 0 {
        warnings.push(format!(
            "{}: {non_finite} CT voxels are not finite numbers (NaN or infinite); they were counted as tissue",
            scene.case.ct_source.path().display()
        ));
    }
    let mut selection = timed(&mut timings.selection, || {
        selection::select_frames(&mut scene, opts, &mut warnings)
    })?;
    let registration = timed(&mut timings.registration, || {
        registration::register_poses(&mut scene, opts, selection.as_mut(), &mut warnings)
    })?;
    // Trusted poses get the check the registration runs after its rounds.
    let blur_check = match (&registration, opts.leave_out_blurred) {
        (None, true) => timed(&mut timings.blur_check, || {
            blur_check::leave_out_blurred(&mut scene, opts, &mut warnings)
        })?,
        _ => None,
    };
    let pose_truth = poses_against_truth(
        registration.as_ref(),
        &scene,
        opts.truth.as_deref(),
        &mut warnings,
    )?;
    let (pass, samples) = timed(&mut timings.fit, || fit_pass::fit_pass(&mut scene, opts))?;
    let light = timed(&mut timings.calibrated_fit, || {
        light::calibrated_light(&scene, samples, opts, &mut warnings)
    })?;
    let light_fit = light.as_ref().map(|l| l.settings.clone());
    let mut shading =
        FittedShading::new(ShadingKind::Paper, pass.psi.clone(), light.map(|l| l.model));
    let cross_validation = timed(&mut timings.cross_validation, || {
        evaluate_models(&scene, &shading, opts, &mut warnings)
    });
    shading.model = choose_model(opts.shading, &shading, cross_validation.as_ref());
    let textures = timed(&mut timings.fusion, || {
        textures::fuse_textures(&mut scene, &shading, pass.pixel_sum, opts)
    })?;
    let built = write::BuiltModel {
        scene: &scene,
        pass: &pass,
        shading: &shading,
        light_fit,
        selection,
        registration,
        blur_check,
        pose_truth,
        cross_validation,
        textures: &textures,
        timings,
        warnings,
    };
    write::write_model(out_dir, &built, opts, started)
}

/// The cross-validation of the fitted models, or `None` when it is off or could not run (said
/// in `warnings`).
fn evaluate_models(
    scene: &BuildScene,
    shading: &FittedShading,
    opts: &BuildOptions,
    warnings: &mut Vec<String>,
) -> Option<CrossValidation> {
    if opts.cross_validate_every == 0 {
        return None;
    }
    cross_validation::cross_validate(scene, shading, opts)
        .map_err(|e| warnings.push(format!("cross-validation skipped: {e}")))
        .ok()
}

/// The model in use: the one asked for when it was fitted, else the one that predicts held-out
/// frames better (the calibrated light when fitted and not cross-validated).
fn choose_model(
    requested: Option<ShadingKind>,
    shading: &FittedShading,
    cross_validation: Option<&CrossValidation>,
) -> ShadingKind {
    match requested {
        Some(kind) if shading.has(kind) => kind,
        Some(_) => ShadingKind::Paper,
        None if !shading.has(ShadingKind::Calibrated) => ShadingKind::Paper,
        None => cross_validation.map_or(ShadingKind::Calibrated, |cv| cv.winner()),
    }
}

/// Run `stage`, adding its seconds to `seconds`.
fn timed<T>(seconds: &mut f64, stage: impl FnOnce() -> T) -> T {
    let t = Instant::now();
    let out = stage();
    *seconds += t.elapsed().as_secs_f64();
    out
}
