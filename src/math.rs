//! The one place points, vectors and transforms come from (nalgebra, f64 unless noted).
//!
//! World coordinates are the CT's patient space in mm, RAS+. Camera coordinates follow
//! OpenCV: +x right, +y down, +z forward.

pub use nalgebra::{Matrix3, Matrix4, Point2, Point3, Rotation3, Vector2, Vector3, Vector4};

/// A 4x4 homogeneous affine transform (e.g. voxel index → world mm, camera → world).
pub type Affine = Matrix4<f64>;

/// Apply a homogeneous affine to a point.
#[inline]
pub fn transform_point(m: &Affine, p: &Point3<f64>) -> Point3<f64> {
    Point3::new(
        m[(0, 0)] * p.x + m[(0, 1)] * p.y + m[(0, 2)] * p.z + m[(0, 3)],
        m[(1, 0)] * p.x + m[(1, 1)] * p.y + m[(1, 2)] * p.z + m[(1, 3)],
        m[(2, 0)] * p.x + m[(2, 1)] * p.y + m[(2, 2)] * p.z + m[(2, 3)],
    )
}

/// Apply the linear part of a homogeneous affine to a direction.
#[inline]
pub fn transform_vector(m: &Affine, v: &Vector3<f64>) -> Vector3<f64> {
    m.fixed_view::<3, 3>(0, 0) * v
}
