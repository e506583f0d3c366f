//! Shading stage timings for one 320x320 frame: sample extraction, density weights, and the
//! Psi fit (~80k samples, plain and robust). The per-frame budget is set by the ray cast of
//! the same frame (~100k rays at about 1 Mray/s per thread, i.e. tens of ms on 2 cores).

use bronchosim::shading::{
    density_weights, extract_samples, fit_psi, FitOptions, Robust, SampleOptions, WeightOptions,
};
use criterion::{criterion_group, criterion_main, Criterion};
use std::hint::black_box;

/// A 320x320 frame's G-buffer and pixels: a tube seen from inside (gamma ≈ R / z), with a
/// Psi-like shading, a few no-hit and saturated pixels. Deterministic.
fn frame() -> (Vec<f32>, Vec<f32>, Vec<f32>) {
    let n = 320 * 320;
    let (mut g, mut z, mut rgb) = (vec![0f32; n], vec![0f32; n], vec![0f32; 3 * n]);
    let mut rng = bronchosim::rng::SplitMix64::new(12345);
    let mut rnd = || rng.uniform_f32();
    for py in 0..320 {
        for px in 0..320 {
            let i = py * 320 + px;
            let (x, y) = ((px as f32 - 159.5) / 134.0, (py as f32 - 159.5) / 134.0);
            let sin_t = (x * x + y * y).sqrt() / (1.0 + x * x + y * y).sqrt();
            if sin_t < 0.12 {
                continue; // the far lumen: no hit
            }
            let zz = 8.0 / sin_t * (1.0 + 0.05 * rnd());
            let gg = (sin_t + 0.1 * (rnd() - 0.5)).clamp(0.02, 1.0);
            z[i] = zz;
            g[i] = gg;
            let shade = 60.0 * gg / (zz * zz) * (1.0 + 0.1 * (rnd() - 0.5));
            for (ch, a) in [0.8f32, 0.42, 0.35].iter().enumerate() {
                rgb[3 * i + ch] = (a * shade).min(1.0);
            }
        }
    }
    (g, z, rgb)
}

fn bench(c: &mut Criterion) {
    let (g, z, rgb) = frame();
    let so = SampleOptions::default();
    let samples = extract_samples(&g, &z, &rgb, &so);
    eprintln!(
        "samples: {} used, excluded {:?}",
        samples.len(),
        samples.excluded
    );
    let w = density_weights(&samples, &WeightOptions::default()).weights;
    let mut group = c.benchmark_group("shading_320x320");
    group.sample_size(30);
    group.bench_function("extract_samples", |b| {
        b.iter(|| extract_samples(black_box(&g), &z, &rgb, &so))
    });
    group.bench_function("density_weights", |b| {
        b.iter(|| density_weights(black_box(&samples), &WeightOptions::default()))
    });
    group.bench_function("fit_psi", |b| {
        b.iter(|| fit_psi(black_box(&samples), &w, &FitOptions::default()).unwrap())
    });
    let robust = FitOptions {
        robust: Robust::Tukey(4.685),
        ..Default::default()
    };
    group.bench_function("fit_psi_tukey", |b| {
        b.iter(|| fit_psi(black_box(&samples), &w, &robust).unwrap())
    });
    group.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
