//! Criterion: NIfTI load of a CT-like int16 .nii.gz (256x256x200 here to keep `cargo bench`
//! short; bench/nifti_vs_nibabel.py runs the full 512x512x400 against nibabel).

use bronchosim::io::nifti::{read_nifti, write_nifti};
use bronchosim::math::Affine;
use bronchosim::volume::Volume;
use criterion::{criterion_group, criterion_main, Criterion};

fn ct_like(dims: [usize; 3]) -> Volume<i16> {
    let mut state = 0x2545F4914F6CDD1Du64;
    let mut noise = || {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        ((state >> 40) as f32 / (1u64 << 24) as f32 - 0.5) * 70.0
    };
    let mut a = Affine::identity();
    a[(0, 0)] = -0.7;
    a[(1, 1)] = -0.7;
    a[(2, 2)] = 0.8;
    let mut v = Volume::filled(dims, a, 0i16);
    for k in 0..dims[2] {
        for j in 0..dims[1] {
            for i in 0..dims[0] {
                let x = (i as f32 - dims[0] as f32 / 2.0) / (dims[0] as f32 * 0.45);
                let y = (j as f32 - dims[1] as f32 / 2.0) / (dims[1] as f32 * 0.35);
                let base = if x * x + y * y > 1.0 {
                    -1000.0
                } else if ((x.abs() - 0.45) / 0.35).powi(2) + (y / 0.7).powi(2) < 1.0 {
                    -850.0
                } else {
                    40.0
                };
                v.set(i, j, k, (base + noise()) as i16);
            }
        }
    }
    v
}

fn bench(c: &mut Criterion) {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("ct.nii.gz");
    write_nifti(&path, &ct_like([256, 256, 200])).unwrap();
    let mut g = c.benchmark_group("nifti");
    g.sample_size(10);
    g.bench_function("read_nifti 256x256x200 int16 .nii.gz", |b| b.iter(|| read_nifti(&path).unwrap()));
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
