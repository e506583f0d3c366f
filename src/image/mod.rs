//! Images in linear light: the [`Frame`] type, the sRGB transfer curve and image quality
//! scores.

pub mod error;
pub mod frame;
pub mod quality;
pub mod srgb;

pub use error::ImageError;
pub use frame::Frame;
