//! Frame input speed: PNG decode/encode (8 and 16 bit, sRGB↔linear) and streaming video decode.
//!
//! With BRONCHOSIM_BENCH_DIR set (bench/frames.py does this) the inputs are read from that
//! folder so the Python reference times the very same files; otherwise they are made here.

use std::hint::black_box;
use std::path::{Path, PathBuf};
use std::process::Command;

use bronchosim::image::srgb::{linear_to_srgb16, linear_to_srgb8};
use bronchosim::image::Frame;
use bronchosim::io::png::{read_png, write_png_srgb16, write_png_srgb8};
use bronchosim::io::video::VideoReader;
use criterion::{criterion_group, criterion_main, Criterion};

const W: u32 = 320;
const H: u32 = 320;
const VIDEO_FRAMES: usize = 300;

/// A smooth, textured linear frame (compresses like a real endoscope frame, not like noise).
fn test_frame(seed: u32) -> Frame {
    let mut f = Frame::new(W, H);
    for y in 0..H {
        for x in 0..W {
            let (u, v) = (x as f32 / W as f32, y as f32 / H as f32);
            let s = seed as f32 * 0.1;
            let r = 0.5 + 0.4 * (9.0 * u + s).sin() * (7.0 * v).cos();
            let g = 0.3 + 0.2 * (13.0 * v + s).sin();
            let b = 0.2 + 0.15 * (5.0 * (u + v) + s).cos();
            f.set(x, y, [r, g, b]);
        }
    }
    f
}

fn inputs() -> (PathBuf, Option<tempfile::TempDir>) {
    if let Ok(dir) = std::env::var("BRONCHOSIM_BENCH_DIR") {
        return (PathBuf::from(dir), None);
    }
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().to_path_buf();
    write_png_srgb8(&dir.join("frame8.png"), &test_frame(0)).unwrap();
    write_png_srgb16(&dir.join("frame16.png"), &test_frame(0)).unwrap();
    for i in 0..VIDEO_FRAMES {
        write_png_srgb8(&dir.join(format!("v{i:03}.png")), &test_frame(i as u32)).unwrap();
    }
    let ok = Command::new("ffmpeg")
        .args([
            "-v",
            "error",
            "-y",
            "-i",
            "v%03d.png",
            "-c:v",
            "libx264",
            "-crf",
            "18",
        ])
        .args(["-pix_fmt", "yuv420p", "video.mp4"])
        .current_dir(&dir)
        .status()
        .unwrap()
        .success();
    assert!(ok, "ffmpeg failed to make the benchmark video");
    (dir, Some(tmp))
}

fn decode_all(path: &Path) -> usize {
    let mut reader = VideoReader::open(path).unwrap();
    let mut n = 0;
    while let Some(frame) = reader.next_frame() {
        black_box(frame.unwrap());
        n += 1;
    }
    n
}

fn bench(c: &mut Criterion) {
    let (dir, _keep) = inputs();
    let frame = test_frame(0);
    let out = tempfile::tempdir().unwrap();
    c.bench_function("png_read_8bit_320", |b| {
        b.iter(|| black_box(read_png(&dir.join("frame8.png")).unwrap()))
    });
    c.bench_function("png_read_16bit_320", |b| {
        b.iter(|| black_box(read_png(&dir.join("frame16.png")).unwrap()))
    });
    c.bench_function("png_write_8bit_320", |b| {
        b.iter(|| write_png_srgb8(&out.path().join("w8.png"), &frame).unwrap())
    });
    c.bench_function("png_write_16bit_320", |b| {
        b.iter(|| write_png_srgb16(&out.path().join("w16.png"), &frame).unwrap())
    });
    c.bench_function("srgb8_encode_320", |b| {
        b.iter(|| {
            black_box(
                frame
                    .rgb
                    .iter()
                    .map(|&v| linear_to_srgb8(v))
                    .collect::<Vec<u8>>(),
            )
        })
    });
    c.bench_function("srgb16_encode_320", |b| {
        b.iter(|| {
            black_box(
                frame
                    .rgb
                    .iter()
                    .map(|&v| linear_to_srgb16(v))
                    .collect::<Vec<u16>>(),
            )
        })
    });
    let video = dir.join("video.mp4");
    assert_eq!(decode_all(&video), VIDEO_FRAMES);
    let mut g = c.benchmark_group("video");
    g.sample_size(10);
    g.bench_function("video_decode_300x320", |b| b.iter(|| decode_all(&video)));
    // Open (ffprobe + ffmpeg start) and the first frame: the fixed cost per video.
    g.bench_function("video_open_first_frame", |b| {
        b.iter(|| {
            let mut r = VideoReader::open(&video).unwrap();
            black_box(r.next_frame().unwrap().unwrap())
        })
    });
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
