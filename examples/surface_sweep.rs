//! Experiment: can the video place the lumen's wall more precisely than the CT did? Each
//! vertex of a model's mesh is swept along its normal; at each offset a small patch of the
//! tangent plane is projected into every frame that sees the vertex, and the frames' patches
//! are compared (normalised cross-correlation, so the light and the gain drop out). The
//! offset where the frames agree best is the video's estimate of the wall there, and it is
//! compared with the phantom's true surface (truth/lumen.ply).
//!
//! ```sh
//! cargo run --release --example surface_sweep -- CASE MODEL POSES_DIR [range=0.2] [step=0.02]
//!     [spacing=0.04] [half=2] [frames=12] [mincos=0.3]
//! ```
//! POSES_DIR/poses.json gives the frames' poses (the case's truth folder for the true ones).

#[path = "common/phantom_run.rs"]
#[allow(dead_code)]
mod phantom_run;

use bronchosim::camera::pose::camera_centre;
use bronchosim::io::mesh_export::read_ply;
use bronchosim::math::{Affine, Point3, Vector3};
use bronchosim::model::Model;
use bronchosim::raycast::Scene;
use bronchosim::registration::pose::rotation_of;
use phantom_run::{open_phantom, PhantomRun};
use rayon::prelude::*;
use std::path::PathBuf;

/// One vertex's sweep.
#[derive(Clone, Copy)]
struct Swept {
    /// Offset along the normal to the true wall (mm).
    wall: f64,
    /// Offset where the frames agree best (mm).
    estimate: f64,
    /// The frames' mean pairwise correlation there.
    peak: f64,
}

/// Root mean square of `values`.
fn rms(values: impl Iterator<Item = f64>) -> f64 {
    let (sum, n) = values.fold((0.0, 0usize), |(s, n), v| (s + v * v, n + 1));
    (sum / n.max(1) as f64).sqrt()
}

/// Pearson correlation of the pairs.
fn correlation(pairs: &[(f64, f64)]) -> f64 {
    let n = pairs.len() as f64;
    let (ma, mb) = pairs
        .iter()
        .fold((0.0, 0.0), |(a, b), p| (a + p.0 / n, b + p.1 / n));
    let cov: f64 = pairs.iter().map(|p| (p.0 - ma) * (p.1 - mb)).sum();
    let sa = rms(pairs.iter().map(|p| p.0 - ma));
    let sb = rms(pairs.iter().map(|p| p.1 - mb));
    cov / n / (sa * sb)
}

struct Opts {
    range: f64,
    step: f64,
    spacing: f64,
    half: i32,
    frames: usize,
    mincos: f64,
}

fn main() -> anyhow::Result<()> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    if args.len() < 3 {
        anyhow::bail!(
            "usage: surface_sweep CASE MODEL POSES_DIR [key=value ...] (see the file's docs)"
        );
    }
    let case_dir = PathBuf::from(&args[0]);
    let model = Model::load(&PathBuf::from(&args[1]))?;
    let poses_dir = PathBuf::from(&args[2]);
    let mut o = Opts {
        range: 0.2,
        step: 0.02,
        spacing: 0.04,
        half: 2,
        frames: 12,
        mincos: 0.3,
    };
    for kv in &args[3..] {
        match kv.split_once('=') {
            Some(("range", v)) => o.range = v.parse()?,
            Some(("step", v)) => o.step = v.parse()?,
            Some(("spacing", v)) => o.spacing = v.parse()?,
            Some(("half", v)) => o.half = v.parse()?,
            Some(("frames", v)) => o.frames = v.parse()?,
            Some(("mincos", v)) => o.mincos = v.parse()?,
            _ => anyhow::bail!("unknown argument {kv}"),
        }
    }
    let PhantomRun {
        frames, entries, ..
    } = open_phantom(&case_dir, Some(&poses_dir))?;
    let poses: Vec<Affine> = entries.iter().map(|p| p.pose.camera_to_world).collect();
    let truth = Scene::new(&read_ply(&case_dir.join("truth/lumen.ply"))?)?;
    let cam = &model.manifest.camera;
    let mesh = &model.mesh;
    let normals = mesh.vertex_normals();
    let scene = &model.scene;
    let offsets: Vec<f64> = {
        let n = (o.range / o.step).round() as i32;
        (-n..=n).map(|i| f64::from(i) * o.step).collect()
    };
    let centres: Vec<Vector3<f64>> = poses.iter().map(|p| camera_centre(p).coords).collect();
    let rots: Vec<_> = poses.iter().map(|p| rotation_of(p).transpose()).collect();

    let results: Vec<Option<Swept>> = (0..mesh.positions.len())
        .into_par_iter()
        .map(|v| {
            let x0: Vector3<f64> = mesh.positions[v].coords.cast();
            let n: Vector3<f64> = normals[v].cast();
            if n.norm() < 0.5 {
                return None;
            }
            let n = n.normalize();
            // The true wall along the normal: the nearest hit of the true surface either way.
            let t_true = [1.0, -1.0]
                .iter()
                .filter_map(|&s| {
                    let d = n * s;
                    let h =
                        truth.closest_hit(x0.cast::<f32>().into(), d.cast::<f32>().into(), 0.5)?;
                    Some(s * f64::from(h.t))
                })
                .min_by(|a, b| a.abs().total_cmp(&b.abs()))?;
            // Frames that see the vertex, nearest (distance over the root of the incidence's
            // cosine: near and frontal) first.
            let mut seeing: Vec<(f64, usize)> = (0..frames.len())
                .filter_map(|f| {
                    let d = x0 - centres[f];
                    let dist = d.norm();
                    let cos = (n.dot(&d) / dist).abs();
                    if cos < o.mincos {
                        return None;
                    }
                    let p = rots[f] * d;
                    let px = cam.project(&Point3::from(p))?;
                    let m = 4.0;
                    if px.x < m
                        || px.y < m
                        || px.x > f64::from(cam.width) - 1.0 - m
                        || px.y > f64::from(cam.height) - 1.0 - m
                    {
                        return None;
                    }
                    let dir = d / dist;
                    let h = scene.closest_hit(
                        centres[f].cast::<f32>().into(),
                        dir.cast::<f32>().into(),
                        (dist + 0.5) as f32,
                    )?;
                    ((f64::from(h.t) - dist).abs() < 0.1).then_some((dist / cos.sqrt(), f))
                })
                .collect();
            if seeing.len() < 3 {
                return None;
            }
            seeing.sort_by(|a, b| a.0.total_cmp(&b.0));
            seeing.truncate(o.frames);
            let t1 = if n.x.abs() < 0.9 {
                n.cross(&Vector3::x())
            } else {
                n.cross(&Vector3::y())
            }
            .normalize();
            let t2 = n.cross(&t1);
            let side = 2 * o.half + 1;
            let scores: Vec<f64> = offsets
                .iter()
                .map(|&delta| {
                    let mut patches: Vec<Vec<f64>> = Vec::new();
                    for &(_, f) in &seeing {
                        let mut patch = Vec::with_capacity((side * side) as usize);
                        for i in -o.half..=o.half {
                            for j in -o.half..=o.half {
                                let x = x0
                                    + n * delta
                                    + t1 * (f64::from(i) * o.spacing)
                                    + t2 * (f64::from(j) * o.spacing);
                                let p = rots[f] * (x - centres[f]);
                                let Some(px) = cam.project(&Point3::from(p)) else {
                                    break;
                                };
                                let Some(c) = frames[f].bilinear(px.x, px.y) else {
                                    break;
                                };
                                patch.push(f64::from(c[0] + c[1] + c[2]));
                            }
                        }
                        if patch.len() != (side * side) as usize {
                            continue;
                        }
                        let mean = patch.iter().sum::<f64>() / patch.len() as f64;
                        let norm = patch.iter().map(|q| (q - mean).powi(2)).sum::<f64>().sqrt();
                        if norm <= 1e-9 {
                            continue;
                        }
                        patches.push(patch.iter().map(|q| (q - mean) / norm).collect());
                    }
                    if patches.len() < 3 {
                        return f64::NAN;
                    }
                    // Mean pairwise correlation = (|sum|^2 - m) / (m (m - 1)).
                    let m = patches.len() as f64;
                    let sum: Vec<f64> = (0..patches[0].len())
                        .map(|k| patches.iter().map(|p| p[k]).sum())
                        .collect();
                    (sum.iter().map(|s| s * s).sum::<f64>() - m) / (m * (m - 1.0))
                })
                .collect();
            if scores.iter().any(|s| s.is_nan()) {
                return None;
            }
            let (best, &peak) = scores
                .iter()
                .enumerate()
                .max_by(|a, b| a.1.total_cmp(b.1))?;
            let mut est = offsets[best];
            if best > 0 && best + 1 < scores.len() {
                let (a, b, c) = (scores[best - 1], scores[best], scores[best + 1]);
                let den = a - 2.0 * b + c;
                if den < 0.0 {
                    est += 0.5 * (a - c) / den * o.step;
                }
            } else {
                return None;
            }
            Some(Swept {
                wall: t_true,
                estimate: est,
                peak,
            })
        })
        .collect();
    // The estimates averaged over the vertices within a radius (the wall's error is smoother
    // than the sweep's noise).
    for radius in [0.5f64, 1.0, 2.0] {
        let cell = radius as f32;
        let key = |p: &Point3<f32>| {
            (
                (p.x / cell).floor() as i32,
                (p.y / cell).floor() as i32,
                (p.z / cell).floor() as i32,
            )
        };
        let mut grid: std::collections::HashMap<(i32, i32, i32), Vec<usize>> = Default::default();
        for (v, r) in results.iter().enumerate() {
            if r.is_some() {
                grid.entry(key(&mesh.positions[v])).or_default().push(v);
            }
        }
        let (mut before, mut after, mut count) = (0.0, 0.0, 0usize);
        for (v, r) in results.iter().enumerate() {
            let Some(Swept { wall: t_true, .. }) = r else {
                continue;
            };
            let (kx, ky, kz) = key(&mesh.positions[v]);
            let (mut num, mut den) = (0.0, 0.0);
            for dx in -1..=1 {
                for dy in -1..=1 {
                    for dz in -1..=1 {
                        for &u in grid.get(&(kx + dx, ky + dy, kz + dz)).into_iter().flatten() {
                            let d = (mesh.positions[u] - mesh.positions[v]).norm();
                            if f64::from(d) <= radius && normals[u].dot(&normals[v]) > 0.7 {
                                let r = results[u].unwrap();
                                let w = r.peak.max(0.0);
                                num += w * r.estimate;
                                den += w;
                            }
                        }
                    }
                }
            }
            if den > 0.0 {
                before += t_true * t_true;
                after += (t_true - num / den).powi(2);
                count += 1;
            }
        }
        println!(
            "averaged within {radius} mm: {count} vertices, RMS {:.3} -> {:.3} mm",
            (before / count as f64).sqrt(),
            (after / count as f64).sqrt()
        );
    }
    let got: Vec<Swept> = results.iter().flatten().copied().collect();
    println!(
        "{} of {} vertices swept (a true wall within 0.5 mm, 3 frames, an interior peak)",
        got.len(),
        results.len()
    );
    for min_peak in [0.0, 0.3, 0.5, 0.7, 0.8] {
        let sel: Vec<Swept> = got.iter().filter(|r| r.peak >= min_peak).copied().collect();
        if sel.is_empty() {
            continue;
        }
        let m = sel.len() as f64;
        println!(
            "peak >= {min_peak:.1}: {} vertices; wall from the mesh: mean {:+.3} RMS {:.3} mm; \
             after the sweep: RMS {:.3} mm; estimate mean {:+.3}; correlation {:.2}",
            sel.len(),
            sel.iter().map(|r| r.wall).sum::<f64>() / m,
            rms(sel.iter().map(|r| r.wall)),
            rms(sel.iter().map(|r| r.wall - r.estimate)),
            sel.iter().map(|r| r.estimate).sum::<f64>() / m,
            correlation(&sel.iter().map(|r| (r.wall, r.estimate)).collect::<Vec<_>>())
        );
    }
    Ok(())
}
