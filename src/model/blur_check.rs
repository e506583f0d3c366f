//! What the check for blurred frames found (model.json `blur_check`, or the registration's
//! `registration.blur_check`): every judged frame's sharpness against the model's prediction
//! from its pose, relative to the video's median.

use serde::{Deserialize, Serialize};

/// One judged frame.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct FrameSharpness {
    /// Index of the frame in the case's poses.json.
    pub frame: usize,
    /// Its sharpness against the model's prediction over the video's median (`None`: too few
    /// comparable pixels to judge).
    pub relative_sharpness: Option<f64>,
    /// Under `blurred_below`: left out of the model.
    pub blurred: bool,
}

/// What the check found.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct BlurCheck {
    /// A frame whose relative sharpness is under this is blurred.
    pub blurred_below: f64,
    /// The frames judged, in video order.
    pub frames: Vec<FrameSharpness>,
}

impl BlurCheck {
    /// The frames (indices in the case's poses.json) left out as blurred.
    pub fn blurred_frames(&self) -> Vec<usize> {
        self.frames
            .iter()
            .filter(|f| f.blurred)
            .map(|f| f.frame)
            .collect()
    }
}
