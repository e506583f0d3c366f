//! Issue 18 item 2, from the video instead of the CT: can the frames themselves say where the
//! surface's normal departs from the mesh's? The light sits at the lens, so as the camera
//! passes a texel it lights it from changing directions; a tilt of the normal brightens the
//! texel in some frames and darkens it in others, which a different albedo cannot do.
//!
//! Per texel, every frame that sees it gives `log(I / (g (A S(n0) + P)))` against the model
//! light's derivatives in the normal's two tangent directions: a linear least-squares problem
//! in (log scale, u, v), accumulated over the video, smoothed over `SIGMA` texels in the
//! atlas and damped by `LAMBDA`. The tilted normals `n0 + u t1 + v t2` then shade the model's
//! surface in the truth views (the model's light times the true albedo, as `ssim_budget`), and
//! their angle to the true surface's normals is compared with the mesh's.
//!
//! `cargo run --release --example photometric_normals -- MODEL CASE [SIGMA LAMBDA [WIDE]]`

#[path = "common/truth_surface.rs"]
mod truth_surface;

use std::path::Path;

use bronchosim::camera::pose::camera_centre;
use bronchosim::image::Frame;
use bronchosim::io::camera_file::read_camera;
use bronchosim::io::case::Case;
use bronchosim::math::{Affine, Vector3};
use bronchosim::model::Model;
use bronchosim::raycast::cast_frame_with;
use bronchosim::registration::photometric::{PhotometricModel, RayGrid};
use bronchosim::registration::pose::rotation_of;
use bronchosim::render::evaluate::{evaluate_methods, MaskedImage};
use bronchosim::render::views_io::load_truth;
use bronchosim::shading::LUMA;
use rayon::prelude::*;
use truth_surface::{both_views, read_view_image, TrueSurface};

/// Two unit tangents of `n`, the same for the same normal.
fn tangents(n: &Vector3<f64>) -> (Vector3<f64>, Vector3<f64>) {
    let a = if n.x.abs() < 0.9 {
        Vector3::x()
    } else {
        Vector3::y()
    };
    let t1 = n.cross(&a).normalize();
    (t1, n.cross(&t1))
}

/// The atlas texel of a hit (nearest), row-major.
fn texel_of(tri_uv: &[[[f32; 2]; 3]], tri: u32, bary: [f32; 2], w: usize, h: usize) -> usize {
    let [a, b, c] = tri_uv[tri as usize];
    let wa = 1.0 - bary[0] - bary[1];
    let u = wa * a[0] + bary[0] * b[0] + bary[1] * c[0];
    let v = wa * a[1] + bary[0] * b[1] + bary[1] * c[1];
    let x = ((u * w as f32) as usize).min(w - 1);
    let y = ((v * h as f32) as usize).min(h - 1);
    y * w + x
}

/// Luminance of the model's light (albedo `alb`) at camera-frame point `p` with normal `n`.
fn luminance(pm: &PhotometricModel, p: &Vector3<f64>, n: &Vector3<f64>, alb: [f32; 3]) -> f64 {
    let r = pm.light.radiance(p, n, alb);
    (0..3).map(|c| LUMA[c] * r[c]).sum()
}

/// Per texel: the normal equations of (log scale, u, v): 6 of the symmetric matrix, 3 of the
/// right-hand side.
const ACC: usize = 9;

fn main() -> bronchosim::Result<()> {
    let args: Vec<String> = std::env::args().collect();
    if args.len() < 3 {
        eprintln!("usage: photometric_normals MODEL CASE [SIGMA LAMBDA]");
        std::process::exit(2);
    }
    let model = Model::load(Path::new(&args[1]))?;
    let case = Case::open(Path::new(&args[2]))?;
    let sigma: f64 = args.get(3).map_or(Ok(1.5), |s| s.parse()).unwrap_or(1.5);
    let lambda: f64 = args.get(4).map_or(Ok(0.05), |s| s.parse()).unwrap_or(0.05);
    let wide: f64 = args.get(5).map_or(Ok(0.0), |s| s.parse()).unwrap_or(0.0);
    let parts = model
        .registration_parts()
        .ok_or_else(|| bronchosim::Error::Other("the model has no calibrated light".into()))?;
    let pm = PhotometricModel::new(parts)?;
    let light = parts.light;
    let (aw, ah) = (model.texture.width as usize, model.texture.height as usize);
    let grid = RayGrid::new(&case.camera, 0, 1);
    let mut acc = vec![0.0f64; ACC * aw * ah];
    let poses: Vec<Affine> = case.poses.iter().map(|p| p.pose.camera_to_world).collect();
    for (f, frame) in case.frame_source()?.enumerate() {
        let frame = frame?;
        let pose = poses[f];
        let gain = light.gains.get(f).copied().unwrap_or(1.0);
        let offset = pm.view(&grid, &pose, 0.0).offset;
        let off_y: f64 = (0..3).map(|c| LUMA[c] * offset[c]).sum();
        let g = cast_frame_with(parts.scene, &grid.rays, &pose);
        let (r, c) = (rotation_of(&pose).transpose(), camera_centre(&pose).coords);
        let obs: Vec<(usize, [f64; ACC])> = (0..g.z.len())
            .into_par_iter()
            .filter_map(|i| {
                if !g.hit(i) || g.gamma[i] < 0.15 {
                    return None;
                }
                let px = &frame.rgb[3 * i..3 * i + 3];
                if px.iter().any(|&v| v >= 0.98) {
                    return None;
                }
                let t = texel_of(parts.tri_uv, g.tri[i], g.bary[i], aw, ah);
                let x = Vector3::new(g.point[i][0], g.point[i][1], g.point[i][2]).cast::<f64>();
                let n0 = Vector3::new(g.normal[i][0], g.normal[i][1], g.normal[i][2]).cast::<f64>();
                let (t1, t2) = tangents(&n0);
                let alb = model.texture.sample(
                    (t % aw) as f32 / aw as f32 + 0.5 / aw as f32,
                    (t / aw) as f32 / ah as f32 + 0.5 / ah as f32,
                    0.0,
                );
                let p = r * (x - c);
                let s0 = luminance(&pm, &p, &(r * n0), alb);
                let eps = 0.01;
                let su = (luminance(&pm, &p, &(r * (n0 + t1 * eps).normalize()), alb) - s0) / eps;
                let sv = (luminance(&pm, &p, &(r * (n0 + t2 * eps).normalize()), alb) - s0) / eps;
                let y: f64 = (0..3).map(|k| LUMA[k] * f64::from(px[k])).sum::<f64>() / gain - off_y;
                if s0 <= 1e-6 || y <= 0.05 * s0 {
                    return None;
                }
                let z = (y / s0).ln();
                let j = [1.0, su / s0, sv / s0];
                // Relative noise falls with the signal: weigh by it.
                let w = y * gain;
                Some((
                    t,
                    [
                        w * j[0] * j[0],
                        w * j[0] * j[1],
                        w * j[0] * j[2],
                        w * j[1] * j[1],
                        w * j[1] * j[2],
                        w * j[2] * j[2],
                        w * j[0] * z,
                        w * j[1] * z,
                        w * j[2] * z,
                    ],
                ))
            })
            .collect();
        for (t, a) in obs {
            for (dst, v) in acc[ACC * t..ACC * (t + 1)].iter_mut().zip(a) {
                *dst += v;
            }
        }
    }
    // The tilt at the texels' scale; with WIDE, less the tilt at that wider scale: the light
    // model's own error varies slowly over the surface and tilts every normal of a region
    // alike, the relief the mesh misses (rings, facets) does not.
    let fine = solve_tilts(&smooth(&acc, aw, ah, sigma), lambda);
    let tilt: Vec<[f64; 2]> = if wide > 0.0 {
        let broad = solve_tilts(&smooth(&acc, aw, ah, wide), lambda);
        fine.iter()
            .zip(&broad)
            .map(|(f, b)| [f[0] - b[0], f[1] - b[1]])
            .collect()
    } else {
        fine
    };

    // Score in the truth views: the model's light with the mesh's, the tilted and the true
    // normals, times the true albedo.
    let truth = Path::new(&args[2]).join("truth");
    let true_surface = TrueSurface::read(&truth)?;
    let true_pm = true_surface.model(parts)?;
    let (views, references) = load_truth(&truth)?;
    // The truth views' own camera (undistorted), not the video's.
    let camera = &read_camera(&truth.join("camera.json"))?;
    let vgrid = RayGrid::new(camera, 0, 1);
    let names = ["mesh normals", "photometric normals", "true normals"];
    // Per view, per compared pixel: (pixel, camera-frame point, the three normals in the
    // camera frame, true albedo, model albedo, the view's offset).
    type Px = (
        usize,
        Vector3<f64>,
        [Vector3<f64>; 3],
        [f64; 3],
        [f32; 3],
        [f64; 3],
    );
    let mut per_view: Vec<Vec<Px>> = Vec::new();
    let mut angle_sum = [0.0f64; 2];
    let mut angle_n = 0usize;
    for view in &views {
        let true_albedo = read_view_image(view, "albedo", camera)?;
        let pose = view.camera_to_world;
        let (r, c) = (rotation_of(&pose).transpose(), camera_centre(&pose).coords);
        let (mv, tv, on_true) = both_views(&pm, &true_pm, &vgrid, &pose);
        let g = cast_frame_with(parts.scene, &vgrid.rays, &pose);
        let mut pixels = Vec::new();
        for q in &mv.points {
            let i = q.ray as usize;
            let Some(t) = on_true[i].map(|k| &tv.points[k]) else {
                continue;
            };
            let ta: [f64; 3] = std::array::from_fn(|k| f64::from(true_albedo.rgb[3 * i + k]));
            if ta.iter().any(|&a| a <= 1e-3) || !g.hit(i) {
                continue;
            }
            let tex = texel_of(parts.tri_uv, g.tri[i], g.bary[i], aw, ah);
            let n0 = q.n.normalize();
            let (t1, t2) = tangents(&n0);
            let [u, v] = tilt[tex];
            let n_ph = (n0 + t1 * u + t2 * v).normalize();
            let tn = t.n.normalize();
            angle_sum[0] += n0.dot(&tn).clamp(-1.0, 1.0).acos().to_degrees();
            angle_sum[1] += n_ph.dot(&tn).clamp(-1.0, 1.0).acos().to_degrees();
            angle_n += 1;
            pixels.push((
                i,
                r * (q.x - c),
                [r * n0, r * n_ph, r * tn],
                ta,
                q.albedo,
                mv.offset,
            ));
        }
        per_view.push(pixels);
    }
    // The model's albedo is relative: its scale against the true one, per channel.
    let kappa: [f64; 3] = std::array::from_fn(|k| {
        let mut v: Vec<f64> = per_view
            .iter()
            .flatten()
            .map(|p| f64::from(p.4[k]) / p.3[k])
            .collect();
        let mid = v.len() / 2;
        *v.select_nth_unstable_by(mid, f64::total_cmp).1
    });
    let mut images: Vec<Vec<MaskedImage>> = vec![Vec::new(); 3];
    for pixels in &per_view {
        let mut mask = vec![false; (camera.width * camera.height) as usize];
        let mut frames: Vec<Frame> = (0..3)
            .map(|_| Frame::new(camera.width, camera.height))
            .collect();
        for (i, p, normals, ta, _, offset) in pixels {
            mask[*i] = true;
            let alb: [f32; 3] = std::array::from_fn(|k| (kappa[k] * ta[k]) as f32);
            for (m, n) in normals.iter().enumerate() {
                let rad = pm.light.radiance(p, n, alb);
                for k in 0..3 {
                    frames[m].rgb[3 * i + k] = (rad[k] + offset[k]) as f32;
                }
            }
        }
        for (m, frame) in frames.into_iter().enumerate() {
            images[m].push(MaskedImage {
                frame,
                mask: mask.clone(),
            });
        }
    }
    println!(
        "sigma {sigma} texels, lambda {lambda}, wide {wide}: mean angle to the true normals: mesh {:.2} deg, photometric {:.2} deg",
        angle_sum[0] / angle_n as f64,
        angle_sum[1] / angle_n as f64
    );
    let methods: Vec<(String, Vec<MaskedImage>)> = names
        .iter()
        .zip(images)
        .map(|(n, i)| (format!("model light with {n} x true albedo"), i))
        .collect();
    let view_names: Vec<String> = views.iter().map(|v| v.name.clone()).collect();
    for s in evaluate_methods(&methods, &references, &view_names)? {
        println!(
            "{}: PSNR {:.2} dB, SSIM {:.4}",
            s.method, s.mean_psnr_db, s.mean_ssim
        );
    }
    Ok(())
}

/// The per-texel normal equations smoothed over the atlas by a Gaussian of `sigma` texels.
fn smooth(acc: &[f64], aw: usize, ah: usize, sigma: f64) -> Vec<f64> {
    let k: Vec<f64> = {
        let r = (3.0 * sigma).ceil() as i64;
        (-r..=r)
            .map(|x| (-(x * x) as f64 / (2.0 * sigma * sigma)).exp())
            .collect()
    };
    let r = (k.len() / 2) as i64;
    let mut acc = acc.to_vec();
    for pass in 0..2 {
        let src = acc.clone();
        acc.par_chunks_mut(ACC * aw)
            .enumerate()
            .for_each(|(y, row)| {
                for x in 0..aw {
                    let mut s = [0.0; ACC];
                    for (ti, &wk) in k.iter().enumerate() {
                        let d = ti as i64 - r;
                        let (xx, yy) = if pass == 0 {
                            (x as i64 + d, y as i64)
                        } else {
                            (x as i64, y as i64 + d)
                        };
                        if xx < 0 || yy < 0 || xx >= aw as i64 || yy >= ah as i64 {
                            continue;
                        }
                        let o = ACC * (yy as usize * aw + xx as usize);
                        for a in 0..ACC {
                            s[a] += wk * src[o + a];
                        }
                    }
                    row[ACC * x..ACC * (x + 1)].copy_from_slice(&s);
                }
            });
    }
    acc
}

/// Each texel's tilt (u, v) from its normal equations, damped by `lambda` times its weight.
fn solve_tilts(acc: &[f64], lambda: f64) -> Vec<[f64; 2]> {
    acc.par_chunks(ACC)
        .map(|a| {
            if a[0] <= 0.0 {
                return [0.0; 2];
            }
            let d = lambda * a[0];
            let m = nalgebra::Matrix3::new(
                a[0],
                a[1],
                a[2],
                a[1],
                a[3] + d,
                a[4],
                a[2],
                a[4],
                a[5] + d,
            );
            let b = nalgebra::Vector3::new(a[6], a[7], a[8]);
            match m.cholesky() {
                Some(ch) => {
                    let x = ch.solve(&b);
                    [x[1].clamp(-0.6, 0.6), x[2].clamp(-0.6, 0.6)]
                }
                None => [0.0; 2],
            }
        })
        .collect()
}
