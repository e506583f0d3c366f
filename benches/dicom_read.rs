//! Time `read_dicom_series` on a CT-sized series. The series is not committed: bench/dicom_read.py
//! writes it and passes its folder in BRONCHOSIM_DICOM_BENCH_DIR (raw) and
//! BRONCHOSIM_DICOM_BENCH_RLE_DIR (RLE); without them this bench does nothing.

use std::path::PathBuf;

use bronchosim::io::dicom::read_dicom_series;
use criterion::{criterion_group, criterion_main, Criterion};

fn bench(c: &mut Criterion) {
    let mut g = c.benchmark_group("dicom_read");
    g.sample_size(10);
    for (label, var) in [
        ("raw", "BRONCHOSIM_DICOM_BENCH_DIR"),
        ("rle", "BRONCHOSIM_DICOM_BENCH_RLE_DIR"),
    ] {
        let Some(dir) = std::env::var_os(var).map(PathBuf::from) else {
            eprintln!("{var} not set: skipping the {label} DICOM bench (run bench/dicom_read.py)");
            continue;
        };
        g.bench_function(label, |b| b.iter(|| read_dicom_series(&dir).unwrap()));
    }
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
