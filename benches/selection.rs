//! Frame selection (issue 21): scoring one 1280x720 frame (sharpness in four directions,
//! exposure shares), and choosing 200 of 1,800 candidate frames by lazy greedy coverage. The
//! inputs are synthetic with a real video's sizes: a textured frame with a smooth light
//! fall-off, and 1,800 frames each seeing about 3,000 of 120,000 wall cells (an 80x45 coverage
//! grid, the one a 1280x720 camera gets), neighbouring frames overlapping as a camera moving
//! along an airway does. Threads follow RAYON_NUM_THREADS (both are single-threaded).

use bronchosim::image::Frame;
use bronchosim::rng::Pcg32;
use bronchosim::selection::{
    choose_frames, score_frame, Failure, FrameCoverage, Judgement, ScoreOptions, SelectionOptions,
};
use criterion::{criterion_group, criterion_main, Criterion};
use std::hint::black_box;

fn hd_frame() -> Frame {
    let (w, h) = (1280u32, 720u32);
    let mut rng = Pcg32::new(11, 3);
    let mut f = Frame::new(w, h);
    for y in 0..h {
        for x in 0..w {
            let (dx, dy) = (x as f32 / w as f32 - 0.5, y as f32 / h as f32 - 0.5);
            let light = 0.6 / (1.0 + 8.0 * (dx * dx + dy * dy));
            let t = 0.8 + 0.2 * rng.uniform() as f32;
            f.set(x, y, [light * t, 0.5 * light * t, 0.4 * light * t]);
        }
    }
    f
}

fn candidates(n: usize, cells: u32) -> (Vec<Judgement>, Vec<FrameCoverage>) {
    let mut rng = Pcg32::new(5, 9);
    let cov = (0..n)
        .map(|i| {
            // The camera advances along the airway: frame i sees a band of cells starting
            // near i · cells / n, about 3,000 wide, with a quality per cell.
            let start = (i as u32 * cells / n as u32 + (rng.uniform() * 200.0) as u32) % cells;
            let mut c: Vec<u32> = (0..3000).map(|k| (start + k) % cells).collect();
            c.sort_unstable();
            let quality = c.iter().map(|_| rng.uniform() as f32).collect();
            FrameCoverage { cells: c, quality }
        })
        .collect();
    let judged = (0..n)
        .map(|i| Judgement {
            relative_sharpness: 1.0,
            score: 0.7 + 0.3 * rng.uniform(),
            failure: (i % 5 == 0).then_some(Failure::Blurred),
        })
        .collect();
    (judged, cov)
}

fn bench(c: &mut Criterion) {
    let frame = hd_frame();
    let opts = ScoreOptions::default();
    c.bench_function("selection: score one 1280x720 frame", |b| {
        b.iter(|| black_box(score_frame(black_box(&frame), None, &opts)))
    });
    let cells = 120_000;
    let (judged, cov) = candidates(1800, cells);
    let sel = SelectionOptions {
        max_frames: 200,
        ..Default::default()
    };
    let mut g = c.benchmark_group("selection");
    g.sample_size(10);
    g.bench_function("choose 200 of 1800 frames", |b| {
        b.iter(|| black_box(choose_frames(&judged, &cov, cells as usize, &sel)))
    });
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
