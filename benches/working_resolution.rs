//! The fit pass's per-frame cost against the working resolution (issue 21): one 1280x720 frame
//! inside the phantom's lumen (benches/common/phantom_rays.rs's mesh and pose), at pyramid
//! level 0, 1 and 2 — reduce the decoded frame (`image::reduce`), ray cast the reduced
//! camera, extract the samples that obey the model, weigh them and fit Psi. The build's
//! texture is fused from full-resolution pixels whatever the level; this is the part that
//! scales with the pixels.

#[path = "common/phantom_rays.rs"]
mod phantom_rays;

use bronchosim::camera::Camera;
use bronchosim::image::reduce::reduce_frame;
use bronchosim::image::Frame;
use bronchosim::math::Affine;
use bronchosim::raycast::{cast_frame_with, RayTable, Scene};
use bronchosim::shading::{
    density_weights, extract_samples, fit_psi, FitOptions, SampleOptions, WeightOptions,
};
use criterion::{criterion_group, criterion_main, Criterion};
use std::hint::black_box;

/// A 1280x720 camera with a 90 degree horizontal field of view.
fn hd_camera() -> Camera {
    Camera {
        width: 1280,
        height: 720,
        fx: 640.0,
        fy: 640.0,
        cx: 639.5,
        cy: 359.5,
        k1: 0.0,
        k2: 0.0,
        p1: 0.0,
        p2: 0.0,
        k3: 0.0,
    }
}

/// The frame the camera records: albedo 0.8/0.42/0.35 under a cos/z² light, clipped at 1.
fn recorded(scene: &Scene, camera: &Camera, pose: &Affine) -> Frame {
    let g = cast_frame_with(scene, &RayTable::new(camera), pose);
    let mut f = Frame::new(camera.width, camera.height);
    for (i, (&gamma, &z)) in g.gamma.iter().zip(&g.z).enumerate() {
        if z.is_finite() {
            for (c, a) in [0.8f32, 0.42, 0.35].iter().enumerate() {
                f.rgb[3 * i + c] = (a * 60.0 * gamma / (z * z)).min(1.0);
            }
        }
    }
    f
}

fn bench(c: &mut Criterion) {
    let b = phantom_rays::phantom_bench(&phantom_rays::default_dir()).expect("bench scene");
    let scene = Scene::new(&b.mesh).expect("scene");
    let pose = Affine::from_fn(|r, k| b.pose[r][k]);
    let full = hd_camera();
    let frame = recorded(&scene, &full, &pose);
    let so = SampleOptions::default();
    let mut group = c.benchmark_group("fit_frame_1280x720");
    group.sample_size(10);
    for level in 0..=2usize {
        let camera = full.at_level(level);
        let rays = RayTable::new(&camera);
        group.bench_function(format!("level{level}"), |bench| {
            bench.iter(|| {
                let f = reduce_frame(black_box(&frame), level, so.saturation_level);
                let g = cast_frame_with(&scene, &rays, &pose);
                let samples = extract_samples(&g.gamma, &g.z, &f.rgb, &so);
                let w = density_weights(&samples, &WeightOptions::default()).weights;
                fit_psi(&samples, &w, &FitOptions::default()).expect("fit")
            })
        });
    }
    group.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
