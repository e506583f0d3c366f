//! Scoring a model against a phantom's truth: how far the fused albedo is from the true one
//! ([`albedo_error`]) and how well a light law explains each frame given the true albedo and
//! gains ([`shading_residuals`]). Used by tests, examples and benchmarks, never by a build.

pub mod albedo;
pub mod shading;

pub use albedo::{albedo_error, texture_against_truth, TruthView};
pub use shading::{shading_residuals, spread, ShadingLaw};
