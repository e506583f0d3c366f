//! Images in linear light: the [`Frame`] type, the sRGB transfer curve and image quality
//! scores.

pub mod frame;
pub mod quality;
pub mod srgb;

pub use frame::Frame;
