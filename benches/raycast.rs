//! Ray casting on the phantom lumen (benches/common/phantom_rays.rs: `bronchosim phantom`'s
//! truth/lumen.ply, about 260k triangles, written on first use into $BRONCHOSIM_BENCH_DIR or
//! the temporary folder): BVH build, closest hits for a 512x512 camera inside the trachea
//! (as packets of 4x4 pixels, and one ray at a time) and for 2^20 incoherent rays, and a
//! full G-buffer frame from the same pose, and its depth plane alone. Threads follow RAYON_NUM_THREADS. Throughput is
//! reported in rays (elements) per second.

#[path = "common/phantom_rays.rs"]
mod phantom_rays;

use bronchosim::camera::Camera;
use bronchosim::math::Affine;
use bronchosim::raycast::{cast_depth_with, cast_frame_with, RayTable, Scene};
use criterion::{criterion_group, criterion_main, Criterion, Throughput};
use rayon::prelude::*;
use std::hint::black_box;

fn bench(c: &mut Criterion) {
    let b = phantom_rays::phantom_bench(&phantom_rays::default_dir()).unwrap();
    let (cam, rnd) = (&b.camera, &b.random);
    let mut g = c.benchmark_group("raycast");
    g.sample_size(10);
    g.bench_function("build_phantom", |bch| {
        bch.iter(|| Scene::new(black_box(&b.mesh)).unwrap())
    });
    let side = phantom_rays::SIDE;
    for (name, scene) in [
        ("", Scene::new(&b.mesh).unwrap()),
        ("_bvh4", Scene::new_four_wide(&b.mesh).unwrap()),
    ] {
        g.throughput(Throughput::Elements(cam.dirs.len() as u64));
        g.bench_function(format!("closest_camera_512_packets{name}"), |bch| {
            let mut out = vec![None; cam.dirs.len()];
            bch.iter(|| {
                out.par_chunks_mut(Scene::TILE_ROWS * side)
                    .zip(cam.dirs.par_chunks(Scene::TILE_ROWS * side))
                    .for_each(|(o, d)| {
                        scene.closest_hits_image_rows(cam.origins[0], d, side, f32::INFINITY, o)
                    })
            })
        });
        for (rays_name, rays) in [("camera_512_single", cam), ("random_1m", rnd)] {
            g.throughput(Throughput::Elements(rays.dirs.len() as u64));
            g.bench_function(format!("closest_{rays_name}{name}"), |bch| {
                bch.iter(|| scene.closest_hits(&rays.origins, &rays.dirs, f32::INFINITY))
            });
        }
    }
    // A whole G-buffer frame (normals, gamma, points) from the same pose, 512x512 pinhole.
    let scene = Scene::new(&b.mesh).unwrap();
    let camera = Camera {
        width: side as u32,
        height: side as u32,
        fx: phantom_rays::FOCAL,
        fy: phantom_rays::FOCAL,
        cx: (side as f64 - 1.0) / 2.0,
        cy: (side as f64 - 1.0) / 2.0,
        k1: 0.0,
        k2: 0.0,
        p1: 0.0,
        p2: 0.0,
        k3: 0.0,
    };
    let table = RayTable::new(&camera);
    let pose = Affine::from_fn(|i, j| b.pose[i][j]);
    g.throughput(Throughput::Elements((side * side) as u64));
    g.bench_function("gbuffer_512", |bch| {
        bch.iter(|| cast_frame_with(&scene, &table, &pose))
    });
    // Its depth plane alone (what the fusions' visibility tests read).
    g.bench_function("depth_512", |bch| {
        bch.iter(|| cast_depth_with(&scene, &table, &pose))
    });
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
