//! Times the undistortion map and RGB remap of a 1280x1024 frame for
//! bench/undistort_vs_opencv.py: `undistort_timing [REPS] [both|map|remap|reuse]` prints one
//! JSON line with the median milliseconds per operation (0 for an operation not timed; the
//! single-operation modes are for profiling one of them with `perf`): map_ms
//! (UndistortMap::for_camera), remap_ms (remap_bilinear), plan_ms (RemapPlan::new) and
//! reuse_ms (RemapPlan::remap_into a preallocated frame).

use bronchosim::camera::{remap_bilinear, Camera, RemapPlan, UndistortMap};
use std::hint::black_box;
use std::time::Instant;

fn median_ms(reps: usize, mut f: impl FnMut()) -> f64 {
    if reps == 0 {
        return 0.0;
    }
    f(); // warm-up: page faults and rayon's thread pool
    let mut t: Vec<f64> = (0..reps)
        .map(|_| {
            let s = Instant::now();
            f();
            s.elapsed().as_secs_f64() * 1e3
        })
        .collect();
    t.sort_by(f64::total_cmp);
    t[t.len() / 2]
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let reps: usize = std::env::args()
        .nth(1)
        .map(|s| s.parse())
        .transpose()?
        .unwrap_or(20);
    // Same camera as bench/undistort_vs_opencv.py and tests/data ("wide_1280x1024").
    let cam = Camera {
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
    };
    let mode = std::env::args().nth(2).unwrap_or_else(|| "both".into());
    let reps_for = |op: &str| {
        if mode == "both" || mode == "all" || mode == op {
            reps
        } else {
            0
        }
    };
    let map_ms = median_ms(reps_for("map"), || {
        black_box(UndistortMap::for_camera(black_box(&cam)).expect("map"));
    });
    let map = UndistortMap::for_camera(&cam)?;
    let (w, h) = (cam.width as usize, cam.height as usize);
    let img: Vec<f32> = (0..w * h * 3).map(|i| (i % 251) as f32 / 250.0).collect();
    let remap_ms = median_ms(reps_for("remap"), || {
        black_box(
            remap_bilinear(black_box(&img), cam.width, cam.height, 3, &map, 0.0).expect("remap"),
        );
    });
    let plan_ms = median_ms(reps_for("reuse"), || {
        black_box(RemapPlan::new(black_box(&map), cam.width, cam.height).expect("plan"));
    });
    let plan = RemapPlan::new(&map, cam.width, cam.height)?;
    let mut out = vec![0f32; w * h * 3];
    let reuse_ms = median_ms(reps_for("reuse"), || {
        plan.remap_into(black_box(&img), 3, 0.0, &mut out)
            .expect("remap");
        black_box(&out);
    });
    println!(
        "{{\"map_ms\": {map_ms:.4}, \"remap_ms\": {remap_ms:.4}, \"plan_ms\": {plan_ms:.4}, \"reuse_ms\": {reuse_ms:.4}, \"threads\": {}}}",
        rayon::current_num_threads()
    );
    Ok(())
}
