//! [`Pose`]: where a camera is and where it looks, as a rigid camera→world transform (mm).
//!
//! Camera axes follow OpenCV: +x right, +y down, +z the viewing direction; the light sits at
//! the camera centre.

use crate::math::{Affine, Matrix3, Point3, Vector3};

/// Largest allowed deviation of `RᵀR` from the identity (any entry) and of `det R` from +1.
pub const ROTATION_TOLERANCE: f64 = 1e-4;

/// Largest allowed deviation of the last matrix row from `0 0 0 1` (printing round-off only).
pub const LAST_ROW_TOLERANCE: f64 = 1e-9;

/// A camera pose: camera coordinates (mm) → world coordinates (mm, RAS+), a rigid transform.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Pose {
    /// The 4x4 camera→world matrix `[R t; 0 1]`.
    pub camera_to_world: Affine,
}

impl Pose {
    /// The pose of the 4x4 camera→world matrix `m` (not validated; see [`validate_pose`]).
    pub fn new(camera_to_world: Affine) -> Pose {
        Pose { camera_to_world }
    }

    /// The pose of 16 row-major numbers (as poses.json and shading.json store it).
    pub fn from_row_major(m: &[f64; 16]) -> Pose {
        Pose::new(Affine::from_row_slice(m))
    }

    /// The 16 numbers of the camera→world matrix, row-major.
    pub fn row_major(&self) -> [f64; 16] {
        std::array::from_fn(|k| self.camera_to_world[(k / 4, k % 4)])
    }

    /// The camera centre (and light position) in world mm.
    pub fn centre(&self) -> Point3<f64> {
        camera_centre(&self.camera_to_world)
    }

    /// The unit viewing direction (camera +z) in world coordinates.
    pub fn viewing_direction(&self) -> Vector3<f64> {
        viewing_direction(&self.camera_to_world)
    }

    /// The world→camera transform (the exact inverse of the rigid camera→world).
    pub fn world_to_camera(&self) -> Affine {
        rigid_inverse(&self.camera_to_world)
    }

    /// Check that this is a camera pose (see [`validate_pose`]).
    pub fn validate(&self) -> Result<(), String> {
        validate_pose(&self.camera_to_world)
    }
}

/// The camera centre in world mm: the translation column of camera→world.
pub fn camera_centre(camera_to_world: &Affine) -> Point3<f64> {
    Point3::new(
        camera_to_world[(0, 3)],
        camera_to_world[(1, 3)],
        camera_to_world[(2, 3)],
    )
}

/// The unit viewing direction in world coordinates: the image of camera +z.
pub fn viewing_direction(camera_to_world: &Affine) -> Vector3<f64> {
    Vector3::new(
        camera_to_world[(0, 2)],
        camera_to_world[(1, 2)],
        camera_to_world[(2, 2)],
    )
    .normalize()
}

/// Inverse of a rigid transform `[R t; 0 1]`: `[Rᵀ -Rᵀt; 0 1]` (exact, no general inversion).
pub fn rigid_inverse(m: &Affine) -> Affine {
    let r = m.fixed_view::<3, 3>(0, 0).transpose();
    let t = -(r * m.fixed_view::<3, 1>(0, 3));
    let mut out = Affine::identity();
    out.fixed_view_mut::<3, 3>(0, 0).copy_from(&r);
    out.fixed_view_mut::<3, 1>(0, 3).copy_from(&t);
    out
}

/// Check that `m` is a camera→world pose: finite, last row `0 0 0 1`, rotation orthonormal
/// with determinant +1 (within [`ROTATION_TOLERANCE`]). The message says what is wrong.
pub fn validate_pose(m: &Affine) -> Result<(), String> {
    if let Some(k) = (0..16).find(|&k| !m[(k / 4, k % 4)].is_finite()) {
        return Err(format!("element {k} is not finite ({})", m[(k / 4, k % 4)]));
    }
    let last = [m[(3, 0)], m[(3, 1)], m[(3, 2)], m[(3, 3)]];
    if last
        .iter()
        .zip([0.0, 0.0, 0.0, 1.0])
        .any(|(a, b)| (a - b).abs() > LAST_ROW_TOLERANCE)
    {
        return Err(format!(
            "last row is {} {} {} {}, expected 0 0 0 1",
            last[0], last[1], last[2], last[3]
        ));
    }
    let r: Matrix3<f64> = m.fixed_view::<3, 3>(0, 0).into_owned();
    let off = (r.transpose() * r - Matrix3::identity()).abs().max();
    if off > ROTATION_TOLERANCE {
        return Err(format!(
            "rotation is not orthonormal (max |RᵀR - I| = {off:.3e} > {ROTATION_TOLERANCE:e})"
        ));
    }
    let det = r.determinant();
    if (det - 1.0).abs() > ROTATION_TOLERANCE {
        return Err(format!(
            "rotation has determinant {det:.6}, expected +1 (a reflection is not a camera pose)"
        ));
    }
    Ok(())
}
