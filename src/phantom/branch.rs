//! [`Branch`]: one airway branch of the phantom — a tapered tube around a cubic Bézier
//! centreline, with the cartilage-ring relief and optionally a flat back wall — and its signed
//! distance.

use crate::math::{Point3, Vector3};

/// One airway branch: a tapered tube around a cubic Bézier centreline.
#[derive(Clone, Debug)]
pub struct Branch {
    /// Index of this branch in [`AirwayTree::branches`].
    pub id: usize,
    /// The branch it grows from (`None` for the trachea).
    pub parent: Option<usize>,
    /// Generation: 0 trachea, 1 main bronchi, 2 lobar, 3 segmental, ...
    pub generation: u32,
    /// Bézier control points of the centreline (world mm).
    pub control: [Point3<f64>; 4],
    /// Centreline samples from the junction (start) to the tip (world mm).
    pub centreline: Vec<Point3<f64>>,
    /// Arc length (mm) of each centreline sample from the start.
    pub arc_mm: Vec<f64>,
    /// Lumen radius (mm) at each centreline sample, ring relief included.
    pub radii: Vec<f64>,
    /// Lumen radius at the start and at the tip without the ring relief (mm).
    pub radius_start_mm: f64,
    /// Lumen radius at the tip (mm).
    pub radius_end_mm: f64,
    /// Amplitude (mm) and period (mm) of the cartilage-ring relief; amplitude 0 for none.
    pub ring_amplitude_mm: f64,
    /// Period of the cartilage rings along the centreline (mm).
    pub ring_period_mm: f64,
    /// A flat posterior (world -y) wall this fraction of the radius behind the centreline
    /// (the trachea's membranous wall); `None`: round.
    pub posterior_wall: Option<f64>,
    pub(super) bbox_lo: Point3<f64>,
    pub(super) bbox_hi: Point3<f64>,
}

impl Branch {
    /// Centreline length (mm).
    pub fn length_mm(&self) -> f64 {
        *self.arc_mm.last().unwrap_or(&0.0)
    }

    /// Lumen radius (mm) at arc length `s` (mm) from the start, without the ring relief.
    fn base_radius_at(&self, s: f64) -> f64 {
        let t = (s / self.length_mm().max(1e-9)).clamp(0.0, 1.0);
        self.radius_start_mm + (self.radius_end_mm - self.radius_start_mm) * t
    }

    /// Lumen radius (mm) at arc length `s` (mm) from the start.
    pub fn radius_at(&self, s: f64) -> f64 {
        let len = self.length_mm().max(1e-9);
        let base = self.base_radius_at(s);
        if self.ring_amplitude_mm == 0.0 {
            return base;
        }
        // Rings fade out over the last 10 mm so the carina fillet stays smooth.
        let fade = ((len - s) / 10.0).clamp(0.0, 1.0) * (s / 5.0).clamp(0.0, 1.0);
        base + self.ring_amplitude_mm
            * fade
            * (std::f64::consts::TAU * s / self.ring_period_mm).cos()
    }

    /// Smallest lumen diameter along the branch (mm).
    pub fn min_diameter_mm(&self) -> f64 {
        2.0 * self.radii.iter().cloned().fold(f64::INFINITY, f64::min)
    }

    /// Signed distance (mm) to this tube alone: distance to the centreline polyline minus the
    /// radius at the closest point; negative inside.
    pub fn sdf(&self, p: &Point3<f64>) -> f64 {
        let mut best = f64::INFINITY;
        for i in 0..self.centreline.len() - 1 {
            let a = self.centreline[i];
            let ab = self.centreline[i + 1] - a;
            let l2 = ab.norm_squared();
            let t = if l2 > 0.0 {
                ((p - a).dot(&ab) / l2).clamp(0.0, 1.0)
            } else {
                0.0
            };
            let c = a + ab * t;
            let s = self.arc_mm[i] + t * (self.arc_mm[i + 1] - self.arc_mm[i]);
            let mut v = (p - c).norm() - self.radius_at(s);
            if let Some(wall) = self.posterior_wall {
                // The tube cut by the plane of the back wall (the larger of the two distances:
                // their intersection).
                let axis = ab / l2.sqrt().max(1e-12);
                let back = Vector3::new(0.0, -1.0, 0.0);
                let back = (back - axis * back.dot(&axis)).normalize();
                v = v.max((p - c).dot(&back) - wall * self.base_radius_at(s));
            }
            if v < best {
                best = v;
            }
        }
        best
    }

    /// Euclidean distance (mm) from `p` to the branch's bounding box (radius included).
    pub(super) fn bbox_distance(&self, p: &Point3<f64>) -> f64 {
        let mut d2 = 0.0;
        for a in 0..3 {
            let e = (self.bbox_lo[a] - p[a])
                .max(p[a] - self.bbox_hi[a])
                .max(0.0);
            d2 += e * e;
        }
        d2.sqrt()
    }
}
