//! The paper's shading model Psi (Chung et al. 2004, §2.2–2.3) and its weighted fit.
//!
//! Per frame: [`extract_samples`] keeps the pixels that obey the model, [`density_weights`]
//! weighs them inversely to their density in (gamma, z), [`fit_psi`] fits
//! `Psi(gamma, z) = rho(gamma) * varrho(z)` per channel, giving a [`PsiModel`] (serialised in
//! `shading.json`). [`plots`] draws the paper's Fig. 2.

pub mod bernstein;
pub mod fit;
mod moments;
pub mod plots;
pub mod psi;
pub mod samples;
pub mod weights;

pub use fit::{fit_psi, ChannelFit, FitOptions, PsiFit, Robust};
pub use psi::PsiModel;
pub use samples::{extract_samples, ExclusionCounts, SampleOptions, SampleSet};
pub use weights::{density_weights, DensityWeights, WeightOptions};
