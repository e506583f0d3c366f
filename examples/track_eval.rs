//! How far a registration stays on track: each frame's pose error against the truth, the
//! fraction of frames within 1 mm (and within 1 mm and 1 degree), and the first frame off
//! track (error over 1 mm) with the path length (mm of the true camera path) up to it.
//!
//! `cargo run --release --example track_eval -- CASE POSES.json [TRUTH.json]`
//! (TRUTH defaults to CASE/truth/poses.json, else CASE/poses.json).

use bronchosim::camera::pose::camera_centre;
use bronchosim::io::poses::read_poses;
use bronchosim::math::Affine;
use bronchosim::registration::{pose_error, pose_error_axes};
use std::path::PathBuf;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let [case, poses, rest @ ..] = args.as_slice() else {
        return Err("usage: track_eval CASE POSES.json [TRUTH.json]".into());
    };
    let case = PathBuf::from(case);
    let truth_path = match rest.first() {
        Some(t) => PathBuf::from(t),
        None if case.join("truth/poses.json").is_file() => case.join("truth/poses.json"),
        None => case.join("poses.json"),
    };
    let read = |p: &PathBuf| -> Result<Vec<Affine>, Box<dyn std::error::Error>> {
        Ok(read_poses(p, &case)?
            .iter()
            .map(|e| e.pose.camera_to_world)
            .collect())
    };
    let (est, truth) = (read(&PathBuf::from(poses))?, read(&truth_path)?);
    if est.len() != truth.len() {
        return Err(format!("{} poses against {} true ones", est.len(), truth.len()).into());
    }
    let e: Vec<(f64, f64)> = est
        .iter()
        .zip(&truth)
        .map(|(p, t)| pose_error(p, t))
        .collect();
    let n = e.len();
    let mm = e.iter().filter(|x| x.0 <= 1.0).count();
    let both = e.iter().filter(|x| x.0 <= 1.0 && x.1 <= 1.0).count();
    let off = e.iter().position(|x| x.0 > 1.0);
    let path_to = |f: usize| -> f64 {
        (1..=f)
            .map(|i| (camera_centre(&truth[i]) - camera_centre(&truth[i - 1])).norm())
            .sum()
    };
    let mut sorted: Vec<f64> = e.iter().map(|x| x.0).collect();
    sorted.sort_by(f64::total_cmp);
    let mut sorted_deg: Vec<f64> = e.iter().map(|x| x.1).collect();
    sorted_deg.sort_by(f64::total_cmp);
    println!(
        "{n} frames: within 1 mm {mm} ({:.0}%), within 1 mm and 1 deg {both} ({:.0}%); median {:.3} mm / {:.3} deg",
        100.0 * mm as f64 / n as f64,
        100.0 * both as f64 / n as f64,
        sorted[n / 2],
        sorted_deg[n / 2]
    );
    match off {
        Some(f) => println!(
            "first frame off by more than 1 mm: {f} ({:.1} of {:.1} mm of path)",
            path_to(f),
            path_to(n - 1)
        ),
        None => println!(
            "never off by more than 1 mm ({:.1} mm of path)",
            path_to(n - 1)
        ),
    }
    // Per frame: centre and rotation error, then the error along the true camera's axes
    // (x right, y down, z forward; mm and degrees).
    for (i, x) in e.iter().enumerate() {
        let (t, r) = pose_error_axes(&est[i], &truth[i]);
        println!(
            "{i} {:.3} {:.3} [{:.2} {:.2} {:.2}] [{:.2} {:.2} {:.2}]",
            x.0, x.1, t[0], t[1], t[2], r[0], r[1], r[2]
        );
    }
    Ok(())
}
