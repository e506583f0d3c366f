//! How close a model's texture is to the phantom's true albedo (issue 6's accuracy measure).
//!
//! Per truth view, the texture alone is rendered from the model (`albedo_only`) and compared
//! with the true albedo at each pixel-centre hit (`NNNNNN_albedo.png`, linear, code / 65535).
//! Pixels count where the model and the truth see the same surface (depths within
//! 0.3 mm + 2 %, truth depth from `NNNNNN_depth.png`, code / 100 mm) and a frame saw the
//! texel (the model's coverage.png). The texture is relative, so one least-squares scale per
//! channel, then `sqrt(sum (k r - t)^2 / sum t^2)`, averaged over the channels.

use std::path::Path;

use crate::io::png::read_png;
use crate::model::Model;
use crate::phantom::truth_io::read_png16;
use crate::raycast::cast_frame;
use crate::render::{read_views, render_view, MipOptions, MipTexture, RenderInputs, RenderOptions};
use crate::workflow::truth_eval::truth_camera;
use crate::{Error, Result};

/// The relative RMS error of a texture against the true albedo and the pixels it is over.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AlbedoError {
    /// `sqrt(sum (k r - t)^2 / sum t^2)` after the per-channel scale k, mean of the channels.
    pub relative_rms: f64,
    /// Pixels compared (over all truth views).
    pub pixels: usize,
}

/// One truth view: the texture rendered alone and the true albedo (linear RGB, row-major),
/// and the pixels where they can be compared (same surface within 0.3 mm + 2 %, observed).
pub struct TruthView {
    /// The model's texture at each pixel (unshaded).
    pub rendered: Vec<f32>,
    /// The true albedo at each pixel.
    pub truth: Vec<f32>,
    /// Where the two may be compared.
    pub valid: Vec<bool>,
    /// Image width (pixels).
    pub width: usize,
    /// Image height (pixels).
    pub height: usize,
}

/// `texture` on `model`'s mesh seen from every view of the phantom truth folder `truth_dir`,
/// beside the true albedo.
pub fn texture_against_truth(
    model: &Model,
    texture: &MipTexture,
    truth_dir: &Path,
) -> Result<Vec<TruthView>> {
    let camera = truth_camera(truth_dir)?;
    let views = read_views(&truth_dir.join("views.json"), truth_dir)?;
    let cov_png = read_png(&model.dir.join("coverage.png"))?;
    let coverage = MipTexture::new(
        &cov_png,
        None,
        model.manifest.texel_mm,
        &MipOptions { max_level: 0 },
    )?;
    let opts = RenderOptions {
        albedo_only: true,
        mipmap: false,
        ..Default::default()
    };
    let with = |t| RenderInputs {
        texture: t,
        ..model.render_inputs()
    };
    views
        .iter()
        .map(|v| {
            let (alb, hit) = render_view(&with(texture), &camera, &v.camera_to_world, &opts)?;
            let (cov, _) = render_view(&with(&coverage), &camera, &v.camera_to_world, &opts)?;
            let g = cast_frame(&model.scene, &camera, &v.camera_to_world);
            let stem = v.path.with_extension("").to_string_lossy().into_owned();
            let truth = read_png16(Path::new(&format!("{stem}_albedo.png")), 3)?;
            let depth = read_png16(Path::new(&format!("{stem}_depth.png")), 1)?;
            if truth.len() != 3 * hit.len() || depth.len() != hit.len() {
                return Err(Error::invalid(
                    &v.path,
                    "the truth albedo/depth images do not match the camera's size",
                ));
            }
            let valid = (0..hit.len())
                .map(|i| {
                    let (z, t) = (g.z[i], depth[i] as f32 / 100.0);
                    hit[i] && t > 0.0 && cov.rgb[3 * i] >= 0.999 && (z - t).abs() < 0.3 + 0.02 * t
                })
                .collect();
            Ok(TruthView {
                rendered: alb.rgb,
                truth: truth.iter().map(|&c| c as f32 / 65535.0).collect(),
                valid,
                width: camera.width as usize,
                height: camera.height as usize,
            })
        })
        .collect()
}

/// [`AlbedoError`] of `texture` (the model's own or its paper texture) on `model`'s mesh,
/// through the views of the phantom truth folder `truth_dir`.
pub fn albedo_error(model: &Model, texture: &MipTexture, truth_dir: &Path) -> Result<AlbedoError> {
    let (mut tr, mut rr, mut tt) = ([0f64; 3], [0f64; 3], [0f64; 3]);
    let mut pairs: Vec<([f32; 3], [f32; 3])> = Vec::new();
    for v in texture_against_truth(model, texture, truth_dir)? {
        for i in (0..v.valid.len()).filter(|&i| v.valid[i]) {
            let a: [f32; 3] = std::array::from_fn(|c| v.rendered[3 * i + c]);
            let b: [f32; 3] = std::array::from_fn(|c| v.truth[3 * i + c]);
            for c in 0..3 {
                tr[c] += (a[c] * b[c]) as f64;
                rr[c] += (a[c] * a[c]) as f64;
                tt[c] += (b[c] * b[c]) as f64;
            }
            pairs.push((a, b));
        }
    }
    if pairs.is_empty() {
        return Err(Error::Other(format!(
            "{}: no pixel where the model and the truth see the same surface",
            truth_dir.display()
        )));
    }
    let k: [f64; 3] = std::array::from_fn(|c| tr[c] / rr[c].max(1e-300));
    let relative_rms = (0..3)
        .map(|c| {
            let e: f64 = pairs
                .iter()
                .map(|(a, b)| (k[c] * a[c] as f64 - b[c] as f64).powi(2))
                .sum();
            (e / tt[c].max(1e-300)).sqrt() / 3.0
        })
        .sum();
    Ok(AlbedoError {
        relative_rms,
        pixels: pairs.len(),
    })
}
