//! Dev timing: serial closest hits on the bench scene, CPU time from /proc/thread-self/schedstat.
#[path = "../tests/common/meshes.rs"]
mod meshes;
use bronchosim::raycast::Scene;
fn cpu_ns() -> u64 {
    let s = std::fs::read_to_string("/proc/thread-self/schedstat").unwrap();
    s.split_whitespace().next().unwrap().parse().unwrap()
}
fn main() {
    let (mesh, cam, rnd) = meshes::bench_scene();
    let scene = Scene::new(&mesh).unwrap();
    println!("{}", scene.stats());
    if let Ok(s) = std::fs::read_to_string("/proc/self/smaps_rollup") {
        s.lines()
            .filter(|l| l.starts_with("AnonHuge"))
            .for_each(|l| println!("{l}"));
    }
    for (name, r) in [("camera", &cam), ("random", &rnd)] {
        let mut best = f64::INFINITY;
        let mut sum = 0.0f32;
        for _ in 0..5 {
            let t0 = cpu_ns();
            for (o, d) in r.origins.iter().zip(&r.dirs) {
                sum += scene
                    .closest_hit(*o, *d, f32::INFINITY)
                    .map_or(0.0, |h| h.t);
            }
            best = best.min((cpu_ns() - t0) as f64 * 1e-9);
        }
        println!(
            "{name}: {:.3} Mrays/s CPU-time ({sum:.0})",
            r.dirs.len() as f64 / best / 1e6
        );
    }
}
