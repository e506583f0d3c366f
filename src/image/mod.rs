//! Images in linear light: the [`Frame`] type and the sRGB transfer curve.

pub mod frame;
pub mod srgb;

pub use frame::Frame;
