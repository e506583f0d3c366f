//! Write the ray-casting benchmark scene for bench/raycast_vs_embree.py (see
//! benches/common/phantom_rays.rs): DIR/case (the phantom, whose truth/lumen.ply is the mesh),
//! DIR/rays_camera.bin and DIR/rays_random.bin (little-endian f32, six per ray: origin xyz,
//! unit direction xyz). Prints the mesh path.
//!
//! Usage: cargo run --release --example write_bench_mesh -- DIR

#[path = "../benches/common/phantom_rays.rs"]
mod phantom_rays;

use std::io::Write;

fn write_rays(r: &phantom_rays::BenchRays, path: &std::path::Path) -> std::io::Result<()> {
    let mut w = std::io::BufWriter::new(std::fs::File::create(path)?);
    for (o, d) in r.origins.iter().zip(&r.dirs) {
        for c in o.iter().chain(d.iter()) {
            w.write_all(&c.to_le_bytes())?;
        }
    }
    w.flush()
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let dir = std::path::PathBuf::from(std::env::args().nth(1).unwrap_or_else(|| ".".into()));
    let b = phantom_rays::phantom_bench(&dir)?;
    write_rays(&b.camera, &dir.join("rays_camera.bin"))?;
    write_rays(&b.random, &dir.join("rays_random.bin"))?;
    println!("{}", b.mesh_path.display());
    eprintln!(
        "{} triangles, {} camera rays, {} random rays -> {}",
        b.mesh.triangles.len(),
        b.camera.dirs.len(),
        b.random.dirs.len(),
        dir.display()
    );
    Ok(())
}
