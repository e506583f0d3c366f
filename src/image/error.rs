//! What can go wrong with images: frames, textures, maps and their sizes, and encoding them.

/// An image operation that cannot be done on these inputs.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ImageError {
    /// A pixel buffer whose length does not match its image size.
    #[error("{stage}: {what} holds {got} values, expected {expected}")]
    BufferSize {
        /// Which operation.
        stage: &'static str,
        /// Which buffer.
        what: &'static str,
        /// Values given.
        got: usize,
        /// Values expected.
        expected: usize,
    },
    /// Two images (or an image and a camera) that must have the same size do not.
    #[error("{stage}: {what} is {}x{}, expected {}x{}", .got[0], .got[1], .expected[0], .expected[1])]
    SizeMismatch {
        /// Which operation.
        stage: &'static str,
        /// Which image.
        what: String,
        /// Its size (width, height).
        got: [u32; 2],
        /// The size expected.
        expected: [u32; 2],
    },
    /// Inputs that do not fit together (a camera that cannot be used, a pose that is not
    /// finite, a texture parameter out of range).
    #[error("{stage}: {message}")]
    Inconsistent {
        /// Which operation.
        stage: &'static str,
        /// What is wrong.
        message: String,
    },
    /// Encoding an image (PNG, a plot) failed.
    #[error("{stage}: encoding failed: {message}")]
    Encoding {
        /// What was being encoded.
        stage: String,
        /// The encoder's message.
        message: String,
    },
}
