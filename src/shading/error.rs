//! What can go wrong when fitting or using a shading model.

use super::ShadingKind;

/// A shading fit that cannot be made, or a shading model that cannot be used as asked.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ShadingError {
    /// Fewer samples than the model has parameters.
    #[error("{fit}: {got} samples, at least {needed} are needed")]
    TooFewSamples {
        /// Which fit.
        fit: &'static str,
        /// Samples given.
        got: usize,
        /// Samples needed.
        needed: usize,
    },
    /// Two inputs that must match in length do not.
    #[error("{fit}: {got} {what}, expected {expected}")]
    LengthMismatch {
        /// Which fit.
        fit: &'static str,
        /// What was counted (e.g. "weights").
        what: &'static str,
        /// Length given.
        got: usize,
        /// Length expected.
        expected: usize,
    },
    /// A sample weight that is negative or not finite.
    #[error("{fit}: weight {index} is {value} (weights must be finite and >= 0)")]
    BadWeight {
        /// Which fit.
        fit: &'static str,
        /// Sample index.
        index: usize,
        /// The weight.
        value: f64,
    },
    /// All samples at one depth: Psi's normalised depth is undefined.
    #[error("shading fit: empty depth range z_min {z_min} .. z_max {z_max} mm")]
    EmptyDepthRange {
        /// Nearest depth (mm).
        z_min: f64,
        /// Farthest depth (mm).
        z_max: f64,
    },
    /// A frame of the pooled fit without any sample: its gain is undetermined.
    #[error("calibrated fit: frame {frame} has no samples (its gain is undetermined)")]
    FrameWithoutSamples {
        /// The frame.
        frame: usize,
    },
    /// Options that do not describe a model (degrees, reference frame, starting model).
    #[error("{fit}: {message}")]
    BadOptions {
        /// Which fit.
        fit: &'static str,
        /// What is wrong.
        message: String,
    },
    /// The regression's normal equations are singular (the samples do not determine it).
    #[error("{fit}: singular system (the samples do not determine the model)")]
    Singular {
        /// Which fit.
        fit: &'static str,
    },
    /// A model that was not fitted was asked for.
    #[error("the {0} shading model was not fitted")]
    NotFitted(ShadingKind),
}

/// Check one weight per sample (`samples` of them), each finite and non-negative: what every
/// weighted fit (`fit` names it in the error) requires of its weights.
pub fn check_weights(
    fit: &'static str,
    weights: &[f32],
    samples: usize,
) -> Result<(), ShadingError> {
    if weights.len() != samples {
        return Err(ShadingError::LengthMismatch {
            fit,
            what: "weights",
            got: weights.len(),
            expected: samples,
        });
    }
    match weights.iter().position(|w| !(w.is_finite() && *w >= 0.0)) {
        Some(index) => Err(ShadingError::BadWeight {
            fit,
            index,
            value: f64::from(weights[index]),
        }),
        None => Ok(()),
    }
}
