//! Issue 18 item 4's sharpness measure on any phantom model: how much of the true albedo's
//! fine detail the fused texture keeps, through the phantom's truth views.
//!
//! Per truth view the texture alone is rendered (as `albedo_error` does) and the luminance of
//! it and of the true albedo are high-passed (the pixel minus the mean of its 3×3
//! neighbourhood) where all nine pixels see the same surface as the truth and were observed.
//! Printed: `energy` = RMS of the model's high-pass over the truth's (1: as much detail as the
//! truth; under 1: blurred), and `error` = RMS of their difference over the truth's RMS (0: the
//! detail is right), both after one least-squares scale of the luminance.
//!
//! `cargo run --release --example texture_sharpness -- MODEL_DIR CASE_DIR/truth`

use std::path::Path;

use bronchosim::model::Model;
use bronchosim::phantom::analysis::texture_against_truth;

fn lum(c: &[f32]) -> f64 {
    0.2126 * c[0] as f64 + 0.7152 * c[1] as f64 + 0.0722 * c[2] as f64
}

/// High-pass pairs (model, truth) of one view at the pixels whose 3×3 block is all `valid`.
fn high_pass(model: &[f64], truth: &[f64], valid: &[bool], w: usize, h: usize) -> Vec<(f64, f64)> {
    let mut out = Vec::new();
    for y in 1..h.saturating_sub(1) {
        for x in 1..w - 1 {
            let idx = |dx: usize, dy: usize| (y + dy - 1) * w + x + dx - 1;
            if !(0..3).all(|dy| (0..3).all(|dx| valid[idx(dx, dy)])) {
                continue;
            }
            let mean = |img: &[f64]| {
                (0..3)
                    .flat_map(|dy| (0..3).map(move |dx| (dx, dy)))
                    .map(|(dx, dy)| img[idx(dx, dy)])
                    .sum::<f64>()
                    / 9.0
            };
            let i = y * w + x;
            out.push((model[i] - mean(model), truth[i] - mean(truth)));
        }
    }
    out
}

fn main() -> bronchosim::Result<()> {
    let args: Vec<String> = std::env::args().collect();
    let [_, model, truth] = args.as_slice() else {
        eprintln!("usage: texture_sharpness MODEL_DIR TRUTH_DIR");
        std::process::exit(2);
    };
    let model = Model::load(Path::new(model))?;
    let mut pairs = Vec::new();
    let (mut lmt, mut lmm) = (0.0, 0.0);
    for v in texture_against_truth(&model, &model.texture, Path::new(truth))? {
        let m: Vec<f64> = v.rendered.chunks_exact(3).map(lum).collect();
        let t: Vec<f64> = v.truth.chunks_exact(3).map(lum).collect();
        for i in (0..v.valid.len()).filter(|&i| v.valid[i]) {
            lmt += m[i] * t[i];
            lmm += m[i] * m[i];
        }
        pairs.extend(high_pass(&m, &t, &v.valid, v.width, v.height));
    }
    let (mm, tt) = pairs
        .iter()
        .fold((0.0, 0.0), |(b, c), (m, t)| (b + m * m, c + t * t));
    // The texture is relative: the scale that maps its luminance onto the truth's.
    let k = lmt / lmm.max(1e-300);
    let err: f64 = pairs.iter().map(|(m, t)| (k * m - t).powi(2)).sum();
    println!(
        "high-pass over {} pixels: energy {:.3}, error {:.3}",
        pairs.len(),
        (k * k * mm / tt).sqrt(),
        (err / tt).sqrt()
    );
    Ok(())
}
