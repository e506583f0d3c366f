//! De-lighting + fusion of 12 frames of 320x320 into the atlas of a synthetic airway at the
//! default 0.15 mm texels (frames rendered and Psi fitted once, outside the timing).
//! Throughput is reported in frames per second.

#[path = "../tests/texture_support/mod.rs"]
mod texture_support;

use bronchosim::texture::{
    delight_frame, fuse, DelightOptions, FusionMethod, FusionOptions, Observation,
};
use criterion::{criterion_group, criterion_main, Criterion, Throughput};
use std::hint::black_box;
use texture_support::{Shot, World};

const FRAMES: usize = 12;

fn bench_fusion(c: &mut Criterion) {
    let w = World::new(1.0, 0.15, 320);
    let shots: Vec<Shot> = World::poses(FRAMES)
        .iter()
        .enumerate()
        .map(|(i, p)| w.shoot(p, i as u64))
        .collect();
    eprintln!(
        "airway atlas {}x{}, {} chart texels, {FRAMES} frames of 320x320, {} rayon threads",
        w.atlas.width,
        w.atlas.height,
        w.texels.len(),
        rayon::current_num_threads()
    );
    let obs: Vec<Observation> = shots.iter().map(|s| s.observation(&w.camera)).collect();
    let mut g = c.benchmark_group("texture_fusion");
    g.sample_size(10);
    g.throughput(Throughput::Elements(FRAMES as u64));
    for (name, method) in [
        (
            "nms_smoothed_12x320",
            FusionMethod::MaxWeightSmoothed { sigma_texels: 2.0 },
        ),
        (
            "weighted_average_12x320",
            FusionMethod::WeightedAverage {
                weight_exponent: 2.0,
            },
        ),
    ] {
        let opts = FusionOptions {
            method,
            ..Default::default()
        };
        g.bench_function(name, |b| {
            b.iter(|| {
                let mut o = obs.clone();
                fuse(black_box(&w.texels), o.as_mut_slice(), &opts).expect("fuse")
            })
        });
    }
    g.throughput(Throughput::Elements(1));
    g.bench_function("delight_frame_320", |b| {
        b.iter(|| {
            delight_frame(black_box(&w.texels), &obs[5], &DelightOptions::default())
                .expect("delight")
        })
    });
    g.finish();
}

criterion_group!(benches, bench_fusion);
criterion_main!(benches);
