//! What can stop a build, beyond the errors of the stages it calls.

use crate::shading::ExclusionCounts;

/// A build that cannot go on with these frames.
#[derive(Debug, thiserror::Error)]
pub enum BuildError {
    /// A frame in which too few pixels see the airway as the shading model expects.
    #[error("frame {frame} ({name}): too few pixels obey the shading model ({samples} samples; excluded: {excluded}): {}", .excluded.likely_cause())]
    FrameUnusable {
        /// Frame index (poses order).
        frame: usize,
        /// Its file name or video index.
        name: String,
        /// Pixels that obey the model.
        samples: usize,
        /// Why the others were left out.
        excluded: ExclusionCounts,
    },
    /// A frame whose shading fit failed.
    #[error("frame {frame} ({name}): {source}")]
    FrameFit {
        /// Frame index (poses order).
        frame: usize,
        /// Its file name or video index.
        name: String,
        /// What failed.
        #[source]
        source: Box<crate::Error>,
    },
    /// Too few frames to hold any out for the cross-validation.
    #[error("cross-validation: {frames} frames are too few to hold out every {every}-th")]
    TooFewFramesToHoldOut {
        /// Frames in the case.
        frames: usize,
        /// Every how many frames one is held out.
        every: usize,
    },
    /// A frame the frame source ended before.
    #[error("frame {frame} is missing from the frame source ({frames} frames read)")]
    FrameMissing {
        /// Frame index (poses order).
        frame: usize,
        /// Frames the source gave.
        frames: usize,
    },
    /// The calibrated light was asked for and could not be fitted.
    #[error("calibrated light fit: {0}")]
    CalibratedLight(#[source] Box<crate::Error>),
    /// The poses could not be registered to the CT.
    #[error("registration: {0}")]
    Registration(String),
}
