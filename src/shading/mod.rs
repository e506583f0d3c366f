//! The paper's shading model Psi (Chung et al. 2004, §2.2–2.3) and its weighted fit.
//!
//! Per frame: [`extract_samples`] keeps the pixels that obey the model, [`density_weights`]
//! weighs them inversely to their density in (gamma, z), [`fit_psi`] fits
//! `Psi(gamma, z) = rho(gamma) * varrho(z)` per channel, giving a [`PsiModel`] (serialised in
//! `shading.json`). [`plots`] draws the paper's Fig. 2.
//!
//! Beyond the paper, [`calibrated`]: one light model for the whole video (rho(gamma), the
//! light's angular profile s(theta), absolute 1/z², a gain per frame), fitted on samples pooled
//! over all frames by [`fit_calibrated`] (and refitted with a known albedo by
//! [`fit_calibrated_with_albedo`]); [`calibrated_plots`] draws it.

pub mod bernstein;
pub mod calibrated;
pub mod calibrated_fit;
mod calibrated_moments;
pub mod calibrated_plots;
pub mod calibrated_predict;
pub mod calibrated_samples;
pub mod chroma_albedo;
pub mod fit;
pub mod frame_shading;
mod moments;
pub mod plots;
pub mod psi;
pub mod samples;
pub mod weights;

pub use calibrated::CalibratedModel;
pub use calibrated_fit::{
    fit_calibrated, fit_calibrated_with_albedo, CalibratedFit, CalibratedOptions, CalibratedReport,
};
pub use calibrated_predict::{cos_theta_of, fit_gain, predict_frame, predict_pixels, psnr, Albedo};
pub use calibrated_samples::{
    density_weights_3d, pool_frames, FrameData, PoolOptions, PooledSamples,
};
pub use fit::{fit_psi, ChannelFit, FitOptions, PsiFit, Robust};
pub use frame_shading::{FrameShading, Shade};
pub use psi::PsiModel;
pub use samples::{extract_samples, ExclusionCounts, SampleOptions, SampleSet};
pub use weights::{density_weights, DensityWeights, WeightOptions};
