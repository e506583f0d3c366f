//! Synthetic cases with known truth: the airway tree geometry, its CT voxelisation, and
//! CT-like volumes made from real airway masks.

pub mod anatomy;
pub mod ct_volume;
pub mod from_mask;
pub mod rng;

pub use anatomy::{AirwayTree, Branch, TreeOptions};
pub use ct_volume::{make_ct_phantom, CtPhantom, CtPhantomOptions};
