//! The model folder (DESIGN.md "Output: the model folder"): its manifest and shading types,
//! and loading a built model back for rendering.

pub mod blur_check;
pub mod cross_validation;
pub mod load;
pub mod manifest;
pub mod registration;
pub mod selection;

pub use load::Model;
pub use manifest::{ModelManifest, MODEL_FORMAT_VERSION};
