//! Connected pieces of a triangle mesh (triangles joined through shared vertices), and keeping
//! the largest one: the lumen is one surface, and anything else marching cubes finds (noise
//! bubbles inside the airway, specks at the band's edge) is not airway wall.

use super::TriMesh;

/// What [`keep_largest_component`] found and dropped.
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize)]
pub struct ComponentReport {
    /// Connected pieces in the input.
    pub components: usize,
    /// Area of the input (mm²).
    pub area_in_mm2: f64,
    /// Area of the largest piece (mm²), the one kept.
    pub area_kept_mm2: f64,
    /// Triangles dropped (all pieces but the largest).
    pub triangles_dropped: usize,
}

impl ComponentReport {
    /// Fraction of the input's area in its largest piece (1 for an empty mesh).
    pub fn largest_fraction(&self) -> f64 {
        if self.area_in_mm2 > 0.0 {
            self.area_kept_mm2 / self.area_in_mm2
        } else {
            1.0
        }
    }
}

/// Union–find root of `v`, with path halving.
fn find(parent: &mut [u32], mut v: u32) -> u32 {
    while parent[v as usize] != v {
        let g = parent[parent[v as usize] as usize];
        parent[v as usize] = g;
        v = g;
    }
    v
}

/// The piece (a dense label `0..count`) of every triangle, and the number of pieces. Two
/// triangles are in one piece when a chain of shared vertices joins them.
pub fn triangle_components(mesh: &TriMesh) -> (Vec<u32>, usize) {
    let mut parent: Vec<u32> = (0..mesh.positions.len() as u32).collect();
    for t in &mesh.triangles {
        let a = find(&mut parent, t[0]);
        for &v in &t[1..] {
            let b = find(&mut parent, v);
            if a != b {
                // Link to the smaller root: later finds stay short and the result is deterministic.
                let (lo, hi) = if a < b { (a, b) } else { (b, a) };
                parent[hi as usize] = lo;
            }
        }
    }
    let mut label = vec![u32::MAX; mesh.positions.len()];
    let mut count = 0usize;
    let labels = mesh
        .triangles
        .iter()
        .map(|t| {
            let r = find(&mut parent, t[0]) as usize;
            if label[r] == u32::MAX {
                label[r] = count as u32;
                count += 1;
            }
            label[r]
        })
        .collect();
    (labels, count)
}

/// The largest piece of `mesh` by area, with unused vertices removed (vertex order kept).
pub fn keep_largest_component(mesh: &TriMesh) -> (TriMesh, ComponentReport) {
    let (labels, count) = triangle_components(mesh);
    let mut area = vec![0f64; count];
    for (t, &l) in labels.iter().enumerate() {
        area[l as usize] += 0.5 * mesh.face_normal(t).norm() as f64;
    }
    let mut report = ComponentReport {
        components: count,
        area_in_mm2: area.iter().sum(),
        ..Default::default()
    };
    let Some(best) = (0..count).max_by(|&a, &b| area[a].total_cmp(&area[b])) else {
        return (mesh.clone(), report);
    };
    report.area_kept_mm2 = area[best];
    if count == 1 {
        return (mesh.clone(), report);
    }
    let mut new_id = vec![u32::MAX; mesh.positions.len()];
    let mut out = TriMesh::default();
    for (t, &l) in mesh.triangles.iter().zip(&labels) {
        if l as usize != best {
            report.triangles_dropped += 1;
            continue;
        }
        for &v in t {
            if new_id[v as usize] == u32::MAX {
                new_id[v as usize] = 0;
            }
        }
    }
    for (v, id) in new_id.iter_mut().enumerate() {
        if *id == 0 {
            *id = out.positions.len() as u32;
            out.positions.push(mesh.positions[v]);
        }
    }
    out.triangles = mesh
        .triangles
        .iter()
        .zip(&labels)
        .filter(|(_, &l)| l as usize == best)
        .map(|(t, _)| t.map(|v| new_id[v as usize]))
        .collect();
    (out, report)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::math::Point3;

    /// A tetrahedron of edge scale `s` at offset `o`, with vertex ids starting at `base`.
    fn tetra(s: f32, o: f32, base: u32) -> (Vec<Point3<f32>>, Vec<[u32; 3]>) {
        let p = vec![
            Point3::new(o, 0.0, 0.0),
            Point3::new(o + s, 0.0, 0.0),
            Point3::new(o, s, 0.0),
            Point3::new(o, 0.0, s),
        ];
        let t = [[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]]
            .map(|t: [u32; 3]| t.map(|v| v + base))
            .to_vec();
        (p, t)
    }

    #[test]
    fn keeps_the_largest_piece_and_reindexes_it() {
        // Small, large, small: the large one sits in the middle of the vertex array.
        let mut m = TriMesh::default();
        for (k, s) in [0.5f32, 2.0, 0.25].into_iter().enumerate() {
            let (p, t) = tetra(s, 10.0 * k as f32, m.positions.len() as u32);
            m.positions.extend(p);
            m.triangles.extend(t);
        }
        let (kept, rep) = keep_largest_component(&m);
        assert_eq!(rep.components, 3);
        assert_eq!(rep.triangles_dropped, 8);
        assert_eq!(kept.triangles.len(), 4);
        assert_eq!(kept.positions.len(), 4);
        assert_eq!(kept.positions[0], Point3::new(10.0, 0.0, 0.0));
        let large = tetra(2.0, 10.0, 0);
        let large = TriMesh {
            positions: large.0,
            triangles: large.1,
        };
        assert_eq!(kept, large);
        // Areas: each tetrahedron is (3 + sqrt 3)/2 s².
        let unit = (3.0 + 3f64.sqrt()) / 2.0;
        assert!((rep.area_kept_mm2 - 4.0 * unit).abs() < 1e-5);
        assert!((rep.area_in_mm2 - (0.25 + 4.0 + 0.0625) * unit).abs() < 1e-5);
        assert!((rep.largest_fraction() - 4.0 / 4.3125).abs() < 1e-6);
    }

    #[test]
    fn pieces_touching_at_one_vertex_are_one_piece() {
        let (mut p, mut t) = tetra(1.0, 0.0, 0);
        // A second tetrahedron sharing vertex 1 of the first.
        let (p2, t2) = tetra(1.0, 1.0, 4);
        p.extend(p2);
        t.extend(
            t2.into_iter()
                .map(|t| t.map(|v| if v == 4 { 1 } else { v })),
        );
        let m = TriMesh {
            positions: p,
            triangles: t,
        };
        let (labels, count) = triangle_components(&m);
        assert_eq!(count, 1);
        assert!(labels.iter().all(|&l| l == 0));
    }
}
