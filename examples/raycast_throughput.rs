//! Time closest-hit ray casting on the benchmark scene (the same one write_bench_mesh writes)
//! and print one JSON line: build seconds, Mrays/s (wall) and Mrays per CPU-second for camera
//! and random rays. Thread count
//! follows RAYON_NUM_THREADS. With a DIR argument, the hit triangle ids (i32, -1 = miss) are
//! written to DIR/ours_camera.bin and DIR/ours_random.bin so the caller can compare hits.
//!
//! Usage: RAYON_NUM_THREADS=1 cargo run --release --example raycast_throughput -- [DIR] [REPEATS]

#[path = "../tests/common/meshes.rs"]
mod meshes;

use bronchosim::raycast::Scene;
use std::io::Write;
use std::time::Instant;

/// CPU time of all threads of this process (ns), from /proc (Linux); 0 elsewhere. On a shared
/// machine wall time includes waiting for a core; CPU time does not.
fn cpu_ns() -> u64 {
    let Ok(dir) = std::fs::read_dir("/proc/self/task") else {
        return 0;
    };
    dir.filter_map(|e| std::fs::read_to_string(e.ok()?.path().join("schedstat")).ok())
        .filter_map(|s| s.split_whitespace().next()?.parse::<u64>().ok())
        .sum()
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let dir = std::env::args()
        .nth(1)
        .filter(|s| !s.is_empty())
        .map(std::path::PathBuf::from);
    let repeats: usize = std::env::args()
        .nth(2)
        .map(|s| s.parse())
        .transpose()?
        .unwrap_or(5);
    let (mesh, cam, rnd) = meshes::bench_scene();
    let t0 = Instant::now();
    let scene = Scene::new(&mesh)?;
    let build_s = t0.elapsed().as_secs_f64();
    let mut out = Vec::new();
    for (name, rays) in [("camera", &cam), ("random", &rnd)] {
        let mut hits = scene.closest_hits(&rays.origins, &rays.dirs, f32::INFINITY);
        let (mut best, mut best_cpu) = (f64::INFINITY, f64::INFINITY);
        for _ in 0..repeats {
            let (t, c) = (Instant::now(), cpu_ns());
            hits = scene.closest_hits(&rays.origins, &rays.dirs, f32::INFINITY);
            best = best.min(t.elapsed().as_secs_f64());
            best_cpu = best_cpu.min((cpu_ns() - c) as f64 * 1e-9);
        }
        let n_hit = hits.iter().filter(|h| h.is_some()).count();
        let n = rays.dirs.len() as f64;
        out.push(format!(
            "\"{name}_mrays\": {:.4}, \"{name}_mrays_per_cpu_s\": {:.4}, \"{name}_hits\": {n_hit}",
            n / best / 1e6,
            n / best_cpu / 1e6
        ));
        if let Some(d) = &dir {
            let mut w =
                std::io::BufWriter::new(std::fs::File::create(d.join(format!("ours_{name}.bin")))?);
            for h in &hits {
                let id = h.map_or(-1i32, |h| h.tri as i32);
                w.write_all(&id.to_le_bytes())?;
            }
        }
    }
    println!(
        "{{\"threads\": {}, \"triangles\": {}, \"build_s\": {build_s:.4}, {}}}",
        rayon::current_num_threads(),
        mesh.triangles.len(),
        out.join(", ")
    );
    Ok(())
}
