//! Experiment: where, at the true poses, the registration's cost pulls each frame, and which
//! points pull it. Each frame is compared with a built model (its light and texture) at its
//! true pose on one pyramid level, as the registration compares it; the Gauss-Newton step
//! from there (`-H^-1 g`, gain included) is the pull. `g` summed over a subset of the points,
//! with the same `H`, is that subset's share of the step: the shares of a partition add up to
//! the step. Points are split by the cosine between the normal and the ray (grazing to
//! frontal) and by distance.
//!
//! ```sh
//! cargo run --release --example pose_pull -- CASE MODEL_DIR FIRST LAST [LEVEL] [STRIDE] [uniform]
//! ```
//! MODEL_DIR: a model of the case (e.g. built from the true poses, `--poses fixed`); `uniform`
//! compares against the light alone, the albedo uniform (the registration's geometry rounds).

#[path = "common/phantom_run.rs"]
#[allow(dead_code)]
mod phantom_run;

use bronchosim::model::Model;
use bronchosim::registration::align::LevelProblem;
use bronchosim::registration::photometric::RayGrid;
use bronchosim::registration::pyramid::{ObservedPyramid, PyramidOptions};
use bronchosim::registration::{PhotometricModel, RegistrationOptions};
use nalgebra::{SMatrix, SVector};
use phantom_run::{open_phantom, PhantomRun};
use std::path::PathBuf;

type M7 = SMatrix<f64, 7, 7>;
type V7 = SVector<f64, 7>;

const COS_EDGES: [f64; 4] = [0.3, 0.5, 0.7, 0.9];
const DEPTH_EDGES: [f64; 3] = [4.0, 8.0, 16.0];

fn bin(edges: &[f64], v: f64) -> usize {
    edges.iter().take_while(|&&e| v >= e).count()
}

fn show(step: &V7) -> String {
    format!(
        "x {:+.3} y {:+.3} z {:+.3} mm, pitch {:+.2} yaw {:+.2} roll {:+.2} deg",
        step[0],
        step[1],
        step[2],
        step[3].to_degrees(),
        step[4].to_degrees(),
        step[5].to_degrees()
    )
}

fn main() -> anyhow::Result<()> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let case_dir = PathBuf::from(&args[0]);
    let model = Model::load(&PathBuf::from(&args[1]))?;
    let (first, last): (usize, usize) = (args[2].parse()?, args[3].parse()?);
    let level: usize = args.get(4).map_or(Ok(0), |s| s.parse())?;
    let stride: usize = args.get(5).map_or(Ok(2), |s| s.parse())?;
    let PhantomRun { truth, frames, .. } = open_phantom(&case_dir, None)?;
    let light = model.calibrated().expect("a calibrated light");
    let gains = &light.gains;
    anyhow::ensure!(
        gains.len() == frames.len(),
        "the model has {} gains for {} frames: build it from every frame",
        gains.len(),
        frames.len()
    );
    let uniform = args.get(6).is_some_and(|s| s == "uniform");
    let mut parts = model.registration_parts().expect("a calibrated light");
    if uniform {
        parts.texture = None;
    }
    let camera = *parts.camera;
    let pm = PhotometricModel::new(parts)?;
    let o = RegistrationOptions::default();
    let grid = RayGrid::new(&camera, level, stride);
    let n_cos = COS_EDGES.len() + 1;
    let n_depth = DEPTH_EDGES.len() + 1;
    let mut sum_cos = vec![V7::zeros(); n_cos];
    let mut sum_depth = vec![V7::zeros(); n_depth];
    let mut sum_all = V7::zeros();
    for f in first..=last.min(frames.len() - 1) {
        let pose = &truth[f];
        let pyr = ObservedPyramid::new(
            &frames[f],
            &camera,
            gains[f],
            None,
            &PyramidOptions {
                levels: level.max(1),
                saturation_level: o.saturation_level,
            },
        )?;
        let view = pm.view(&grid, pose, o.min_gamma);
        let centre = bronchosim::camera::pose::camera_centre(pose).coords;
        let mut prob = LevelProblem {
            image: &pyr.levels[level],
            light: &pm.light,
            points: view.points,
            offset: view.offset,
            inv_sigma: Vec::new(),
            huber: o.huber,
            dark: (f64::from(o.noise_floor) / gains[f]) as f32,
            ref_cost: Vec::new(),
            model_grad: Vec::new(),
            grad_blend: 0.0,
        };
        let at = prob.at_rendered(pose);
        prob.set_reference(&at, 0.0, o.relative_sigma, f64::from(prob.dark), [1.0; 3]);
        let rows = prob.point_rows(pose, 0.0);
        let mut h = M7::zeros();
        let mut g_all = V7::zeros();
        let mut g_cos = vec![V7::zeros(); n_cos];
        let mut g_depth = vec![V7::zeros(); n_depth];
        for r in &rows {
            let q = &prob.points[r.point as usize];
            let a = f64::from(q.albedo[r.channel as usize]);
            let e = r.residual(a);
            let w = if e.abs() <= o.huber {
                1.0
            } else {
                o.huber / e.abs()
            };
            let j = V7::from(r.jacobian(a));
            h += w * j * j.transpose();
            let gj = w * e * j;
            g_all += gj;
            let ray = q.x - centre;
            let depth = ray.norm();
            let cos = (-ray.dot(&q.n) / depth).abs();
            g_cos[bin(&COS_EDGES, cos)] += gj;
            g_depth[bin(&DEPTH_EDGES, depth)] += gj;
        }
        let Some(hi) = h.try_inverse() else {
            println!("frame {f:3}: singular");
            continue;
        };
        let step = -(hi * g_all);
        println!("frame {f:3} ({} rows): {}", rows.len(), show(&step));
        sum_all += step;
        for (s, g) in sum_cos.iter_mut().zip(&g_cos) {
            *s += -(hi * g);
        }
        for (s, g) in sum_depth.iter_mut().zip(&g_depth) {
            *s += -(hi * g);
        }
    }
    let n = (last.min(frames.len() - 1) + 1 - first) as f64;
    println!(
        "mean pull over frames {first}-{last}: {}",
        show(&(sum_all / n))
    );
    for (b, s) in sum_cos.iter().enumerate() {
        let lo = if b == 0 { 0.0 } else { COS_EDGES[b - 1] };
        let hi = COS_EDGES.get(b).copied().unwrap_or(1.0);
        println!("  cos {lo:.1}-{hi:.1}: {}", show(&(s / n)));
    }
    for (b, s) in sum_depth.iter().enumerate() {
        let lo = if b == 0 { 0.0 } else { DEPTH_EDGES[b - 1] };
        let hi = DEPTH_EDGES.get(b).copied().unwrap_or(f64::INFINITY);
        println!("  depth {lo:.0}-{hi:.0} mm: {}", show(&(s / n)));
    }
    Ok(())
}
