//! What the registration stage of a build did (model.json `registration`, issue 16): every
//! frame's correction and status, and the rounds of the alternation.

use crate::io::poses::PoseEntry;
use crate::math::Affine;
use serde::{Deserialize, Serialize};

/// One frame's registration, as model.json and poses.json record it.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct FramePoseResult {
    /// Index of the frame in the case's poses.json.
    pub frame: usize,
    /// Distance between the given and the refined camera centre (mm).
    pub correction_mm: f64,
    /// Rotation between the given and the refined camera (degrees).
    pub correction_deg: f64,
    /// How its last round ended (`converged`, `not_converged`, `outlier`, ...).
    pub status: String,
    /// The model was built with this frame (flagged frames are left out).
    pub used: bool,
}

/// One round of the alternation.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct RoundSummary {
    /// What the frames were registered against (`geometry` or `texture`).
    pub against: String,
    /// Median over frames of how far this round moved a pose (mm, degrees).
    pub median_step_mm: f64,
    /// See `median_step_mm`.
    pub median_step_deg: f64,
    /// Frames per status at the end of the round.
    pub counts: std::collections::BTreeMap<String, usize>,
    /// Wall time of the round (s): light, texture and registration.
    pub seconds: f64,
}

/// What the registration stage did.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct PoseRegistration {
    /// Every frame of the case, in video order.
    pub frames: Vec<FramePoseResult>,
    /// The rounds run.
    pub rounds: Vec<RoundSummary>,
    /// Frames left out of the model.
    pub left_out: usize,
    /// The poses the model was built with: `refined`, or `given` when the given poses predict
    /// held-out frames better than the refined ones.
    pub kept: String,
    /// The calibrated light's mean PSNR on held-out frames with the given poses (dB; `None`
    /// without cross-validation).
    pub held_out_psnr_given_db: Option<f64>,
    /// The same with the refined poses.
    pub held_out_psnr_refined_db: Option<f64>,
    /// The poses as given (camera → world, every frame of the case).
    #[serde(skip)]
    pub given: Vec<Affine>,
    /// The refined pose of every frame of the case, with its image or video index.
    #[serde(skip)]
    pub refined: Vec<PoseEntry>,
}
