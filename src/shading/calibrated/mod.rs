//! One calibrated light for the whole video (DESIGN.md, "Beyond the paper"):
//! `I_f = g_f · (albedo · rho(gamma) + k · spec(gamma)) · s(theta) / z² (+ inter-reflection)`.
//!
//! [`pool_frames`] keeps a subsample of every frame's model-obeying pixels,
//! [`density_weights_3d`] weighs them over (gamma, z, theta), [`fit_calibrated`] fits rho, s,
//! the gains and the inter-reflection on the pool; [`refit_with_chroma_albedo`] refits them with
//! each pixel's albedo predicted from its colour, and [`fit_calibrated_with_albedo`] with a
//! known albedo (the build's refinements against a fused texture). [`with_video_gains`] carries
//! another model's light (the same scope) to this video, and [`lambert_lamp`] is a light that
//! needs no poses. [`plots`] draws the light.

pub mod chroma_albedo;
pub mod exposure;
pub mod fit;
pub mod lambert_lamp;
pub mod model;
mod moments;
pub mod plots;
pub mod predict;
mod residuals;
pub mod samples;
pub mod scope_light;
mod solver;
pub mod specular;
mod specular_fit;

pub use chroma_albedo::refit_with_chroma_albedo;
pub use exposure::AutoExposure;
pub use fit::{
    fit_calibrated, fit_calibrated_with_albedo, CalibratedFit, CalibratedOptions, CalibratedReport,
};
pub use lambert_lamp::lambert_lamp;
pub use model::CalibratedModel;
pub use predict::{cos_theta_of, predict_frame, predict_pixels, Albedo};
pub use samples::{density_weights_3d, pool_frames, FrameData, PoolOptions, PooledSamples};
pub use scope_light::{with_video_gains, ScopeLight};
pub use specular::{SpecularLobe, SpecularMode};
