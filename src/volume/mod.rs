//! Voxel volumes with their index→world affine.

mod grid;

pub use grid::{orientation_code, Volume};
