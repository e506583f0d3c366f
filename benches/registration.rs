//! One frame's pose refinement (issue 16): a frame of the demo-sized phantom (320x320, default
//! seed) registered against a model built from the true poses, starting from a tracker-like
//! pose (1.5 mm / 2 degrees RMS drift and jitter). The case and model are written once into
//! `$BRONCHOSIM_BENCH_DIR/registration` (default: the system temp folder) and reused. Threads
//! follow RAYON_NUM_THREADS.

use bronchosim::io::case::Case;
use bronchosim::math::Affine;
use bronchosim::model::Model;
use bronchosim::phantom::pose_noise::{tracker_poses, PoseNoise};
use bronchosim::phantom::{write_phantom_case, PhantomOptions};
use bronchosim::registration::{pose_error, FrameObs, FrameRegistrar, RegistrationOptions};
use bronchosim::shading::ShadingKind;
use bronchosim::workflow::build::{build_model, BuildOptions, PosesMode};
use criterion::{criterion_group, criterion_main, Criterion};
use std::hint::black_box;
use std::path::PathBuf;

fn bench(c: &mut Criterion) {
    let dir = std::env::var_os("BRONCHOSIM_BENCH_DIR")
        .map(PathBuf::from)
        .unwrap_or_else(std::env::temp_dir)
        .join("registration");
    let (case_dir, model_dir) = (dir.join("case"), dir.join("model"));
    if !model_dir.join("model.json").exists() {
        let opts = PhantomOptions {
            frames: 12,
            force: true,
            ..Default::default()
        };
        write_phantom_case(&case_dir, &opts).unwrap();
        let build = BuildOptions {
            cross_validate_every: 0,
            shading: Some(ShadingKind::Calibrated),
            poses: PosesMode::Fixed,
            quiet: true,
            force: true,
            ..Default::default()
        };
        build_model(&case_dir, &model_dir, &build).unwrap();
    }
    let case = Case::open(&case_dir).unwrap();
    let model = Model::load(&model_dir).unwrap();
    let light = model.calibrated().unwrap();
    let f = 6;
    let frame = case.frame_source().unwrap().nth(f).unwrap().unwrap();
    let truth: Vec<Affine> = case.poses.iter().map(|p| p.pose.camera_to_world).collect();
    let start = tracker_poses(&truth, &PoseNoise::new(1.5, 2.0), 7)[f];
    let reg = FrameRegistrar::new(
        model.registration_parts().unwrap(),
        RegistrationOptions::default(),
    )
    .unwrap();
    let obs = FrameObs {
        frame: &frame,
        gain: light.gains[f],
        mask: None,
    };
    let r = reg.refine_frame(&obs, &start).unwrap();
    let (mm0, deg0) = pose_error(&start, &truth[f]);
    let (mm, deg) = pose_error(&r.pose, &truth[f]);
    eprintln!(
        "frame {f}: {mm0:.2} mm {deg0:.2} deg -> {mm:.3} mm {deg:.3} deg in {} steps ({:?})",
        r.iterations, r.status
    );
    let mut g = c.benchmark_group("registration");
    g.sample_size(10);
    g.bench_function("refine_frame_320", |b| {
        b.iter(|| {
            reg.refine_frame(black_box(&obs), black_box(&start))
                .unwrap()
        })
    });
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
