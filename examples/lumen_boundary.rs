//! How much of a lumen mesh is the airway wall: the fraction of its area within 1 and 2 mm of
//! the segmentation's boundary (the marching-cubes surface of the mask at 0.5), its connected
//! pieces and its manifoldness.
//!
//! Usage:
//!   lumen_boundary SEGMENT_DIR   measure the output of `bronchosim segment` (lumen.ply +
//!                                segmentation.nii.gz), e.g. one written by another build
//!   lumen_boundary CT.nii.gz     segment and mesh the CT here (default options), then measure

use bronchosim::io::ct::{read_ct, CtSource};
use bronchosim::io::mesh_export::read_ply;
use bronchosim::io::nifti::read_nifti;
use bronchosim::mesh::components::keep_largest_component;
use bronchosim::mesh::lumen::{lumen_mesh, LumenMeshOptions};
use bronchosim::mesh::metrics::{area_within, mesh_stats};
use bronchosim::volume::marching_cubes;
use bronchosim::volume::segment::{segment_airway, SegmentOptions};
use std::path::Path;
use std::time::Instant;

fn main() -> anyhow::Result<()> {
    let arg = std::env::args()
        .nth(1)
        .ok_or_else(|| anyhow::anyhow!("usage: lumen_boundary SEGMENT_DIR | CT.nii.gz"))?;
    let path = Path::new(&arg);
    let (mesh, mask) = if path.is_dir() {
        let mask = read_nifti(&path.join("segmentation.nii.gz"))?.map(|v| u8::from(v > 0.5));
        (read_ply(&path.join("lumen.ply"))?, mask)
    } else {
        let (ct, _) = read_ct(&CtSource::Nifti(path.to_path_buf()))?;
        let t = Instant::now();
        let seg = segment_airway(&ct, &SegmentOptions::default())?;
        let t_seg = t.elapsed().as_secs_f64();
        let t = Instant::now();
        let (mesh, report) = lumen_mesh(&ct, &seg.mask, &LumenMeshOptions::default())?;
        println!(
            "segment   seed voxel {:?}, threshold {} HU, {:.2} ml, {} branches ({t_seg:.2} s)",
            seg.seed_voxel, seg.threshold_hu, seg.volume_ml, seg.branch_count
        );
        println!(
            "mesh      {:.2} s; marching cubes {} triangles in {} pieces, largest {:.2}% of the area",
            t.elapsed().as_secs_f64(),
            report.marching_cubes.triangles,
            report.components.components,
            100.0 * report.components.largest_fraction()
        );
        (mesh, seg.mask)
    };
    let boundary = marching_cubes(&mask.map(|v| v as f32), 0.5, None)?;
    let within = area_within(&mesh, &boundary, &[1.0, 2.0]);
    let stats = mesh_stats(&mesh);
    let (_, pieces) = keep_largest_component(&mesh);
    println!(
        "lumen     {:.0} mm², {} triangles; mask boundary {:.0} mm²",
        stats.area_mm2,
        stats.triangles,
        boundary.area()
    );
    println!(
        "within    1 mm: {:.1}%   2 mm: {:.1}% of the area",
        100.0 * within[0],
        100.0 * within[1]
    );
    println!(
        "pieces    {} (largest {:.2}% of the area); boundary edges {}, non-manifold edges {}",
        pieces.components,
        100.0 * pieces.largest_fraction(),
        stats.boundary_edges,
        stats.non_manifold_edges
    );
    Ok(())
}
