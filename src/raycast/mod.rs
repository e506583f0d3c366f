//! Ray casting the lumen mesh: a wide SAH BVH with SIMD box and triangle tests, packets of
//! coherent rays from one origin,
//! watertight two-sided ray–triangle intersection, closest-hit and any-hit queries, and the
//! per-frame geometry buffer (depth, surface point, normal, gamma, triangle, barycentrics).
//!
//! ```text
//! TriMesh ─ Scene::new ─► Scene ─ closest_hit / any_hit / cast_frame(camera, pose) ─► GBuffer
//! ```

mod bvh;
mod bvh_build;
mod gbuffer;
mod packet;
mod packet_avx;
mod scene;
pub mod triangle;

pub use gbuffer::{
    cast_depth_with, cast_frame, cast_frame_with, mask_out_depth, GBuffer, RayTable,
};
pub use scene::{Hit, Scene};
