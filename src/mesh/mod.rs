//! Triangle meshes: the lumen surface and what is done to it.

pub mod components;
pub mod decimate;
pub mod error;
pub mod lumen;
pub mod lumen_field;
pub mod metrics;
pub mod smooth;
mod trimesh;

pub use error::GeometryError;
pub use trimesh::TriMesh;
