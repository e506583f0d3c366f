//! Times `read_nifti` on one file: `cargo run --release --example nifti_load_timing -- FILE [REPEATS]`.
//! Prints one line per repeat, "ms <milliseconds>", for bench/nifti_vs_nibabel.py.

fn main() {
    let mut args = std::env::args().skip(1);
    let path = args.next().expect("usage: nifti_load_timing FILE [REPEATS]");
    let repeats: usize = args.next().map(|s| s.parse().expect("REPEATS is a number")).unwrap_or(3);
    for _ in 0..repeats {
        let t = std::time::Instant::now();
        let v = bronchosim::io::nifti::read_nifti(std::path::Path::new(&path)).expect("read");
        let ms = t.elapsed().as_secs_f64() * 1e3;
        std::hint::black_box(&v);
        println!("ms {ms:.1} dims {:?}", v.dims);
    }
}
