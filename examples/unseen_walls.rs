//! Issue 18's measure of walls the video never saw, on a phantom model: the model's texture on
//! its unseen texels (coverage.png = 0; synthesised with `build --unseen synthesise`) against
//! the phantom's true albedo there, beside today's fill computed from the same seen texels.
//! Statistics a viewer notices: mean colour, contrast (std of the luminance), the radially
//! averaged power spectrum of the luminance; the seam (mean luminance step across the border
//! of the seen region against the step between seen neighbours); and, for completeness, the
//! texel-wise relative RMS (which no synthesis can win: the fill's smear is the least-squares
//! guess).
//!
//! Build a phantom model from part of its video (e.g. the first half of poses.json), then
//! `cargo run --release --example unseen_walls -- MODEL_DIR CASE_DIR/truth [WINDOW_TEXELS]`

use std::path::Path;

use bronchosim::io::png::read_png;
use bronchosim::math::Point3;
use bronchosim::model::Model;
use bronchosim::phantom::case::phantom_albedo;
use bronchosim::texture::atlas::fill_uncovered;
use bronchosim::texture::synthesis::stats::{
    region_stats, seam_gradients, spectrum_distance, RegionStats,
};
use bronchosim::{Error, Result};

fn main() -> Result<()> {
    let args: Vec<String> = std::env::args().collect();
    if args.len() < 3 {
        eprintln!("usage: unseen_walls MODEL_DIR TRUTH_DIR [WINDOW_TEXELS]");
        std::process::exit(2);
    }
    let (model_dir, truth_dir) = (Path::new(&args[1]), Path::new(&args[2]));
    let window: usize = args
        .get(3)
        .map_or(Ok(32), |s| s.parse())
        .map_err(|_| Error::Other(format!("window {:?} is not a number of texels", args[3])))?;
    let model = Model::load(model_dir)?;
    let albedo = read_png(&model_dir.join("albedo.png"))?;
    let coverage = read_png(&model_dir.join("coverage.png"))?;
    let (w, h) = (albedo.width as usize, albedo.height as usize);
    if (coverage.width, coverage.height) != (albedo.width, albedo.height) {
        return Err(Error::invalid(
            model_dir.join("coverage.png"),
            "not the size of albedo.png",
        ));
    }
    let truth_json = truth_dir.join("truth.json");
    let text = std::fs::read_to_string(&truth_json).map_err(|e| Error::io(&truth_json, e))?;
    let seed = serde_json::from_str::<serde_json::Value>(&text)
        .ok()
        .and_then(|v| v["seed"].as_u64())
        .ok_or_else(|| Error::invalid(&truth_json, "no integer seed"))?;
    let mucosa = phantom_albedo(seed);

    let points = texel_points(&model, w, h);
    let chart: Vec<u32> = points
        .iter()
        .map(|p| if p.is_some() { 0 } else { u32::MAX })
        .collect();
    let seen: Vec<bool> = (0..w * h)
        .map(|i| points[i].is_some() && coverage.rgb[3 * i] > 0.5)
        .collect();
    let unseen: Vec<bool> = (0..w * h)
        .map(|i| points[i].is_some() && !seen[i])
        .collect();
    let mut truth = vec![0.0f32; 3 * w * h];
    for (i, p) in points.iter().enumerate() {
        if let Some(p) = p {
            let c = mucosa.eval(Point3::new(p[0] as f64, p[1] as f64, p[2] as f64));
            truth[3 * i..3 * i + 3].copy_from_slice(&c);
        }
    }
    // The texture is relative: one least-squares scale per channel on the seen texels.
    let k: [f64; 3] = std::array::from_fn(|c| {
        let (mut at, mut aa) = (0.0f64, 0.0f64);
        for i in (0..w * h).filter(|&i| seen[i]) {
            at += albedo.rgb[3 * i + c] as f64 * truth[3 * i + c] as f64;
            aa += (albedo.rgb[3 * i + c] as f64).powi(2);
        }
        at / aa.max(1e-300)
    });
    let model_rgb: Vec<f32> = albedo
        .rgb
        .iter()
        .enumerate()
        .map(|(j, &v)| v * k[j % 3] as f32)
        .collect();
    let mut fill = model_rgb.clone();
    fill_uncovered(&mut fill, w, h, &seen, &chart)?;

    let n_unseen = unseen.iter().filter(|&&u| u).count();
    let n_chart = points.iter().filter(|p| p.is_some()).count();
    println!(
        "{}: atlas {w}x{h}, {} chart texels, unseen {} ({:.1}%), spectrum windows {window} texels",
        model_dir.display(),
        n_chart,
        n_unseen,
        100.0 * n_unseen as f64 / n_chart.max(1) as f64
    );
    let t = region_stats(&truth, w, h, &unseen, window);
    let rows = [
        ("truth", &truth),
        ("model (as built)", &model_rgb),
        ("today's fill", &fill),
    ];
    println!("| unseen walls | mean RGB | lum. std | spectrum log10 RMS vs truth | seam across / within seen / seen near border | texel rel. RMS |");
    println!("|---|---|---|---|---|---|");
    for (name, rgb) in rows {
        let s = region_stats(rgb, w, h, &unseen, window);
        let seam = seam_gradients(rgb, w, &seen, &unseen, &chart);
        println!(
            "| {name} | {} | {:.4} | {:.3} | {:.4} / {:.4} / {:.4} ({} pairs) | {:.1}% |",
            fmt_rgb(&s),
            s.luminance_std,
            spectrum_distance(&s.spectrum, &t.spectrum),
            seam.across,
            seam.within_seen,
            seam.within_seen_near,
            seam.border_pairs,
            100.0 * relative_rms(rgb, &truth, &unseen)
        );
    }
    println!("spectrum windows in the unseen region: {}", t.windows);
    let ts = region_stats(&truth, w, h, &seen, window);
    let ms = region_stats(&model_rgb, w, h, &seen, window);
    println!(
        "seen walls for reference: truth lum. std {:.4}, model {:.4}, spectrum log10 RMS {:.3}",
        ts.luminance_std,
        ms.luminance_std,
        spectrum_distance(&ms.spectrum, &ts.spectrum)
    );
    Ok(())
}

fn fmt_rgb(s: &RegionStats) -> String {
    format!(
        "{:.3} {:.3} {:.3}",
        s.mean_rgb[0], s.mean_rgb[1], s.mean_rgb[2]
    )
}

/// `sqrt(sum (a - t)^2 / sum t^2)` over the masked texels, mean of the channels.
fn relative_rms(a: &[f32], t: &[f32], mask: &[bool]) -> f64 {
    (0..3)
        .map(|c| {
            let (mut e, mut n) = (0.0f64, 0.0f64);
            for i in (0..mask.len()).filter(|&i| mask[i]) {
                e += (a[3 * i + c] as f64 - t[3 * i + c] as f64).powi(2);
                n += (t[3 * i + c] as f64).powi(2);
            }
            (e / n.max(1e-300)).sqrt() / 3.0
        })
        .sum()
}

/// The 3-D point (world mm) of every texel whose centre lies in a triangle of the model's
/// atlas (UVs in [0, 1], texel (x, y) centred at ((x + 0.5) / w, (y + 0.5) / h)).
fn texel_points(model: &Model, w: usize, h: usize) -> Vec<Option<[f32; 3]>> {
    let mut out = vec![None; w * h];
    for (t, tri) in model.mesh.triangles.iter().enumerate() {
        let uv =
            model.tri_uv[t].map(|q| [q[0] as f64 * w as f64 - 0.5, q[1] as f64 * h as f64 - 0.5]);
        let p = tri.map(|v| {
            let q = model.mesh.positions[v as usize];
            [q.x, q.y, q.z]
        });
        let area = (uv[1][0] - uv[0][0]) * (uv[2][1] - uv[0][1])
            - (uv[2][0] - uv[0][0]) * (uv[1][1] - uv[0][1]);
        if area.abs() < 1e-12 {
            continue;
        }
        let lo = |k: usize| {
            uv.iter()
                .map(|q| q[k])
                .fold(f64::INFINITY, f64::min)
                .floor()
                .max(0.0) as usize
        };
        let hi = |k: usize, n: usize| {
            (uv.iter()
                .map(|q| q[k])
                .fold(f64::NEG_INFINITY, f64::max)
                .ceil() as usize)
                .min(n - 1)
        };
        for y in lo(1)..=hi(1, h) {
            for x in lo(0)..=hi(0, w) {
                let (px, py) = (x as f64, y as f64);
                let b1 = ((px - uv[0][0]) * (uv[2][1] - uv[0][1])
                    - (uv[2][0] - uv[0][0]) * (py - uv[0][1]))
                    / area;
                let b2 = ((uv[1][0] - uv[0][0]) * (py - uv[0][1])
                    - (px - uv[0][0]) * (uv[1][1] - uv[0][1]))
                    / area;
                let b0 = 1.0 - b1 - b2;
                if b0 < 0.0 || b1 < 0.0 || b2 < 0.0 {
                    continue;
                }
                out[y * w + x] = Some(std::array::from_fn(|k| {
                    (b0 * p[0][k] as f64 + b1 * p[1][k] as f64 + b2 * p[2][k] as f64) as f32
                }));
            }
        }
    }
    out
}
