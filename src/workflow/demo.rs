//! `bronchosim demo`: the embedded default. Writes the phantom case (CT, video frames, poses,
//! camera, and the truth), builds the model from it, and says where to look.

use crate::io::output_dir::OutputDir;
use crate::model::ModelManifest;
use crate::phantom::{write_phantom_case, PhantomOptions};
use crate::workflow::build::{build_model, BuildOptions};
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
    let manifest = build_model(&case, &model, build)?;
    let out = dir.commit()?;
    Ok(DemoSummary {
        case: out.join("case"),
        model: out.join("model"),
        out,
        manifest,
        phantom_seconds,
    })
}
