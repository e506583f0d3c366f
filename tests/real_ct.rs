//! The real chest CT of tests/data/real_ct (1.5 mm, bronchial walls thinner than a voxel):
//! the tree found stays the same, and the lumen mesh is that tree's wall and nothing else —
//! on its segmentation's boundary, one piece, manifold, open only where the airway leaves the
//! CT's grid (issue 17).

use bronchosim::io::nifti::read_nifti;
use bronchosim::math::Point3;
use bronchosim::mesh::lumen::{lumen_mesh, LumenMeshOptions};
use bronchosim::mesh::metrics::{area_within, mesh_stats};
use bronchosim::volume::marching_cubes;
use bronchosim::volume::segment::{segment_airway, SegmentOptions};
use std::collections::HashMap;

#[test]
fn lumen_mesh_is_the_segmented_trees_wall() {
    let path = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/tests/data/real_ct/ct_thorax_1.5mm.nii.gz"
    );
    let ct = read_nifti(path.as_ref()).unwrap();
    let seg = segment_airway(&ct, &SegmentOptions::default()).unwrap();
    let voxels = seg.mask.data.iter().filter(|&&m| m != 0).count();
    println!(
        "seed {:?} ({}), threshold {} HU, {} voxels = {:.2} ml, {} branches",
        seg.seed_voxel,
        if seg.seed_automatic { "auto" } else { "given" },
        seg.threshold_hu,
        voxels,
        seg.volume_ml,
        seg.branch_count
    );
    // The tree found when this test was written (36.9 ml, trachea to segmental bronchi).
    assert!(seg.seed_automatic);
    assert_eq!(seg.seed_voxel, [46, 59, 158]);
    assert_eq!(seg.threshold_hu, -875.0);
    assert_eq!(voxels, 10937);

    let (mesh, report) = lumen_mesh(&ct, &seg.mask, &LumenMeshOptions::default()).unwrap();
    let boundary = marching_cubes(&seg.mask.map(|v| v as f32), 0.5, None).unwrap();
    let within = area_within(&mesh, &boundary, &[1.0, 2.0]);
    let stats = mesh_stats(&mesh);
    println!(
        "mesh {:.0} mm² ({} triangles), mask boundary {:.0} mm²; within 1 mm {:.1}%, 2 mm {:.1}%; \
         marching cubes in {} pieces, largest {:.3}% of the area; boundary edges {}, non-manifold {}",
        stats.area_mm2,
        stats.triangles,
        boundary.area(),
        100.0 * within[0],
        100.0 * within[1],
        report.components.components,
        100.0 * report.components.largest_fraction(),
        stats.boundary_edges,
        stats.non_manifold_edges
    );
    // The CT's iso-surface alone wraps parenchyma here: 63,800 mm², a third within 2 mm.
    assert!(within[1] >= 0.95, "{:.3} within 2 mm", within[1]);
    assert!(within[0] >= 0.9, "{:.3} within 1 mm", within[0]);
    assert!(report.components.largest_fraction() >= 0.99);
    assert!(stats.area_mm2 < 1.5 * boundary.area());
    assert_eq!(stats.non_manifold_edges, 0);

    // One piece: every triangle reachable from the first through shared vertices.
    let (_, pieces) = bronchosim::mesh::components::keep_largest_component(&mesh);
    assert_eq!(pieces.components, 1);

    // Open only on the grid's border: every rim vertex within a voxel of a face of the grid.
    let mut uses: HashMap<(u32, u32), u32> = HashMap::new();
    for t in &mesh.triangles {
        for k in 0..3 {
            let (a, b) = (t[k], t[(k + 1) % 3]);
            *uses.entry((a.min(b), a.max(b))).or_default() += 1;
        }
    }
    let on_border = |v: u32| {
        let p = mesh.positions[v as usize];
        let ijk = ct.world_to_index(Point3::new(p.x as f64, p.y as f64, p.z as f64));
        (0..3).any(|a| ijk[a] < 1.0 || ijk[a] > ct.dims[a] as f64 - 2.0)
    };
    let rims: Vec<(u32, u32)> = uses
        .into_iter()
        .filter(|&(_, n)| n == 1)
        .map(|(e, _)| e)
        .collect();
    assert!(!rims.is_empty(), "the trachea leaves the grid: an open rim");
    let inside = rims
        .iter()
        .filter(|&&(a, b)| !on_border(a) || !on_border(b))
        .count();
    assert_eq!(
        inside,
        0,
        "{inside} of {} rim edges inside the grid",
        rims.len()
    );
}
