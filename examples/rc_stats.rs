//! Dev timing: serial closest hits on the bench scene (single rays and packets of eight),
//! CPU time of this thread from /proc/thread-self/schedstat, so load from other processes
//! does not inflate the figures. Linux only.

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
    for (name, r) in [("camera", &cam), ("random", &rnd)] {
        let n = r.dirs.len() as f64;
        let (mut single, mut packet) = (f64::INFINITY, f64::INFINITY);
        let (mut s1, mut s2) = (0.0f64, 0.0f64);
        for _ in 0..5 {
            let t0 = cpu_ns();
            for (o, d) in r.origins.iter().zip(&r.dirs) {
                s1 += scene.closest_hit(*o, *d, f32::INFINITY).map_or(0.0, |h| h.t as f64);
            }
            single = single.min((cpu_ns() - t0) as f64 * 1e-9);
            let t0 = cpu_ns();
            for (o, d) in r.origins.chunks_exact(8).zip(r.dirs.chunks_exact(8)) {
                let h = scene.closest_hit_packet(o.try_into().unwrap(), d.try_into().unwrap(), f32::INFINITY);
                s2 += h.iter().map(|h| h.map_or(0.0, |h| h.t as f64)).sum::<f64>();
            }
            packet = packet.min((cpu_ns() - t0) as f64 * 1e-9);
        }
        println!(
            "{name}: single {:.3} Mrays/s, packets of 8 {:.3} Mrays/s (CPU time; checksums {s1:.0} {s2:.0})",
            n / single / 1e6,
            n / packet / 1e6
        );
    }
}
