//! The command line's arguments (clap derive). Every default comes from the library's
//! `Default`s, so each number is written once.

use bronchosim::phantom::PhantomOptions;
use bronchosim::render::RenderOptions;
use bronchosim::shading::paper::{PsiLookup, PsiLookupKind};
use bronchosim::shading::ShadingKind;
use bronchosim::texture::fusion::FusionKind;
use bronchosim::workflow::build::BuildOptions;
use bronchosim::workflow::flythrough::FlythroughOptions;
use bronchosim::workflow::segment::{parse_point, SegmentCommandOptions};
use clap::{Parser, Subcommand};
use std::path::PathBuf;

/// Patient-specific, photo-realistic airway models from CT and bronchoscope video.
#[derive(Parser, Debug)]
#[command(name = "bronchosim", version, about, long_about = None)]
pub struct Cli {
    /// Silence progress bars and informational output.
    #[arg(long, global = true)]
    pub quiet: bool,
    #[command(subcommand)]
    pub command: Command,
}

fn build_defaults() -> BuildOptions {
    BuildOptions::default()
}

fn segment_defaults() -> SegmentCommandOptions {
    SegmentCommandOptions::default()
}

#[derive(Subcommand, Debug)]
pub enum Command {
    /// Validate a case folder (CT, camera, poses, frames) and print a summary.
    Inspect {
        /// The case folder (see CASE_FORMAT.md).
        case: PathBuf,
        /// Print the summary as JSON instead of text.
        #[arg(long)]
        json: bool,
        /// Only read frame headers instead of decoding every frame (faster, checks less).
        #[arg(long)]
        quick: bool,
    },
    /// Segment the airway in a CT and extract the lumen mesh (segmentation.nii.gz,
    /// lumen.ply/.obj/.glb, summary.json).
    Segment {
        /// A case folder, a NIfTI file (.nii / .nii.gz) or a DICOM folder.
        input: PathBuf,
        /// Output folder (default: <input>_segment beside the input).
        #[arg(long)]
        out: Option<PathBuf>,
        /// Seed point inside the trachea, world mm (RAS): X,Y,Z. Default: found automatically.
        #[arg(long, value_parser = parse_point, allow_hyphen_values = true)]
        seed: Option<[f64; 3]>,
        /// First upper threshold of the adaptive region growing (HU).
        #[arg(long, default_value_t = segment_defaults().segment.growth.start_hu, allow_hyphen_values = true)]
        start_hu: f32,
        /// Highest threshold the adaptive region growing may reach (HU).
        #[arg(long, default_value_t = segment_defaults().segment.growth.max_hu, allow_hyphen_values = true)]
        max_hu: f32,
        /// Threshold increase per step (HU).
        #[arg(long, default_value_t = segment_defaults().segment.growth.step_hu)]
        step_hu: f32,
        /// A step whose volume grows by more than this factor is a leak: growing stops before it.
        #[arg(long, default_value_t = segment_defaults().segment.growth.leak_growth_limit)]
        leak_growth_limit: f64,
        /// Radius of the morphological closing (mm).
        #[arg(long, default_value_t = segment_defaults().segment.closing_radius_mm)]
        closing_mm: f64,
        /// Marching-cubes level between lumen air and wall (HU).
        #[arg(long, default_value_t = segment_defaults().mesh.iso_hu, allow_hyphen_values = true)]
        iso_hu: f32,
        /// Target edge length of the decimated lumen mesh (mm).
        #[arg(long, default_value_t = segment_defaults().mesh.decimate.target_edge_mm)]
        edge_mm: f64,
        /// Replace an existing output folder.
        #[arg(long)]
        force: bool,
    },
    /// Build the photo-realistic model of a case: segment, mesh, atlas, fit the shading, de-light
    /// and fuse the texture; writes the model folder (model.json, airway.glb, albedo.png,
    /// shading.json, segmentation.nii.gz, report.html).
    Build {
        /// The case folder (see CASE_FORMAT.md).
        case: PathBuf,
        /// The model folder to write.
        #[arg(long)]
        out: PathBuf,
        /// Texel size of the albedo atlas (mm).
        #[arg(long, default_value_t = build_defaults().atlas.texel_mm)]
        texel_mm: f64,
        /// Target edge length of the decimated lumen mesh (mm).
        #[arg(long, default_value_t = build_defaults().segment.mesh.decimate.target_edge_mm)]
        edge_mm: f64,
        /// Fusion of the de-lit frames: the paper's max-weight choice with smoothed weights, or
        /// the average weighted by the predicted intensity to the power
        /// --fusion-weight-exponent.
        #[arg(long, value_enum, default_value_t = FusionKind::Average)]
        fusion: FusionKind,
        /// Power of the predicted intensity that weights the average (1: the paper's first
        /// attempt; 2: inverse-variance weights for intensity errors of constant size).
        #[arg(long, default_value_t = bronchosim::texture::fusion::DEFAULT_WEIGHT_EXPONENT)]
        fusion_weight_exponent: f32,
        /// Shading model of the texture and of new views: paper (per-viewpoint Psi),
        /// calibrated (one light for the whole video) or auto (the one that predicts held-out
        /// frames better).
        #[arg(long, default_value = "auto", value_parser = parse_shading)]
        shading: ::std::option::Option<ShadingKind>,
        /// Fit the calibrated light's free per-frame inter-reflection term a_f instead of
        /// kappa times the frame's light (see BENCHMARKS.md).
        #[arg(long)]
        ambient: bool,
        /// Leave out the calibrated light's inter-reflection term (kappa times the frame's mean
        /// observed light, 3 parameters for the whole video; see BENCHMARKS.md).
        #[arg(long)]
        no_interreflection: bool,
        /// Rounds of refitting the calibrated light and its gains with each pixel's albedo
        /// predicted from its colour (0 keeps the uniform albedo; see BENCHMARKS.md).
        #[arg(long, default_value_t = build_defaults().chroma_refits)]
        chroma_refits: usize,
        /// Rounds of refitting the calibrated light's shape with the fused texture's albedo
        /// (each followed by a gain correction; 0 keeps the uniform-albedo light).
        #[arg(long, default_value_t = build_defaults().refine_light)]
        light_refits: usize,
        /// Hold out every N-th frame to cross-validate both shading models (0: skip).
        #[arg(long, default_value_t = build_defaults().cross_validate_every)]
        cross_validate_every: usize,
        /// Reference views (views.json, camera.json, images; e.g. the phantom's truth/): the
        /// report then scores new views against them next to two baselines.
        #[arg(long)]
        truth: Option<PathBuf>,
        /// Replace an existing model folder.
        #[arg(long)]
        force: bool,
    },
    /// The embedded default: write the phantom case (CT, video, poses, camera, truth) and build
    /// its model; open DIR/model/report.html afterwards.
    Demo {
        /// Folder for the case and the model.
        #[arg(long, default_value = "bronchosim-demo")]
        out: PathBuf,
        /// Number of video frames of the phantom.
        #[arg(long, default_value_t = PhantomOptions::default().frames)]
        frames: usize,
        /// Replace the folder if it exists.
        #[arg(long)]
        force: bool,
    },
    /// Write a synthetic case (CT, frames, poses, camera) with its truth in CASE/truth/.
    Phantom {
        /// The case folder to create.
        #[arg(long)]
        out: PathBuf,
        /// Number of video frames.
        #[arg(long, default_value_t = PhantomOptions::default().frames)]
        frames: usize,
        /// Frame size in pixels, WIDTHxHEIGHT (default 320x320).
        #[arg(long, value_parser = parse_size)]
        size: Option<(u32, u32)>,
        /// Master seed (same seed, identical files).
        #[arg(long, default_value_t = PhantomOptions::default().seed)]
        seed: u64,
        /// Take the airway from this binary mask (NIfTI) instead of the built-in tree.
        #[arg(long)]
        anatomy: Option<PathBuf>,
        /// Average blocks of N³ mask voxels first (with --anatomy; faster, coarser).
        #[arg(long, default_value_t = PhantomOptions::default().mask.downsample)]
        downsample: usize,
        /// Sub-samples per pixel along each axis (antialiasing).
        #[arg(long, default_value_t = PhantomOptions::default().supersample)]
        supersample: u32,
        /// Replace CASE if it exists.
        #[arg(long)]
        force: bool,
    },
    /// Render new views of a built model (paper Fig. 4) from the poses of a views.json.
    Render {
        /// The model folder (from `build`).
        model: PathBuf,
        /// Poses of the new views, in the poses.json schema; each "image" names the output PNG
        /// inside --out.
        #[arg(long)]
        views: PathBuf,
        /// Camera of the new views (camera.json or OpenCV YAML/XML); default: the training camera.
        #[arg(long)]
        camera: Option<PathBuf>,
        /// Output folder.
        #[arg(long)]
        out: PathBuf,
        /// For a model shaded with the paper's Psi: nearest (the paper: Psi of the nearest
        /// fitted viewpoint) or blend (the k nearest viewpoints' Psi blended continuously).
        /// A model with the calibrated light needs no viewpoint lookup and ignores it.
        #[arg(long, value_enum, default_value_t = PsiLookupKind::Blend)]
        shading: PsiLookupKind,
        /// Viewpoints blended by --shading blend.
        #[arg(long, default_value_t = PsiLookup::DEFAULT_K)]
        k: usize,
        /// Rays per pixel along each axis (antialiasing).
        #[arg(long, default_value_t = RenderOptions::default().supersample)]
        supersample: u32,
        /// Write the texture alone (the fused albedo, unshaded), e.g. to inspect the texture.
        #[arg(long)]
        albedo_only: bool,
        /// Replace an existing output folder.
        #[arg(long)]
        force: bool,
    },
    /// Fly along the airway's centre line through the textured region (first to last training
    /// camera): DIR/frame_0000.png …, DIR/path.json (views for `render`) and, with ffmpeg,
    /// DIR/flythrough.mp4.
    Flythrough {
        /// The model folder (from `bronchosim build`).
        model: PathBuf,
        /// Output folder.
        #[arg(long)]
        out: PathBuf,
        /// Number of frames.
        #[arg(long, default_value_t = FlythroughOptions::default().frames)]
        frames: usize,
        /// Frame rate of the video (frames per second).
        #[arg(long, default_value_t = FlythroughOptions::default().fps)]
        fps: u32,
        /// Replace the output folder if it exists.
        #[arg(long)]
        force: bool,
    },
    /// Score rendered views against reference images: PSNR and SSIM on the pixels both cover,
    /// after one least-squares gain per channel over all views.
    Evaluate {
        /// Folder of rendered views: the images named in the truth's views.json (and their
        /// `<stem>_mask.png` hit masks, when present).
        rendered: PathBuf,
        /// Truth folder: views.json, the reference images it names, optional `<stem>_mask.png`.
        #[arg(long)]
        truth: PathBuf,
        /// Also render and score, from this model folder, the paper's method (nearest and
        /// k-nearest Psi) and the two baselines ((a) nearest training frame reprojected,
        /// (b) flat albedo with cos(gamma)/z^2 shading) on the same pixels.
        #[arg(long, value_name = "MODEL")]
        baselines: Option<PathBuf>,
        /// The case the model was built from (default: the one model.json names).
        #[arg(long, requires = "baselines")]
        case: Option<PathBuf>,
        /// Print the scores as JSON.
        #[arg(long)]
        json: bool,
    },
}

/// "auto" (decided by cross-validation) or a shading model's name.
fn parse_shading(s: &str) -> Result<Option<ShadingKind>, String> {
    use clap::ValueEnum;
    match s {
        "auto" => Ok(None),
        _ => ShadingKind::from_str(s, false)
            .map(Some)
            .map_err(|_| format!("{s:?}: expected auto, paper or calibrated")),
    }
}

/// Parse "WxH" into (width, height).
fn parse_size(s: &str) -> Result<(u32, u32), String> {
    let (w, h) = s
        .split_once(['x', 'X'])
        .ok_or_else(|| format!("size {s:?} is not WIDTHxHEIGHT"))?;
    let p = |v: &str| {
        v.trim()
            .parse::<u32>()
            .map_err(|e| format!("size {s:?}: {e}"))
    };
    Ok((p(w)?, p(h)?))
}
