//! The bronchoscope camera: OpenCV's pinhole + Brown–Conrady model (k1, k2, p1, p2, k3).
//!
//! Pixel centres are at integer coordinates; camera axes are +x right, +y down, +z forward.

use crate::math::{Point2, Point3, Vector2, Vector3};
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

impl Camera {
    /// True when all distortion coefficients are zero.
    pub fn is_pinhole(&self) -> bool {
        self.k1 == 0.0 && self.k2 == 0.0 && self.p1 == 0.0 && self.p2 == 0.0 && self.k3 == 0.0
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
        let xd = Vector2::new((u - self.cx) / self.fx, (v - self.cy) / self.fy);
        let n = if self.is_pinhole() {
            xd
        } else {
            self.undistort_normalized(xd)
        };
        Vector3::new(n.x, n.y, 1.0).normalize()
    }

    /// Invert [`Camera::distort_normalized`] by Newton iteration on the 2x2 Jacobian
    /// (converges to 1e-12 in normalised units for the field of view of real bronchoscopes).
    pub fn undistort_normalized(&self, xd: Vector2<f64>) -> Vector2<f64> {
        let mut p = xd;
        for _ in 0..50 {
            let (x, y) = (p.x, p.y);
            let r2 = x * x + y * y;
            let radial = 1.0 + r2 * (self.k1 + r2 * (self.k2 + r2 * self.k3));
            let dradial = self.k1 + r2 * (2.0 * self.k2 + 3.0 * r2 * self.k3); // d radial / d r2
            let f = self.distort_normalized(p) - xd;
            // Jacobian of the distortion map.
            let j00 = radial + 2.0 * x * x * dradial + 2.0 * self.p1 * y + 6.0 * self.p2 * x;
            let j01 = 2.0 * x * y * dradial + 2.0 * self.p1 * x + 2.0 * self.p2 * y;
            let j10 = 2.0 * x * y * dradial + 2.0 * self.p1 * x + 2.0 * self.p2 * y;
            let j11 = radial + 2.0 * y * y * dradial + 6.0 * self.p1 * y + 2.0 * self.p2 * x;
            let det = j00 * j11 - j01 * j10;
            if det.abs() < 1e-15 {
                break;
            }
            let step = Vector2::new(
                (j11 * f.x - j01 * f.y) / det,
                (-j10 * f.x + j00 * f.y) / det,
            );
            p -= step;
            if step.norm() < 1e-14 {
                break;
            }
        }
        p
    }
}
