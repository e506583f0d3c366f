//! bronchosim: patient-specific, photo-realistic airway models from CT and bronchoscope video.
//!
//! The pipeline follows Chung et al., "Enhancement of Visual Realism with BRDF for Patient
//! Specific Bronchoscopy Simulation" (MICCAI 2004). Stages meet at plain data types:
//! [`volume::Volume`], [`camera::Camera`], [`camera::Pose`], [`image::Frame`].

pub mod allocator;
pub mod camera;
pub mod error;
pub mod image;
pub mod inspect;
pub mod io;
pub mod math;
pub mod mesh;
pub mod model;
pub mod parallel;
pub mod phantom;
pub mod raycast;
pub mod registration;
pub mod render;
pub mod rng;
pub mod selection;
pub mod shading;
pub mod texture;
pub mod viewer;
pub mod volume;
pub mod workflow;

pub use error::{Error, Result};
