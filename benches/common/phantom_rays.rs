//! The ray-casting benchmark scene, shared by benches/raycast.rs, examples/write_bench_mesh.rs
//! and examples/raycast_throughput.rs (and through them bench/raycast_vs_embree.py): the
//! phantom's true lumen mesh (`bronchosim phantom`, default seed, 16 frames; CASE/truth/lumen.ply,
//! about 260k triangles), a 512x512 pinhole camera (fx = fy = 256 px, 90 degree field of view)
//! at the pose of frame 4 inside the trachea, and 1M (2^20) incoherent rays: random unit
//! directions from random points inside the lumen (a random point along a random ray from a
//! random frame's camera centre to the wall it sees).
//!
//! Everything is deterministic: the case is written once into `DIR/case` and reused.
//! (Included with `#[path]`, so not every item is used by every includer.)
#![allow(dead_code)]

use bronchosim::io::mesh_export::read_ply;
use bronchosim::io::poses::read_poses;
use bronchosim::mesh::TriMesh;
use bronchosim::phantom::{write_phantom_case, PhantomOptions};
use bronchosim::raycast::Scene;
use bronchosim::rng::SplitMix64;
use std::path::{Path, PathBuf};

/// Rays, origin and unit direction each (world mm).
pub struct BenchRays {
    pub origins: Vec<[f32; 3]>,
    pub dirs: Vec<[f32; 3]>,
}

/// The benchmark scene.
pub struct PhantomBench {
    /// Path of the lumen mesh (CASE/truth/lumen.ply).
    pub mesh_path: PathBuf,
    pub mesh: TriMesh,
    /// Camera-to-world pose of the 512x512 camera (rigid, world mm).
    pub pose: [[f64; 4]; 4],
    /// 512x512 camera rays, row-major pixels.
    pub camera: BenchRays,
    /// 2^20 incoherent rays.
    pub random: BenchRays,
}

/// Camera image side (pixels) and focal length (pixels).
pub const SIDE: usize = 512;
pub const FOCAL: f64 = 256.0;

/// Load (writing it first when `dir/case` does not exist) the benchmark scene.
pub fn phantom_bench(dir: &Path) -> Result<PhantomBench, Box<dyn std::error::Error>> {
    let case = dir.join("case");
    if !case.join("truth").join("lumen.ply").exists() {
        std::fs::create_dir_all(dir)?;
        let opts = PhantomOptions {
            frames: 16,
            force: true,
            ..Default::default()
        };
        write_phantom_case(&case, &opts)?;
    }
    let mesh_path = case.join("truth").join("lumen.ply");
    let mesh = read_ply(&mesh_path)?;
    let poses = read_poses(&case.join("poses.json"), &case)?;
    let m = poses[4.min(poses.len() - 1)].pose.camera_to_world;
    let pose: [[f64; 4]; 4] = std::array::from_fn(|i| std::array::from_fn(|j| m[(i, j)]));
    let org = [0, 1, 2].map(|i| pose[i][3] as f32);
    let mut camera = BenchRays {
        origins: Vec::with_capacity(SIDE * SIDE),
        dirs: Vec::with_capacity(SIDE * SIDE),
    };
    let c = (SIDE as f64 - 1.0) / 2.0;
    for v in 0..SIDE {
        for u in 0..SIDE {
            let d = [(u as f64 - c) / FOCAL, (v as f64 - c) / FOCAL, 1.0];
            let w = [0, 1, 2].map(|i| pose[i][0] * d[0] + pose[i][1] * d[1] + pose[i][2] * d[2]);
            let l = (w[0] * w[0] + w[1] * w[1] + w[2] * w[2]).sqrt();
            camera.origins.push(org);
            camera.dirs.push(w.map(|x| (x / l) as f32));
        }
    }
    let scene = Scene::new(&mesh)?;
    let centres: Vec<[f32; 3]> = poses
        .iter()
        .map(|p| [0, 1, 2].map(|i| p.pose.camera_to_world[(i, 3)] as f32))
        .collect();
    let mut rng = SplitMix64::new(0x5EED);
    let n = 1 << 20;
    let mut random = BenchRays {
        origins: Vec::with_capacity(n),
        dirs: Vec::with_capacity(n),
    };
    while random.dirs.len() < n {
        let c = centres[(rng.next_u64() % centres.len() as u64) as usize];
        let d = rng.unit_vector();
        let Some(h) = scene.closest_hit(c, d, f32::INFINITY) else {
            continue;
        };
        let s = h.t * (0.05 + 0.9 * rng.uniform_f32());
        random
            .origins
            .push([c[0] + s * d[0], c[1] + s * d[1], c[2] + s * d[2]]);
        random.dirs.push(rng.unit_vector());
    }
    Ok(PhantomBench {
        mesh_path,
        mesh,
        pose,
        camera,
        random,
    })
}

/// The benchmark directory: `$BRONCHOSIM_BENCH_DIR`, else `bronchosim-raycast-bench` in the
/// system temporary folder.
pub fn default_dir() -> PathBuf {
    std::env::var_os("BRONCHOSIM_BENCH_DIR")
        .map(PathBuf::from)
        .unwrap_or_else(|| std::env::temp_dir().join("bronchosim-raycast-bench"))
}
