//! Voxel volumes with their index→world affine, and airway segmentation.

pub mod branches;
pub mod error;
pub mod filter;
pub mod geodesic;
mod grid;
pub mod marching_cubes;
mod mc_tables;
pub mod morphology;
pub mod region_grow;
pub mod seed;
pub mod segment;

pub use error::VolumeError;
pub use grid::{orientation_code, Volume};
pub use marching_cubes::marching_cubes;
