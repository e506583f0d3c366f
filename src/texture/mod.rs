//! Texturing the lumen mesh (paper §2.4): the texture atlas, texel geometry and hole filling;
//! texel-centric de-lighting of each frame by its Psi; fusion of the frames into one albedo
//! atlas; the albedo PNG and textured glTF outputs.
//!
//! ```text
//! Atlas ─ rasterize_texels ─► TexelGeometry ─ TexelSet::new ─► TexelSet
//! TexelSet + frames (Frame, pose, PsiModel, depth) ─ fuse ─► FusedTexture ─ completed ─► albedo.png, airway.glb
//!                                                  (unseen texels synthesised: synthesis)
//! ```

pub mod atlas;
mod blur;
pub mod coarse;
pub mod delight;
pub mod fusion;
mod max_weight;
mod multiband;
pub mod output;
mod pass;
mod robust;
pub mod seams;
pub mod synthesis;
pub mod texels;

pub use delight::{delight_frame, DelightOptions, DelitFrame, Observation};
pub use fusion::{fuse, FrameStream, FusedTexture, FusionMethod, FusionOptions, FusionStats};
pub use output::{
    encode_albedo, encode_coverage, write_texture_outputs, AlbedoImage, TextureOutputs,
};
pub use texels::{TexelRect, TexelSet};
