//! Write the ray-casting benchmark scene for bench/raycast_vs_embree.py:
//! DIR/mesh.ply (binary PLY) and DIR/rays_camera.bin, DIR/rays_random.bin (little-endian f32,
//! six per ray: origin xyz, unit direction xyz).
//!
//! Usage: cargo run --release --example write_bench_mesh -- DIR

#[path = "../tests/common/meshes.rs"]
mod meshes;

use std::io::Write;

fn write_rays(r: &meshes::BenchRays, path: &std::path::Path) -> std::io::Result<()> {
    let mut w = std::io::BufWriter::new(std::fs::File::create(path)?);
    for (o, d) in r.origins.iter().zip(&r.dirs) {
        for c in o.iter().chain(d.iter()) {
            w.write_all(&c.to_le_bytes())?;
        }
    }
    w.flush()
}

fn main() -> std::io::Result<()> {
    let dir = std::path::PathBuf::from(std::env::args().nth(1).unwrap_or_else(|| ".".into()));
    std::fs::create_dir_all(&dir)?;
    let (mesh, cam, rnd) = meshes::bench_scene();
    meshes::write_ply(&mesh, &dir.join("mesh.ply"))?;
    write_rays(&cam, &dir.join("rays_camera.bin"))?;
    write_rays(&rnd, &dir.join("rays_random.bin"))?;
    println!(
        "{} triangles, {} camera rays, {} random rays -> {}",
        mesh.triangles.len(),
        cam.dirs.len(),
        rnd.dirs.len(),
        dir.display()
    );
    Ok(())
}
