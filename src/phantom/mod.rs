//! Synthetic cases with known truth: the airway tree geometry, its CT voxelisation, CT-like
//! volumes made from real airway masks, the mucosa albedo, camera paths, the physically based
//! frame renderer and the case writer (`bronchosim phantom`).

pub mod albedo;
pub mod analysis;
pub mod anatomy;
pub mod baked_albedo;
pub mod branch;
pub mod case;
pub mod ct_volume;
pub mod from_mask;
pub mod mask_path;
pub mod motion_blur;
pub mod overlay;
pub mod path;
pub mod pose_noise;
pub mod render;
pub mod truth_io;
pub mod truth_mesh;

pub use albedo::MucosaAlbedo;
pub use anatomy::{AirwayTree, Branch, TreeOptions};
pub use case::{write_phantom_case, PhantomOptions, PhantomSummary};
pub use ct_volume::{make_ct_phantom, CtPhantom, CtPhantomOptions};
