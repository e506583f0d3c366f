//! Ray casting on the benchmark airway (~300k triangles): BVH build, closest hits for a
//! 512x512 camera inside the trachea and for 262144 incoherent rays, and a full G-buffer frame.
//! Threads follow RAYON_NUM_THREADS. Throughput is reported in rays (elements) per second.

#[path = "../tests/common/meshes.rs"]
mod meshes;

use bronchosim::camera::Camera;
use bronchosim::math::Affine;
use bronchosim::raycast::{cast_frame_with, RayTable, Scene};
use criterion::{criterion_group, criterion_main, Criterion, Throughput};
use std::hint::black_box;

fn bench(c: &mut Criterion) {
    let (mesh, cam, rnd) = meshes::bench_scene();
    let mut g = c.benchmark_group("raycast");
    g.sample_size(10);
    g.bench_function("build_300k", |b| {
        b.iter(|| Scene::new(black_box(&mesh)).unwrap())
    });
    for (name, scene) in [
        ("", Scene::new(&mesh).unwrap()),
        ("_bvh4", Scene::new_four_wide(&mesh).unwrap()),
    ] {
        for (rays_name, rays) in [("camera_512", &cam), ("random_262k", &rnd)] {
            g.throughput(Throughput::Elements(rays.dirs.len() as u64));
            g.bench_function(format!("closest_{rays_name}{name}"), |b| {
                b.iter(|| scene.closest_hits(&rays.origins, &rays.dirs, f32::INFINITY))
            });
        }
    }
    // A whole G-buffer frame (normals, gamma, points) from the trachea, 512x512 pinhole.
    let scene = Scene::new(&mesh).unwrap();
    let camera = Camera {
        width: 512,
        height: 512,
        fx: 256.0,
        fy: 256.0,
        cx: 255.5,
        cy: 255.5,
        k1: 0.0,
        k2: 0.0,
        p1: 0.0,
        p2: 0.0,
        k3: 0.0,
    };
    let table = RayTable::new(&camera);
    let mut pose = Affine::identity();
    pose[(0, 3)] = 0.5;
    pose[(1, 3)] = -0.8;
    pose[(2, 3)] = 30.0;
    g.throughput(Throughput::Elements(512 * 512));
    g.bench_function("gbuffer_512", |b| {
        b.iter(|| cast_frame_with(&scene, &table, &pose))
    });
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
