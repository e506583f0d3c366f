//! A synthetic airway lumen for atlas tests and benchmarks: the zero level set of a smooth union
//! of capsules (trachea, two main bronchi, four lobar bronchi), triangulated by marching
//! tetrahedra (six Kuhn tetrahedra per cube, so the surface is watertight and manifold).

#![allow(dead_code)]

use std::collections::HashMap;

use bronchosim::math::Point3;
use bronchosim::mesh::TriMesh;
use rayon::prelude::*;

/// Branch segments (mm) and radii (mm): a trachea, a bifurcation and a second generation.
const SEGMENTS: [([f32; 3], [f32; 3], f32); 7] = [
    ([0.0, 0.0, 50.0], [0.0, 0.0, 0.0], 8.0),
    ([0.0, 0.0, 0.0], [-20.0, 0.0, -30.0], 6.0),
    ([0.0, 0.0, 0.0], [18.0, 2.0, -25.0], 6.5),
    ([-20.0, 0.0, -30.0], [-30.0, 5.0, -50.0], 4.0),
    ([-20.0, 0.0, -30.0], [-14.0, -5.0, -50.0], 4.0),
    ([18.0, 2.0, -25.0], [30.0, -5.0, -45.0], 4.5),
    ([18.0, 2.0, -25.0], [20.0, 8.0, -48.0], 4.0),
];

/// Smooth-union blending width (mm): rounds the carinas like real bifurcations.
const BLEND: f32 = 3.0;

fn capsule(p: [f32; 3], a: [f32; 3], b: [f32; 3], r: f32) -> f32 {
    let ab = [b[0] - a[0], b[1] - a[1], b[2] - a[2]];
    let ap = [p[0] - a[0], p[1] - a[1], p[2] - a[2]];
    let t = ((ap[0] * ab[0] + ap[1] * ab[1] + ap[2] * ab[2])
        / (ab[0] * ab[0] + ab[1] * ab[1] + ab[2] * ab[2]))
        .clamp(0.0, 1.0);
    let d = [ap[0] - t * ab[0], ap[1] - t * ab[1], ap[2] - t * ab[2]];
    (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt() - r
}

/// Signed distance-like field of the airway lumen (negative inside the air).
pub fn airway_sdf(p: [f32; 3]) -> f32 {
    let mut d = f32::INFINITY;
    for (a, b, r) in SEGMENTS {
        let e = capsule(p, a, b, r);
        // Polynomial smooth minimum.
        let h = (0.5 + 0.5 * (e - d) / BLEND).clamp(0.0, 1.0);
        d = if d.is_infinite() {
            e
        } else {
            e * (1.0 - h) + d * h - BLEND * h * (1.0 - h)
        };
    }
    d
}

/// The airway lumen triangulated on a grid of spacing `h` (mm). Triangles face into the air.
pub fn airway_mesh(h: f32) -> TriMesh {
    marching_tetrahedra(&airway_sdf, [-40.0, -16.0, -60.0], [42.0, 18.0, 62.0], h)
}

/// Marching tetrahedra of `f` on the box `lo`..`hi` with spacing `h`; normals point to f < 0.
pub fn marching_tetrahedra(
    f: &(dyn Fn([f32; 3]) -> f32 + Sync),
    lo: [f32; 3],
    hi: [f32; 3],
    h: f32,
) -> TriMesh {
    let n = [0, 1, 2].map(|k| ((hi[k] - lo[k]) / h).ceil() as usize + 1);
    let at = |i: usize, j: usize, k: usize| {
        [
            lo[0] + i as f32 * h,
            lo[1] + j as f32 * h,
            lo[2] + k as f32 * h,
        ]
    };
    let values: Vec<f32> = (0..n[0] * n[1] * n[2])
        .into_par_iter()
        .map(|id| {
            let (i, j, k) = (id % n[0], (id / n[0]) % n[1], id / (n[0] * n[1]));
            f(at(i, j, k))
        })
        .collect();
    let id = |i: usize, j: usize, k: usize| (k * n[1] + j) * n[0] + i;
    // Kuhn decomposition: the six monotone paths from corner 0 to corner 7 (bit 0 = x, 1 = y, 2 = z).
    const TETS: [[usize; 4]; 6] = [
        [0, 1, 3, 7],
        [0, 1, 5, 7],
        [0, 2, 3, 7],
        [0, 2, 6, 7],
        [0, 4, 5, 7],
        [0, 4, 6, 7],
    ];
    let mut verts: HashMap<(usize, usize), u32> = HashMap::new();
    let mut positions: Vec<Point3<f32>> = Vec::new();
    let mut triangles: Vec<[u32; 3]> = Vec::new();
    let mut vertex = |a: usize, b: usize, positions: &mut Vec<Point3<f32>>| -> u32 {
        let key = (a.min(b), a.max(b));
        *verts.entry(key).or_insert_with(|| {
            let (fa, fb) = (values[key.0], values[key.1]);
            // Clamped so no vertex sits on a grid point (which would make slivers of zero area).
            let t = (fa / (fa - fb)).clamp(0.02, 0.98);
            let pos = |g: usize| at(g % n[0], (g / n[0]) % n[1], g / (n[0] * n[1]));
            let (pa, pb) = (pos(key.0), pos(key.1));
            positions.push(Point3::new(
                pa[0] + t * (pb[0] - pa[0]),
                pa[1] + t * (pb[1] - pa[1]),
                pa[2] + t * (pb[2] - pa[2]),
            ));
            positions.len() as u32 - 1
        })
    };
    for k in 0..n[2] - 1 {
        for j in 0..n[1] - 1 {
            for i in 0..n[0] - 1 {
                let corner = |c: usize| id(i + (c & 1), j + ((c >> 1) & 1), k + ((c >> 2) & 1));
                let cs: [usize; 8] = std::array::from_fn(corner);
                let inside = cs.map(|g| values[g] < 0.0);
                if inside.iter().all(|&b| b) || inside.iter().all(|&b| !b) {
                    continue;
                }
                for tet in TETS {
                    let g = tet.map(|c| cs[c]);
                    let ins: Vec<usize> = g.iter().copied().filter(|&x| values[x] < 0.0).collect();
                    let out: Vec<usize> = g.iter().copied().filter(|&x| values[x] >= 0.0).collect();
                    let polys: Vec<Vec<u32>> = match ins.len() {
                        1 => vec![out
                            .iter()
                            .map(|&o| vertex(ins[0], o, &mut positions))
                            .collect()],
                        3 => vec![ins
                            .iter()
                            .map(|&i| vertex(i, out[0], &mut positions))
                            .collect()],
                        2 => vec![vec![
                            vertex(ins[0], out[0], &mut positions),
                            vertex(ins[0], out[1], &mut positions),
                            vertex(ins[1], out[1], &mut positions),
                            vertex(ins[1], out[0], &mut positions),
                        ]],
                        _ => continue,
                    };
                    // Orient toward the inside corners' side.
                    let mean = |s: &[usize]| {
                        let mut m = [0.0f32; 3];
                        for &x in s {
                            let p = at(x % n[0], (x / n[0]) % n[1], x / (n[0] * n[1]));
                            for a in 0..3 {
                                m[a] += p[a] / s.len() as f32;
                            }
                        }
                        m
                    };
                    let (mi, mo) = (mean(&ins), mean(&out));
                    let dir = [mi[0] - mo[0], mi[1] - mo[1], mi[2] - mo[2]];
                    for poly in polys {
                        let fan: Vec<[u32; 3]> = (1..poly.len() - 1)
                            .map(|q| [poly[0], poly[q], poly[q + 1]])
                            .collect();
                        for mut t in fan {
                            let p = t.map(|v| positions[v as usize]);
                            let nrm = (p[1] - p[0]).cross(&(p[2] - p[0]));
                            if nrm.x * dir[0] + nrm.y * dir[1] + nrm.z * dir[2] < 0.0 {
                                t.swap(1, 2);
                            }
                            triangles.push(t);
                        }
                    }
                }
            }
        }
    }
    TriMesh {
        positions,
        triangles,
    }
}
