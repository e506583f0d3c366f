//! Taubin λ|μ smoothing: alternating shrink (λ > 0) and inflate (μ < −λ) Laplacian steps remove
//! the staircase and noise of marching cubes without the shrinkage of plain Laplacian smoothing.

use rayon::prelude::*;

use super::metrics::sorted_edges;
use super::TriMesh;
use crate::math::{Point3, Vector3};
use crate::mesh::error::GeometryError;
use crate::Result;

/// Parameters of [`taubin`].
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct TaubinOptions {
    /// Number of λ|μ step pairs.
    pub iterations: usize,
    /// Positive (shrinking) step weight, in (0, 1).
    pub lambda: f32,
    /// Negative (inflating) step weight, with |μ| slightly above λ.
    pub mu: f32,
}

impl Default for TaubinOptions {
    /// λ = 0.5, μ = −0.53 (pass-band k_PB = 1/λ + 1/μ ≈ 0.11), 10 pairs.
    fn default() -> Self {
        TaubinOptions {
            iterations: 10,
            lambda: 0.5,
            mu: -0.53,
        }
    }
}

/// Vertex adjacency in CSR form, plus which vertices lie on the mesh boundary.
struct Adjacency {
    starts: Vec<u32>,
    neighbours: Vec<u32>,
    boundary: Vec<bool>,
}

fn adjacency(mesh: &TriMesh) -> Adjacency {
    let n = mesh.positions.len();
    let edges = sorted_edges(mesh);
    let mut boundary = vec![false; n];
    let mut unique: Vec<(u32, u32)> = Vec::with_capacity(edges.len() / 2 + 1);
    let mut i = 0;
    while i < edges.len() {
        let mut j = i + 1;
        while j < edges.len() && edges[j].0 == edges[i].0 {
            j += 1;
        }
        let (a, b) = ((edges[i].0 >> 32) as u32, edges[i].0 as u32);
        if j - i != 2 {
            // Open or non-manifold edges: their vertices stay put so openings keep their rims.
            boundary[a as usize] = true;
            boundary[b as usize] = true;
        }
        unique.push((a, b));
        i = j;
    }
    let mut starts = vec![0u32; n + 1];
    for &(a, b) in &unique {
        starts[a as usize + 1] += 1;
        starts[b as usize + 1] += 1;
    }
    for v in 0..n {
        starts[v + 1] += starts[v];
    }
    let mut fill = starts.clone();
    let mut neighbours = vec![0u32; starts[n] as usize];
    for &(a, b) in &unique {
        neighbours[fill[a as usize] as usize] = b;
        fill[a as usize] += 1;
        neighbours[fill[b as usize] as usize] = a;
        fill[b as usize] += 1;
    }
    Adjacency {
        starts,
        neighbours,
        boundary,
    }
}

/// Smooth `mesh` in place with Taubin's λ|μ scheme on the uniform (umbrella) Laplacian.
///
/// Boundary vertices (on edges used by one triangle, or by more than two) are kept fixed, so
/// the rims where the airway leaves the CT do not move.
pub fn taubin(mesh: &mut TriMesh, opts: &TaubinOptions) -> Result<()> {
    if !(opts.lambda > 0.0 && opts.lambda < 1.0 && opts.mu < -opts.lambda && opts.mu > -1.0) {
        return Err(GeometryError::BadOptions {
            stage: "Taubin smoothing",
            message: format!(
                "need 0 < lambda < 1 and -1 < mu < -lambda, got lambda {} mu {}",
                opts.lambda, opts.mu
            ),
        }
        .into());
    }
    if let Some(t) = mesh
        .triangles
        .iter()
        .position(|t| t.iter().any(|&v| v as usize >= mesh.positions.len()))
    {
        return Err(GeometryError::VertexIndex {
            stage: "Taubin smoothing",
            triangle: t,
            vertices: mesh.positions.len(),
        }
        .into());
    }
    let adj = adjacency(mesh);
    let mut next = mesh.positions.clone();
    for _ in 0..opts.iterations {
        for w in [opts.lambda, opts.mu] {
            laplacian_step(&adj, &mesh.positions, &mut next, w);
            std::mem::swap(&mut mesh.positions, &mut next);
        }
    }
    Ok(())
}

/// `out[v] = p[v] + w * (mean of neighbours − p[v])` for interior vertices.
fn laplacian_step(adj: &Adjacency, p: &[Point3<f32>], out: &mut [Point3<f32>], w: f32) {
    out.par_iter_mut().enumerate().for_each(|(v, o)| {
        let (s, e) = (adj.starts[v] as usize, adj.starts[v + 1] as usize);
        if adj.boundary[v] || s == e {
            *o = p[v];
            return;
        }
        let mut sum = Vector3::zeros();
        for &u in &adj.neighbours[s..e] {
            sum += p[u as usize].coords;
        }
        let mean = sum / (e - s) as f32;
        *o = p[v] + (mean - p[v].coords) * w;
    });
}
