//! Texturing the lumen mesh: the texture atlas, texel geometry and hole filling (paper §2.4).

pub mod atlas;
