//! The paper's shading model Psi (Chung et al. 2004, §2.2–2.3): one `rho(gamma) * varrho(z)`
//! per viewpoint and colour channel, fitted by weighted least squares to that frame's pixels.
//!
//! Per frame: [`crate::shading::extract_samples`] keeps the pixels that obey the model,
//! [`crate::shading::density_weights`] weighs them inversely to their density in (gamma, z),
//! [`fit_psi`] fits Psi per channel, giving a [`PsiModel`]. New views take the Psi of the
//! nearest fitted viewpoints ([`ViewpointIndex`], [`BlendedPsi`]). [`plots`] draws Fig. 2.

pub mod fit;
mod moments;
pub mod plots;
pub mod psi;
pub mod viewpoints;

pub use fit::{fit_psi, ChannelFit, FitOptions, PsiFit};
pub use psi::PsiModel;
pub use viewpoints::{BlendedPsi, PsiLookup, PsiLookupKind, ViewpointIndex};
