//! Experiment: does the video show where the CT's occluding contours are, independently of the
//! texture? For each frame, the model's mesh is ray cast from a pose on a grid; where two
//! neighbouring grid rays' depths differ by more than a ratio, the contour between them is
//! located by bisection; the frame's intensity step is searched along the same line, and its
//! offset from the model's contour is reported (pixels), at the poses of START and at the truth.
//!
//! ```sh
//! cargo run --release --example contour_offsets -- CASE START_DIR MODEL_DIR FIRST LAST
//! ```

#[path = "common/phantom_run.rs"]
#[allow(dead_code)]
mod phantom_run;

use bronchosim::camera::pose::camera_centre;
use bronchosim::camera::Camera;
use bronchosim::image::Frame;
use bronchosim::math::{Affine, Vector3};
use bronchosim::model::Model;
use bronchosim::raycast::Scene;
use phantom_run::{open_phantom, PhantomRun};
use std::path::PathBuf;

const STEP: f64 = 2.0;
const RATIO: f32 = 1.3;
const REACH: f64 = 3.0;

fn depth(scene: &Scene, cam: &Camera, pose: &Affine, u: f64, v: f64) -> Option<f32> {
    let d = cam.pixel_ray(u, v);
    let r = pose.fixed_view::<3, 3>(0, 0);
    let w: Vector3<f64> = r * d;
    let o = camera_centre(pose);
    scene
        .closest_hit(
            [o.x as f32, o.y as f32, o.z as f32],
            [w.x as f32, w.y as f32, w.z as f32],
            1e4,
        )
        .map(|h| h.t)
}

/// The frame's summed channels at (x, y), bilinear.
fn lum(frame: &Frame, x: f64, y: f64) -> Option<f64> {
    frame
        .bilinear(x, y)
        .map(|p| p.iter().map(|&v| f64::from(v)).sum())
}

/// Offsets (px, along near -> far) of the frame's steepest step from the model's contours.
fn offsets(scene: &Scene, cam: &Camera, pose: &Affine, frame: &Frame) -> Vec<(f64, f64, f64)> {
    let (w, h) = (cam.width as f64, cam.height as f64);
    let nx = ((w - 12.0) / STEP) as usize;
    let ny = ((h - 12.0) / STEP) as usize;
    let grid: Vec<Option<f32>> = (0..nx * ny)
        .map(|k| {
            let (i, j) = (k % nx, k / nx);
            depth(
                scene,
                cam,
                pose,
                6.0 + i as f64 * STEP,
                6.0 + j as f64 * STEP,
            )
        })
        .collect();
    let mut out = Vec::new();
    for j in 0..ny {
        for i in 0..nx {
            for (di, dj) in [(1usize, 0usize), (0, 1)] {
                let (i2, j2) = (i + di, j + dj);
                if i2 >= nx || j2 >= ny {
                    continue;
                }
                let (Some(a), Some(b)) = (grid[j * nx + i], grid[j2 * nx + i2]) else {
                    continue;
                };
                if a.max(b) / a.min(b) < RATIO {
                    continue;
                }
                let pa = (6.0 + i as f64 * STEP, 6.0 + j as f64 * STEP);
                let pb = (6.0 + i2 as f64 * STEP, 6.0 + j2 as f64 * STEP);
                let (near, far, tn, tf) = if a < b {
                    (pa, pb, a, b)
                } else {
                    (pb, pa, b, a)
                };
                let split = (tn * tf).sqrt();
                let (mut lo, mut hi) = (0.0f64, 1.0f64);
                for _ in 0..10 {
                    let m = 0.5 * (lo + hi);
                    let p = (near.0 + m * (far.0 - near.0), near.1 + m * (far.1 - near.1));
                    match depth(scene, cam, pose, p.0, p.1) {
                        Some(t) if t < split => lo = m,
                        _ => hi = m,
                    }
                }
                let m = 0.5 * (lo + hi);
                let c = (near.0 + m * (far.0 - near.0), near.1 + m * (far.1 - near.1));
                let d = ((far.0 - near.0) / STEP, (far.1 - near.1) / STEP);
                // The steepest step of the frame along d within REACH.
                let mut best: Option<(f64, f64)> = None;
                let n = (2.0 * REACH / 0.125) as i32;
                let mut prof = Vec::new();
                for s in 0..=n {
                    let t = -REACH + s as f64 * 0.125;
                    let l0 = lum(frame, c.0 + (t - 0.5) * d.0, c.1 + (t - 0.5) * d.1);
                    let l1 = lum(frame, c.0 + (t + 0.5) * d.0, c.1 + (t + 0.5) * d.1);
                    let (Some(l0), Some(l1)) = (l0, l1) else {
                        prof.clear();
                        break;
                    };
                    prof.push((t, l1 - l0));
                }
                for &(t, g) in &prof {
                    if best.is_none_or(|b| g.abs() > b.1.abs()) {
                        best = Some((t, g));
                    }
                }
                if let Some((t, g)) = best {
                    out.push((t, g, (tf / tn) as f64));
                }
            }
        }
    }
    out
}

fn stats(v: &[(f64, f64, f64)]) -> String {
    if v.is_empty() {
        return "none".into();
    }
    let mut t: Vec<f64> = v.iter().map(|x| x.0).collect();
    t.sort_by(f64::total_cmp);
    let mean = t.iter().sum::<f64>() / t.len() as f64;
    let inner: Vec<f64> = t
        .iter()
        .copied()
        .filter(|x| x.abs() < REACH - 0.5)
        .collect();
    let imean = inner.iter().sum::<f64>() / inner.len().max(1) as f64;
    let irms = (inner.iter().map(|x| x * x).sum::<f64>() / inner.len().max(1) as f64).sqrt();
    let pos = v.iter().filter(|x| x.1 > 0.0).count();
    format!(
        "n {:4} median {:+.2} mean {:+.2} | inner n {:4} mean {:+.2} rms {:.2} | rising {pos}",
        t.len(),
        t[t.len() / 2],
        mean,
        inner.len(),
        imean,
        irms
    )
}

fn main() -> anyhow::Result<()> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let case_dir = PathBuf::from(&args[0]);
    let start = PathBuf::from(&args[1]);
    let model = Model::load(&PathBuf::from(&args[2]))?;
    let (first, last): (usize, usize) = (args[3].parse()?, args[4].parse()?);
    let PhantomRun {
        truth,
        frames,
        entries,
    } = open_phantom(&case_dir, Some(&start))?;
    let cam = &model.manifest.camera;
    for f in first..=last.min(frames.len() - 1) {
        let a = offsets(
            &model.scene,
            cam,
            &entries[f].pose.camera_to_world,
            &frames[f],
        );
        let b = offsets(&model.scene, cam, &truth[f], &frames[f]);
        println!("frame {f:3} start: {}", stats(&a));
        println!("frame {f:3} truth: {}", stats(&b));
    }
    Ok(())
}
