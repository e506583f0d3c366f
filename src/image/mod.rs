//! Images in linear light: the [`Frame`] type, the sRGB transfer curve, image quality
//! scores and power-of-two reduction.

pub mod error;
pub mod frame;
pub mod quality;
pub mod reduce;
pub mod srgb;

pub use error::ImageError;
pub use frame::Frame;
