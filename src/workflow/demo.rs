//! `bronchosim demo`: the embedded default. Writes the phantom case (CT, video frames, poses,
//! camera, and the truth), builds the model from it (the report scores new views against the
//! truth views, Fig. 4), renders the truth views with `render` and scores them next to the
//! paper's method and both baselines, and writes the browser viewer (`bronchosim view`).

use crate::io::output_dir::OutputDir;
use crate::model::ModelManifest;
use crate::phantom::{write_phantom_case, PhantomOptions};
use crate::render::MethodScore;
use crate::viewer::{write_viewer, ViewerOptions};
use crate::workflow::build::{build_model, BuildOptions};
use crate::workflow::render::{render_command, RenderCommandOptions};
use crate::workflow::truth_eval::evaluate_with_baselines;
use crate::Result;
use std::path::{Path, PathBuf};

/// What the demo wrote.
pub struct DemoSummary {
    /// The demo folder.
    pub out: PathBuf,
    /// The phantom case (with truth/).
    pub case: PathBuf,
    /// The model folder.
    pub model: PathBuf,
    /// The model's manifest.
    pub manifest: ModelManifest,
    /// Seconds to write the phantom case.
    pub phantom_seconds: f64,
    /// The truth views rendered from the model (`bronchosim render`).
    pub views: PathBuf,
    /// Their scores next to the paper's method and both baselines.
    pub scores: Vec<MethodScore>,
    /// The browser viewer of the model (`bronchosim view`).
    pub viewer: PathBuf,
}

/// Run the demo into `out` (atomically; an existing `out` is replaced only with `force`).
pub fn run_demo(
    out: &Path,
    phantom: &PhantomOptions,
    build: &BuildOptions,
    force: bool,
) -> Result<DemoSummary> {
    let dir = OutputDir::create(out, force)?;
    let t = std::time::Instant::now();
    let case = dir.join("case");
    write_phantom_case(&case, phantom)?;
    let phantom_seconds = t.elapsed().as_secs_f64();
    let model = dir.join("model");
    let build = BuildOptions {
        truth: Some(case.join("truth")),
        ..build.clone()
    };
    let manifest = build_model(&case, &model, &build)?;
    let truth = case.join("truth");
    let views = dir.join("views");
    let render = RenderCommandOptions {
        camera: Some(truth.join("camera.json")),
        ..Default::default()
    };
    render_command(&model, &truth.join("views.json"), &views, &render)?;
    let scores = evaluate_with_baselines(&views, &truth, &model, Some(&case))?;
    write_viewer(&model, &dir.join("viewer"), &ViewerOptions::default())?;
    let out = dir.commit()?;
    Ok(DemoSummary {
        case: out.join("case"),
        model: out.join("model"),
        views: out.join("views"),
        viewer: out.join("viewer"),
        out,
        manifest,
        phantom_seconds,
        scores,
    })
}
