//! Scoring a model's new views against reference views (the phantom's `truth/`), next to the
//! two baselines of issue 7, on the same pixels with the same per-channel gain fit:
//! the calibrated light (when it is the model's shading), the paper (nearest viewpoint's Psi,
//! with the paper's texture), the paper with k-nearest blending, (a) the nearest
//! training frame projected onto the geometry without de-lighting, (b) a flat albedo under
//! `cos(gamma) / z²`. Used by `bronchosim evaluate --baselines` and by `build --truth`
//! (report Fig. 4).

use std::path::Path;

use crate::camera::Camera;
use crate::io::camera_file::read_camera;
use crate::io::case::Case;
use crate::model::Model;
use crate::render::views_io::load_truth;
use crate::render::{
    evaluate_methods, flat_albedo_view, render_view_with, reproject_nearest_frame, MaskedImage,
    MethodScore, RenderInputs, RenderOptions, TrainingView, ViewRays,
};
use crate::shading::paper::{PsiLookup, ViewpointIndex};
use crate::{Error, Result};

/// Method names as they appear in tables and the report. The calibrated light (when it is the
/// model's shading).
pub const CALIBRATED: &str = "calibrated light";
/// The paper: nearest viewpoint's Psi.
pub const PAPER_NEAREST: &str = "paper (nearest Psi)";
/// The paper's texture with the Psi of the k nearest viewpoints blended.
pub const PAPER_BLENDED: &str = "paper, k-nearest Psi";
/// Baseline (a).
pub const BASELINE_REPROJECTED: &str = "(a) reprojected frame";
/// Baseline (b).
pub const BASELINE_FLAT: &str = "(b) flat cos/z²";

/// Scores of every method, and the images for the report's Fig. 4.
pub struct TruthEvaluation {
    /// One entry per method, views in views.json order.
    pub scores: Vec<MethodScore>,
    /// View names (views.json order).
    pub names: Vec<String>,
    /// The reference views.
    pub truth: Vec<MaskedImage>,
    /// Every method's images, in `scores` order.
    pub images: Vec<(String, Vec<MaskedImage>)>,
}

/// The reference camera of a truth folder: `truth_dir/camera.json`.
pub fn truth_camera(truth_dir: &Path) -> Result<Camera> {
    let p = truth_dir.join("camera.json");
    if !p.exists() {
        return Err(Error::missing(&p, "the camera of the reference views"));
    }
    read_camera(&p)
}

/// Render the methods for every view of `truth_dir` and score them; `rendered` (e.g. a folder
/// written by `bronchosim render`) is scored first when given. The training frames come from
/// `case` (the case the model was built from).
pub fn evaluate_against_truth(
    model: &Model,
    case: &Case,
    truth_dir: &Path,
    rendered: Option<(String, Vec<MaskedImage>)>,
) -> Result<TruthEvaluation> {
    let (views, truth) = load_truth(truth_dir)?;
    let camera = truth_camera(truth_dir)?;
    let names: Vec<String> = views.iter().map(|v| v.name.clone()).collect();
    let rays = ViewRays::new(&camera, 1)?;
    let render = |inputs: &RenderInputs, lookup: PsiLookup| -> Result<Vec<MaskedImage>> {
        let opts = RenderOptions {
            psi_lookup: lookup,
            ..Default::default()
        };
        views
            .iter()
            .map(|v| {
                let (frame, mask) = render_view_with(inputs, &rays, &v.camera_to_world, &opts)?;
                Ok(MaskedImage { frame, mask })
            })
            .collect()
    };
    let paper = model.paper_render_inputs();
    let nearest = render(&paper, PsiLookup::Nearest)?;
    let blended = render(&paper, PsiLookup::default())?;
    let calibrated = match model.calibrated() {
        Some(_) => Some(render(&model.render_inputs(), PsiLookup::default())?),
        None => None,
    };

    let poses: Vec<_> = case.poses.iter().map(|p| p.pose.camera_to_world).collect();
    let index = ViewpointIndex::from_poses(&poses);
    let near: Vec<usize> = views
        .iter()
        .map(|v| {
            index
                .nearest(&v.camera_to_world)
                .ok_or_else(|| Error::invalid(&case.poses_path, "no training frames"))
        })
        .collect::<Result<_>>()?;
    let frames = case.frames_at(&near)?;
    let reprojected = views
        .iter()
        .zip(&near)
        .map(|(v, &i)| {
            let tv = TrainingView {
                frame: &frames[&i],
                camera_to_world: &poses[i],
                image_mask: case.mask.as_ref().map(|m| m.image.as_slice()),
            };
            let (frame, mask) = reproject_nearest_frame(
                &model.scene,
                &camera,
                &v.camera_to_world,
                &case.camera,
                &[tv],
            )?;
            Ok(MaskedImage { frame, mask })
        })
        .collect::<Result<Vec<_>>>()?;
    let flat = views
        .iter()
        .map(|v| {
            let (frame, mask) = flat_albedo_view(&model.scene, &camera, &v.camera_to_world);
            MaskedImage { frame, mask }
        })
        .collect();

    let mut methods = Vec::new();
    if let Some(r) = rendered {
        methods.push(r);
    }
    if let Some(c) = calibrated {
        methods.push((CALIBRATED.to_string(), c));
    }
    methods.push((PAPER_NEAREST.to_string(), nearest));
    methods.push((PAPER_BLENDED.to_string(), blended));
    methods.push((BASELINE_REPROJECTED.to_string(), reprojected));
    methods.push((BASELINE_FLAT.to_string(), flat));
    let scores = evaluate_methods(&methods, &truth, &names)?;
    Ok(TruthEvaluation {
        scores,
        names,
        truth,
        images: methods,
    })
}

/// `bronchosim evaluate RENDERED --truth DIR --baselines MODEL [--case CASE]`: the rendered
/// folder next to the paper's method and both baselines. `case_dir` defaults to the case
/// recorded in the model's manifest.
pub fn evaluate_with_baselines(
    rendered_dir: &Path,
    truth_dir: &Path,
    model_dir: &Path,
    case_dir: Option<&Path>,
) -> Result<Vec<MethodScore>> {
    let model = Model::load(model_dir)?;
    let case_path = case_dir
        .map(Path::to_path_buf)
        .unwrap_or_else(|| model.manifest.inputs.case_dir(&model.dir));
    let case = Case::open(&case_path)?;
    let (views, _) = load_truth(truth_dir)?;
    let rendered = crate::render::views_io::load_rendered(rendered_dir, &views)?;
    let label = format!(
        "rendered ({})",
        rendered_dir.file_name().map_or_else(
            || rendered_dir.display().to_string(),
            |n| n.to_string_lossy().into_owned()
        )
    );
    Ok(evaluate_against_truth(&model, &case, truth_dir, Some((label, rendered)))?.scores)
}
