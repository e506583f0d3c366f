//! Triangle meshes: the lumen surface and what is done to it.

pub mod decimate;
pub mod lumen;
pub mod metrics;
pub mod smooth;
mod trimesh;

pub use trimesh::TriMesh;
