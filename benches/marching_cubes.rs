//! Criterion benchmarks of the lumen-surface stages on a 256x256x200 CT-like volume (a few
//! air tubes in tissue with noise): marching cubes, Taubin smoothing, decimation. The
//! full-size comparison against VTK and scikit-image is bench/marching_cubes_vs_vtk.py.

use bronchosim::math::{Affine, Point3, Vector3};
use bronchosim::mesh::decimate::{decimate, DecimateOptions};
use bronchosim::mesh::smooth::{taubin, TaubinOptions};
use bronchosim::volume::{marching_cubes, Volume};
use criterion::{criterion_group, criterion_main, Criterion};

fn volume() -> Volume<f32> {
    let dims = [256, 256, 200];
    let mut a = Affine::identity();
    a[(0, 0)] = 0.7;
    a[(1, 1)] = 0.7;
    a[(2, 2)] = 0.8;
    let tubes = [
        (
            Point3::new(90.0, 90.0, 160.0),
            Vector3::new(0.0, 0.0, -1.0),
            8.0,
        ),
        (
            Point3::new(90.0, 90.0, 100.0),
            Vector3::new(0.5, 0.2, -0.8).normalize(),
            5.0,
        ),
        (
            Point3::new(90.0, 90.0, 100.0),
            Vector3::new(-0.5, -0.1, -0.8).normalize(),
            5.0,
        ),
    ];
    let mut v = Volume::filled(dims, a, 0f32);
    let mut rng = bronchosim::rng::SplitMix64::new(99);
    for k in 0..dims[2] {
        for j in 0..dims[1] {
            for i in 0..dims[0] {
                let p = Point3::new(i as f64 * 0.7, j as f64 * 0.7, k as f64 * 0.8);
                let mut d = f64::INFINITY;
                for (o, dir, r) in &tubes {
                    let rel = p - o;
                    let t = rel.dot(dir).clamp(0.0, 70.0);
                    d = d.min((rel - dir * t).norm() - r);
                }
                let noise = (rng.uniform() - 0.5) * 60.0;
                v.set(i, j, k, (-480.0 + 520.0 * (d / 0.6).tanh() + noise) as f32);
            }
        }
    }
    v
}

fn bench(c: &mut Criterion) {
    let vol = volume();
    let mut g = c.benchmark_group("lumen_surface");
    g.sample_size(10);
    g.bench_function("marching_cubes_256x256x200", |b| {
        b.iter(|| marching_cubes(&vol, -500.0, None).unwrap())
    });
    let mesh = marching_cubes(&vol, -500.0, None).unwrap();
    g.bench_function("taubin_10", |b| {
        b.iter(|| {
            let mut m = mesh.clone();
            taubin(&mut m, &TaubinOptions::default()).unwrap();
            m
        })
    });
    let mut smooth = mesh.clone();
    taubin(&mut smooth, &TaubinOptions::default()).unwrap();
    g.bench_function("decimate_0.7mm", |b| {
        b.iter(|| decimate(&smooth, &DecimateOptions::default()).unwrap())
    });
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
