//! [`Volume<T>`]: a 3-D voxel grid with its index→world affine.

use super::error::VolumeError;
use crate::math::{transform_point, Affine, Point3};
use crate::Result;

/// A 3-D voxel grid. Voxel `(i, j, k)` is stored at `i + nx * (j + ny * k)` (x fastest, as in
/// NIfTI and DICOM), and its centre lies at `affine * (i, j, k, 1)` in world mm (RAS+).
#[derive(Clone, Debug, PartialEq)]
pub struct Volume<T> {
    /// Grid size (nx, ny, nz) in voxels.
    pub dims: [usize; 3],
    /// Voxel index → world mm (RAS+).
    pub affine: Affine,
    /// Voxel values, x fastest.
    pub data: Vec<T>,
}

impl<T: Copy> Volume<T> {
    /// A volume of `dims` filled with `value`.
    pub fn filled(dims: [usize; 3], affine: Affine, value: T) -> Self {
        Volume {
            dims,
            affine,
            data: vec![value; dims[0] * dims[1] * dims[2]],
        }
    }

    /// Wrap `data` (x fastest); fails when its length is not `nx*ny*nz` or the affine is singular.
    pub fn from_data(dims: [usize; 3], affine: Affine, data: Vec<T>) -> Result<Self> {
        if data.len() != dims[0] * dims[1] * dims[2] {
            return Err(VolumeError::DataLength {
                got: data.len(),
                dims,
            }
            .into());
        }
        if !affine.iter().all(|v| v.is_finite())
            || affine.fixed_view::<3, 3>(0, 0).determinant().abs() < 1e-12
        {
            return Err(VolumeError::SingularAffine.into());
        }
        Ok(Volume { dims, affine, data })
    }

    /// Number of voxels.
    pub fn len(&self) -> usize {
        self.data.len()
    }

    /// True when the grid has no voxels.
    pub fn is_empty(&self) -> bool {
        self.data.is_empty()
    }

    /// Linear index of voxel (i, j, k).
    #[inline]
    pub fn index(&self, i: usize, j: usize, k: usize) -> usize {
        i + self.dims[0] * (j + self.dims[1] * k)
    }

    /// Value at voxel (i, j, k).
    #[inline]
    pub fn get(&self, i: usize, j: usize, k: usize) -> T {
        self.data[self.index(i, j, k)]
    }

    /// Set the value at voxel (i, j, k).
    #[inline]
    pub fn set(&mut self, i: usize, j: usize, k: usize, v: T) {
        let n = self.index(i, j, k);
        self.data[n] = v;
    }

    /// A volume on the same grid with every value mapped by `f`.
    pub fn map<U: Copy>(&self, f: impl Fn(T) -> U) -> Volume<U> {
        Volume {
            dims: self.dims,
            affine: self.affine,
            data: self.data.iter().map(|&v| f(v)).collect(),
        }
    }

    /// World position (mm) of a continuous voxel index.
    pub fn index_to_world(&self, ijk: Point3<f64>) -> Point3<f64> {
        transform_point(&self.affine, &ijk)
    }

    /// Continuous voxel index of a world position (mm).
    pub fn world_to_index(&self, xyz: Point3<f64>) -> Point3<f64> {
        let inv = self
            .affine
            .try_inverse()
            .expect("a volume's affine is invertible");
        transform_point(&inv, &xyz)
    }

    /// The nearest voxel to a world position, or `None` outside the grid.
    pub fn voxel_at_world(&self, xyz: Point3<f64>) -> Option<[usize; 3]> {
        let p = self.world_to_index(xyz);
        let r = [p.x.round(), p.y.round(), p.z.round()];
        if r.iter()
            .zip(self.dims)
            .any(|(&v, n)| !(v >= 0.0 && v < n as f64))
        {
            return None;
        }
        Some([r[0] as usize, r[1] as usize, r[2] as usize])
    }

    /// Voxel spacing (mm) along each grid axis: the lengths of the affine's columns.
    pub fn spacing(&self) -> [f64; 3] {
        let c = |a: usize| self.affine.fixed_view::<3, 1>(0, a).norm();
        [c(0), c(1), c(2)]
    }

    /// World-space axis-aligned bounding box of the voxel centres: (min, max) in mm.
    pub fn world_bounds(&self) -> (Point3<f64>, Point3<f64>) {
        let mut lo = Point3::new(f64::INFINITY, f64::INFINITY, f64::INFINITY);
        let mut hi = Point3::new(f64::NEG_INFINITY, f64::NEG_INFINITY, f64::NEG_INFINITY);
        for c in 0..8 {
            let ijk = Point3::new(
                if c & 1 == 0 {
                    0.0
                } else {
                    self.dims[0].saturating_sub(1) as f64
                },
                if c & 2 == 0 {
                    0.0
                } else {
                    self.dims[1].saturating_sub(1) as f64
                },
                if c & 4 == 0 {
                    0.0
                } else {
                    self.dims[2].saturating_sub(1) as f64
                },
            );
            let w = self.index_to_world(ijk);
            for a in 0..3 {
                lo[a] = lo[a].min(w[a]);
                hi[a] = hi[a].max(w[a]);
            }
        }
        (lo, hi)
    }

    /// Orientation code of the grid axes in world space, e.g. "RAS" or "LPS" (see [`orientation_code`]).
    pub fn orientation(&self) -> String {
        orientation_code(&self.affine)
    }
}

impl Volume<f32> {
    /// Trilinear interpolation at a continuous voxel index; `None` outside the grid.
    pub fn sample_index(&self, p: Point3<f64>) -> Option<f32> {
        let [nx, ny, nz] = self.dims;
        if !(p.x >= 0.0 && p.y >= 0.0 && p.z >= 0.0) {
            return None;
        }
        if p.x > (nx - 1) as f64 || p.y > (ny - 1) as f64 || p.z > (nz - 1) as f64 {
            return None;
        }
        let (i0, j0, k0) = (
            p.x.floor() as usize,
            p.y.floor() as usize,
            p.z.floor() as usize,
        );
        let (i1, j1, k1) = (
            (i0 + 1).min(nx - 1),
            (j0 + 1).min(ny - 1),
            (k0 + 1).min(nz - 1),
        );
        let (fx, fy, fz) = (
            (p.x - i0 as f64) as f32,
            (p.y - j0 as f64) as f32,
            (p.z - k0 as f64) as f32,
        );
        let l = |a: f32, b: f32, t: f32| a + (b - a) * t;
        let c00 = l(self.get(i0, j0, k0), self.get(i1, j0, k0), fx);
        let c10 = l(self.get(i0, j1, k0), self.get(i1, j1, k0), fx);
        let c01 = l(self.get(i0, j0, k1), self.get(i1, j0, k1), fx);
        let c11 = l(self.get(i0, j1, k1), self.get(i1, j1, k1), fx);
        Some(l(l(c00, c10, fy), l(c01, c11, fy), fz))
    }

    /// Trilinear interpolation at a world position (mm); `None` outside the grid.
    pub fn sample_world(&self, xyz: Point3<f64>) -> Option<f32> {
        self.sample_index(self.world_to_index(xyz))
    }
}

/// The orientation code of an index→world affine, as ITK-SNAP and nibabel's `aff2axcodes`
/// write it: for each grid axis, the world direction (R/L, A/P, S/I) it points most along.
pub fn orientation_code(affine: &Affine) -> String {
    const POS: [char; 3] = ['R', 'A', 'S'];
    const NEG: [char; 3] = ['L', 'P', 'I'];
    let mut used = [false; 3];
    let mut code = String::new();
    for a in 0..3 {
        let col = affine.fixed_view::<3, 1>(0, a);
        let mut best = 0;
        let mut best_v = -1.0;
        for w in 0..3 {
            if !used[w] && col[w].abs() > best_v {
                best_v = col[w].abs();
                best = w;
            }
        }
        used[best] = true;
        code.push(if col[best] >= 0.0 {
            POS[best]
        } else {
            NEG[best]
        });
    }
    code
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn world_index_round_trip_through_flipped_oblique_affine() {
        let mut a = Affine::identity();
        let (s, c) = (0.3f64.sin(), 0.3f64.cos());
        a.fixed_view_mut::<3, 3>(0, 0)
            .copy_from(&nalgebra::Matrix3::new(
                -0.7 * c,
                0.7 * s,
                0.0,
                -0.7 * s,
                -0.7 * c,
                0.0,
                0.0,
                0.0,
                2.5,
            ));
        a[(0, 3)] = 120.0;
        a[(1, 3)] = -80.0;
        a[(2, 3)] = -300.0;
        let v = Volume::filled([10, 12, 14], a, 0i16);
        let p = Point3::new(3.25, 7.5, 11.0);
        let w = v.index_to_world(p);
        let back = v.world_to_index(w);
        assert!((back - p).norm() < 1e-9);
        assert_eq!(v.orientation(), "LPS");
        let sp = v.spacing();
        assert!((sp[0] - 0.7).abs() < 1e-12 && (sp[2] - 2.5).abs() < 1e-12);
    }
}
