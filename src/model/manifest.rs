//! The model folder's manifest (model.json) and shading file (shading.json): the plain data
//! `build` writes and `render`, `flythrough` and `evaluate` read back.

use crate::model::registration::{PoseRegistration, PoseTruth};
use crate::model::selection::FrameSelection;
use serde::{Deserialize, Serialize};

use crate::camera::Camera;
use crate::shading::ShadingKind;

pub use super::cross_validation::{CrossValidation, HeldOutScore, ModelCrossValidation};

/// Version of the model folder layout (model.json `format_version`).
///
/// 2: `texel_mm`, `colour_balance` and `shading_model` in model.json (what the renderer needs
/// to reproduce the training frames' intensities from airway.glb and shading.json).
pub const MODEL_FORMAT_VERSION: u32 = 2;

/// Fit quality of one frame.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct FrameFit {
    /// Index of the frame in the case's poses.json.
    pub frame: usize,
    /// Samples used in the fit.
    pub samples: usize,
    /// Weighted RMS residual per channel (linear intensity).
    pub rms: [f64; 3],
    /// Coefficient of determination of Psi against the samples, per channel.
    pub r2: [f64; 3],
    /// True when the positivity-constrained fallback was used in some channel.
    pub constrained: bool,
}

/// Seconds per stage.
#[derive(Clone, Debug, Default, Serialize, Deserialize)]
pub struct BuildTimings {
    /// Reading and validating the case.
    pub read_case: f64,
    /// Region growing and morphology.
    pub segment: f64,
    /// Marching cubes, smoothing, decimation.
    pub mesh: f64,
    /// Atlas and texel rasterisation.
    pub atlas: f64,
    /// Frame selection: scoring every frame, the coverage cast, the choice.
    #[serde(default)]
    pub selection: f64,
    /// Registration of the poses to the CT (every round: light, texture, poses).
    #[serde(default)]
    pub registration: f64,
    /// With the poses trusted as given, the check for blurred frames (a light and a texture
    /// at the given poses, and every frame's prediction).
    #[serde(default)]
    pub blur_check: f64,
    /// Per-frame ray cast, samples and Psi fit (all frames).
    pub fit: f64,
    /// The calibrated light fit on the pooled samples.
    pub calibrated_fit: f64,
    /// Cross-validation of both shading models (fusions without the held-out frames).
    pub cross_validation: f64,
    /// De-lighting and fusion (all frames, both passes).
    pub fusion: f64,
    /// Writing the model folder and the report.
    pub write: f64,
    /// Everything.
    pub total: f64,
}

/// model.json: the manifest of a model folder.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct ModelManifest {
    /// Layout version of the folder.
    pub format_version: u32,
    /// bronchosim version that wrote it.
    pub generator: String,
    /// Input files.
    pub inputs: ModelInputs,
    /// Sizes of what was built.
    pub counts: ModelCounts,
    /// Seconds per stage.
    pub timings: BuildTimings,
    /// Fit quality per frame.
    pub fit_quality: Vec<FrameFit>,
    /// Mean R² of Psi over frames and channels.
    pub mean_r2: f64,
    /// The camera of the training frames.
    pub camera: Camera,
    /// Scale from the fused (relative) albedo to albedo.png's linear values (all channels).
    pub albedo_scale: f32,
    /// Per-channel factors the build multiplied the fused albedo by so that albedo.png has the
    /// colour of the mucosa (the per-channel shading divides each channel's mean out). The
    /// texture the shading multiplies is `albedo.png (linear) / (albedo_scale · colour_balance)`.
    pub colour_balance: [f32; 3],
    /// Texel edge length of the atlas on the surface (mm).
    pub texel_mm: f64,
    /// The fits, the light, the cross-validation and the registration ran on the frames
    /// reduced by `2^working_level` (the texture is fused from full-resolution pixels).
    #[serde(default)]
    pub working_level: usize,
    /// The shading model the texture was de-lit with and new views use.
    pub shading_model: ShadingKind,
    /// The paper's texture (de-lit by each frame's Psi) when the model's shading is
    /// calibrated: the reference the report compares against.
    pub paper_texture: Option<ExtraTexture>,
    /// Held-out frame prediction per shading model (absent when not run).
    pub cross_validation: Option<CrossValidation>,
    /// How the calibrated light was fitted (absent when it was not, and in older models).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub light_fit: Option<LightFitSettings>,
    /// How the poses were registered to the CT (`None`: trusted as given, `--poses fixed`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub registration: Option<PoseRegistration>,
    /// With the poses trusted as given (`--poses fixed`): every frame's sharpness against the
    /// model's prediction from its pose, and which were left out as blurred (absent when not
    /// run; a registration records its own check in `registration.blur_check`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub blur_check: Option<crate::model::blur_check::BlurCheck>,
    /// The poses against the true poses of `build --truth` (absent without them).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub pose_truth: Option<PoseTruth>,
    /// Which frames were used and why the others were not (absent when every frame was used
    /// without a selection, `--max-frames 0`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub frame_selection: Option<FrameSelection>,
    /// What the texture holds where no frame saw the wall (absent in models written before
    /// it was recorded).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub unseen_walls: Option<UnseenWalls>,
    /// The albedo's gradient across and within the borders of the regions different frames
    /// dominate (absent in models written before it was recorded).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub fusion_seams: Option<crate::texture::seams::SeamStats>,
    /// What the build could not do as asked (e.g. a failed calibrated fit).
    pub warnings: Vec<String>,
    /// Mean L2 stretch of the atlas.
    pub atlas_mean_l2_stretch: f64,
    /// Atlas utilisation (covered / all texels).
    pub atlas_utilisation: f64,
}

/// The share of the surface the video observed and what the texture holds elsewhere
/// (coverage.png marks the observed texels; shares are of the chart texels, each the same
/// area on the surface).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct UnseenWalls {
    /// `fill` or `synthesise` (`build --unseen`).
    pub mode: crate::texture::synthesis::UnseenMode,
    /// Share of the surface seen by a frame.
    pub observed_share: f64,
    /// Share given synthesised mucosa.
    pub synthesised_share: f64,
    /// Share filled from neighbouring seen colours.
    pub filled_share: f64,
    /// Edge of the synthesis patches on the surface (mm; 0 when nothing was synthesised).
    pub patch_mm: f64,
    /// Seconds the completion took (albedo and the paper's texture).
    pub seconds: f64,
}

/// The settings the calibrated light was fitted with (`build` options), for reproducing a model.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct LightFitSettings {
    /// Degree of rho(gamma) per channel.
    pub rho_degree: usize,
    /// Degree of s in cos theta.
    pub s_degree: usize,
    /// Robust loss of the pooled fit ("none", "huber 1.345", "tukey 4.685").
    pub robust: String,
    /// Free inter-reflection term a_f per frame (`--ambient`).
    pub ambient_per_frame: bool,
    /// Inter-reflection term kappa times the frame's mean light (off with `--no-interreflection`).
    pub interreflection: bool,
    /// `uniform` (kappa times the frame's light) or `gathered` from the mesh
    /// (`--interreflection`); models built before it are uniform.
    #[serde(default)]
    pub interreflection_mode: crate::shading::indirect::InterreflectionMode,
    /// Frame whose gain is 1 (the exposure of new views).
    pub reference_frame: usize,
    /// Refits of the light and its gains with the albedo predicted from each pixel's colour
    /// (`--chroma-refits`), before the gain corrections.
    #[serde(default)]
    pub chroma_refits: usize,
    /// Gain corrections against the fused texture before the light's refits.
    pub gain_corrections: usize,
    /// Refits of the light's shape with the fused texture's albedo (`--light-refits`), each
    /// followed by one more gain correction.
    pub light_refits: usize,
}

/// File name of the paper's texture beside a calibrated model's albedo.png.
pub const PAPER_TEXTURE_FILE: &str = "albedo_paper.png";

/// A second texture atlas of the model folder (same atlas layout as albedo.png).
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct ExtraTexture {
    /// File name inside the model folder.
    pub file: String,
    /// As [`ModelManifest::albedo_scale`], for this file.
    pub albedo_scale: f32,
    /// As [`ModelManifest::colour_balance`], for this file.
    pub colour_balance: [f32; 3],
}

/// Input files of a model.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct ModelInputs {
    /// The case folder (absolute, as at build time).
    pub case: String,
    /// The case folder relative to the model folder, when they share a parent folder: still
    /// valid after both are moved together (e.g. the demo folder).
    pub case_relative: Option<String>,
    /// The CT.
    pub ct: String,
    /// The camera file.
    pub camera: String,
    /// poses.json.
    pub poses: String,
    /// frames/ or the video.
    pub frames: String,
}

/// Sizes of a model.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct ModelCounts {
    /// Frames used.
    pub frames: usize,
    /// Lumen mesh triangles.
    pub triangles: usize,
    /// Atlas size in texels.
    pub atlas_size: [u32; 2],
    /// Texels on a chart.
    pub chart_texels: usize,
    /// Texels seen by at least one frame.
    pub covered_texels: usize,
    /// Atlas charts.
    pub charts: usize,
    /// Segmented airway volume (ml).
    pub airway_volume_ml: f64,
    /// Airway branches the segmentation found (as `segment` counts them); absent in model
    /// folders written before it was recorded.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub branches: Option<usize>,
}

/// `to` relative to the folder `from` ("../case"), when both are absolute and share a first
/// component below the root; `None` otherwise.
pub fn relative_path(from: &std::path::Path, to: &std::path::Path) -> Option<String> {
    use std::path::Component;
    let a: Vec<Component> = from.components().collect();
    let b: Vec<Component> = to.components().collect();
    if !from.is_absolute() || !to.is_absolute() {
        return None;
    }
    let common = a.iter().zip(&b).take_while(|(x, y)| x == y).count();
    if common < 2 {
        return None;
    }
    let mut parts: Vec<String> = vec!["..".into(); a.len() - common];
    parts.extend(
        b[common..]
            .iter()
            .map(|c| c.as_os_str().to_string_lossy().into_owned()),
    );
    Some(if parts.is_empty() {
        ".".into()
    } else {
        parts.join("/")
    })
}

impl ModelInputs {
    /// The case folder of a model loaded from `model_dir`: the relative path when it still
    /// leads to a folder, else the absolute one.
    pub fn case_dir(&self, model_dir: &std::path::Path) -> std::path::PathBuf {
        if let Some(r) = &self.case_relative {
            let p = model_dir.join(r);
            if p.is_dir() {
                return p;
            }
        }
        self.case.clone().into()
    }
}

#[cfg(test)]
mod tests {
    use super::relative_path;
    use std::path::Path;

    #[test]
    fn relative_paths() {
        let r = |a: &str, b: &str| relative_path(Path::new(a), Path::new(b));
        assert_eq!(
            r("/tmp/demo/model", "/tmp/demo/case").as_deref(),
            Some("../case")
        );
        assert_eq!(r("/tmp/m", "/tmp/m").as_deref(), Some("."));
        assert_eq!(r("/a/b/c", "/a/x").as_deref(), Some("../../x"));
        assert_eq!(r("/a/m", "/b/c"), None);
        assert_eq!(r("rel/m", "/a/c"), None);
    }
}
