//! The true lumen surface as a triangle mesh (normals into the lumen).
//!
//! Built-in tree: marching cubes at level 0 of the lumen SDF sampled on a fine axis-aligned
//! grid. Sampling is narrow-band: 16³ blocks, then 4³ blocks, are classified by the SDF at
//! their centre, and only voxels of blocks the surface may cross are evaluated exactly (the
//! SDF is close to 1-Lipschitz; the test keeps a 1.5x margin for the ring relief's slope).
//! Real mask: marching cubes at 0.5 of the Gaussian-blurred mask, Taubin-smoothed.
//! Either result is decimated when it has more than a triangle budget.

use super::anatomy::AirwayTree;
use crate::math::{Affine, Point3};
use crate::mesh::decimate::{decimate, DecimateOptions};
use crate::mesh::smooth::{taubin, TaubinOptions};
use crate::mesh::TriMesh;
use crate::volume::{marching_cubes, Volume};
use crate::Result;
use rayon::prelude::*;

/// Sample the tree's lumen SDF (mm, negative inside) on an axis-aligned grid of spacing `h`
/// (mm) covering the tree plus 2 mm, cut at `top_z` (world mm) where the CT ends.
pub fn sample_tree_sdf(tree: &AirwayTree, h: f64, top_z: f64) -> Result<Volume<f32>> {
    let (lo, hi) = tree.bounds();
    let lo = lo - crate::math::Vector3::new(2.0, 2.0, 2.0);
    let hi = Point3::new(hi.x + 2.0, hi.y + 2.0, (hi.z + 2.0).min(top_z));
    let dims = [0, 1, 2].map(|a| ((hi[a] - lo[a]) / h).ceil() as usize + 1);
    let [nx, ny, nz] = dims;
    let mut affine = Affine::identity();
    for a in 0..3 {
        affine[(a, a)] = h;
        affine[(a, 3)] = lo[a];
    }
    let world = |i: f64, j: f64, k: f64| Point3::new(lo.x + i * h, lo.y + j * h, lo.z + k * h);
    // Classify blocks of `b` voxels: Some(value) when the whole block has that sign.
    // parent: (the coarser classification, its block size, its block-grid dims).
    type Parent<'a> = Option<(&'a [Option<f32>], usize, [usize; 3])>;
    let classify = |b: usize, parent: Parent| {
        let bd = dims.map(|d| d.div_ceil(b));
        (0..bd[0] * bd[1] * bd[2])
            .into_par_iter()
            .map(|q| {
                let bi = [q % bd[0], (q / bd[0]) % bd[1], q / (bd[0] * bd[1])];
                if let Some((pc, pb, pd)) = parent {
                    let pi = bi.map(|x| x * b / pb);
                    if let Some(v) = pc[pi[0] + pd[0] * (pi[1] + pd[1] * pi[2])] {
                        return Some(v);
                    }
                }
                let c = world(
                    (bi[0] * b) as f64 + (b as f64 - 1.0) / 2.0,
                    (bi[1] * b) as f64 + (b as f64 - 1.0) / 2.0,
                    (bi[2] * b) as f64 + (b as f64 - 1.0) / 2.0,
                );
                let d = tree.lumen_sdf(c);
                let reach = 1.5 * 0.5 * 3f64.sqrt() * b as f64 * h + 0.3;
                (d.abs() > reach).then_some(d.signum() as f32 * (d.abs() - reach).max(0.5) as f32)
            })
            .collect::<Vec<_>>()
    };
    let coarse = classify(16, None);
    let cd = dims.map(|d| d.div_ceil(16));
    let fine = classify(4, Some((&coarse[..], 16, cd)));
    let fd = dims.map(|d| d.div_ceil(4));
    let mut data = vec![0f32; nx * ny * nz];
    data.par_chunks_mut(nx * ny)
        .enumerate()
        .for_each(|(k, slice)| {
            for bj in 0..fd[1] {
                for bi in 0..fd[0] {
                    let cls = fine[bi + fd[0] * (bj + fd[1] * (k / 4))];
                    let (i0, j0) = (bi * 4, bj * 4);
                    let (i1, j1) = ((i0 + 4).min(nx), (j0 + 4).min(ny));
                    if let Some(v) = cls {
                        for j in j0..j1 {
                            slice[j * nx + i0..j * nx + i1].fill(v);
                        }
                        continue;
                    }
                    let a = world(i0 as f64, j0 as f64, k as f64);
                    let b = world((i1 - 1) as f64, (j1 - 1) as f64, k as f64);
                    let cands = tree.branches_near(&a, &b, 4.0 + tree.junction_smoothing_mm);
                    for j in j0..j1 {
                        for i in i0..i1 {
                            let p = world(i as f64, j as f64, k as f64);
                            slice[j * nx + i] = tree.sdf_among(&p, cands.iter().copied()) as f32;
                        }
                    }
                }
            }
        });
    Volume::from_data(dims, affine, data)
}

/// Truth mesh of the built-in tree: marching cubes of [`sample_tree_sdf`] at level 0.
pub fn tree_truth_mesh(
    tree: &AirwayTree,
    h: f64,
    top_z: f64,
    max_triangles: usize,
) -> Result<TriMesh> {
    let sdf = sample_tree_sdf(tree, h, top_z)?;
    let mesh = marching_cubes(&sdf, 0.0, None)?;
    limit_triangles(mesh, max_triangles)
}

/// Truth mesh of a binary lumen mask: blur (σ = 0.7 voxel), marching cubes at one half,
/// 10 Taubin steps.
pub fn mask_truth_mesh(mask: &Volume<u8>, max_triangles: usize) -> Result<TriMesh> {
    // Values below the level are inside for marching cubes: use 1 - mask.
    let mut v = mask.map(|m| if m != 0 { 0.0f32 } else { 1.0 });
    crate::volume::filter::gaussian_blur(&mut v, [0.7; 3]);
    let mut mesh = marching_cubes(&v, 0.5, None)?;
    taubin(&mut mesh, &TaubinOptions::default())?;
    limit_triangles(mesh, max_triangles)
}

/// Decimate to about `max_triangles` when the mesh is larger.
fn limit_triangles(mesh: TriMesh, max_triangles: usize) -> Result<TriMesh> {
    if mesh.triangles.len() <= max_triangles {
        return Ok(mesh);
    }
    // Equilateral triangles of edge l cover √3/4 l² each.
    let edge = (mesh.area() / (max_triangles as f64 * 3f64.sqrt() / 4.0)).sqrt();
    let (m, _) = decimate(
        &mesh,
        &DecimateOptions {
            target_edge_mm: edge,
            max_error_mm: 0.05,
            ..Default::default()
        },
    )?;
    Ok(m)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mesh::metrics::mesh_stats;
    use crate::phantom::anatomy::TreeOptions;

    #[test]
    fn narrow_band_sdf_matches_the_exact_sdf_near_the_surface() {
        let tree = AirwayTree::new(&TreeOptions {
            generations: 2,
            ..Default::default()
        });
        let top = tree.branches[0].control[0].z - 5.0;
        let v = sample_tree_sdf(&tree, 0.6, top).unwrap();
        let mut checked = 0;
        for q in (0..v.len()).step_by(97) {
            let ijk = [
                q % v.dims[0],
                (q / v.dims[0]) % v.dims[1],
                q / (v.dims[0] * v.dims[1]),
            ];
            let p = v.index_to_world(Point3::new(ijk[0] as f64, ijk[1] as f64, ijk[2] as f64));
            let d = tree.lumen_sdf(p) as f32;
            let s = v.data[q];
            assert_eq!(d > 0.0, s > 0.0, "sign at {p:?}: exact {d}, sampled {s}");
            if d.abs() < 1.0 {
                assert!((d - s).abs() < 1e-4);
                checked += 1;
            }
        }
        assert!(checked > 100, "{checked}");
        let mesh = marching_cubes(&v, 0.0, None).unwrap();
        let st = mesh_stats(&mesh);
        assert_eq!(st.non_manifold_edges, 0);
        // Open only where the trachea leaves the grid at the top.
        assert!(st.boundary_edges > 0 && st.boundary_edges < 400, "{st:?}");
    }
}
