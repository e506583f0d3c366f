//! Triangle meshes: the lumen surface and what is done to it.

mod trimesh;

pub use trimesh::TriMesh;
