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

    /// The mesh with vertices at bit-identical positions merged (a texture atlas splits
    /// vertices along chart seams; merging them back gives normals that are smooth across the
    /// seams). Returns the merged mesh and, for every vertex of `self`, its merged index.
    /// Triangle order is kept.
    pub fn welded(&self) -> (TriMesh, Vec<u32>) {
        let mut first: std::collections::HashMap<[u32; 3], u32> =
            std::collections::HashMap::with_capacity(self.positions.len());
        let mut positions = Vec::new();
        let map: Vec<u32> = self
            .positions
            .iter()
            .map(|p| {
                let key = [p.x.to_bits(), p.y.to_bits(), p.z.to_bits()];
                *first.entry(key).or_insert_with(|| {
                    positions.push(*p);
                    (positions.len() - 1) as u32
                })
            })
            .collect();
        let triangles = self
            .triangles
            .iter()
            .map(|t| t.map(|v| map[v as usize]))
            .collect();
        (
            TriMesh {
                positions,
                triangles,
            },
            map,
        )
    }

    /// Area-weighted unit vertex normals that ignore seams: vertices at the same position get
    /// the same normal (see [`TriMesh::welded`]).
    pub fn seamless_vertex_normals(&self) -> Vec<Vector3<f32>> {
        let (welded, map) = self.welded();
        let n = welded.vertex_normals();
        map.iter().map(|&v| n[v as usize]).collect()
    }

    /// Total surface area (mm²).
    pub fn area(&self) -> f64 {
        (0..self.triangles.len())
            .map(|t| 0.5 * self.face_normal(t).norm() as f64)
            .sum()
    }
}
