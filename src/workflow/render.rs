//! `bronchosim render MODEL --views views.json [--camera camera.json] --out DIR`: new views of
//! a built model (paper §2.4, Fig. 4) from any poses and any camera, written atomically.

use std::path::{Path, PathBuf};
use std::time::Instant;

use serde::Serialize;

use crate::camera::Camera;
use crate::io::camera_file::read_camera;
use crate::io::output_dir::OutputDir;
use crate::model::Model;
use crate::render::{render_views, RenderOptions};
use crate::shading::ShadingKind;
use crate::Result;

/// Options of [`render_command`].
#[derive(Clone, Debug, Default)]
pub struct RenderCommandOptions {
    /// The output camera file (camera.json or OpenCV YAML/XML); `None` = the training camera.
    pub camera: Option<PathBuf>,
    /// Shading, supersampling, mip-mapping.
    pub render: RenderOptions,
    /// Replace an existing output folder.
    pub force: bool,
}

/// What [`render_command`] wrote (also saved as `render.json` in the output folder).
#[derive(Clone, Debug, Serialize)]
pub struct RenderSummary {
    /// The model folder.
    pub model: String,
    /// The views file.
    pub views: String,
    /// The camera used (its file, or "training camera").
    pub camera_source: String,
    /// The camera used.
    pub camera: Camera,
    /// The shading of the new views: "calibrated light", or how the paper's fitted Psi were
    /// chosen ("nearest" or "k-nearest (k = 4)").
    pub shading: String,
    /// Images written (relative to the output folder).
    pub images: Vec<String>,
    /// Seconds to load the model.
    pub load_seconds: f64,
    /// Seconds to render and write every view.
    pub render_seconds: f64,
}

/// Render every view of `views_json` from the model in `model_dir` into `out`: per view the
/// sRGB PNG its `"image"` names and `<stem>_mask.png`, plus `render.json`.
pub fn render_command(
    model_dir: &Path,
    views_json: &Path,
    out: &Path,
    opts: &RenderCommandOptions,
) -> Result<RenderSummary> {
    let t = Instant::now();
    let model = Model::load(model_dir)?;
    let (camera, camera_source) = match &opts.camera {
        Some(p) => (read_camera(p)?, p.display().to_string()),
        None => (model.manifest.camera, "training camera".to_string()),
    };
    let load_seconds = t.elapsed().as_secs_f64();
    let dir = OutputDir::create(out, opts.force)?;
    let t = Instant::now();
    let written = render_views(
        &model.render_inputs(),
        &camera,
        views_json,
        dir.path(),
        &opts.render,
    )?;
    let render_seconds = t.elapsed().as_secs_f64();
    let images = written
        .iter()
        .map(|p| {
            p.strip_prefix(dir.path())
                .unwrap_or(p)
                .to_string_lossy()
                .replace('\\', "/")
        })
        .collect();
    let summary = RenderSummary {
        model: model_dir.display().to_string(),
        views: views_json.display().to_string(),
        camera_source,
        camera,
        shading: match model.shading.model {
            ShadingKind::Calibrated => "calibrated light".into(),
            ShadingKind::Paper => opts.render.psi_lookup.to_string(),
        },
        images,
        load_seconds,
        render_seconds,
    };
    crate::io::atomic::write_json_atomic(&dir.join("render.json"), &summary)?;
    dir.commit()?;
    Ok(summary)
}
