//! The coarse inside-distance field the viewer keeps the camera in the lumen with: the distance
//! (mm) from each voxel of the airway mask to the nearest voxel outside it, on every `stride`-th
//! voxel of the segmentation grid, cropped to the mask's bounding box, quantised to bytes.
//!
//! The lumen mesh lies on or outside the mask's boundary (the CT's wall surface, or the mask's
//! boundary pushed out by 1 mm), so a camera whose interpolated distance stays above a small
//! clearance is inside the mesh.

use crate::math::{Affine, Point3};
use crate::volume::geodesic::inside_distance;
use crate::volume::Volume;

/// Quantisation step of the stored distances (mm): 0.05 mm, so a byte holds 0..12.75 mm, more
/// than the radius of any airway a bronchoscope enters (larger distances saturate, harmless:
/// the camera only needs the field near the wall).
pub const FIELD_STEP_MM: f64 = 0.05;

/// The field, ready to embed.
#[derive(Clone, Debug)]
pub struct LumenField {
    /// Samples along x, y, z.
    pub dims: [usize; 3],
    /// Index → world (mm) of the field's own grid (the mask's affine with the stride and crop).
    pub affine: Affine,
    /// Distance / [`FIELD_STEP_MM`], rounded and saturated, x fastest.
    pub data: Vec<u8>,
}

/// Sample the inside distance of `mask` (nonzero = lumen) on a grid about `spacing_mm` apart
/// (every `stride`-th voxel, stride >= 1), cropped to the mask's bounding box plus one sample.
/// `None` when the mask is empty.
pub fn lumen_field(mask: &Volume<u8>, spacing_mm: f64) -> Option<LumenField> {
    let dims = mask.dims;
    let (mut lo, mut hi) = ([usize::MAX; 3], [0usize; 3]);
    for z in 0..dims[2] {
        for y in 0..dims[1] {
            for x in 0..dims[0] {
                if mask.data[mask.index(x, y, z)] != 0 {
                    for (k, v) in [x, y, z].into_iter().enumerate() {
                        lo[k] = lo[k].min(v);
                        hi[k] = hi[k].max(v);
                    }
                }
            }
        }
    }
    if lo[0] == usize::MAX {
        return None;
    }
    let dist = inside_distance(mask);
    let sp = mask.spacing();
    let min_sp = sp.iter().copied().fold(f64::INFINITY, f64::min);
    let stride = ((spacing_mm / min_sp).floor() as usize).max(1);
    // One sample of zeros beyond the mask on each side, on the stride's lattice.
    let start: [usize; 3] = std::array::from_fn(|k| lo[k].saturating_sub(stride) / stride * stride);
    let n: [usize; 3] = std::array::from_fn(|k| {
        let end = (hi[k] + stride).min(dims[k] - 1);
        (end - start[k]) / stride + 1
    });
    let mut data = Vec::with_capacity(n[0] * n[1] * n[2]);
    for k in 0..n[2] {
        for j in 0..n[1] {
            for i in 0..n[0] {
                let (x, y, z) = (
                    start[0] + i * stride,
                    start[1] + j * stride,
                    start[2] + k * stride,
                );
                let d = dist[mask.index(x, y, z)] as f64 / FIELD_STEP_MM;
                data.push(d.round().clamp(0.0, 255.0) as u8);
            }
        }
    }
    // Field index (i, j, k) is mask voxel start + stride * (i, j, k).
    let mut scale = Affine::identity();
    for k in 0..3 {
        scale[(k, k)] = stride as f64;
        scale[(k, 3)] = start[k] as f64;
    }
    Some(LumenField {
        dims: n,
        affine: mask.affine * scale,
        data,
    })
}

impl LumenField {
    /// Trilinear distance (mm) at world point `p`; 0 outside the grid.
    pub fn distance(&self, p: Point3<f64>) -> f64 {
        let Some(inv) = self.affine.try_inverse() else {
            return 0.0;
        };
        let q = inv.transform_point(&p);
        let idx = [q.x, q.y, q.z];
        if (0..3).any(|k| !(idx[k] >= 0.0 && idx[k] <= (self.dims[k] - 1) as f64)) {
            return 0.0;
        }
        let i0: [usize; 3] =
            std::array::from_fn(|k| (idx[k].floor() as usize).min(self.dims[k].saturating_sub(2)));
        let f: [f64; 3] = std::array::from_fn(|k| idx[k] - i0[k] as f64);
        let at = |i: usize, j: usize, k: usize| {
            let (i, j, k) = (
                (i0[0] + i).min(self.dims[0] - 1),
                (i0[1] + j).min(self.dims[1] - 1),
                (i0[2] + k).min(self.dims[2] - 1),
            );
            self.data[i + self.dims[0] * (j + self.dims[1] * k)] as f64 * FIELD_STEP_MM
        };
        let mut v = 0.0;
        for (dz, wz) in [(0, 1.0 - f[2]), (1, f[2])] {
            for (dy, wy) in [(0, 1.0 - f[1]), (1, f[1])] {
                for (dx, wx) in [(0, 1.0 - f[0]), (1, f[0])] {
                    v += wx * wy * wz * at(dx, dy, dz);
                }
            }
        }
        v
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_tube_keeps_its_radius_and_is_zero_outside() {
        // A tube of radius 4 mm along z on a 0.5 mm grid, off the grid's origin.
        let dims = [40, 40, 30];
        let mut a = Affine::identity();
        for k in 0..3 {
            a[(k, k)] = 0.5;
            a[(k, 3)] = 100.0;
        }
        let mut m = Volume::filled(dims, a, 0u8);
        for z in 2..28 {
            for y in 0..40 {
                for x in 0..40 {
                    let (dx, dy) = (x as f64 * 0.5 - 10.0, y as f64 * 0.5 - 10.0);
                    if (dx * dx + dy * dy).sqrt() <= 4.0 {
                        m.set(x, y, z, 1);
                    }
                }
            }
        }
        let f = lumen_field(&m, 1.0).unwrap();
        // Stride 2 over a 17-voxel-wide tube plus a margin.
        assert!(f.dims[0] <= 12 && f.dims[0] >= 9, "{:?}", f.dims);
        // On the axis about 4 mm (the distance to the first voxel outside), off axis less.
        let centre = f.distance(Point3::new(110.0, 110.0, 107.0));
        assert!((centre - 4.25).abs() < 0.4, "axis {centre}");
        let off = f.distance(Point3::new(112.0, 110.0, 107.0));
        assert!((off - (centre - 2.0)).abs() < 0.4, "2 mm off axis {off}");
        assert_eq!(f.distance(Point3::new(118.0, 110.0, 107.0)), 0.0);
        assert_eq!(f.distance(Point3::new(0.0, 0.0, 0.0)), 0.0);
        assert!(lumen_field(&Volume::filled(dims, a, 0u8), 1.0).is_none());
    }
}
