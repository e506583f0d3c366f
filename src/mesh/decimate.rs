//! Decimation to a target edge length with meshoptimizer's edge-collapse simplifier, followed by
//! a manifoldness check and repair (meshopt can leave a few edges shared by three or more
//! triangles where two sheets of the surface come close).

use super::metrics::sorted_edges;
use super::TriMesh;
use crate::math::Point3;
use crate::mesh::error::GeometryError;
use crate::Result;

/// Parameters of [`decimate`].
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct DecimateOptions {
    /// Target edge length (mm): the triangle budget is area / (√3/4 · l²), i.e. equilateral
    /// triangles of this edge.
    pub target_edge_mm: f64,
    /// Largest geometric error a collapse may introduce (mm); stops decimation early where the
    /// surface is too curved for the target edge.
    pub max_error_mm: f64,
    /// Retries with locked vertices before falling back to removing non-manifold triangles.
    pub repair_passes: usize,
}

impl Default for DecimateOptions {
    /// 0.7 mm edges, at most 0.15 mm error per collapse, 4 repair passes.
    fn default() -> Self {
        DecimateOptions {
            target_edge_mm: 0.7,
            max_error_mm: 0.15,
            repair_passes: 4,
        }
    }
}

/// What [`decimate`] did.
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize)]
pub struct DecimateReport {
    /// Triangles before.
    pub triangles_in: usize,
    /// Triangle budget from the area and the target edge.
    pub triangles_target: usize,
    /// Triangles after (and after repair).
    pub triangles_out: usize,
    /// meshopt's own error estimate of the result (mm).
    pub simplifier_error_mm: f64,
    /// Non-manifold edges in the first simplification, before repair.
    pub non_manifold_before_repair: usize,
    /// Vertices locked by the repair passes.
    pub locked_vertices: usize,
    /// Triangles removed by the fallback repair (0 when the locked re-runs sufficed).
    pub triangles_removed: usize,
}

/// Decimate `mesh` toward the target edge length; the result has no edge shared by more than
/// two triangles. Border vertices (where the surface is open) are locked, so openings keep
/// their exact rims.
pub fn decimate(mesh: &TriMesh, opts: &DecimateOptions) -> Result<(TriMesh, DecimateReport)> {
    if !(opts.target_edge_mm > 0.0 && opts.target_edge_mm.is_finite() && opts.max_error_mm > 0.0) {
        return Err(GeometryError::BadOptions {
            stage: "decimation",
            message: format!(
                "target edge {} mm and max error {} mm must be positive",
                opts.target_edge_mm, opts.max_error_mm
            ),
        }
        .into());
    }
    let area = mesh.area();
    let target =
        (area / (3f64.sqrt() / 4.0 * opts.target_edge_mm * opts.target_edge_mm)).round() as usize;
    let mut report = DecimateReport {
        triangles_in: mesh.triangles.len(),
        triangles_target: target,
        ..Default::default()
    };
    let positions: Vec<[f32; 3]> = mesh.positions.iter().map(|p| [p.x, p.y, p.z]).collect();
    let indices: Vec<u32> = mesh.triangles.iter().flatten().copied().collect();
    if target >= mesh.triangles.len() || indices.is_empty() {
        report.triangles_out = mesh.triangles.len();
        return Ok((mesh.clone(), report));
    }
    let mut locks = vec![false; positions.len()];
    let mut out;
    let mut pass = 0;
    loop {
        let mut err = 0f32;
        out = meshopt::simplify_with_locks_decoder(
            &indices,
            &positions,
            &locks,
            3 * target,
            opts.max_error_mm as f32,
            meshopt::SimplifyOptions::LockBorder | meshopt::SimplifyOptions::ErrorAbsolute,
            Some(&mut err),
        );
        report.simplifier_error_mm = err as f64;
        let bad = non_manifold_vertices(&out);
        if pass == 0 {
            report.non_manifold_before_repair = bad.len() / 2;
        }
        if bad.is_empty() || pass == opts.repair_passes {
            break;
        }
        // Lock the offending edges' ends and their one-ring in the input, so no collapse can
        // fold the two sheets onto each other there again.
        for &v in &bad {
            locks[v as usize] = true;
        }
        for t in indices.chunks_exact(3) {
            if t.iter().any(|&v| bad.binary_search(&v).is_ok()) {
                for &v in t {
                    locks[v as usize] = true;
                }
            }
        }
        pass += 1;
    }
    report.locked_vertices = locks.iter().filter(|&&l| l).count();
    let mut tris: Vec<[u32; 3]> = out.chunks_exact(3).map(|t| [t[0], t[1], t[2]]).collect();
    report.triangles_removed = remove_non_manifold(&mut tris);
    let mut flat: Vec<u32> = tris.iter().flatten().copied().collect();
    let compact = meshopt::optimize_vertex_fetch(&mut flat, &positions);
    let result = TriMesh {
        positions: compact
            .iter()
            .map(|p| Point3::new(p[0], p[1], p[2]))
            .collect(),
        triangles: flat.chunks_exact(3).map(|t| [t[0], t[1], t[2]]).collect(),
    };
    report.triangles_out = result.triangles.len();
    Ok((result, report))
}

/// Sorted, deduplicated vertex ids of the edges used by more than two triangles.
fn non_manifold_vertices(indices: &[u32]) -> Vec<u32> {
    let m = TriMesh {
        positions: Vec::new(),
        triangles: indices
            .chunks_exact(3)
            .map(|t| [t[0], t[1], t[2]])
            .collect(),
    };
    let edges = sorted_edges(&m);
    let mut bad = Vec::new();
    let mut i = 0;
    while i < edges.len() {
        let mut j = i + 1;
        while j < edges.len() && edges[j].0 == edges[i].0 {
            j += 1;
        }
        if j - i > 2 {
            bad.push((edges[i].0 >> 32) as u32);
            bad.push(edges[i].0 as u32);
        }
        i = j;
    }
    bad.sort_unstable();
    bad.dedup();
    bad
}

/// Last-resort repair: drop degenerate triangles, every copy of a duplicated triangle (the
/// zero-volume folds meshopt leaves), then every triangle on a remaining non-manifold edge. Returns how many were removed.
fn remove_non_manifold(tris: &mut Vec<[u32; 3]>) -> usize {
    let before = tris.len();
    tris.retain(|t| t[0] != t[1] && t[1] != t[2] && t[2] != t[0]);
    let mut keyed: Vec<([u32; 3], usize)> = tris
        .iter()
        .enumerate()
        .map(|(n, t)| {
            let mut k = *t;
            k.sort_unstable();
            (k, n)
        })
        .collect();
    keyed.sort_unstable();
    let mut drop = vec![false; tris.len()];
    for w in keyed.chunk_by(|a, b| a.0 == b.0) {
        if w.len() > 1 {
            for &(_, n) in w {
                drop[n] = true;
            }
        }
    }
    let mut n = 0;
    tris.retain(|_| {
        n += 1;
        !drop[n - 1]
    });
    loop {
        let m = TriMesh {
            positions: Vec::new(),
            triangles: tris.clone(),
        };
        let edges = sorted_edges(&m);
        let mut bad = vec![false; tris.len()];
        let mut any = false;
        for w in edges.chunk_by(|a, b| a.0 == b.0) {
            if w.len() > 2 {
                any = true;
                for &(_, t) in w {
                    bad[t as usize] = true;
                }
            }
        }
        if !any {
            break;
        }
        let mut n = 0;
        tris.retain(|_| {
            n += 1;
            !bad[n - 1]
        });
    }
    before - tris.len()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn repair_removes_folds_and_fins() {
        // Two triangles on edge 0-1 plus a third "fin" on it, a duplicated (folded) pair, and a
        // degenerate triangle.
        let mut tris = vec![
            [0, 1, 2],
            [1, 0, 3],
            [0, 1, 4],
            [5, 6, 7],
            [7, 6, 5],
            [2, 2, 3],
            [8, 9, 10],
        ];
        assert_eq!(
            non_manifold_vertices(&tris.iter().flatten().copied().collect::<Vec<_>>()),
            vec![0, 1]
        );
        let removed = remove_non_manifold(&mut tris);
        // Degenerate (1) + fold pair (2) + the three triangles on the non-manifold edge (3).
        assert_eq!(removed, 6);
        assert_eq!(tris, vec![[8, 9, 10]]);
    }
}
