//! Region growing on a 512x512x400 phantom CT: fixed-threshold flood fill and the adaptive
//! schedule with explosion control.

use bronchosim::phantom::{make_ct_phantom, CtPhantomOptions};
use bronchosim::volume::region_grow::{connected_threshold, grow_adaptive, AdaptiveOptions};
use bronchosim::volume::seed::find_trachea_seed;
use criterion::{criterion_group, criterion_main, Criterion};

fn bench(c: &mut Criterion) {
    let opts = CtPhantomOptions {
        dims: Some([512, 512, 400]),
        spacing_mm: [0.7, 0.7, 0.5],
        ..Default::default()
    };
    let ct = make_ct_phantom(&opts).expect("phantom").ct;
    let seed = find_trachea_seed(&ct, &Default::default())
        .expect("seed")
        .voxel;
    let mut g = c.benchmark_group("region_grow_512x512x400");
    g.sample_size(10);
    g.bench_function("connected_threshold_-500", |b| {
        b.iter(|| connected_threshold(&ct, seed, f32::MIN, -500.0).unwrap())
    });
    g.bench_function("grow_adaptive_default", |b| {
        b.iter(|| grow_adaptive(&ct, seed, &AdaptiveOptions::default()).unwrap())
    });
    g.bench_function("find_trachea_seed", |b| {
        b.iter(|| find_trachea_seed(&ct, &Default::default()).unwrap())
    });
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
