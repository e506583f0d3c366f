//! The command line's arguments (clap derive). Every default comes from the library's
//! `Default`s, so each number is written once.

use bronchosim::phantom::PhantomOptions;
use bronchosim::render::RenderOptions;
use bronchosim::shading::paper::{PsiLookup, PsiLookupKind};
use bronchosim::shading::ShadingKind;
use bronchosim::texture::fusion::FusionKind;
use bronchosim::workflow::build::{BuildOptions, PosesMode};
use bronchosim::workflow::flythrough::FlythroughOptions;
use bronchosim::workflow::segment::{parse_point, SegmentCommandOptions};
use clap::{Args, Parser, Subcommand};
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
    /// Validate a case folder (CT, camera, poses, frames), or a bare CT, and print a summary.
    Inspect(InspectArgs),
    /// Convert a CT (a DICOM folder, a NIfTI file or a case's CT) to one NIfTI file in HU with
    /// its affine, as 3D Slicer and ITK-SNAP open it.
    Convert(ConvertArgs),
    /// Segment the airway in a CT and extract the lumen mesh (segmentation.nii.gz,
    /// lumen.ply/.obj/.glb, summary.json).
    Segment(SegmentArgs),
    /// Build the photo-realistic model of a case: segment, mesh, atlas, fit the shading, de-light
    /// and fuse the texture; writes the model folder (model.json, airway.glb, albedo.png,
    /// shading.json, segmentation.nii.gz, report.html).
    Build(BuildArgs),
    /// Register every frame's pose to the CT (photometric, against the fitted light and
    /// texture): DIR/poses.json (refined, with each frame's correction and status),
    /// DIR/registration.json, DIR/report.html.
    Register(RegisterArgs),
    /// The embedded default: write the phantom case (CT, video, poses, camera, truth) and build
    /// its model; open DIR/model/report.html afterwards.
    Demo(DemoArgs),
    /// Write a synthetic case (CT, frames, poses, camera) with its truth in CASE/truth/.
    Phantom(PhantomArgs),
    /// Render new views of a built model (paper Fig. 4) from the poses of a views.json.
    Render(RenderArgs),
    /// Fly along the airway's centre line through the textured region (first to last training
    /// camera): DIR/frame_0000.png …, DIR/path.json (views for `render`) and, with ffmpeg,
    /// DIR/flythrough.mp4.
    Flythrough(FlythroughArgs),
    /// Score rendered views against reference images: PSNR and SSIM on the pixels both cover,
    /// after one least-squares gain per channel over all views; and the PSNR on those where the
    /// reference is not saturated.
    Evaluate(EvaluateArgs),
    /// Write a self-contained browser viewer (index.html, works from file://) to fly through
    /// the model, lit as the bronchoscope lights it.
    View(ViewArgs),
}

/// The arguments of `bronchosim inspect`.
#[derive(Args, Debug)]
pub struct InspectArgs {
    /// A case folder (see CASE_FORMAT.md), a NIfTI file (.nii / .nii.gz) or a DICOM folder.
    pub case: PathBuf,
    /// Print the summary as JSON instead of text.
    #[arg(long)]
    pub json: bool,
    /// Only read frame headers instead of decoding every frame (faster, checks less).
    #[arg(long)]
    pub quick: bool,
}

/// The arguments of `bronchosim convert`.
#[derive(Args, Debug)]
pub struct ConvertArgs {
    /// A DICOM folder, a NIfTI file (.nii / .nii.gz) or a case folder.
    pub input: PathBuf,
    /// The NIfTI file to write (.nii or .nii.gz).
    #[arg(long)]
    pub out: PathBuf,
    /// Replace an existing output file.
    #[arg(long)]
    pub force: bool,
}

/// The arguments of `bronchosim segment`.
#[derive(Args, Debug)]
pub struct SegmentArgs {
    /// A case folder, a NIfTI file (.nii / .nii.gz) or a DICOM folder.
    pub input: PathBuf,
    /// Output folder (default: <input>_segment beside the input).
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Seed point inside the trachea, world mm (RAS): X,Y,Z. Default: found automatically.
    #[arg(long, value_parser = parse_point, allow_hyphen_values = true)]
    pub seed: Option<[f64; 3]>,
    /// First upper threshold of the adaptive region growing (HU).
    #[arg(long, default_value_t = segment_defaults().segment.growth.start_hu, allow_hyphen_values = true)]
    pub start_hu: f32,
    /// Highest threshold the adaptive region growing may reach (HU).
    #[arg(long, default_value_t = segment_defaults().segment.growth.max_hu, allow_hyphen_values = true)]
    pub max_hu: f32,
    /// Threshold increase per step (HU).
    #[arg(long, default_value_t = segment_defaults().segment.growth.step_hu)]
    pub step_hu: f32,
    /// A step whose volume grows by more than this factor is a leak: growing stops before it.
    #[arg(long, default_value_t = segment_defaults().segment.growth.leak_growth_limit)]
    pub leak_growth_limit: f64,
    /// Radius of the morphological closing (mm).
    #[arg(long, default_value_t = segment_defaults().segment.closing_radius_mm)]
    pub closing_mm: f64,
    /// Marching-cubes level between lumen air and wall (HU).
    #[arg(long, default_value_t = segment_defaults().mesh.iso_hu, allow_hyphen_values = true)]
    pub iso_hu: f32,
    /// Target edge length of the decimated lumen mesh (mm).
    #[arg(long, default_value_t = segment_defaults().mesh.decimate.target_edge_mm)]
    pub edge_mm: f64,
    /// Replace an existing output folder.
    #[arg(long)]
    pub force: bool,
}

/// The arguments of `bronchosim build`.
#[derive(Args, Debug)]
pub struct BuildArgs {
    /// The case folder (see CASE_FORMAT.md).
    pub case: PathBuf,
    /// The model folder to write.
    #[arg(long)]
    pub out: PathBuf,
    /// Texel size of the albedo atlas (mm).
    #[arg(long, default_value_t = build_defaults().atlas.texel_mm)]
    pub texel_mm: f64,
    /// Target edge length of the decimated lumen mesh (mm).
    #[arg(long, default_value_t = build_defaults().segment.mesh.decimate.target_edge_mm)]
    pub edge_mm: f64,
    /// Fusion of the de-lit frames: the paper's max-weight choice with smoothed weights, the
    /// average weighted by the predicted intensity to the power --fusion-weight-exponent,
    /// that average re-weighted by each observation's agreement with it (robust), or that
    /// average's low frequencies with the best frames' fine detail (multi-band).
    #[arg(long, value_enum, default_value_t = FusionKind::Average)]
    pub fusion: FusionKind,
    /// Power of the predicted intensity that weights the average (1: the paper's first
    /// attempt; 2: inverse-variance weights for intensity errors of constant size).
    #[arg(long, default_value_t = bronchosim::texture::fusion::DEFAULT_WEIGHT_EXPONENT)]
    pub fusion_weight_exponent: f32,
    /// Robust fusion: relative disagreement with the consensus (|v - m| / |m|) that halves an
    /// observation's weight.
    #[arg(long, default_value_t = bronchosim::texture::fusion::DEFAULT_RESIDUAL_SCALE)]
    pub fusion_residual_scale: f32,
    /// Robust fusion: re-weighting passes over the frames after the weighted average.
    #[arg(long, default_value_t = bronchosim::texture::fusion::DEFAULT_ROBUST_ROUNDS)]
    pub fusion_rounds: u32,
    /// Multi-band fusion: power of the predicted intensity in the average that gives the fine
    /// detail (high: close to the single best-lit, closest, most frontal frame).
    #[arg(long, default_value_t = bronchosim::texture::fusion::DEFAULT_DETAIL_EXPONENT)]
    pub fusion_detail_exponent: f32,
    /// Multi-band fusion: standard deviation (texels) of the Gaussian that splits the low
    /// band (all frames) from the high band (the best frames).
    #[arg(long, default_value_t = bronchosim::texture::fusion::DEFAULT_BAND_SIGMA_TEXELS)]
    pub fusion_band_sigma: f32,
    /// Texels no frame saw: mucosa synthesised from the seen texture (patch quilting, seamless
    /// at the border) or the chart's nearest seen colours pushed in (a flat fill).
    /// coverage.png keeps marking the seen texels either way.
    #[arg(long, value_enum, default_value_t = build_defaults().unseen.mode)]
    pub unseen: bronchosim::texture::synthesis::UnseenMode,
    /// Shading model of the texture and of new views: paper (per-viewpoint Psi),
    /// calibrated (one light for the whole video) or auto (the one that predicts held-out
    /// frames better).
    #[arg(long, default_value = "auto", value_parser = parse_shading)]
    pub shading: ::std::option::Option<ShadingKind>,
    /// Fit the calibrated light's free per-frame inter-reflection term a_f instead of
    /// kappa times the frame's light (see BENCHMARKS.md).
    #[arg(long)]
    pub ambient: bool,
    /// Leave out the calibrated light's inter-reflection term (kappa times the frame's mean
    /// observed light, 3 parameters for the whole video; see BENCHMARKS.md).
    #[arg(long)]
    pub no_interreflection: bool,
    /// The calibrated light's highlights: `white` (a GGX lobe of a white light added to the
    /// diffuse light, not multiplied by the albedo), `coloured` (the lobe's colour fitted) or
    /// `none` (rho holds them).
    #[arg(long, value_enum, default_value_t = build_defaults().calibrated.specular)]
    pub specular: bronchosim::shading::calibrated::SpecularMode,
    /// Inter-reflection: `uniform` (kappa times each frame's mean light) or `gathered` (the
    /// light once reflected by the wall, gathered from the mesh at every surface point).
    #[arg(long, value_enum, default_value_t = build_defaults().interreflection)]
    pub interreflection: bronchosim::shading::indirect::InterreflectionMode,
    /// Grid nodes across each frame the gathered inter-reflection is gathered at.
    #[arg(long, value_name = "N", default_value_t = build_defaults().gather_nodes,
          value_parser = clap::builder::RangedU64ValueParser::<usize>::new().range(1..=4096))]
    pub gather_nodes: usize,
    /// Hemisphere rays per node of the gathered inter-reflection.
    #[arg(long, value_name = "N", default_value_t = build_defaults().gather_rays,
          value_parser = clap::builder::RangedU64ValueParser::<usize>::new().range(1..=65536))]
    pub gather_rays: usize,
    /// Test each bounce point of the gathered inter-reflection for visibility from the light.
    #[arg(long)]
    pub gather_visibility: bool,
    /// Rounds of refitting the calibrated light and its gains with each pixel's albedo
    /// predicted from its colour (0 keeps the uniform albedo; see BENCHMARKS.md).
    #[arg(long, default_value_t = build_defaults().chroma_refits)]
    pub chroma_refits: usize,
    /// Rounds of refitting the calibrated light's shape with the fused texture's albedo
    /// (each followed by a gain correction; 0 keeps the uniform-albedo light).
    #[arg(long, default_value_t = build_defaults().refine_light)]
    pub light_refits: usize,
    /// The light's gain corrections and refits compare against a texture fused on one atlas
    /// texel of every KxK block (1: every texel; their passes cost about 1/K²).
    #[arg(long, value_name = "K", default_value_t = build_defaults().consensus_texel_factor,
          value_parser = clap::value_parser!(u32).range(1..=8))]
    pub consensus_texels: u32,
    /// Fit, register and cross-validate on the frames reduced by 2^N (default: chosen from
    /// the texel size and the camera; the texture always takes full-resolution pixels).
    #[arg(long, value_name = "N", value_parser = clap::value_parser!(u8).range(0..=3))]
    pub working_level: Option<u8>,
    /// Most pixel samples pooled over the whole video for the calibrated light (its fit's time
    /// and memory grow with them; a long video keeps fewer per frame, at least 1000).
    #[arg(long, value_name = "N", default_value_t = build_defaults().max_pooled_samples)]
    pub max_pooled_samples: usize,
    /// Hold out every N-th frame to cross-validate both shading models (0: skip).
    #[arg(long, default_value_t = build_defaults().cross_validate_every)]
    pub cross_validate_every: usize,
    /// Reference views (views.json, camera.json, images; e.g. the phantom's truth/): the
    /// report then scores new views against them next to two baselines, and the poses against
    /// the true ones when the folder has a poses.json (model.json `pose_truth`; a folder with
    /// the true poses.json alone scores the poses only).
    #[arg(long)]
    pub truth: Option<PathBuf>,
    /// `refine`: register every frame's pose to the CT before fitting (photometric, against
    /// the light and texture; frames that will not register are left out and counted).
    /// `fixed`: trust the given poses. `first`: trust only the first frame's pose (a video
    /// without a tracker; poses.json may hold that pose alone): track the others from it,
    /// then refine them.
    #[arg(long, value_enum, default_value_t = build_defaults().poses)]
    pub poses: PosesMode,
    /// With `--poses first`: trust the first frame's pose exactly (e.g. from another
    /// registration): it is neither refined against the CT before tracking, as a pose aligned
    /// by hand needs, nor by the registration's rounds after it.
    #[arg(long)]
    pub trust_first_pose: bool,
    /// Most rounds of the registration (light + texture, then every frame's pose); rounds
    /// 0, N, 2N, ... (N = --geometry-every) register against the CT's geometry alone, and so
    /// does the round after a geometry round that leaves over a fifth of the frames outliers;
    /// from round 6 on those rounds also hold the texture's albedo in the image.
    #[arg(long, default_value_t = build_defaults().registration_rounds)]
    pub registration_rounds: usize,
    /// Every N-th registration round registers against the geometry again: the texture
    /// cannot see an error all frames share (a turn about the airway's axis).
    #[arg(long, default_value_t = build_defaults().registration_geometry_every)]
    pub geometry_every: usize,
    /// The calibrated light of a model built with the same bronchoscope (its folder or its
    /// shading.json): the registration's first round registers against that light's shape,
    /// with this video's gains, instead of a light fitted at the given poses, which follows
    /// their errors. For tracker poses several millimetres off.
    #[arg(long, value_name = "MODEL")]
    pub scope_light: Option<PathBuf>,
    /// Most frames the model is built from: every frame is scored (sharpness against its
    /// neighbours, exposure) and the frames that add the most coverage of the wall are kept;
    /// blurred or badly exposed frames only where nothing better sees the wall (model.json
    /// `frame_selection` says why each frame was or was not used). 0: every frame.
    #[arg(long, default_value_t = build_defaults().selection.max_frames)]
    pub max_frames: usize,
    /// Keep the frames far less sharp than the model predicts them from their poses (motion
    /// blur, defocus); by default they are left out, and with `--poses first` not tracked
    /// against (model.json `blur_check`, or `registration.blur_check`, lists every frame's
    /// sharpness).
    #[arg(long)]
    pub keep_blurred: bool,
    /// Replace an existing model folder.
    #[arg(long)]
    pub force: bool,
}

/// The arguments of `bronchosim register`.
#[derive(Args, Debug)]
pub struct RegisterArgs {
    /// The case folder.
    pub case: PathBuf,
    /// Output folder (poses.json, registration.json, report.html).
    #[arg(long)]
    pub out: PathBuf,
    /// Most rounds (light + texture, then every frame's pose); rounds 0, N, 2N, ...
    /// (N = --geometry-every) register against the CT's geometry alone, and so does the round
    /// after a geometry round that leaves over a fifth of the frames outliers; from round 6
    /// on those rounds also hold the texture's albedo in the image.
    #[arg(long, default_value_t = build_defaults().registration_rounds)]
    pub rounds: usize,
    /// Every N-th round registers against the geometry again: the texture cannot see an error
    /// all frames share (a turn about the airway's axis).
    #[arg(long, default_value_t = build_defaults().registration_geometry_every)]
    pub geometry_every: usize,
    /// `refine`: start from every frame's given pose. `first`: trust only the first frame's
    /// (poses.json may hold that pose alone) and track the others from it before the rounds
    /// (0 rounds: tracking alone). `fixed` is refused: there would be nothing to do.
    #[arg(long, value_enum, default_value_t = PosesMode::Refine)]
    pub poses: PosesMode,
    /// With `--poses first`: trust the first frame's pose exactly (e.g. from another
    /// registration): it is neither refined against the CT before tracking, as a pose aligned
    /// by hand needs, nor by the registration's rounds after it.
    #[arg(long)]
    pub trust_first_pose: bool,
    /// The calibrated light of a model built with the same bronchoscope (its folder or its
    /// shading.json): the registration's first round registers against that light's shape,
    /// with this video's gains, instead of a light fitted at the given poses, which follows
    /// their errors. For tracker poses several millimetres off.
    #[arg(long, value_name = "MODEL")]
    pub scope_light: Option<PathBuf>,
    /// A truth folder with the frames' true poses (poses.json; e.g. the phantom's truth/):
    /// registration.json and the report then score the given and refined poses against them.
    #[arg(long)]
    pub truth: Option<PathBuf>,
    /// Replace DIR if it exists.
    #[arg(long)]
    pub force: bool,
}

/// The arguments of `bronchosim demo`.
#[derive(Args, Debug)]
pub struct DemoArgs {
    /// Folder for the case and the model.
    #[arg(long, default_value = "bronchosim-demo")]
    pub out: PathBuf,
    /// Number of video frames of the phantom.
    #[arg(long, default_value_t = PhantomOptions::default().frames)]
    pub frames: usize,
    /// Replace the folder if it exists.
    #[arg(long)]
    pub force: bool,
}

/// The arguments of `bronchosim phantom`.
#[derive(Args, Debug)]
pub struct PhantomArgs {
    /// The case folder to create.
    #[arg(long)]
    pub out: PathBuf,
    /// Number of video frames.
    #[arg(long, default_value_t = PhantomOptions::default().frames)]
    pub frames: usize,
    /// Frame size in pixels, WIDTHxHEIGHT (default 320x320).
    #[arg(long, value_parser = parse_size)]
    pub size: Option<(u32, u32)>,
    /// Master seed (same seed, identical files).
    #[arg(long, default_value_t = PhantomOptions::default().seed)]
    pub seed: u64,
    /// Take the airway from this binary mask (NIfTI) instead of the built-in tree.
    #[arg(long)]
    pub anatomy: Option<PathBuf>,
    /// Average blocks of N³ mask voxels first (with --anatomy; faster, coarser).
    #[arg(long, default_value_t = PhantomOptions::default().mask.downsample)]
    pub downsample: usize,
    /// Flatten the built-in trachea's back (its membranous wall, where the cartilage rings
    /// are open) to a plane FRACTION of the radius behind its axis, as in a real trachea
    /// (e.g. 0.7; default: round).
    #[arg(long, value_name = "FRACTION")]
    pub trachea_posterior_wall: Option<f64>,
    /// Sub-samples per pixel along each axis (antialiasing).
    #[arg(long, default_value_t = PhantomOptions::default().supersample)]
    pub supersample: u32,
    /// Burn a scope's overlay into the frames (black border around an octagonal field of
    /// view, on-screen text over the image) and write the matching mask.png.
    #[arg(long)]
    pub scope_overlay: bool,
    /// Tracker-like error of the poses written to poses.json: RMS camera-centre distance (mm)
    /// of a smooth drift plus per-frame jitter; the true poses go to truth/poses.json.
    #[arg(long, default_value_t = 0.0)]
    pub pose_noise_mm: f64,
    /// RMS rotation error (degrees) of the poses written to poses.json.
    #[arg(long, default_value_t = 0.0)]
    pub pose_noise_deg: f64,
    /// Share of the frames (0 to 1, drawn with the seed) with motion blur: the average of
    /// sub-renders along a fast turn of the scope during the exposure, the pose in poses.json
    /// its middle; truth/truth.json `motion_blur.frames` lists them.
    #[arg(long, default_value_t = 0.0)]
    pub motion_blur_share: f64,
    /// Bake the mucosa albedo on the truth mesh, lattice points at most MM apart, and render
    /// with the lookup (0: evaluate the procedural albedo at every ray hit). The truth views
    /// and truth/albedo_vertices.ply use the same albedo, so the truth stays exact. Default:
    /// baked 0.075 mm apart above 50 million frame pixels (frames x width x height), where the
    /// procedural albedo would cost hours.
    #[arg(long, value_name = "MM")]
    pub baked_albedo_mm: Option<f64>,
    /// Replace CASE if it exists.
    #[arg(long)]
    pub force: bool,
}

/// The arguments of `bronchosim render`.
#[derive(Args, Debug)]
pub struct RenderArgs {
    /// The model folder (from `build`).
    pub model: PathBuf,
    /// Poses of the new views, in the poses.json schema; each "image" names the output PNG
    /// inside --out.
    #[arg(long)]
    pub views: PathBuf,
    /// Camera of the new views (camera.json or OpenCV YAML/XML); default: the training camera.
    #[arg(long)]
    pub camera: Option<PathBuf>,
    /// Output folder.
    #[arg(long)]
    pub out: PathBuf,
    /// For a model shaded with the paper's Psi: nearest (the paper: Psi of the nearest
    /// fitted viewpoint) or blend (the k nearest viewpoints' Psi blended continuously).
    /// A model with the calibrated light needs no viewpoint lookup and ignores it.
    #[arg(long, value_enum, default_value_t = PsiLookupKind::Blend)]
    pub shading: PsiLookupKind,
    /// Viewpoints blended by --shading blend.
    #[arg(long, default_value_t = PsiLookup::DEFAULT_K)]
    pub k: usize,
    /// Rays per pixel along each axis (antialiasing).
    #[arg(long, default_value_t = RenderOptions::default().supersample)]
    pub supersample: u32,
    /// Write the texture alone (the fused albedo, unshaded), e.g. to inspect the texture.
    #[arg(long)]
    pub albedo_only: bool,
    /// Expose each view as the patient's scope would: the gain its auto-exposure (learnt by
    /// `build` from the video's gains) picks for the view's brightness, instead of the fixed
    /// reference gain (calibrated light only).
    #[arg(long)]
    pub auto_exposure: bool,
    /// Replace an existing output folder.
    #[arg(long)]
    pub force: bool,
}

/// The arguments of `bronchosim flythrough`.
#[derive(Args, Debug)]
pub struct FlythroughArgs {
    /// The model folder (from `bronchosim build`).
    pub model: PathBuf,
    /// Output folder.
    #[arg(long)]
    pub out: PathBuf,
    /// Number of frames.
    #[arg(long, default_value_t = FlythroughOptions::default().frames)]
    pub frames: usize,
    /// Frame rate of the video (frames per second).
    #[arg(long, default_value_t = FlythroughOptions::default().fps)]
    pub fps: u32,
    /// Render every frame at the fixed reference gain instead of with the scope's learnt
    /// auto-exposure.
    #[arg(long)]
    pub fixed_exposure: bool,
    /// Replace the output folder if it exists.
    #[arg(long)]
    pub force: bool,
}

/// The arguments of `bronchosim view`.
#[derive(Args, Debug)]
pub struct ViewArgs {
    /// The model folder (from `bronchosim build`).
    pub model: PathBuf,
    /// Output folder (default: `viewer` beside the model folder, where its report links).
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Open the viewer in the desktop's browser afterwards.
    #[arg(long)]
    pub open: bool,
    /// For a model shaded with the paper's Psi: nearest (the paper) or blend (the k nearest
    /// viewpoints, as `render` does by default).
    #[arg(long, value_enum, default_value_t = PsiLookupKind::Blend)]
    pub shading: PsiLookupKind,
    /// Replace an existing output folder.
    #[arg(long)]
    pub force: bool,
}

/// The arguments of `bronchosim evaluate`.
#[derive(Args, Debug)]
pub struct EvaluateArgs {
    /// Folder of rendered views: the images named in the truth's views.json (and their
    /// `<stem>_mask.png` hit masks, when present).
    pub rendered: PathBuf,
    /// Truth folder: views.json, the reference images it names, optional `<stem>_mask.png`.
    #[arg(long)]
    pub truth: PathBuf,
    /// Also render and score, from this model folder, the paper's method (nearest and
    /// k-nearest Psi) and the two baselines ((a) nearest training frame reprojected,
    /// (b) flat albedo with cos(gamma)/z^2 shading) on the same pixels.
    #[arg(long, value_name = "MODEL")]
    pub baselines: Option<PathBuf>,
    /// The case the model was built from (default: the one model.json names).
    #[arg(long, requires = "baselines")]
    pub case: Option<PathBuf>,
    /// Print the scores as JSON.
    #[arg(long)]
    pub json: bool,
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
