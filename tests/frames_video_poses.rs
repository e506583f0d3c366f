//! Frames (PNG, video), poses.json and safe paths: known answers and every bad input.

use std::fs::File;
use std::io::BufWriter;
use std::path::{Path, PathBuf};
use std::process::Command;

use bronchosim::image::srgb::{linear_to_srgb8, srgb_to_linear};
use bronchosim::image::Frame;
use bronchosim::io::frame_source::FrameSource;
use bronchosim::io::paths::resolve_inside;
use bronchosim::io::png::{read_png, write_png_srgb16, write_png_srgb8};
use bronchosim::io::poses::{read_poses, write_poses, FrameRef, PoseEntry};
use bronchosim::io::video::VideoReader;
use bronchosim::math::{Affine, Matrix3, Vector3};

/// The IEC 61966-2-1 decoding curve, written out independently of the library.
fn reference_linear(code: u32, max: u32) -> f64 {
    let c = code as f64 / max as f64;
    if c <= 0.04045 {
        c / 12.92
    } else {
        ((c + 0.055) / 1.055).powf(2.4)
    }
}

/// Write a PNG with the png crate: `samples` already in the file's layout (16-bit big-endian).
fn write_raw_png(
    path: &Path,
    w: u32,
    h: u32,
    color: png::ColorType,
    depth: png::BitDepth,
    samples: &[u8],
) {
    let mut enc = png::Encoder::new(BufWriter::new(File::create(path).unwrap()), w, h);
    enc.set_color(color);
    enc.set_depth(depth);
    let mut writer = enc.write_header().unwrap();
    writer.write_image_data(samples).unwrap();
    writer.finish().unwrap();
}

/// Pixel codes used in the decode tests: black, the linear-segment edge, mid, white.
const CODES8: [u32; 4] = [0, 10, 128, 255];
const CODES16: [u32; 4] = [0, 2651, 40000, 65535];

#[test]
fn png_all_layouts_decode_to_the_srgb_formula() {
    let dir = tempfile::tempdir().unwrap();
    use png::{BitDepth, ColorType};
    for (depth, codes, max) in [
        (BitDepth::Eight, CODES8, 255u32),
        (BitDepth::Sixteen, CODES16, 65535u32),
    ] {
        for (color, channels) in [
            (ColorType::Grayscale, 1usize),
            (ColorType::GrayscaleAlpha, 2),
            (ColorType::Rgb, 3),
            (ColorType::Rgba, 4),
        ] {
            // A 4x2 image: pixel x has grey/R = codes[x], G = codes[3-x], B = codes[(x+1)%4];
            // the second row repeats the first reversed. Alpha is an arbitrary 7.
            let (w, h) = (4u32, 2u32);
            let mut expected = Vec::new();
            let mut bytes = Vec::new();
            for y in 0..h {
                for x in 0..w {
                    let x = if y == 0 { x } else { 3 - x } as usize;
                    let rgb = [codes[x], codes[3 - x], codes[(x + 1) % 4]];
                    let stored: Vec<u32> = match channels {
                        1 => vec![rgb[0]],
                        2 => vec![rgb[0], 7],
                        3 => rgb.to_vec(),
                        _ => vec![rgb[0], rgb[1], rgb[2], 7],
                    };
                    for s in stored {
                        if max == 255 {
                            bytes.push(s as u8);
                        } else {
                            bytes.extend_from_slice(&(s as u16).to_be_bytes());
                        }
                    }
                    let shown = if channels < 3 { [rgb[0]; 3] } else { rgb };
                    expected.extend(shown.map(|c| reference_linear(c, max)));
                }
            }
            let path = dir.path().join(format!("{color:?}{}.png", max));
            write_raw_png(&path, w, h, color, depth, &bytes);
            let frame = read_png(&path).unwrap();
            assert_eq!((frame.width, frame.height), (w, h));
            assert_eq!(frame.rgb.len(), expected.len());
            for (got, want) in frame.rgb.iter().zip(&expected) {
                // f32 storage: relative error below 1e-7 of values in 0..=1.
                assert!(
                    (*got as f64 - want).abs() < 1e-7,
                    "{color:?} {max}: got {got}, want {want}"
                );
            }
        }
    }
    // Known points of the curve: code 128/255 → 0.2158605, white → exactly 1.
    let mid = reference_linear(128, 255);
    assert!((mid - 0.215_860_5).abs() < 1e-6, "{mid}");
    assert_eq!(srgb_to_linear(1.0), 1.0);
}

#[test]
fn png_palette_and_low_bit_grey_are_expanded() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("palette.png");
    let mut enc = png::Encoder::new(BufWriter::new(File::create(&path).unwrap()), 2, 1);
    enc.set_color(png::ColorType::Indexed);
    enc.set_depth(png::BitDepth::Eight);
    enc.set_palette(vec![255u8, 0, 0, 0, 128, 255]);
    let mut writer = enc.write_header().unwrap();
    writer.write_image_data(&[1, 0]).unwrap();
    writer.finish().unwrap();
    let f = read_png(&path).unwrap();
    let want = [0.0, reference_linear(128, 255), 1.0, 1.0, 0.0, 0.0];
    for (g, w) in f.rgb.iter().zip(want) {
        assert!((*g as f64 - w).abs() < 1e-7, "{:?}", f.rgb);
    }

    // 1-bit grey: 0 → black, 1 → white.
    let path = dir.path().join("bits.png");
    write_raw_png(
        &path,
        8,
        1,
        png::ColorType::Grayscale,
        png::BitDepth::One,
        &[0b1010_0000],
    );
    let f = read_png(&path).unwrap();
    assert_eq!(&f.rgb[..9], &[1.0, 1.0, 1.0, 0.0, 0.0, 0.0, 1.0, 1.0, 1.0]);
}

/// A deterministic linear test frame covering 0..=1 including the exact ends.
fn ramp_frame(w: u32, h: u32) -> Frame {
    let mut f = Frame::new(w, h);
    let n = f.rgb.len();
    for (i, v) in f.rgb.iter_mut().enumerate() {
        // A scrambled but deterministic order so neighbouring channels differ.
        *v = ((i * 7919) % n) as f32 / (n - 1) as f32;
    }
    f
}

#[test]
fn png_write_read_round_trip_within_half_a_code() {
    let dir = tempfile::tempdir().unwrap();
    let frame = ramp_frame(64, 48);
    // Worst case: half a code times the curve's steepest slope, 2.4 / 1.055 at white.
    let slope = 2.4 / 1.055;
    for (bits, bound) in [(8, slope * 0.5 / 255.0), (16, slope * 0.5 / 65535.0)] {
        let path = dir.path().join(format!("rt{bits}.png"));
        if bits == 8 {
            write_png_srgb8(&path, &frame).unwrap();
        } else {
            write_png_srgb16(&path, &frame).unwrap();
        }
        let back = read_png(&path).unwrap();
        assert_eq!((back.width, back.height), (64, 48));
        let max_err = frame
            .rgb
            .iter()
            .zip(&back.rgb)
            .map(|(a, b)| (a - b).abs() as f64)
            .fold(0.0, f64::max);
        assert!(
            max_err <= bound + 1e-7,
            "{bits}-bit: max error {max_err} > {bound}"
        );
        // The ramp is dense enough that the error reaches a good part of the bound.
        assert!(
            max_err > 0.3 * bound,
            "{bits}-bit: {max_err} suspiciously small"
        );
        // Decoded values are exact codes: a second round trip changes nothing.
        let again = dir.path().join(format!("rt{bits}b.png"));
        if bits == 8 {
            write_png_srgb8(&again, &back).unwrap();
        } else {
            write_png_srgb16(&again, &back).unwrap();
        }
        assert_eq!(read_png(&again).unwrap(), back);
    }
}

/// Five flat-colour 8-bit frames, 64x48; returns the folder with frame_%d.png and the colours.
fn flat_frames(dir: &Path) -> Vec<[u8; 3]> {
    let colours = vec![
        [200u8, 30, 40],
        [20, 180, 60],
        [10, 20, 230],
        [128, 128, 128],
        [250, 240, 5],
    ];
    for (i, c) in colours.iter().enumerate() {
        let bytes: Vec<u8> = (0..64 * 48).flat_map(|_| *c).collect();
        write_raw_png(
            &dir.join(format!("frame_{i}.png")),
            64,
            48,
            png::ColorType::Rgb,
            png::BitDepth::Eight,
            &bytes,
        );
    }
    colours
}

fn ffmpeg(args: &[&str], dir: &Path) {
    let out = Command::new("ffmpeg")
        .args(["-v", "error", "-y", "-nostdin"])
        .args(args)
        .current_dir(dir)
        .output()
        .expect("ffmpeg (Debian package ffmpeg) is needed for the video tests");
    assert!(
        out.status.success(),
        "ffmpeg {args:?}: {}",
        String::from_utf8_lossy(&out.stderr)
    );
}

/// Largest |decoded - expected| in linear units over all pixels of the frame.
fn max_flat_error(frame: &Frame, colour: [u8; 3]) -> f64 {
    let want = colour.map(|c| reference_linear(c as u32, 255));
    frame
        .rgb
        .chunks_exact(3)
        .flat_map(|px| (0..3).map(move |k| (px[k] as f64 - want[k]).abs()))
        .fold(0.0, f64::max)
}

#[test]
fn lossless_ffv1_video_decodes_exactly() {
    let dir = tempfile::tempdir().unwrap();
    let colours = flat_frames(dir.path());
    ffmpeg(
        &[
            "-i",
            "frame_%d.png",
            "-c:v",
            "ffv1",
            "-pix_fmt",
            "bgr0",
            "v.mkv",
        ],
        dir.path(),
    );
    let mut reader = VideoReader::open(&dir.path().join("v.mkv")).unwrap();
    assert_eq!((reader.width(), reader.height()), (64, 48));
    assert_eq!(reader.frame_count(), 5);
    assert!(!reader.is_sixteen_bit());
    let mut n = 0;
    while let Some(frame) = reader.next_frame() {
        let frame = frame.unwrap();
        assert_eq!((frame.width, frame.height), (64, 48));
        // Lossless RGB: every channel is the f32 of the exact code's linear value.
        assert!(max_flat_error(&frame, colours[n]) < 1e-7, "frame {n}");
        n += 1;
    }
    assert_eq!(n, 5);
    assert!(reader.next_frame().is_none(), "the stream stays ended");
}

#[test]
fn h264_mp4_decodes_within_a_few_codes() {
    let dir = tempfile::tempdir().unwrap();
    let colours = flat_frames(dir.path());
    ffmpeg(
        &[
            "-i",
            "frame_%d.png",
            "-c:v",
            "libx264",
            "-qp",
            "0",
            "-pix_fmt",
            "yuv444p",
            "video.mp4",
        ],
        dir.path(),
    );
    let reader = VideoReader::open(&dir.path().join("video.mp4")).unwrap();
    assert_eq!(reader.frame_count(), 5);
    let frames: Vec<Frame> = reader.map(|f| f.unwrap()).collect();
    assert_eq!(frames.len(), 5);
    for (i, frame) in frames.iter().enumerate() {
        // Lossless H.264 in 8-bit YUV: only the RGB↔YUV rounding remains, about 1-2 codes,
        // i.e. below 3 codes at white's slope: 3 * 2.275 / 255 = 0.027.
        let err = max_flat_error(frame, colours[i]);
        assert!(err < 0.027, "frame {i}: max linear error {err}");
        let c = frame.get(10, 10);
        let codes = c.map(linear_to_srgb8);
        for k in 0..3 {
            assert!(
                (codes[k] as i32 - colours[i][k] as i32).abs() <= 2,
                "frame {i}: {codes:?} vs {:?}",
                colours[i]
            );
        }
    }
}

#[test]
fn sixteen_bit_video_keeps_sixteen_bit_precision() {
    let dir = tempfile::tempdir().unwrap();
    // Codes 1000 + 257 k cannot be represented in 8 bits (not multiples of 257).
    let codes: Vec<u16> = (0..3).map(|k| 1000 + 257 * 40 * k).collect();
    for i in 0..3usize {
        let c = [codes[i], codes[(i + 1) % 3], codes[(i + 2) % 3]];
        let bytes: Vec<u8> = (0..32 * 16)
            .flat_map(|_| c.iter().flat_map(|v| v.to_be_bytes()).collect::<Vec<_>>())
            .collect();
        write_raw_png(
            &dir.path().join(format!("f{i}.png")),
            32,
            16,
            png::ColorType::Rgb,
            png::BitDepth::Sixteen,
            &bytes,
        );
    }
    ffmpeg(&["-i", "f%d.png", "-c:v", "ffv1", "v16.mkv"], dir.path());
    let reader = VideoReader::open(&dir.path().join("v16.mkv")).unwrap();
    assert!(reader.is_sixteen_bit());
    let frames: Vec<Frame> = reader.map(|f| f.unwrap()).collect();
    assert_eq!(frames.len(), 3);
    for (i, f) in frames.iter().enumerate() {
        let want = [codes[i], codes[(i + 1) % 3], codes[(i + 2) % 3]]
            .map(|c| reference_linear(c as u32, 65535));
        let got = f.get(31, 15);
        for k in 0..3 {
            assert!(
                (got[k] as f64 - want[k]).abs() < 1e-7,
                "frame {i}: {got:?} vs {want:?}"
            );
        }
    }
}

fn pose_with(frame: FrameRef, angle: f64, t: [f64; 3]) -> PoseEntry {
    let r = nalgebra::Rotation3::from_axis_angle(
        &nalgebra::Unit::new_normalize(Vector3::new(1.0, 2.0, 3.0)),
        angle,
    );
    let mut m = Affine::identity();
    m.fixed_view_mut::<3, 3>(0, 0).copy_from(r.matrix());
    m[(0, 3)] = t[0];
    m[(1, 3)] = t[1];
    m[(2, 3)] = t[2];
    PoseEntry {
        frame,
        pose: bronchosim::camera::Pose::new(m),
    }
}

#[test]
fn frame_source_picks_video_frames_and_png_files_in_pose_order() {
    let dir = tempfile::tempdir().unwrap();
    let colours = flat_frames(dir.path());
    ffmpeg(
        &[
            "-i",
            "frame_%d.png",
            "-c:v",
            "ffv1",
            "-pix_fmt",
            "bgr0",
            "video.mkv",
        ],
        dir.path(),
    );
    let poses: Vec<PoseEntry> = [1usize, 3, 4]
        .iter()
        .map(|&i| {
            pose_with(
                FrameRef::VideoIndex(i),
                0.1 * i as f64,
                [i as f64, 0.0, 0.0],
            )
        })
        .collect();
    let video = dir.path().join("video.mkv");
    let source = FrameSource::from_poses(&poses, Some(&video), 64, 48).unwrap();
    assert_eq!(source.len(), 3);
    let got: Vec<Frame> = source.map(|f| f.unwrap()).collect();
    for (frame, i) in got.iter().zip([1usize, 3, 4]) {
        assert!(max_flat_error(frame, colours[i]) < 1e-7, "video frame {i}");
    }

    let poses: Vec<PoseEntry> = [4usize, 0]
        .iter()
        .map(|&i| {
            let p = dir.path().join(format!("frame_{i}.png"));
            pose_with(FrameRef::Image(p), 0.2, [0.0; 3])
        })
        .collect();
    let got: Vec<Frame> = FrameSource::from_poses(&poses, None, 64, 48)
        .unwrap()
        .map(|f| f.unwrap())
        .collect();
    assert!(max_flat_error(&got[0], colours[4]) < 1e-7);
    assert!(max_flat_error(&got[1], colours[0]) < 1e-7);

    // Asking for frame 5 of a 5-frame video fails before decoding, naming the file.
    let poses = vec![pose_with(FrameRef::VideoIndex(5), 0.0, [0.0; 3])];
    let err = FrameSource::from_poses(&poses, Some(&video), 64, 48)
        .err()
        .unwrap()
        .to_string();
    assert!(
        err.contains("video.mkv") && err.contains("frame 5"),
        "{err}"
    );
}

#[test]
fn poses_write_read_round_trip_is_exact() {
    let dir = tempfile::tempdir().unwrap();
    let poses: Vec<PoseEntry> = (0..4)
        .map(|i| {
            let img = dir.path().join(format!("frames/{i:06}.png"));
            pose_with(
                FrameRef::Image(img),
                0.37 * i as f64 + 0.1,
                [1.5 * i as f64, -2.25, 1e-3],
            )
        })
        .collect();
    let path = dir.path().join("poses.json");
    write_poses(&path, &poses, dir.path()).unwrap();
    let text = std::fs::read_to_string(&path).unwrap();
    assert!(text.contains("\"image\": \"frames/000002.png\""), "{text}");
    let back = read_poses(&path, dir.path()).unwrap();
    assert_eq!(back, poses, "shortest round-trip numbers are exact");

    let video_poses: Vec<PoseEntry> = [0usize, 2, 9]
        .iter()
        .map(|&i| pose_with(FrameRef::VideoIndex(i), 1.0, [0.0; 3]))
        .collect();
    write_poses(&path, &video_poses, dir.path()).unwrap();
    assert_eq!(read_poses(&path, dir.path()).unwrap(), video_poses);
}

#[test]
fn pose_helpers_centre_direction_inverse() {
    // Camera at (10, 20, 30) looking along world -y: camera +z → world -y, +x → world +x.
    let m = Affine::new(
        1.0, 0.0, 0.0, 10.0, //
        0.0, 0.0, -1.0, 20.0, //
        0.0, 1.0, 0.0, 30.0, //
        0.0, 0.0, 0.0, 1.0,
    );
    let p = PoseEntry {
        frame: FrameRef::VideoIndex(0),
        pose: bronchosim::camera::Pose::new(m),
    };
    assert_eq!(p.pose.centre().coords, Vector3::new(10.0, 20.0, 30.0));
    assert_eq!(p.pose.viewing_direction(), Vector3::new(0.0, -1.0, 0.0));
    let inv = p.pose.world_to_camera();
    assert!((inv * m - Affine::identity()).abs().max() < 1e-15);
    let general = pose_with(FrameRef::VideoIndex(0), 0.77, [3.0, -4.0, 5.0]);
    let err = (general.pose.world_to_camera()
        - general.pose.camera_to_world.try_inverse().unwrap())
    .abs()
    .max();
    assert!(err < 1e-14, "{err}");
    let _ = Matrix3::<f64>::identity();
}

// ---------------------------------------------------------------- bad inputs

/// Write `json` as CASE/poses.json and return read_poses' error message.
fn poses_error(case: &Path, json: &str) -> String {
    let path = case.join("poses.json");
    std::fs::write(&path, json).unwrap();
    match read_poses(&path, case) {
        Ok(p) => panic!("accepted bad poses.json: {json} -> {p:?}"),
        Err(e) => {
            let msg = e.to_string();
            assert!(
                msg.contains("poses.json"),
                "message does not name the file: {msg}"
            );
            assert!(!msg.contains('\n'), "message is not one line: {msg}");
            msg
        }
    }
}

const ID: &str = "1,0,0,0, 0,1,0,0, 0,0,1,0, 0,0,0,1";

fn entry(image: &str, m: &str) -> String {
    format!("{{\"frames\": [{{\"image\": \"frames/0.png\", \"camera_to_world\": [{ID}]}}, {{\"image\": {image:?}, \"camera_to_world\": [{m}]}}]}}")
}

#[test]
fn bad_poses_are_refused_with_the_file_and_the_frame() {
    let dir = tempfile::tempdir().unwrap();
    let case = dir.path();
    let msg = poses_error(case, "{\"frames\": [ {\"image\": \"a.png\", ");
    assert!(msg.contains("not valid JSON"), "{msg}");
    let msg = poses_error(case, &entry("b.png", &ID.replace("0,1,0,0", "1e400,1,0,0")));
    assert!(msg.contains("out of range"), "{msg}");
    let msg = poses_error(
        case,
        &entry("b.png", &ID.replace("0,1,0,0", "\"NaN\",1,0,0")),
    );
    assert!(
        msg.contains("frame 1 (b.png)") && msg.contains("camera_to_world[4]"),
        "{msg}"
    );
    let msg = poses_error(case, &entry("b.png", &ID.replace("0,1,0,0", "0,1.01,0,0")));
    assert!(
        msg.contains("frame 1 (b.png)") && msg.contains("not orthonormal"),
        "{msg}"
    );
    let msg = poses_error(case, &entry("b.png", &ID.replace("1,0,0,0,", "-1,0,0,0,")));
    assert!(msg.contains("determinant"), "{msg}");
    let msg = poses_error(case, &entry("b.png", "1,0,0,0, 0,1,0,0, 0,0,1,0, 0,0,0"));
    assert!(msg.contains("has 15 numbers, expected 16"), "{msg}");
    let msg = poses_error(case, &entry("b.png", &ID.replace("0,0,0,1", "0,0,1,1")));
    assert!(msg.contains("last row"), "{msg}");
    // A rotation good to 1e-5 is accepted (tolerance 1e-4).
    let path = case.join("poses.json");
    std::fs::write(
        &path,
        entry("b.png", &ID.replace("0,1,0,0", "0,1.00001,0,0")),
    )
    .unwrap();
    assert_eq!(read_poses(&path, case).unwrap().len(), 2);

    let msg = poses_error(case, &entry("/etc/passwd", ID));
    assert!(msg.contains("absolute"), "{msg}");
    let msg = poses_error(case, &entry("frames/../../outside.png", ID));
    assert!(msg.contains("outside"), "{msg}");
    let msg = poses_error(case, "{\"frames\": []}");
    assert!(msg.contains("empty"), "{msg}");
    let msg = poses_error(case, "[1, 2]");
    assert!(msg.contains("frames"), "{msg}");
    let both = format!(
        "{{\"frames\": [{{\"image\": \"a.png\", \"frame\": 0, \"camera_to_world\": [{ID}]}}]}}"
    );
    assert!(poses_error(case, &both).contains("both"));
    let neither = format!("{{\"frames\": [{{\"camera_to_world\": [{ID}]}}]}}");
    assert!(poses_error(case, &neither).contains("needs"));
    let backwards = format!(
        "{{\"frames\": [{{\"frame\": 3, \"camera_to_world\": [{ID}]}}, {{\"frame\": 2, \"camera_to_world\": [{ID}]}}]}}"
    );
    assert!(poses_error(case, &backwards).contains("strictly increase"));
    let negative = format!("{{\"frames\": [{{\"frame\": -1, \"camera_to_world\": [{ID}]}}]}}");
    assert!(poses_error(case, &negative).contains("non-negative integer"));
}

#[cfg(unix)]
#[test]
fn links_placed_in_the_case_are_followed_and_written_paths_stay_inside() {
    let dir = tempfile::tempdir().unwrap();
    let case = dir.path().join("case");
    let outside = dir.path().join("outside");
    std::fs::create_dir_all(case.join("frames")).unwrap();
    std::fs::create_dir_all(&outside).unwrap();
    std::fs::write(outside.join("data.png"), b"x").unwrap();
    std::os::unix::fs::symlink(&outside, case.join("disk")).unwrap();
    let f = case.join("poses.json");
    // A link the user placed in the case folder is followed wherever it points.
    assert_eq!(
        resolve_inside(&case, "disk/data.png", &f).unwrap(),
        case.join("disk/data.png")
    );
    // What a poses.json writes cannot leave the case by itself.
    for (rel, why) in [
        ("../outside/data.png", "too many '..'"),
        ("frames/../../outside/data.png", "too many '..'"),
        ("/etc/passwd", "absolute"),
    ] {
        let msg = resolve_inside(&case, rel, &f).unwrap_err().to_string();
        assert!(
            msg.contains("poses.json") && msg.contains(why),
            "{rel}: {msg}"
        );
    }
    let msg = poses_error(&case, &entry("../outside/data.png", ID));
    assert!(msg.contains("frame 1") && msg.contains("'..'"), "{msg}");
}

#[test]
fn unreadable_pngs_are_refused_with_the_file() {
    let dir = tempfile::tempdir().unwrap();
    let good = dir.path().join("good.png");
    write_png_srgb8(&good, &ramp_frame(16, 8)).unwrap();
    let bytes = std::fs::read(&good).unwrap();
    let cases: Vec<(&str, Vec<u8>)> = vec![
        ("garbage.png", b"this is not a png at all".to_vec()),
        ("truncated.png", bytes[..bytes.len() / 2].to_vec()),
        ("empty.png", Vec::new()),
        ("badcrc.png", {
            let mut b = bytes.clone();
            let n = b.len();
            b[n / 2] ^= 0xff;
            b
        }),
    ];
    for (name, data) in cases {
        let path = dir.path().join(name);
        std::fs::write(&path, data).unwrap();
        let msg = read_png(&path).unwrap_err().to_string();
        assert!(msg.contains(name) && !msg.contains('\n'), "{msg}");
    }
    let msg = read_png(&dir.path().join("missing.png"))
        .unwrap_err()
        .to_string();
    assert!(msg.contains("missing.png"), "{msg}");
}

#[test]
fn undecodable_videos_are_refused_with_the_file() {
    let dir = tempfile::tempdir().unwrap();
    let text = dir.path().join("video.mp4");
    std::fs::write(&text, "hello, I am not a video\n").unwrap();
    let msg = VideoReader::open(&text).err().unwrap().to_string();
    assert!(msg.contains("video.mp4: ffmpeg could not decode"), "{msg}");

    let msg = VideoReader::open(&dir.path().join("none.mp4"))
        .err()
        .unwrap()
        .to_string();
    assert!(
        msg.contains("none.mp4") && msg.contains("not found"),
        "{msg}"
    );

    // A 40-frame H.264 video with bytes overwritten in the middle: decoding must fail with
    // an error naming the file and the frame, not silently drop frames (which would shift
    // every later pose onto the wrong image).
    ffmpeg(
        &[
            "-f",
            "lavfi",
            "-i",
            "testsrc=size=160x120:rate=10",
            "-frames:v",
            "40",
        ]
        .iter()
        .chain(&["-c:v", "libx264", "-pix_fmt", "yuv420p", "good.mp4"])
        .copied()
        .collect::<Vec<_>>(),
        dir.path(),
    );
    let mut data = std::fs::read(dir.path().join("good.mp4")).unwrap();
    let n = data.len();
    data[n / 3..n / 3 + n / 10].fill(0x55);
    let broken = dir.path().join("broken.mp4");
    std::fs::write(&broken, &data).unwrap();
    let reader = VideoReader::open(&broken).unwrap();
    let results: Vec<_> = reader.collect();
    let first_err = results.iter().position(|r| r.is_err()).expect("an error");
    assert!(first_err < 40, "{first_err}");
    let msg = results[first_err].as_ref().unwrap_err().to_string();
    assert!(
        msg.contains("broken.mp4: ffmpeg could not decode frame"),
        "{msg}"
    );
    assert_eq!(results.len(), first_err + 1, "the stream ends at the error");

    // A truncated mp4 (the index is written at the end) cannot even be opened.
    std::fs::write(dir.path().join("cut.mp4"), &data[..n / 2]).unwrap();
    let msg = VideoReader::open(&dir.path().join("cut.mp4"))
        .err()
        .unwrap()
        .to_string();
    assert!(msg.contains("cut.mp4: ffmpeg could not decode"), "{msg}");
}

#[test]
fn frame_size_must_match_the_camera() {
    let dir = tempfile::tempdir().unwrap();
    flat_frames(dir.path());
    ffmpeg(
        &["-i", "frame_%d.png", "-c:v", "ffv1", "video.mkv"],
        dir.path(),
    );
    let video = dir.path().join("video.mkv");
    let poses = vec![pose_with(FrameRef::VideoIndex(0), 0.0, [0.0; 3])];
    let msg = FrameSource::from_poses(&poses, Some(&video), 320, 320)
        .err()
        .unwrap()
        .to_string();
    assert!(
        msg.contains("video.mkv") && msg.contains("64x48 differs from the camera's 320x320"),
        "{msg}"
    );

    let png: PathBuf = dir.path().join("frame_2.png");
    let poses = vec![pose_with(FrameRef::Image(png), 0.0, [0.0; 3])];
    let mut source = FrameSource::from_poses(&poses, None, 64, 50).unwrap();
    let msg = source.next().unwrap().unwrap_err().to_string();
    assert!(
        msg.contains("frame_2.png") && msg.contains("64x48 differs from the camera's 64x50"),
        "{msg}"
    );
    assert!(source.next().is_none());
}
