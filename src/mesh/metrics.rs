//! Mesh measurements: counts, edge lengths, manifoldness, enclosed volume, and the deviation of
//! one mesh from another (vertex-to-surface distances through a uniform grid of triangles).

use rayon::prelude::*;

use super::TriMesh;
use crate::math::{Point3, Vector3};

/// Summary numbers of a mesh.
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize)]
pub struct MeshStats {
    /// Number of vertices.
    pub vertices: usize,
    /// Number of triangles.
    pub triangles: usize,
    /// Shortest, mean and longest edge (mm), each undirected edge counted once.
    pub edge_min_mm: f64,
    /// Mean edge length (mm).
    pub edge_mean_mm: f64,
    /// Longest edge (mm).
    pub edge_max_mm: f64,
    /// Edges used by exactly one triangle (where the surface is open).
    pub boundary_edges: usize,
    /// Edges used by more than two triangles (0 for a manifold mesh).
    pub non_manifold_edges: usize,
    /// Total area (mm²).
    pub area_mm2: f64,
}

/// Undirected edge key: smaller vertex id in the high half.
#[inline]
pub(crate) fn edge_key(a: u32, b: u32) -> u64 {
    let (lo, hi) = if a < b { (a, b) } else { (b, a) };
    ((lo as u64) << 32) | hi as u64
}

/// Every triangle edge as (undirected key, triangle index), sorted by key.
pub(crate) fn sorted_edges(mesh: &TriMesh) -> Vec<(u64, u32)> {
    let mut e: Vec<(u64, u32)> = mesh
        .triangles
        .par_iter()
        .enumerate()
        .flat_map_iter(|(t, &[a, b, c])| {
            [
                (edge_key(a, b), t as u32),
                (edge_key(b, c), t as u32),
                (edge_key(c, a), t as u32),
            ]
        })
        .collect();
    e.par_sort_unstable();
    e
}

/// Counts, edge lengths, boundary and non-manifold edges, area.
pub fn mesh_stats(mesh: &TriMesh) -> MeshStats {
    let edges = sorted_edges(mesh);
    let (mut boundary, mut non_manifold, mut n) = (0usize, 0usize, 0usize);
    let (mut lmin, mut lmax, mut lsum) = (f64::INFINITY, 0f64, 0f64);
    let mut i = 0;
    while i < edges.len() {
        let mut j = i + 1;
        while j < edges.len() && edges[j].0 == edges[i].0 {
            j += 1;
        }
        match j - i {
            1 => boundary += 1,
            2 => {}
            _ => non_manifold += 1,
        }
        let k = edges[i].0;
        let (a, b) = ((k >> 32) as usize, (k & 0xffff_ffff) as usize);
        let l = (mesh.positions[a] - mesh.positions[b]).norm() as f64;
        lmin = lmin.min(l);
        lmax = lmax.max(l);
        lsum += l;
        n += 1;
        i = j;
    }
    MeshStats {
        vertices: mesh.positions.len(),
        triangles: mesh.triangles.len(),
        edge_min_mm: if n > 0 { lmin } else { 0.0 },
        edge_mean_mm: if n > 0 { lsum / n as f64 } else { 0.0 },
        edge_max_mm: lmax,
        boundary_edges: boundary,
        non_manifold_edges: non_manifold,
        area_mm2: mesh.area(),
    }
}

/// Signed enclosed volume (mm³) by the divergence theorem: positive when normals face outward,
/// so a closed lumen mesh (normals facing in) gives minus the lumen's volume; the same value on
/// every run, whatever the threads ([`crate::parallel`]).
pub fn signed_volume(mesh: &TriMesh) -> f64 {
    let p = |v: u32| mesh.positions[v as usize].coords.cast::<f64>();
    let block = |r: std::ops::Range<usize>| {
        mesh.triangles[r]
            .iter()
            .map(|&[a, b, c]| p(a).dot(&p(b).cross(&p(c))) / 6.0)
            .sum::<f64>()
    };
    crate::parallel::ordered_block_sum(mesh.triangles.len(), 4096, 0.0, block, |x, y| x + y)
}

/// Distances from the vertices of one mesh to the surface of another (mm).
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize)]
pub struct Deviation {
    /// Mean distance (mm).
    pub mean_mm: f64,
    /// Root mean square distance (mm).
    pub rms_mm: f64,
    /// Largest distance (mm).
    pub max_mm: f64,
}

/// Distance from every vertex of `from` to the nearest point on the triangles of `to`.
pub fn deviation(from: &TriMesh, to: &TriMesh) -> Deviation {
    if from.positions.is_empty() || to.triangles.is_empty() {
        return Deviation::default();
    }
    let grid = TriangleGrid::new(to);
    let d: Vec<f64> = from
        .positions
        .par_iter()
        .map(|p| grid.distance(p))
        .collect();
    let n = d.len() as f64;
    Deviation {
        mean_mm: d.iter().sum::<f64>() / n,
        rms_mm: (d.iter().map(|x| x * x).sum::<f64>() / n).sqrt(),
        max_mm: d.iter().cloned().fold(0.0, f64::max),
    }
}

/// For each distance in `dists_mm`, the fraction of `mesh`'s area lying within that distance
/// (mm) of the surface of `to`, judged at triangle centroids (so triangles should be small
/// next to the distances). All zeros when either mesh is empty.
pub fn area_within(mesh: &TriMesh, to: &TriMesh, dists_mm: &[f64]) -> Vec<f64> {
    let total = mesh.area();
    if total <= 0.0 || to.triangles.is_empty() {
        return vec![0.0; dists_mm.len()];
    }
    let grid = TriangleGrid::new(to);
    let per: Vec<(f64, f64)> = (0..mesh.triangles.len())
        .into_par_iter()
        .map(|t| {
            let [a, b, c] = mesh.triangles[t].map(|v| mesh.positions[v as usize].coords);
            let centroid = Point3::from((a + b + c) / 3.0);
            (
                0.5 * mesh.face_normal(t).norm() as f64,
                grid.distance(&centroid),
            )
        })
        .collect();
    dists_mm
        .iter()
        .map(|&d| {
            per.iter()
                .filter(|(_, x)| *x <= d)
                .map(|(a, _)| a)
                .sum::<f64>()
                / total
        })
        .collect()
}

/// A uniform grid of triangle ids over a mesh's bounding box, for nearest-surface queries.
pub struct TriangleGrid<'a> {
    mesh: &'a TriMesh,
    lo: Vector3<f64>,
    cell: f64,
    dims: [usize; 3],
    /// Start of each cell's run in `ids` (CSR layout), `cells + 1` entries.
    starts: Vec<u32>,
    ids: Vec<u32>,
}

impl<'a> TriangleGrid<'a> {
    /// Bin every triangle of `mesh` into the cells its bounding box overlaps. The cell size is
    /// about twice the mean edge length, capped so the grid has at most ~64 cells per triangle.
    pub fn new(mesh: &'a TriMesh) -> Self {
        let mut lo = Vector3::repeat(f64::INFINITY);
        let mut hi = Vector3::repeat(f64::NEG_INFINITY);
        for p in &mesh.positions {
            let p = p.coords.cast::<f64>();
            lo = lo.inf(&p);
            hi = hi.sup(&p);
        }
        let ext = (hi - lo).map(|v| v.max(1e-6));
        let mean_edge = (2.0 * mesh.area() / mesh.triangles.len().max(1) as f64)
            .sqrt()
            .max(1e-6);
        let mut cell = 2.0 * mean_edge;
        let max_cells = 64.0 * mesh.triangles.len() as f64 + 1.0;
        while (ext.x / cell + 1.0) * (ext.y / cell + 1.0) * (ext.z / cell + 1.0) > max_cells {
            cell *= 1.5;
        }
        let dims = [0, 1, 2].map(|a| (ext[a] / cell) as usize + 1);
        let cell_of =
            |p: &Vector3<f64>, a: usize| (((p[a] - lo[a]) / cell) as usize).min(dims[a] - 1);
        let ranges: Vec<[[usize; 2]; 3]> = mesh
            .triangles
            .iter()
            .map(|t| {
                let ps = t.map(|v| mesh.positions[v as usize].coords.cast::<f64>());
                let tlo = ps[0].inf(&ps[1]).inf(&ps[2]);
                let thi = ps[0].sup(&ps[1]).sup(&ps[2]);
                [0, 1, 2].map(|a| [cell_of(&tlo, a), cell_of(&thi, a)])
            })
            .collect();
        let ncells = dims[0] * dims[1] * dims[2];
        let mut counts = vec![0u32; ncells + 1];
        let each = |r: &[[usize; 2]; 3], f: &mut dyn FnMut(usize)| {
            for z in r[2][0]..=r[2][1] {
                for y in r[1][0]..=r[1][1] {
                    for x in r[0][0]..=r[0][1] {
                        f(x + dims[0] * (y + dims[1] * z));
                    }
                }
            }
        };
        for r in &ranges {
            each(r, &mut |c| counts[c + 1] += 1);
        }
        for c in 0..ncells {
            counts[c + 1] += counts[c];
        }
        let starts = counts.clone();
        let mut ids = vec![0u32; counts[ncells] as usize];
        for (t, r) in ranges.iter().enumerate() {
            each(r, &mut |c| {
                ids[counts[c] as usize] = t as u32;
                counts[c] += 1;
            });
        }
        TriangleGrid {
            mesh,
            lo,
            cell,
            dims,
            starts,
            ids,
        }
    }

    /// Distance (mm) from `p` to the nearest triangle; NaN when `p` is not finite.
    pub fn distance(&self, p: &Point3<f32>) -> f64 {
        let q = p.coords.cast::<f64>();
        if !q.iter().all(|v| v.is_finite()) {
            return f64::NAN;
        }
        // Search rings around the grid cell nearest to p: for a point outside the grid, cells
        // beyond ring r of that cell are still at least r cells away, so the stop rule holds.
        let c = [0, 1, 2].map(|a| {
            (((q[a] - self.lo[a]) / self.cell).floor() as i64).clamp(0, self.dims[a] as i64 - 1)
        });
        let mut best = f64::INFINITY;
        let max_ring = self.dims.iter().map(|&d| d as i64).max().unwrap_or(1);
        for r in 0..=max_ring {
            for z in c[2] - r..=c[2] + r {
                for y in c[1] - r..=c[1] + r {
                    for x in c[0] - r..=c[0] + r {
                        let on_shell =
                            (x - c[0]).abs() == r || (y - c[1]).abs() == r || (z - c[2]).abs() == r;
                        if !on_shell || x < 0 || y < 0 || z < 0 {
                            continue;
                        }
                        let (x, y, z) = (x as usize, y as usize, z as usize);
                        if x >= self.dims[0] || y >= self.dims[1] || z >= self.dims[2] {
                            continue;
                        }
                        let cell = x + self.dims[0] * (y + self.dims[1] * z);
                        for &t in
                            &self.ids[self.starts[cell] as usize..self.starts[cell + 1] as usize]
                        {
                            let tri = self.mesh.triangles[t as usize]
                                .map(|v| self.mesh.positions[v as usize].coords.cast::<f64>());
                            best = best.min(point_triangle_distance(&q, &tri));
                        }
                    }
                }
            }
            // Cells beyond ring r lie at least r cells away from any point of p's cell.
            if best <= r as f64 * self.cell {
                break;
            }
        }
        best
    }
}

/// Euclidean distance from `p` to the triangle `t` (closest-point regions, Ericson §5.1.5).
pub fn point_triangle_distance(p: &Vector3<f64>, t: &[Vector3<f64>; 3]) -> f64 {
    let (a, b, c) = (t[0], t[1], t[2]);
    let (ab, ac, ap) = (b - a, c - a, p - a);
    let (d1, d2) = (ab.dot(&ap), ac.dot(&ap));
    if d1 <= 0.0 && d2 <= 0.0 {
        return ap.norm();
    }
    let bp = p - b;
    let (d3, d4) = (ab.dot(&bp), ac.dot(&bp));
    if d3 >= 0.0 && d4 <= d3 {
        return bp.norm();
    }
    let vc = d1 * d4 - d3 * d2;
    if vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0 {
        let v = d1 / (d1 - d3);
        return (p - (a + ab * v)).norm();
    }
    let cp = p - c;
    let (d5, d6) = (ab.dot(&cp), ac.dot(&cp));
    if d6 >= 0.0 && d5 <= d6 {
        return cp.norm();
    }
    let vb = d5 * d2 - d1 * d6;
    if vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0 {
        let w = d2 / (d2 - d6);
        return (p - (a + ac * w)).norm();
    }
    let va = d3 * d6 - d5 * d4;
    if va <= 0.0 && (d4 - d3) >= 0.0 && (d5 - d6) >= 0.0 {
        let w = (d4 - d3) / ((d4 - d3) + (d5 - d6));
        return (p - (b + (c - b) * w)).norm();
    }
    let denom = va + vb + vc;
    if denom.abs() < 1e-300 {
        // Degenerate triangle: the nearest of its vertices is close enough.
        return ap.norm().min(bp.norm()).min(cp.norm());
    }
    let (v, w) = (vb / denom, vc / denom);
    (p - (a + ab * v + ac * w)).norm()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn tetra() -> TriMesh {
        TriMesh {
            positions: vec![
                Point3::new(0.0, 0.0, 0.0),
                Point3::new(1.0, 0.0, 0.0),
                Point3::new(0.0, 1.0, 0.0),
                Point3::new(0.0, 0.0, 1.0),
            ],
            // Outward-facing.
            triangles: vec![[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]],
        }
    }

    #[test]
    fn tetrahedron_stats_and_volume() {
        let m = tetra();
        let s = mesh_stats(&m);
        assert_eq!(
            (s.triangles, s.boundary_edges, s.non_manifold_edges),
            (4, 0, 0)
        );
        assert!((s.edge_min_mm - 1.0).abs() < 1e-6 && (s.edge_max_mm - 2f64.sqrt()).abs() < 1e-6);
        assert!((signed_volume(&m) - 1.0 / 6.0).abs() < 1e-9);
    }

    #[test]
    fn area_within_counts_triangles_by_their_distance() {
        // Two unit right triangles (area 0.5 each) at heights 0.5 and 3 above the tetrahedron's
        // base face z = 0, beside it in x so the base face is nearest.
        let base = tetra();
        let flat = |z: f32| TriMesh {
            positions: vec![
                Point3::new(0.0, 0.0, z),
                Point3::new(1.0, 0.0, z),
                Point3::new(0.0, 1.0, z),
            ],
            triangles: vec![[0, 1, 2]],
        };
        let (lo, hi) = (flat(-0.5), flat(-3.0));
        let mut both = lo.clone();
        both.positions.extend(hi.positions);
        both.triangles.push([3, 4, 5]);
        let f = area_within(&both, &base, &[0.4, 0.6, 2.9, 3.1]);
        assert_eq!(f, vec![0.0, 0.5, 0.5, 1.0]);
        assert_eq!(area_within(&TriMesh::default(), &base, &[1.0]), vec![0.0]);
    }

    #[test]
    fn grid_distance_matches_brute_force() {
        let m = tetra();
        let grid = TriangleGrid::new(&m);
        let mut rng = crate::rng::SplitMix64::new(12345);
        let mut rnd = || rng.range(-2.0, 2.0);
        for _ in 0..500 {
            let p = Point3::new(rnd() as f32, rnd() as f32, rnd() as f32);
            let q = p.coords.cast::<f64>();
            let brute = m
                .triangles
                .iter()
                .map(|t| {
                    point_triangle_distance(
                        &q,
                        &t.map(|v| m.positions[v as usize].coords.cast::<f64>()),
                    )
                })
                .fold(f64::INFINITY, f64::min);
            assert!((grid.distance(&p) - brute).abs() < 1e-9);
        }
        // Far away and not-a-number queries end (a NaN vertex once made this loop for minutes).
        let far = Point3::new(1e6f32, -2e6, 5e5);
        let brute = m
            .triangles
            .iter()
            .map(|t| {
                point_triangle_distance(
                    &far.coords.cast(),
                    &t.map(|v| m.positions[v as usize].coords.cast::<f64>()),
                )
            })
            .fold(f64::INFINITY, f64::min);
        assert!((grid.distance(&far) - brute).abs() < 1e-6 * brute);
        assert!(grid.distance(&Point3::new(f32::NAN, 0.0, 0.0)).is_nan());
        assert!(grid
            .distance(&Point3::new(f32::INFINITY, 0.0, 0.0))
            .is_nan());
        // A point above the slanted face (1,1,1)/sqrt(3) at distance 1.
        let c = Vector3::new(1.0, 1.0, 1.0) / 3.0;
        let p = c + Vector3::new(1.0, 1.0, 1.0) / 3f64.sqrt();
        assert!(
            (point_triangle_distance(&p, &[Vector3::x(), Vector3::y(), Vector3::z()]) - 1.0).abs()
                < 1e-12
        );
    }
}
