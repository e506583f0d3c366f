//! Least-squares conformal maps (Lévy et al. 2002) for one chart, solved with faer's sparse
//! Cholesky on the normal equations, and Sander et al.'s (2001) L2 stretch of the result.

use std::collections::HashMap;

use faer::linalg::solvers::Solve;
use faer::sparse::{SparseColMat, Triplet};
use faer::{Mat, Side};

use crate::math::Vector3;
use crate::mesh::TriMesh;

/// A chart parameterised in the plane, in mm (area-preserving scale).
pub(crate) struct ChartUv {
    /// Mesh faces of the chart.
    pub faces: Vec<u32>,
    /// Mesh vertex id of each chart vertex.
    pub verts: Vec<u32>,
    /// Chart-local vertex indices of each face (same order as `faces`).
    pub tris: Vec<[u32; 3]>,
    /// UV of each chart vertex (mm; total UV area equals total 3-D area).
    pub uv: Vec<[f64; 2]>,
    /// Faces whose UV triangle has non-positive signed area.
    pub flipped: usize,
    /// Sum of 3-D area (mm²).
    pub area: f64,
    /// Sum of L2 stretch weighted by 3-D area.
    pub l2_sum: f64,
    /// Sum of squared L2 stretch weighted by 3-D area.
    pub l2_sq_sum: f64,
    /// Largest per-face L2 stretch.
    pub l2_max: f64,
}

impl ChartUv {
    /// Sander's L2 stretch norm of the chart: RMS of the per-face stretch over 3-D area.
    pub fn l2_norm(&self) -> f64 {
        if self.area > 0.0 {
            (self.l2_sq_sum / self.area).sqrt()
        } else {
            1.0
        }
    }
}

/// Flatten `faces` of `mesh` by LSCM with two pinned vertices (the pair farthest apart, pinned
/// at their projection on the chart's mean plane), then scale so UV area equals 3-D area.
pub(crate) fn lscm(mesh: &TriMesh, faces: &[u32], mean_normal: &Vector3<f64>) -> ChartUv {
    let mut local: HashMap<u32, u32> = HashMap::with_capacity(faces.len());
    let mut verts = Vec::new();
    let tris: Vec<[u32; 3]> = faces
        .iter()
        .map(|&f| {
            mesh.triangles[f as usize].map(|v| {
                *local.entry(v).or_insert_with(|| {
                    verts.push(v);
                    verts.len() as u32 - 1
                })
            })
        })
        .collect();
    let pos: Vec<Vector3<f64>> = verts
        .iter()
        .map(|&v| mesh.positions[v as usize].coords.cast::<f64>())
        .collect();
    let n = verts.len();

    // A frame of the chart's mean plane, for the pins and as the fallback.
    let nrm = *mean_normal;
    let t1 = if nrm.x.abs() < 0.9 {
        Vector3::x().cross(&nrm).normalize()
    } else {
        Vector3::y().cross(&nrm).normalize()
    };
    let t2 = nrm.cross(&t1);
    let project = |p: &Vector3<f64>| [p.dot(&t1), p.dot(&t2)];

    let far = |from: usize| {
        (0..n)
            .max_by(|&a, &b| {
                let da = (pos[a] - pos[from]).norm_squared();
                let db = (pos[b] - pos[from]).norm_squared();
                da.total_cmp(&db)
            })
            .expect("a chart has vertices")
    };
    let pa = far(0);
    let pb = far(pa);
    let mut uv: Vec<[f64; 2]> = pos.iter().map(project).collect();
    if pa != pb && n > 2 {
        if let Some(sol) = solve(&pos, &tris, pa, pb, &uv) {
            uv = sol;
        }
    }
    finish(faces.to_vec(), verts, tris, uv, &pos)
}

/// Solve the LSCM normal equations with vertices `pa`, `pb` pinned at their `uv`.
fn solve(
    pos: &[Vector3<f64>],
    tris: &[[u32; 3]],
    pa: usize,
    pb: usize,
    uv: &[[f64; 2]],
) -> Option<Vec<[f64; 2]>> {
    let n = pos.len();
    // Free-variable index of each vertex (u at 2i, v at 2i+1), NONE for the pins.
    let mut free = vec![usize::MAX; n];
    let mut nf = 0;
    for (v, slot) in free.iter_mut().enumerate() {
        if v != pa && v != pb {
            *slot = nf;
            nf += 1;
        }
    }
    let dim = 2 * nf;
    let mut trip: Vec<Triplet<usize, usize, f64>> = Vec::with_capacity(tris.len() * 42);
    let mut rhs = vec![0.0f64; dim];
    let mut diag_sum = 0.0;
    for t in tris {
        let p = [pos[t[0] as usize], pos[t[1] as usize], pos[t[2] as usize]];
        // Triangle in its own orthonormal frame.
        let e1 = p[1] - p[0];
        let l1 = e1.norm();
        let nrm = e1.cross(&(p[2] - p[0]));
        let d = nrm.norm(); // twice the area
        if l1 == 0.0 || d <= 1e-12 * l1 * l1 {
            continue; // degenerate: no conformality to ask for
        }
        let ex = e1 / l1;
        let ey = (nrm / d).cross(&ex);
        let q: [[f64; 2]; 3] = p.map(|x| [(x - p[0]).dot(&ex), (x - p[0]).dot(&ey)]);
        let s = 1.0 / d.sqrt();
        // W_j = (x_k - x_l) + i (y_k - y_l) for the opposite edge (j, k, l cyclic).
        let mut re = [(0usize, 0.0f64); 6];
        let mut im = [(0usize, 0.0f64); 6];
        for j in 0..3 {
            let (k, l) = ((j + 1) % 3, (j + 2) % 3);
            let a = (q[l][0] - q[k][0]) * s;
            let b = (q[l][1] - q[k][1]) * s;
            let v = t[j] as usize;
            // Re(W U) = a u - b v ; Im(W U) = b u + a v, variables (u_v, v_v).
            re[2 * j] = (v * 2, a);
            re[2 * j + 1] = (v * 2 + 1, -b);
            im[2 * j] = (v * 2, b);
            im[2 * j + 1] = (v * 2 + 1, a);
        }
        for row in [&re, &im] {
            // Known part from the pinned vertices moves to the right-hand side.
            let mut known = 0.0;
            for &(var, c) in row.iter() {
                let v = var / 2;
                if free[v] == usize::MAX {
                    known += c * uv[v][var % 2];
                }
            }
            for &(vi, ci) in row.iter() {
                if free[vi / 2] == usize::MAX {
                    continue;
                }
                let i = 2 * free[vi / 2] + vi % 2;
                rhs[i] -= ci * known;
                for &(vj, cj) in row.iter() {
                    if free[vj / 2] == usize::MAX {
                        continue;
                    }
                    let j = 2 * free[vj / 2] + vj % 2;
                    if i >= j {
                        trip.push(Triplet::new(i, j, ci * cj));
                        if i == j {
                            diag_sum += ci * cj;
                        }
                    }
                }
            }
        }
    }
    if dim == 0 {
        return Some(uv.to_vec());
    }
    // A tiny Tikhonov term keeps vertices touched only by degenerate faces determined.
    let eps = 1e-10 * diag_sum / dim as f64 + 1e-300;
    for i in 0..dim {
        trip.push(Triplet::new(i, i, eps));
    }
    let a = SparseColMat::<usize, f64>::try_new_from_triplets(dim, dim, &trip).ok()?;
    let llt = a.sp_cholesky(Side::Lower).ok()?;
    let mut x = Mat::from_fn(dim, 1, |i, _| rhs[i]);
    llt.solve_in_place(x.as_mut());
    let mut out = uv.to_vec();
    for v in 0..n {
        if free[v] != usize::MAX {
            out[v] = [x[(2 * free[v], 0)], x[(2 * free[v] + 1, 0)]];
        }
    }
    if out.iter().any(|p| !p[0].is_finite() || !p[1].is_finite()) {
        return None;
    }
    Some(out)
}

/// Orient (mirror if needed), scale to equal area and measure flips and stretch.
fn finish(
    faces: Vec<u32>,
    verts: Vec<u32>,
    tris: Vec<[u32; 3]>,
    mut uv: Vec<[f64; 2]>,
    pos: &[Vector3<f64>],
) -> ChartUv {
    let signed = |uv: &[[f64; 2]], t: &[u32; 3]| {
        let (a, b, c) = (uv[t[0] as usize], uv[t[1] as usize], uv[t[2] as usize]);
        0.5 * ((b[0] - a[0]) * (c[1] - a[1]) - (c[0] - a[0]) * (b[1] - a[1]))
    };
    let area3 = |t: &[u32; 3]| {
        let (a, b, c) = (pos[t[0] as usize], pos[t[1] as usize], pos[t[2] as usize]);
        0.5 * (b - a).cross(&(c - a)).norm()
    };
    let uv_area: f64 = tris.iter().map(|t| signed(&uv, t)).sum();
    if uv_area < 0.0 {
        for p in &mut uv {
            p[0] = -p[0];
        }
    }
    let area: f64 = tris.iter().map(area3).sum();
    let scale = if uv_area.abs() > 0.0 && area > 0.0 {
        (area / uv_area.abs()).sqrt()
    } else {
        1.0
    };
    for p in &mut uv {
        p[0] *= scale;
        p[1] *= scale;
    }
    let mut out = ChartUv {
        faces,
        verts,
        tris,
        uv,
        flipped: 0,
        area,
        l2_sum: 0.0,
        l2_sq_sum: 0.0,
        l2_max: 0.0,
    };
    for t in &out.tris {
        let a3 = area3(t);
        let a2 = signed(&out.uv, t);
        if a2 <= 0.0 {
            if a3 > 0.0 {
                out.flipped += 1;
            }
            continue;
        }
        let l2 = l2_stretch(
            [pos[t[0] as usize], pos[t[1] as usize], pos[t[2] as usize]],
            [
                out.uv[t[0] as usize],
                out.uv[t[1] as usize],
                out.uv[t[2] as usize],
            ],
        );
        out.l2_sum += l2 * a3;
        out.l2_sq_sum += l2 * l2 * a3;
        out.l2_max = out.l2_max.max(l2);
    }
    out
}

/// Sander et al.'s L2 stretch of one triangle: sqrt((Γ² + γ²) / 2) for the singular values of the
/// Jacobian of the map UV → 3-D; 1 for an isometry. `uv` in mm, positively oriented.
pub(crate) fn l2_stretch(q: [Vector3<f64>; 3], uv: [[f64; 2]; 3]) -> f64 {
    let [(s1, t1), (s2, t2), (s3, t3)] = uv.map(|p| (p[0], p[1]));
    let a2 = ((s2 - s1) * (t3 - t1) - (s3 - s1) * (t2 - t1)) / 2.0;
    let ss = (q[0] * (t2 - t3) + q[1] * (t3 - t1) + q[2] * (t1 - t2)) / (2.0 * a2);
    let st = (q[0] * (s3 - s2) + q[1] * (s1 - s3) + q[2] * (s2 - s1)) / (2.0 * a2);
    ((ss.norm_squared() + st.norm_squared()) / 2.0).sqrt()
}
