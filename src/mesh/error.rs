//! What can go wrong with a surface: meshes, their smoothing and decimation, ray-casting scenes,
//! texture atlases.

/// A geometry operation that cannot be done on these inputs.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum GeometryError {
    /// A triangle that refers past the mesh's vertices.
    #[error("{stage}: triangle {triangle} refers to a vertex past the mesh's {vertices} vertices")]
    VertexIndex {
        /// Which operation.
        stage: &'static str,
        /// The triangle.
        triangle: usize,
        /// Vertices in the mesh.
        vertices: usize,
    },
    /// A triangle with a NaN or infinite corner.
    #[error("{stage}: triangle {triangle} has a non-finite vertex")]
    NonFiniteVertex {
        /// Which operation.
        stage: &'static str,
        /// The triangle.
        triangle: usize,
    },
    /// Per-vertex, per-triangle or per-texel data whose length does not match.
    #[error("{stage}: {got} {what}, expected {expected}")]
    LengthMismatch {
        /// Which operation.
        stage: &'static str,
        /// What was counted.
        what: &'static str,
        /// Length given.
        got: usize,
        /// Length expected.
        expected: usize,
    },
    /// Options that are out of their range.
    #[error("{stage}: {message}")]
    BadOptions {
        /// Which operation.
        stage: &'static str,
        /// What is wrong.
        message: String,
    },
    /// No lumen surface: the airway has no wall around it inside the CT.
    #[error("lumen mesh: no surface at {iso_hu} HU around the airway mask inside the CT's grid of {} x {} x {} voxels (the airway must have tissue around it, and the grid 2 voxels along each axis)", .dims[0], .dims[1], .dims[2])]
    NoLumenSurface {
        /// The iso level (HU).
        iso_hu: f32,
        /// The CT's grid.
        dims: [usize; 3],
    },
    /// An atlas larger than allowed at this texel size.
    #[error("texture atlas: {width}x{height} texels exceed the largest atlas {max_size} at {texel_mm} mm per texel: use larger texels")]
    AtlasTooLarge {
        /// Atlas width (texels).
        width: u32,
        /// Atlas height (texels).
        height: u32,
        /// Largest side allowed (texels).
        max_size: u32,
        /// Texel size (mm).
        texel_mm: f64,
    },
    /// Geometry the operation cannot handle (empty, degenerate, too large).
    #[error("{stage}: {message}")]
    Degenerate {
        /// Which operation.
        stage: &'static str,
        /// What is wrong.
        message: String,
    },
}
