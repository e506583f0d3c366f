//! Time closest-hit ray casting on the benchmark scene (benches/common/phantom_rays.rs, the
//! phantom lumen; written into DIR on first use) and print one JSON line: build seconds, and
//! Mrays/s (wall) and Mrays per CPU-second for the 512x512 camera traced as packets
//! (`camera`, bands of image rows through `Scene::closest_hits_image_rows`, in parallel),
//! the same camera rays one at a time (`camera_single`), and the random rays (`random`). Thread
//! count follows RAYON_NUM_THREADS. The hit triangle ids (i32, -1 = miss) are written to
//! DIR/ours_camera.bin and DIR/ours_random.bin so the caller can compare hits.
//!
//! Usage: RAYON_NUM_THREADS=1 cargo run --release --example raycast_throughput -- DIR [REPEATS]

#[path = "../benches/common/phantom_rays.rs"]
mod phantom_rays;

use bronchosim::raycast::{Hit, Scene};
use rayon::prelude::*;
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
    let dir = std::path::PathBuf::from(std::env::args().nth(1).unwrap_or_else(|| ".".into()));
    let repeats: usize = std::env::args()
        .nth(2)
        .map(|s| s.parse())
        .transpose()?
        .unwrap_or(5);
    let b = phantom_rays::phantom_bench(&dir)?;
    let t0 = Instant::now();
    let scene = Scene::new(&b.mesh)?;
    let build_s = t0.elapsed().as_secs_f64();
    let org = b.camera.origins[0];
    let w = phantom_rays::SIDE;
    let packets = |s: &Scene| {
        let mut out = vec![None; b.camera.dirs.len()];
        out.par_chunks_mut(Scene::TILE_ROWS * w)
            .zip(b.camera.dirs.par_chunks(Scene::TILE_ROWS * w))
            .for_each(|(o, d)| s.closest_hits_image_rows(org, d, w, f32::INFINITY, o));
        out
    };
    type Run<'a> = Box<dyn Fn(&Scene) -> Vec<Option<Hit>> + 'a>;
    let runs: [(&str, Run); 3] = [
        ("camera", Box::new(packets)),
        (
            "camera_single",
            Box::new(|s: &Scene| s.closest_hits(&b.camera.origins, &b.camera.dirs, f32::INFINITY)),
        ),
        (
            "random",
            Box::new(|s: &Scene| s.closest_hits(&b.random.origins, &b.random.dirs, f32::INFINITY)),
        ),
    ];
    let mut out = Vec::new();
    for (name, run) in &runs {
        let mut hits = run(&scene);
        let (mut best, mut best_cpu) = (f64::INFINITY, f64::INFINITY);
        for _ in 0..repeats {
            let (t, c) = (Instant::now(), cpu_ns());
            hits = run(&scene);
            best = best.min(t.elapsed().as_secs_f64());
            best_cpu = best_cpu.min((cpu_ns() - c) as f64 * 1e-9);
        }
        let n_hit = hits.iter().filter(|h| h.is_some()).count();
        let n = hits.len() as f64;
        out.push(format!(
            "\"{name}_mrays\": {:.4}, \"{name}_mrays_per_cpu_s\": {:.4}, \"{name}_hits\": {n_hit}",
            n / best / 1e6,
            n / best_cpu / 1e6
        ));
        if *name != "camera_single" {
            let path = dir.join(format!("ours_{name}.bin"));
            let mut f = std::io::BufWriter::new(std::fs::File::create(path)?);
            for h in &hits {
                let id = h.map_or(-1i32, |h| h.tri as i32);
                f.write_all(&id.to_le_bytes())?;
            }
        }
    }
    println!(
        "{{\"threads\": {}, \"triangles\": {}, \"build_s\": {build_s:.4}, {}}}",
        rayon::current_num_threads(),
        b.mesh.triangles.len(),
        out.join(", ")
    );
    Ok(())
}
