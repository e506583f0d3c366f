//! A phantom video without a tracker (`--poses first`): the demo's pace (80 frames over the
//! path, about 1.7 mm apart), its first frames kept, poses.json holding the first frame's pose
//! alone.
#![allow(dead_code)]

use bronchosim::io::case::Case;
use bronchosim::io::poses::{write_poses, FrameRef};
use bronchosim::math::Affine;
use bronchosim::phantom::path::PathOptions;
use bronchosim::phantom::{write_phantom_case, PhantomOptions};
use std::path::Path;

/// Write the case into `case_dir` with its first `kept` frames (128x128); returns their true
/// poses.
pub fn untracked_phantom(case_dir: &Path, kept: usize) -> Vec<Affine> {
    untracked_phantom_paced(case_dir, 80, kept, PathOptions::default().jitter_deg)
}

/// The same with `frames` frames over the whole path (80: the demo's pace), the view
/// direction swinging up to `jitter_deg`.
pub fn untracked_phantom_paced(
    case_dir: &Path,
    frames: usize,
    kept: usize,
    jitter_deg: f64,
) -> Vec<Affine> {
    untracked_phantom_sized(case_dir, frames, kept, jitter_deg, 128)
}

/// The same with `side` x `side` frames.
pub fn untracked_phantom_sized(
    case_dir: &Path,
    frames: usize,
    kept: usize,
    jitter_deg: f64,
    side: u32,
) -> Vec<Affine> {
    let opts = PhantomOptions {
        frames,
        width: side,
        height: side,
        novel_views: 1,
        path: PathOptions {
            jitter_deg,
            ..Default::default()
        },
        ..Default::default()
    };
    untracked_phantom_of(case_dir, &opts, kept).0
}

/// The phantom of `opts` written into `case_dir` with its first `kept` frames; their true
/// poses and the frames among them the phantom motion-blurred.
pub fn untracked_phantom_of(
    case_dir: &Path,
    opts: &PhantomOptions,
    kept: usize,
) -> (Vec<Affine>, Vec<usize>) {
    let (case, blurred) = phantom_cut_to(case_dir, opts, kept);
    write_poses(&case_dir.join("poses.json"), &case.poses[..1], case_dir).unwrap();
    perturb_frame0(case_dir);
    let truth = case.poses.iter().map(|p| p.pose.camera_to_world).collect();
    (truth, blurred)
}

/// The phantom of `opts` written into `case_dir`, cut to its first `kept` frames (the other
/// frames' files removed, poses.json holding the kept frames' poses as the phantom gave them);
/// the case opened, and the frames among the kept the phantom motion-blurred.
pub fn phantom_cut_to(case_dir: &Path, opts: &PhantomOptions, kept: usize) -> (Case, Vec<usize>) {
    let blurred = write_phantom_case(case_dir, opts)
        .unwrap()
        .blurred_frames
        .into_iter()
        .filter(|&f| f < kept)
        .collect();
    let case = Case::open(case_dir).unwrap();
    for e in &case.poses[kept..] {
        let FrameRef::Image(p) = &e.frame else {
            panic!("the phantom writes PNG frames")
        };
        std::fs::remove_file(p).unwrap();
    }
    write_poses(&case_dir.join("poses.json"), &case.poses[..kept], case_dir).unwrap();
    (Case::open(case_dir).unwrap(), blurred)
}

/// Each pose's error against its true pose (mm, degrees), and how many are within 1 mm, and
/// within 1 mm and 1 degree.
pub fn tracked_errors(poses: &[Affine], truth: &[Affine]) -> (Vec<(f64, f64)>, usize, usize) {
    let errors: Vec<(f64, f64)> = poses
        .iter()
        .zip(truth)
        .map(|(p, t)| bronchosim::registration::pose_error(p, t))
        .collect();
    let within_mm = errors.iter().filter(|e| e.0 <= 1.0).count();
    let within_both = errors.iter().filter(|e| e.0 <= 1.0 && e.1 <= 1.0).count();
    (errors, within_mm, within_both)
}

/// With `BRONCHOSIM_TEST_PERTURB=k` (k > 0) in the environment, frame 0 of `case_dir` gets one
/// pixel's green 2 % brighter (pixel (5k, height / 3)): an input no detector could tell from
/// the phantom's, whose last bits reach every fit and pose after it. Run a test with k = 1, 2,
/// ... to see how far its measured values move by chance alone before setting a bound on them
/// (BENCHMARKS.md, session 51); unset, the case is the phantom's.
pub fn perturb_frame0(case_dir: &Path) {
    let Ok(k) = std::env::var("BRONCHOSIM_TEST_PERTURB") else {
        return;
    };
    let k: usize = k.parse().expect("BRONCHOSIM_TEST_PERTURB: a whole number");
    if k == 0 {
        return;
    }
    let path = case_dir.join("frames/000000.png");
    let mut frame = bronchosim::io::png::read_png(&path).unwrap();
    let (x, y) = (5 * k, frame.height as usize / 3);
    assert!(
        x < frame.width as usize,
        "BRONCHOSIM_TEST_PERTURB={k}: past the frame"
    );
    frame.rgb[(y * frame.width as usize + x) * 3 + 1] *= 1.02;
    bronchosim::io::png::write_png_srgb8(&path, &frame).unwrap();
}
