//! The model folder (DESIGN.md "Output: the model folder"): its manifest and shading types,
//! and loading a built model back for rendering.

pub mod load;
pub mod manifest;

pub use load::Model;
pub use manifest::{ModelManifest, ShadingFile, MODEL_FORMAT_VERSION};
