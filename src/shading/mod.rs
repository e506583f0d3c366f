//! Shading: how the bronchoscope's light makes each pixel's brightness from the surface's
//! albedo, and its fit to the video.
//!
//! Two models, named by [`ShadingKind`]:
//! - [`paper`]: the paper's Psi (Chung et al. 2004, §2.2–2.3), one per viewpoint;
//! - [`calibrated`]: one calibrated light for the whole video (DESIGN.md, "Beyond the paper").
//!
//! Both are fitted to the pixels that obey a shading model ([`samples`]), weighted inversely
//! to their density ([`density`]), by small exact solves ([`solve`]) under a robust loss
//! ([`robust`]), in a [`bernstein`] basis. The fitted models of a video are one
//! [`FittedShading`] (shading.json), which gives the shader of each training frame
//! ([`FrameShading`], what de-lighting divides by) and of each new view ([`ViewShader`], what
//! rendering multiplies by).
//!
//! Adding a shading model: a variant of [`ShadingKind`]; a folder beside `paper/` and
//! `calibrated/` with its model type and fit; a field of [`FittedShading`] and its arms in
//! `has`, `frame_shaders` and `view_shader`; a variant of [`FrameShading`] and of
//! [`ViewShader`] (their `match`es tell the compiler what is left); and its fit as a stage of
//! the build (`workflow::build`). Cross-validation, the manifest and the report then list it.

pub mod bernstein;
pub mod calibrated;
pub mod density;
pub mod error;
pub mod fitted;
pub mod frame_shading;
pub mod indirect;
pub mod kind;
pub mod paper;
pub mod plotting;
pub mod robust;
pub mod samples;
pub mod solve;
pub mod view_shading;

pub use calibrated::CalibratedModel;
pub use density::{density_weights, density_weights_nd, DensityWeights, WeightOptions};
pub use error::ShadingError;
pub use fitted::FittedShading;
pub use frame_shading::{masked_luminance_sum, FrameShaders, FrameShading, Shade, LUMA};
pub use kind::ShadingKind;
pub use paper::{fit_psi, FitOptions, PsiModel};
pub use robust::Robust;
pub use samples::{extract_samples, ExclusionCounts, SampleOptions, SampleSet};
pub use view_shading::ViewShader;
