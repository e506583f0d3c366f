//! The last stage: the model folder (DESIGN.md, "Output: the model folder") — textures, mesh,
//! segmentation, shading.json, model.json — and the report with its new views (paper Fig. 4),
//! rendered from the model as written.

use std::time::Instant;

use super::fit_pass::FitPass;
use super::options::BuildOptions;
use super::registration::pose_notes;
use super::scene::BuildScene;
use super::textures::Textures;
use crate::io::atomic::{write_bytes_atomic, write_json_atomic};
use crate::io::nifti::write_nifti;
use crate::io::output_dir::OutputDir;
use crate::io::poses::write_poses_annotated;
use crate::model::manifest::{
    relative_path, BuildTimings, CrossValidation, ExtraTexture, LightFitSettings, ModelCounts,
    ModelInputs, ModelManifest, UnseenWalls, MODEL_FORMAT_VERSION, PAPER_TEXTURE_FILE,
};
use crate::model::registration::{PoseRegistration, PoseTruth};
use crate::model::selection::FrameSelection;
use crate::model::Model;
use crate::shading::FittedShading;
use crate::texture::output::{encode_albedo, write_texture_outputs};
use crate::workflow::new_views_figure::{novel_figure, truth_figure};
use crate::workflow::report::{write_report, ReportInputs};
use crate::{Error, Result};

/// Everything the build made, as the model folder stores it.
pub struct BuiltModel<'a> {
    /// The scene (case, segmentation, atlas).
    pub scene: &'a BuildScene,
    /// The first pass (fit quality, report frames).
    pub pass: &'a FitPass,
    /// The fitted shading models and the one in use.
    pub shading: &'a FittedShading,
    /// How the calibrated light was fitted, when it was.
    pub light_fit: Option<LightFitSettings>,
    /// Which frames were used, when a selection ran.
    pub selection: Option<FrameSelection>,
    /// How the poses were registered, when they were.
    pub registration: Option<PoseRegistration>,
    /// Which frames were blurred, when the poses were trusted as given.
    pub blur_check: Option<crate::model::blur_check::BlurCheck>,
    /// The poses against the truth's, when `--truth` has a poses.json.
    pub pose_truth: Option<PoseTruth>,
    /// The cross-validation of the shading models, when it ran.
    pub cross_validation: Option<CrossValidation>,
    /// The fused textures.
    pub textures: &'a Textures,
    /// Seconds per stage so far.
    pub timings: BuildTimings,
    /// What the build could not do as asked.
    pub warnings: Vec<String>,
}

/// Write the model folder into `out_dir`, render its new views and report, and commit the
/// folder into place. `started` is when the build began (for the total time).
pub fn write_model(
    out_dir: OutputDir,
    built: &BuiltModel,
    opts: &BuildOptions,
    started: Instant,
) -> Result<ModelManifest> {
    let t = Instant::now();
    let mut manifest = write_model_files(&out_dir, built)?;
    // Fig. 4 is rendered from the model as written (airway.glb, shading.json, model.json).
    write_json_atomic(&out_dir.join("model.json"), &manifest)?;
    write_model_report(&out_dir, &manifest, built, opts)?;
    manifest.timings.write = t.elapsed().as_secs_f64();
    manifest.timings.total = started.elapsed().as_secs_f64();
    write_json_atomic(&out_dir.join("model.json"), &manifest)?;
    out_dir.commit()?;
    Ok(manifest)
}

/// The textures, mesh, segmentation and shading.json; returns the manifest.
fn write_model_files(out_dir: &OutputDir, built: &BuiltModel) -> Result<ModelManifest> {
    let scene = built.scene;
    let atlas = &scene.atlas;
    let albedo = &built.textures.albedo;
    let tex = write_texture_outputs(out_dir.path(), atlas, &albedo.rgb, &albedo.covered)?;
    // The scope's light in airway.glb for engines (KHR_lights_punctual; issue 19).
    crate::io::glb_light::add_scope_light(
        &out_dir.join("airway.glb"),
        built.shading,
        &scene.case.camera,
        tex.albedo_scale,
        albedo.colour_balance,
    )?;
    let paper_texture = match &built.textures.paper {
        Some(paper) => {
            let img = encode_albedo(&paper.rgb, atlas.width, atlas.height, &paper.covered)?;
            write_bytes_atomic(&out_dir.join(PAPER_TEXTURE_FILE), &img.png)?;
            Some(ExtraTexture {
                file: PAPER_TEXTURE_FILE.into(),
                albedo_scale: img.scale,
                colour_balance: paper.colour_balance,
            })
        }
        None => None,
    };
    write_nifti(
        &out_dir.join("segmentation.nii.gz"),
        &scene.segmentation.mask,
    )?;
    write_json_atomic(&out_dir.join("shading.json"), built.shading)?;
    write_model_poses(out_dir, built)?;
    let fits = &built.pass.fits;
    let mean_r2 = fits.iter().flat_map(|f| f.r2).sum::<f64>() / (3 * fits.len().max(1)) as f64;
    let case = &scene.case;
    Ok(ModelManifest {
        format_version: MODEL_FORMAT_VERSION,
        generator: format!("bronchosim {}", env!("CARGO_PKG_VERSION")),
        inputs: ModelInputs {
            case: case.dir.display().to_string(),
            case_relative: std::path::absolute(&case.dir).ok().and_then(|c| {
                let m = std::path::absolute(out_dir.target()).ok()?;
                relative_path(&m, &c)
            }),
            ct: case.ct_source.path().display().to_string(),
            camera: case.camera_path.display().to_string(),
            poses: case.poses_path.display().to_string(),
            frames: case.frames.path().display().to_string(),
        },
        counts: ModelCounts {
            frames: scene.frame_count(),
            triangles: atlas.mesh.triangles.len(),
            atlas_size: [atlas.width, atlas.height],
            chart_texels: scene.texels.len(),
            covered_texels: tex.covered_texels,
            charts: atlas.chart_count,
            airway_volume_ml: scene.segmentation.volume_ml,
            branches: Some(scene.segmentation.branch_count),
        },
        timings: built.timings.clone(),
        fit_quality: fits.clone(),
        mean_r2,
        camera: case.camera,
        albedo_scale: tex.albedo_scale,
        colour_balance: albedo.colour_balance,
        texel_mm: atlas.texel_mm,
        working_level: scene.level,
        shading_model: built.shading.model,
        paper_texture,
        cross_validation: built.cross_validation.clone(),
        light_fit: built.light_fit.clone(),
        registration: built.registration.clone(),
        blur_check: built.blur_check.clone(),
        pose_truth: built.pose_truth.clone(),
        frame_selection: built.selection.clone(),
        unseen_walls: Some(unseen_walls(built, atlas.texel_mm)),
        fusion_seams: Some(built.textures.albedo.seams),
        warnings: built.warnings.clone(),
        atlas_mean_l2_stretch: atlas.stats.mean_l2_stretch,
        atlas_utilisation: atlas.stats.utilisation,
    })
}

/// poses.json: the pose of every frame of the case as the model was built with it (refined
/// when the registration ran, with each frame's correction and status), images relative to
/// the case folder, so it can replace the case's own poses.json.
fn write_model_poses(out_dir: &OutputDir, built: &BuiltModel) -> Result<()> {
    let case = &built.scene.case;
    let tmp = out_dir.join("poses.json");
    match &built.registration {
        Some(reg) => write_poses_annotated(&tmp, &reg.poses, &case.dir, &pose_notes(reg)),
        None => write_poses_annotated(&tmp, &case.poses, &case.dir, &[]),
    }
}

/// New views of the written model (against the truth views when given, else between training
/// viewpoints: paper Fig. 4) and report.html.
fn write_model_report(
    out_dir: &OutputDir,
    manifest: &ModelManifest,
    built: &BuiltModel,
    opts: &BuildOptions,
) -> Result<()> {
    let model = Model::load(out_dir.path())?;
    let case = &built.scene.case;
    // A truth folder with the true poses alone scores the poses (model.json `pose_truth`); the
    // new views are then shown between training viewpoints, as without one.
    let views = opts
        .truth
        .as_ref()
        .filter(|t| t.join("views.json").exists() || !t.join("poses.json").exists());
    let figure = match views {
        Some(truth) => {
            let fig = truth_figure(&model, case, truth)?;
            write_json_atomic(&out_dir.join("evaluation.json"), &fig.scores)?;
            fig
        }
        None => novel_figure(&model, case)?,
    };
    let albedo_png = out_dir.join("albedo.png");
    write_report(
        &out_dir.join("report.html"),
        &ReportInputs {
            manifest,
            frames: &built.pass.report_frames,
            albedo_png: &std::fs::read(&albedo_png).map_err(|e| Error::io(&albedo_png, e))?,
            new_views: Some(&figure),
            shading: built.shading,
        },
    )
}

/// model.json's record of the observed and the made-up surface.
fn unseen_walls(built: &BuiltModel, texel_mm: f64) -> UnseenWalls {
    let albedo = &built.textures.albedo;
    let st = &albedo.synthesis;
    let all = (st.seen_texels + st.synthesised_texels + st.filled_texels).max(1) as f64;
    let paper_seconds = built
        .textures
        .paper
        .as_ref()
        .map_or(0.0, |p| p.synthesis_seconds);
    UnseenWalls {
        mode: st.mode,
        observed_share: st.seen_texels as f64 / all,
        synthesised_share: st.synthesised_texels as f64 / all,
        filled_share: st.filled_texels as f64 / all,
        patch_mm: st.patch_texels as f64 * texel_mm,
        seconds: albedo.synthesis_seconds + paper_seconds,
    }
}
