//! The bronchoscope camera: OpenCV's pinhole + Brown–Conrady model (k1, k2, p1, p2, k3).
//!
//! Pixel centres are at integer coordinates; camera axes are +x right, +y down, +z forward.
//! Every formula matches OpenCV (cv2.projectPoints, cv2.undistortPoints,
//! cv2.initUndistortRectifyMap); tests/camera_opencv.rs pins the agreement to 1e-3 px.

pub mod pose;
mod remap;
mod remap_plan;
mod undistort;

pub use pose::Pose;
pub use remap::remap_bilinear;
pub use remap_plan::RemapPlan;
pub use undistort::UndistortMap;

use crate::math::{Matrix3, Point2, Point3, Vector2, Vector3};
use serde::{Deserialize, Serialize};

/// Intrinsics and lens distortion, all in pixels (as camera.json in CASE_FORMAT.md).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Camera {
    /// Image width (pixels).
    pub width: u32,
    /// Image height (pixels).
    pub height: u32,
    /// Focal length along x (pixels).
    pub fx: f64,
    /// Focal length along y (pixels).
    pub fy: f64,
    /// Principal point x (pixels, pixel centres at integers).
    pub cx: f64,
    /// Principal point y (pixels).
    pub cy: f64,
    /// Radial distortion, r² term.
    #[serde(default)]
    pub k1: f64,
    /// Radial distortion, r⁴ term.
    #[serde(default)]
    pub k2: f64,
    /// Tangential distortion p1.
    #[serde(default)]
    pub p1: f64,
    /// Tangential distortion p2.
    #[serde(default)]
    pub p2: f64,
    /// Radial distortion, r⁶ term.
    #[serde(default)]
    pub k3: f64,
}

/// Angular field of view in degrees, measured through the lens distortion (see
/// [`Camera::field_of_view`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FieldOfView {
    /// Angle between the rays through the left and right image edges on row `cy` (degrees).
    pub horizontal: f64,
    /// Angle between the rays through the top and bottom image edges on column `cx` (degrees).
    pub vertical: f64,
    /// Angle between the rays through the top-left and bottom-right image corners (degrees).
    pub diagonal: f64,
}

/// Normalised-coordinate residual at which Newton undistortion stops (1e-13 × fx ≈ 1e-10 px).
const UNDISTORT_TOL: f64 = 1e-13;
/// Residual above which an undistortion counts as failed (1e-10 × fx ≤ 1e-6 px for fx ≤ 1e4).
const UNDISTORT_FAIL: f64 = 1e-10;

impl Camera {
    /// The camera of the image reduced by `2^level` ([`crate::image::reduce`]): a reduced
    /// pixel averages a `2^level × 2^level` block, so its centre is at full-resolution
    /// `2^level u + (2^level - 1) / 2` (pixel centres at integers); the distortion, in
    /// normalised coordinates, is unchanged.
    pub fn at_level(&self, level: usize) -> Camera {
        let s = (1u32 << level) as f64;
        Camera {
            width: self.width >> level,
            height: self.height >> level,
            fx: self.fx / s,
            fy: self.fy / s,
            cx: (self.cx + 0.5) / s - 0.5,
            cy: (self.cy + 0.5) / s - 0.5,
            ..*self
        }
    }

    /// True when all distortion coefficients are zero.
    pub fn is_pinhole(&self) -> bool {
        self.k1 == 0.0 && self.k2 == 0.0 && self.p1 == 0.0 && self.p2 == 0.0 && self.k3 == 0.0
    }

    /// The same intrinsics without lens distortion (the ideal camera undistortion maps to).
    pub fn pinhole(&self) -> Camera {
        Camera {
            k1: 0.0,
            k2: 0.0,
            p1: 0.0,
            p2: 0.0,
            k3: 0.0,
            ..*self
        }
    }

    /// The 3x3 camera matrix K = [[fx, 0, cx], [0, fy, cy], [0, 0, 1]] (pixels).
    pub fn k_matrix(&self) -> Matrix3<f64> {
        Matrix3::new(self.fx, 0.0, self.cx, 0.0, self.fy, self.cy, 0.0, 0.0, 1.0)
    }

    /// Check that the camera is usable: positive image size, finite values, positive focal
    /// lengths, and a distortion that can be inverted everywhere inside the image.
    /// The message names the offending field.
    pub fn validate(&self) -> Result<(), String> {
        if self.width == 0 {
            return Err("width must be a positive number of pixels, got 0".into());
        }
        if self.height == 0 {
            return Err("height must be a positive number of pixels, got 0".into());
        }
        let fields = [
            ("fx", self.fx),
            ("fy", self.fy),
            ("cx", self.cx),
            ("cy", self.cy),
            ("k1", self.k1),
            ("k2", self.k2),
            ("p1", self.p1),
            ("p2", self.p2),
            ("k3", self.k3),
        ];
        for (name, v) in fields {
            if !v.is_finite() {
                return Err(format!("{name} must be a finite number, got {v}"));
            }
        }
        for (name, v) in [("fx", self.fx), ("fy", self.fy)] {
            if v <= 0.0 {
                return Err(format!(
                    "{name} must be a positive focal length in pixels, got {v}"
                ));
            }
        }
        self.check_invertible()
    }

    /// Check that the distortion does not fold over inside the image: every border pixel has a
    /// converged undistortion, and the distortion Jacobian stays positive on the segment from
    /// the optical axis to it (a fold would give two undistorted points for one pixel).
    fn check_invertible(&self) -> Result<(), String> {
        if self.is_pinhole() {
            return Ok(());
        }
        for (u, v) in self.border_pixels(4) {
            let xd = self.normalize(u, v);
            let Some(x) = self.try_undistort_normalized(xd) else {
                return Err(format!(
                    "k1, k2, p1, p2, k3: the distortion cannot be inverted at pixel ({u}, {v}) \
                     (the lens model folds over inside the image)"
                ));
            };
            for i in 1..=16 {
                let p = x * (i as f64 / 16.0);
                if self.distortion_jacobian(p).determinant() <= 0.0 {
                    return Err(format!(
                        "k1, k2, p1, p2, k3: the distortion folds over between the image centre \
                         and pixel ({u}, {v})"
                    ));
                }
            }
        }
        Ok(())
    }

    /// Pixel centres on the image border, every `step` pixels, always including the corners.
    fn border_pixels(&self, step: u32) -> Vec<(f64, f64)> {
        let (w, h) = (self.width.max(1) - 1, self.height.max(1) - 1);
        let along = |n: u32| (0..n).step_by(step.max(1) as usize).chain([n]);
        let mut out = Vec::new();
        for u in along(w) {
            out.push((u as f64, 0.0));
            out.push((u as f64, h as f64));
        }
        for v in along(h) {
            out.push((0.0, v as f64));
            out.push((w as f64, v as f64));
        }
        out
    }

    /// Normalised distorted coordinates of pixel (u, v): ((u - cx)/fx, (v - cy)/fy).
    #[inline]
    pub fn normalize(&self, u: f64, v: f64) -> Vector2<f64> {
        Vector2::new((u - self.cx) / self.fx, (v - self.cy) / self.fy)
    }

    /// Apply lens distortion to normalised image coordinates (x/z, y/z), as cv2.projectPoints.
    #[inline]
    pub fn distort_normalized(&self, p: Vector2<f64>) -> Vector2<f64> {
        let (x, y) = (p.x, p.y);
        let r2 = x * x + y * y;
        let radial = 1.0 + r2 * (self.k1 + r2 * (self.k2 + r2 * self.k3));
        Vector2::new(
            x * radial + 2.0 * self.p1 * x * y + self.p2 * (r2 + 2.0 * x * x),
            y * radial + self.p1 * (r2 + 2.0 * y * y) + 2.0 * self.p2 * x * y,
        )
    }

    /// Jacobian of [`Camera::distort_normalized`] at the undistorted normalised point `p`.
    #[inline]
    pub fn distortion_jacobian(&self, p: Vector2<f64>) -> Matrix3<f64> {
        let (x, y) = (p.x, p.y);
        let r2 = x * x + y * y;
        let radial = 1.0 + r2 * (self.k1 + r2 * (self.k2 + r2 * self.k3));
        let dradial = self.k1 + r2 * (2.0 * self.k2 + 3.0 * r2 * self.k3); // d radial / d r²
        let j00 = radial + 2.0 * x * x * dradial + 2.0 * self.p1 * y + 6.0 * self.p2 * x;
        let j01 = 2.0 * x * y * dradial + 2.0 * self.p1 * x + 2.0 * self.p2 * y;
        let j11 = radial + 2.0 * y * y * dradial + 6.0 * self.p1 * y + 2.0 * self.p2 * x;
        // Embedded in a 3x3 so callers get determinant() without a 2x2 type in crate::math.
        Matrix3::new(j00, j01, 0.0, j01, j11, 0.0, 0.0, 0.0, 1.0)
    }

    /// Project a point in camera coordinates (mm) to a distorted pixel; `None` behind the camera.
    #[inline]
    pub fn project(&self, p: &Point3<f64>) -> Option<Point2<f64>> {
        if p.z <= 0.0 {
            return None;
        }
        let d = self.distort_normalized(Vector2::new(p.x / p.z, p.y / p.z));
        Some(Point2::new(
            self.fx * d.x + self.cx,
            self.fy * d.y + self.cy,
        ))
    }

    /// Unit viewing ray in camera coordinates through distorted pixel (u, v).
    #[inline]
    pub fn pixel_ray(&self, u: f64, v: f64) -> Vector3<f64> {
        let xd = self.normalize(u, v);
        let n = if self.is_pinhole() {
            xd
        } else {
            self.undistort_normalized(xd)
        };
        Vector3::new(n.x, n.y, 1.0).normalize()
    }

    /// Invert [`Camera::distort_normalized`] by damped Newton iteration on the 2x2 Jacobian,
    /// to a residual of 1e-13 in normalised units (1e-10 px at fx = 1000). Inside the image
    /// of a camera that passes [`Camera::validate`] this always converges; elsewhere the best
    /// iterate is returned (use [`Camera::try_undistort_normalized`] to detect failure).
    pub fn undistort_normalized(&self, xd: Vector2<f64>) -> Vector2<f64> {
        self.newton_undistort(xd).0
    }

    /// As [`Camera::undistort_normalized`], but `None` when the iteration did not converge
    /// (the pixel lies beyond a fold of the distortion).
    pub fn try_undistort_normalized(&self, xd: Vector2<f64>) -> Option<Vector2<f64>> {
        let (p, residual) = self.newton_undistort(xd);
        (residual <= UNDISTORT_FAIL).then_some(p)
    }

    /// Newton with step halving (never accepts a step that increases the residual, so strong
    /// barrel distortion at the corners cannot overshoot into the fold). Returns the point and
    /// its residual norm.
    fn newton_undistort(&self, xd: Vector2<f64>) -> (Vector2<f64>, f64) {
        let mut p = xd;
        let mut f = self.distort_normalized(p) - xd;
        let mut fnorm = f.norm();
        for _ in 0..60 {
            if fnorm <= UNDISTORT_TOL {
                break;
            }
            let j = self.distortion_jacobian(p);
            let (j00, j01, j11) = (j[(0, 0)], j[(0, 1)], j[(1, 1)]);
            let det = j00 * j11 - j01 * j01;
            if det.abs() < 1e-300 {
                break;
            }
            let step = Vector2::new(
                (j11 * f.x - j01 * f.y) / det,
                (-j01 * f.x + j00 * f.y) / det,
            );
            let mut t = 1.0;
            let mut improved = false;
            while t > 1e-6 {
                let q = p - step * t;
                let fq = self.distort_normalized(q) - xd;
                let nq = fq.norm();
                if nq < fnorm {
                    (p, f, fnorm, improved) = (q, fq, nq, true);
                    break;
                }
                t *= 0.5;
            }
            if !improved {
                break;
            }
        }
        (p, fnorm)
    }

    /// The ideal (undistorted, same K) pixel of distorted pixel (u, v), as
    /// cv2.undistortPoints(..., P=K) run to convergence.
    #[inline]
    pub fn undistort_pixel(&self, u: f64, v: f64) -> Point2<f64> {
        let n = self.undistort_normalized(self.normalize(u, v));
        Point2::new(self.fx * n.x + self.cx, self.fy * n.y + self.cy)
    }

    /// Undistort distorted pixels as cv2.undistortPoints(src, K, D, R=I, P) with a converged
    /// stopping rule: with `p = None` the result is normalised (x/z, y/z); with a new camera
    /// matrix P the result is in P's pixels (`[X Y W]ᵀ = P [x y 1]ᵀ`, divided by W).
    /// (OpenCV's default stops after 5 fixed-point iterations, tens of pixels short at the
    /// corners of strongly distorted images; pass it converging criteria to compare.)
    pub fn undistort_points(
        &self,
        pts: &[Point2<f64>],
        p: Option<&Matrix3<f64>>,
    ) -> Vec<Point2<f64>> {
        pts.iter()
            .map(|q| {
                let n = self.undistort_normalized(self.normalize(q.x, q.y));
                match p {
                    None => Point2::new(n.x, n.y),
                    Some(m) => {
                        let h = m * Vector3::new(n.x, n.y, 1.0);
                        Point2::new(h.x / h.z, h.y / h.z)
                    }
                }
            })
            .collect()
    }

    /// Field of view through the distortion: angles between the viewing rays through the
    /// outer edges of the edge pixels (pixel centres are integers, so edges are at -0.5 and
    /// width - 0.5), horizontally on row cy, vertically on column cx, and diagonally between
    /// the top-left and bottom-right corners (degrees).
    pub fn field_of_view(&self) -> FieldOfView {
        let (w, h) = (self.width as f64 - 0.5, self.height as f64 - 0.5);
        let angle = |a: (f64, f64), b: (f64, f64)| {
            let (ra, rb) = (self.pixel_ray(a.0, a.1), self.pixel_ray(b.0, b.1));
            ra.cross(&rb).norm().atan2(ra.dot(&rb)).to_degrees()
        };
        FieldOfView {
            horizontal: angle((-0.5, self.cy), (w, self.cy)),
            vertical: angle((self.cx, -0.5), (self.cx, h)),
            diagonal: angle((-0.5, -0.5), (w, h)),
        }
    }

    /// Distortion strength: the largest distance (pixels) between a pixel centre on the image
    /// border and its ideal pinhole position [`Camera::undistort_pixel`]. For barrel
    /// distortion this is reached at a corner. 0 for a pinhole camera.
    pub fn max_distortion_px(&self) -> f64 {
        if self.is_pinhole() {
            return 0.0;
        }
        self.border_pixels(1)
            .into_iter()
            .map(|(u, v)| (self.undistort_pixel(u, v) - Point2::new(u, v)).norm())
            .fold(0.0, f64::max)
    }
}
