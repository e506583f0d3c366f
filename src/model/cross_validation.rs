//! The cross-validation record of model.json: how well each shading model predicted the
//! frames held out of the texture (written by the build's evaluation stage).

use serde::{Deserialize, Serialize};

use crate::shading::ShadingKind;

/// One held-out frame's prediction score.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct HeldOutScore {
    /// Index of the frame in the case's poses.json.
    pub frame: usize,
    /// Pixels compared.
    pub pixels: usize,
    /// PSNR (dB) of the sRGB-encoded prediction after its gain fit.
    pub psnr_db: Option<f64>,
    /// SSIM of the same.
    pub ssim: Option<f64>,
}

/// One shading model's cross-validation.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct ModelCrossValidation {
    /// The shading model.
    pub model: ShadingKind,
    /// Mean PSNR over the held-out frames (dB).
    pub mean_psnr_db: Option<f64>,
    /// Mean SSIM over the held-out frames.
    pub mean_ssim: Option<f64>,
    /// Per held-out frame.
    pub frames: Vec<HeldOutScore>,
}

/// The cross-validation of a build (model.json `cross_validation`).
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct CrossValidation {
    /// Every `every`-th frame was held out.
    pub every: usize,
    /// The held-out frames.
    pub held_out: Vec<usize>,
    /// One entry per shading model.
    pub models: Vec<ModelCrossValidation>,
}

impl CrossValidation {
    /// The model with the higher mean held-out PSNR (the paper's when none scored).
    pub fn winner(&self) -> ShadingKind {
        self.models
            .iter()
            .filter_map(|m| m.mean_psnr_db.map(|p| (m.model, p)))
            .max_by(|a, b| a.1.total_cmp(&b.1))
            .map_or(ShadingKind::Paper, |(m, _)| m)
    }
}
