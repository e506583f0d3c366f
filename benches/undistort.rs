//! Undistortion of a 1280x1024 bronchoscope image: building the map (as
//! cv2.initUndistortRectifyMap) and resampling an RGB f32 frame through it (as cv2.remap).
//! bench/undistort_vs_opencv.py times the same two operations against OpenCV in one run.

use bronchosim::camera::{remap_bilinear, Camera, RemapPlan, UndistortMap};
use criterion::{criterion_group, criterion_main, Criterion};
use std::hint::black_box;

/// The 1280x1024 camera of tests/data/camera_opencv.json ("wide_1280x1024").
fn camera() -> Camera {
    Camera {
        width: 1280,
        height: 1024,
        fx: 800.0,
        fy: 800.0,
        cx: 639.5,
        cy: 511.5,
        k1: -0.35,
        k2: 0.12,
        p1: 0.001,
        p2: 0.0015,
        k3: 0.0,
    }
}

fn bench(c: &mut Criterion) {
    let cam = camera();
    c.bench_function("undistort_map_1280x1024", |b| {
        b.iter(|| UndistortMap::for_camera(black_box(&cam)).expect("map"))
    });
    let map = UndistortMap::for_camera(&cam).expect("map");
    let (w, h) = (cam.width as usize, cam.height as usize);
    let img: Vec<f32> = (0..w * h * 3).map(|i| (i % 251) as f32 / 250.0).collect();
    c.bench_function("remap_rgb_f32_1280x1024", |b| {
        b.iter(|| {
            remap_bilinear(black_box(&img), cam.width, cam.height, 3, &map, 0.0).expect("remap")
        })
    });
    let plan = RemapPlan::new(&map, cam.width, cam.height).expect("plan");
    let mut out = vec![0f32; w * h * 3];
    c.bench_function("remap_plan_rgb_f32_1280x1024", |b| {
        b.iter(|| {
            plan.remap_into(black_box(&img), 3, 0.0, &mut out)
                .expect("remap")
        })
    });
}

criterion_group!(benches, bench);
criterion_main!(benches);
