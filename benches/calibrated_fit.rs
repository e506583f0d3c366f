//! The pooled calibrated fit over 80 frames of 320x320 (synthetic physically based video,
//! tests/calibrated_support): pooling (<= 20k samples per frame, 1.6M in all), the 3-D density
//! weights, and the fit (alternation + LM polish + robust IRLS with the default Huber loss).
//! Issue 8 asks for < 5 s.

#[path = "../tests/calibrated_support/mod.rs"]
mod calibrated_support;

use bronchosim::shading::calibrated::{
    density_weights_3d, fit_calibrated, pool_frames, CalibratedOptions, FrameData, PoolOptions,
};
use bronchosim::shading::WeightOptions;
use calibrated_support::{render, sequence, RenderOptions};
use criterion::{criterion_group, criterion_main, Criterion};
use rayon::prelude::*;
use std::hint::black_box;

fn bench(c: &mut Criterion) {
    let views = sequence(80, 3);
    let ropts = RenderOptions {
        size: 320,
        ..Default::default()
    };
    let frames: Vec<_> = views
        .par_iter()
        .enumerate()
        .map(|(f, v)| render(v, &ropts, f as u64))
        .collect();
    // Without texel ids: the pooling's cost alone.
    let data: Vec<FrameData> = frames
        .iter()
        .map(|fr| FrameData {
            texel: None,
            ..fr.data()
        })
        .collect();
    let popts = PoolOptions::default();
    let samples = pool_frames(&data, &popts).unwrap();
    let w = density_weights_3d(&samples, &WeightOptions::default());
    let opts = CalibratedOptions::default();
    let fit = fit_calibrated(&samples, &w, &opts).unwrap();
    eprintln!(
        "{} samples over {} frames; report {:?}",
        samples.len(),
        samples.frames(),
        fit.report
    );
    let mut g = c.benchmark_group("calibrated_fit_80x320x320");
    g.sample_size(10);
    g.bench_function("pool_and_weights", |b| {
        b.iter(|| {
            let s = pool_frames(black_box(&data), &popts).unwrap();
            black_box(density_weights_3d(&s, &WeightOptions::default()))
        })
    });
    g.bench_function("fit", |b| {
        b.iter(|| black_box(fit_calibrated(black_box(&samples), &w, &opts).unwrap()))
    });
    g.bench_function("pool_weights_fit_total", |b| {
        b.iter(|| {
            let s = pool_frames(black_box(&data), &popts).unwrap();
            let w = density_weights_3d(&s, &WeightOptions::default());
            black_box(fit_calibrated(&s, &w, &opts).unwrap())
        })
    });
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
