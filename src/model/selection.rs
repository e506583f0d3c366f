//! What the frame selection of a build did (model.json `frame_selection`, issue 21): every
//! frame of the case with its scores, whether it was used and why (not).

use crate::selection::Reason;
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;

/// One frame of the case.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct SelectedFrame {
    /// Index of the frame in the case's poses.json.
    pub frame: usize,
    /// The model was built with this frame.
    pub used: bool,
    /// Why it was used or not.
    pub reason: Reason,
    /// Judged `blurred` or `badly_exposed` (also when used: a video within the budget is used
    /// whole), `None` when healthy.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub flagged: Option<String>,
    /// Gradient energy in its least sharp direction over the squared mean luminance.
    pub sharpness: f64,
    /// Sharpness over the median of its neighbours' (1 = as sharp).
    pub relative_sharpness: f64,
    /// Share of image pixels with a saturated channel.
    pub saturated_share: f64,
    /// Share of image pixels that are dark.
    pub dark_share: f64,
    /// Weight of its views in the choice (0..1).
    pub score: f64,
    /// Coverage it added when chosen, or would have added (weighted quality × cells).
    pub coverage_gain: f64,
}

/// What the selection did.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct FrameSelection {
    /// Most frames to use (`--max-frames`).
    pub budget: usize,
    /// Frames used.
    pub used: usize,
    /// Frames per reason (`chosen`, `blurred`, ...).
    pub counts: BTreeMap<String, usize>,
    /// Ray grid of the coverage cast (pixels), `None` when no cast was needed.
    pub coverage_grid: Option<[u32; 2]>,
    /// Wall cells seen by the used frames, of those seen by any frame.
    pub cells_seen_used: usize,
    /// Wall cells seen by any frame.
    pub cells_seen_all: usize,
    /// Seconds: scoring pass, coverage cast, choice.
    pub seconds: [f64; 3],
    /// Every frame of the case, in video order.
    pub frames: Vec<SelectedFrame>,
}
