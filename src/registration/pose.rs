//! Pose arithmetic of the registration: corrections as a camera-centre shift plus a rotation
//! about the centre (how a tracker's error is described), the optimiser's camera-frame
//! perturbation, and the pose error against a known truth.

use crate::camera::pose::camera_centre;
use crate::math::{Affine, Matrix3, Rotation3, Vector3};

/// A pose correction in world terms: the camera centre moves by `translation_mm` (world mm)
/// and the camera turns about its centre by the rotation vector `rotation` (world frame,
/// axis times angle in radians). Decoupled on purpose: a tracker's position and orientation
/// errors are independent, and a rotation never moves the centre.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct PoseDelta {
    /// Shift of the camera centre (world mm).
    pub translation_mm: Vector3<f64>,
    /// Rotation about the camera centre (world frame, radians).
    pub rotation: Vector3<f64>,
}

impl PoseDelta {
    /// The six numbers (translation mm, then rotation radians).
    pub fn to_array(&self) -> [f64; 6] {
        let (t, r) = (&self.translation_mm, &self.rotation);
        [t.x, t.y, t.z, r.x, r.y, r.z]
    }

    /// From six numbers (translation mm, then rotation radians).
    pub fn from_array(a: &[f64; 6]) -> PoseDelta {
        PoseDelta {
            translation_mm: Vector3::new(a[0], a[1], a[2]),
            rotation: Vector3::new(a[3], a[4], a[5]),
        }
    }

    /// Size of the shift (mm).
    pub fn mm(&self) -> f64 {
        self.translation_mm.norm()
    }

    /// Size of the rotation (degrees).
    pub fn deg(&self) -> f64 {
        self.rotation.norm().to_degrees()
    }
}

/// The rotation block of a camera → world pose.
pub fn rotation_of(pose: &Affine) -> Matrix3<f64> {
    pose.fixed_view::<3, 3>(0, 0).into_owned()
}

/// A pose from its rotation block and camera centre (world mm).
pub fn pose_from(r: &Matrix3<f64>, centre: &Vector3<f64>) -> Affine {
    let mut m = Affine::identity();
    m.fixed_view_mut::<3, 3>(0, 0).copy_from(r);
    m.fixed_view_mut::<3, 1>(0, 3).copy_from(centre);
    m
}

/// `pose` corrected by `delta`: centre `c + t`, rotation `exp([w]x) R`.
pub fn apply_delta(pose: &Affine, delta: &PoseDelta) -> Affine {
    let r = Rotation3::new(delta.rotation).into_inner() * rotation_of(pose);
    let c = camera_centre(pose).coords + delta.translation_mm;
    pose_from(&orthonormalise(&r), &c)
}

/// The pose at time `f` on the constant-velocity motion through `pa` (at time `a`) and `pb`
/// (at time `b`, `a < b`).
pub fn extrapolate(pa: &Affine, a: f64, pb: &Affine, b: f64, f: f64) -> Affine {
    let t = (f - a) / (b - a);
    let (ra, rb) = (rotation_of(pa), rotation_of(pb));
    let w = rotation_log(&(rb * ra.transpose()));
    let r = Rotation3::new(w * t).into_inner() * ra;
    let c = camera_centre(pa).coords * (1.0 - t) + camera_centre(pb).coords * t;
    pose_from(&orthonormalise(&r), &c)
}

/// The correction that takes `from` to `to` (inverse of [`apply_delta`]).
pub fn delta_between(from: &Affine, to: &Affine) -> PoseDelta {
    let dr = rotation_of(to) * rotation_of(from).transpose();
    PoseDelta {
        translation_mm: camera_centre(to) - camera_centre(from),
        rotation: rotation_log(&dr),
    }
}

/// The rotation vector (axis times angle, radians) of rotation matrix `r`; stable at small
/// angles, where `acos` of the trace loses everything to round-off.
pub fn rotation_log(r: &Matrix3<f64>) -> Vector3<f64> {
    let skew = Vector3::new(
        r[(2, 1)] - r[(1, 2)],
        r[(0, 2)] - r[(2, 0)],
        r[(1, 0)] - r[(0, 1)],
    ) * 0.5;
    let (s, c) = (skew.norm(), 0.5 * (r.trace() - 1.0));
    if c > -0.99 {
        let angle = s.atan2(c);
        if s < 1e-300 {
            return skew;
        }
        skew * (angle / s)
    } else {
        // Near pi the skew part vanishes: let nalgebra take the axis from the symmetric part.
        Rotation3::from_matrix_unchecked(orthonormalise(r)).scaled_axis()
    }
}

/// `pose` moved by the optimiser's camera-frame step `xi = (v, w)`: centre `c + R v` (mm),
/// rotation `R exp([w]x)`. To first order a camera-frame point P becomes `P - v - w x P`.
pub fn perturb(pose: &Affine, xi: &[f64; 6]) -> Affine {
    let r = rotation_of(pose);
    let v = Vector3::new(xi[0], xi[1], xi[2]);
    let w = Vector3::new(xi[3], xi[4], xi[5]);
    let c = camera_centre(pose).coords + r * v;
    pose_from(&orthonormalise(&(r * Rotation3::new(w).into_inner())), &c)
}

/// Pose error of `estimate` against `truth`: distance between the camera centres (mm) and
/// the angle of the relative rotation (degrees).
pub fn pose_error(estimate: &Affine, truth: &Affine) -> (f64, f64) {
    let d = delta_between(truth, estimate);
    (d.mm(), d.deg())
}

/// The error of `estimate` along the axes of the true camera: centre offset (x right, y down,
/// z forward; mm) and rotation about those axes (degrees; z is the roll about the view
/// direction). Shows which axes the images constrain.
pub fn pose_error_axes(estimate: &Affine, truth: &Affine) -> ([f64; 3], [f64; 3]) {
    let rt = rotation_of(truth).transpose();
    let d = rt * (camera_centre(estimate) - camera_centre(truth));
    let w = rotation_log(&(rt * rotation_of(estimate)));
    (
        [d.x, d.y, d.z],
        [w.x.to_degrees(), w.y.to_degrees(), w.z.to_degrees()],
    )
}

/// The nearest rotation to `m` (polar decomposition by SVD), so round-off never accumulates
/// in poses updated many times.
pub fn orthonormalise(m: &Matrix3<f64>) -> Matrix3<f64> {
    let svd = m.svd(true, true);
    let (u, vt) = (svd.u.expect("u requested"), svd.v_t.expect("v_t requested"));
    let mut r = u * vt;
    if r.determinant() < 0.0 {
        let mut u2 = u;
        u2.column_mut(2).neg_mut();
        r = u2 * vt;
    }
    r
}

#[cfg(test)]
mod tests {
    use super::*;

    fn some_pose() -> Affine {
        let r = Rotation3::new(Vector3::new(0.3, -1.1, 0.7)).into_inner();
        pose_from(&r, &Vector3::new(12.0, -4.0, 101.0))
    }

    #[test]
    fn delta_round_trips_and_error_matches() {
        let p = some_pose();
        let d = PoseDelta {
            translation_mm: Vector3::new(0.5, -1.0, 2.0),
            rotation: Vector3::new(0.01, 0.02, -0.03),
        };
        let q = apply_delta(&p, &d);
        let back = delta_between(&p, &q);
        assert!((back.translation_mm - d.translation_mm).norm() < 1e-12);
        assert!((back.rotation - d.rotation).norm() < 1e-12);
        let (mm, deg) = pose_error(&q, &p);
        assert!((mm - d.translation_mm.norm()).abs() < 1e-12);
        assert!((deg - d.rotation.norm().to_degrees()).abs() < 1e-9);
        // A rotation about the centre leaves the centre where it was.
        let turn = PoseDelta {
            rotation: Vector3::new(0.2, 0.0, 0.0),
            ..Default::default()
        };
        assert!(pose_error(&apply_delta(&p, &turn), &p).0 < 1e-12);
    }

    #[test]
    fn perturbation_moves_camera_points_to_first_order() {
        let p = some_pose();
        let x = Vector3::new(14.0, -2.0, 110.0);
        let cam = |m: &Affine| rotation_of(m).transpose() * (x - camera_centre(m).coords);
        let p0 = cam(&p);
        let xi = [1e-6, -2e-6, 3e-6, 2e-6, 1e-6, -1e-6];
        let p1 = cam(&perturb(&p, &xi));
        let v = Vector3::new(xi[0], xi[1], xi[2]);
        let w = Vector3::new(xi[3], xi[4], xi[5]);
        let expect = p0 - v - w.cross(&p0);
        assert!((p1 - expect).norm() < 1e-9, "{:?} vs {:?}", p1, expect);
        // Axes: a shift along the true camera's +z is a forward error.
        let fwd = rotation_of(&p) * Vector3::new(0.0, 0.0, 0.7);
        let q = apply_delta(
            &p,
            &PoseDelta {
                translation_mm: fwd,
                ..Default::default()
            },
        );
        let (t, r) = pose_error_axes(&q, &p);
        assert!(t[0].abs() < 1e-12 && t[1].abs() < 1e-12 && (t[2] - 0.7).abs() < 1e-12);
        assert!(r.iter().all(|v| v.abs() < 1e-9));
    }
}
