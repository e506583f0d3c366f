//! [`TriMesh`]: an indexed triangle mesh in world mm.

use crate::math::{Point3, Vector3};

/// An indexed triangle mesh. Positions are world mm (RAS+); triangles wind counter-clockwise
/// seen from the side their normal faces, and for the lumen that side is the inside of the airway.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct TriMesh {
    /// Vertex positions (mm).
    pub positions: Vec<Point3<f32>>,
    /// Vertex indices of each triangle.
    pub triangles: Vec<[u32; 3]>,
}

impl TriMesh {
    /// Unnormalised face normal of triangle `t` (length = twice its area, mm²).
    pub fn face_normal(&self, t: usize) -> Vector3<f32> {
        let [a, b, c] = self.triangles[t];
        let (a, b, c) = (
            self.positions[a as usize],
            self.positions[b as usize],
            self.positions[c as usize],
        );
        (b - a).cross(&(c - a))
    }

    /// Area-weighted unit vertex normals.
    pub fn vertex_normals(&self) -> Vec<Vector3<f32>> {
        let mut n = vec![Vector3::zeros(); self.positions.len()];
        for t in 0..self.triangles.len() {
            let f = self.face_normal(t);
            for &v in &self.triangles[t] {
                n[v as usize] += f;
            }
        }
        for v in &mut n {
            let l = v.norm();
            if l > 0.0 {
                *v /= l;
            }
        }
        n
    }

    /// Total surface area (mm²).
    pub fn area(&self) -> f64 {
        (0..self.triangles.len())
            .map(|t| 0.5 * self.face_normal(t).norm() as f64)
            .sum()
    }
}
