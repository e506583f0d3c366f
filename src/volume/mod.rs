//! Voxel volumes with their index→world affine.

mod grid;
pub mod marching_cubes;
mod mc_tables;

pub use grid::{orientation_code, Volume};
pub use marching_cubes::marching_cubes;
