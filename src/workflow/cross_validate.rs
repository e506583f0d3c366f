//! Honest self-assessment without ground truth (issue 8, item 4): hold out every k-th frame
//! from texture fusion, render each held-out frame from its pose as a new view, and compare it
//! with the recorded frame (after one least-squares gain per channel) on the pixels that obey
//! the shading model. Done for both shading models, each with its own de-lit texture.
//!
//! Protocol, the same for both models: the held-out frames give no texture; the paper's new
//! view takes the Psi of the nearest *training* viewpoint (the held-out frame's own Psi is not
//! used); the calibrated light's rho and s are shared by all frames (7 numbers fitted on the
//! whole video; the held-out frame's own gain is replaced by the gain fit of the comparison).

use serde::{Deserialize, Serialize};

use crate::image::Frame;
use crate::io::case::Case;
use crate::raycast::{cast_frame_with, RayTable, Scene};
use crate::render::{
    evaluate_methods, render_view_with, MaskedImage, MipOptions, MipTexture, RenderInputs,
    RenderOptions, ShadingMode, ViewRays, ViewpointIndex,
};
use crate::shading::psi::PsiModel;
use crate::shading::{CalibratedModel, SampleOptions};
use crate::texture::fusion::{fuse, FusionOptions};
use crate::texture::texels::TexelSet;
use crate::workflow::build_frames::{CaseFrames, DepthCache, FrameShadingSource};
use crate::workflow::progress::Progress;
use crate::{Error, Result};

/// One held-out frame's prediction score.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct HeldOutScore {
    /// Frame index.
    pub frame: usize,
    /// Pixels compared.
    pub pixels: usize,
    /// PSNR (dB) of the sRGB-encoded prediction after its gain fit.
    pub psnr_db: Option<f64>,
    /// SSIM of the same.
    pub ssim: Option<f64>,
}

/// One shading model's cross-validation.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct ModelCrossValidation {
    /// "paper" or "calibrated".
    pub model: String,
    /// Mean PSNR over the held-out frames (dB).
    pub mean_psnr_db: Option<f64>,
    /// Mean SSIM over the held-out frames.
    pub mean_ssim: Option<f64>,
    /// Per held-out frame.
    pub frames: Vec<HeldOutScore>,
}

/// The cross-validation of a build (model.json `cross_validation`).
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct CrossValidation {
    /// Every `every`-th frame was held out.
    pub every: usize,
    /// The held-out frames.
    pub held_out: Vec<usize>,
    /// One entry per shading model.
    pub models: Vec<ModelCrossValidation>,
}

/// What the cross-validation works on (the build's state after the fit pass).
pub struct CrossValidationInputs<'a> {
    /// The case.
    pub case: &'a Case,
    /// The atlas mesh, for ray casting.
    pub scene: &'a Scene,
    /// The training camera's rays.
    pub rays: &'a RayTable,
    /// Texels of the atlas.
    pub texels: &'a TexelSet,
    /// UV corners per triangle of the atlas mesh.
    pub tri_uv: &'a [[[f32; 2]; 3]],
    /// Atlas size (texels) and texel size (mm).
    pub atlas_size: [u32; 2],
    /// Texel size (mm).
    pub texel_mm: f64,
    /// Psi of every frame.
    pub psi: &'a [PsiModel],
    /// The calibrated light, when it was fitted.
    pub calibrated: Option<&'a CalibratedModel>,
    /// Depth buffers of the fit pass.
    pub cache: &'a DepthCache,
    /// Fusion options of the build.
    pub fusion: &'a FusionOptions,
    /// Pixel thresholds of the fit.
    pub samples: &'a SampleOptions,
    /// No progress bars.
    pub quiet: bool,
}

/// The held-out frames: every `every`-th frame starting at `every / 2`, at most `max` of them
/// (evenly thinned), so that both neighbours of each are training frames.
pub fn held_out_frames(n: usize, every: usize, max: usize) -> Vec<usize> {
    let every = every.max(2);
    let all: Vec<usize> = (every / 2..n.saturating_sub(1)).step_by(every).collect();
    if all.len() <= max.max(1) {
        return all;
    }
    let m = max.max(1);
    (0..m).map(|k| all[k * all.len() / m]).collect()
}

/// Run the cross-validation for the paper's Psi and, when fitted, the calibrated light.
pub fn cross_validate(
    inp: &CrossValidationInputs,
    every: usize,
    max_frames: usize,
) -> Result<CrossValidation> {
    let n = inp.case.frame_count();
    let held = held_out_frames(n, every, max_frames);
    if held.is_empty() {
        return Err(Error::Other(format!(
            "cross-validation: {n} frames are too few to hold out every {every}-th"
        )));
    }
    let train: Vec<usize> = (0..n).filter(|i| !held.contains(i)).collect();
    // The held-out frames and the pixels of each that obey the model.
    let mut frames: Vec<(usize, Frame, Vec<bool>)> = Vec::with_capacity(held.len());
    for (i, f) in inp.case.frames_at(&held)? {
        let g = cast_frame_with(inp.scene, inp.rays, &inp.case.poses[i].pose.camera_to_world);
        let s = inp.samples;
        let mask = (0..g.z.len())
            .map(|p| {
                let px = &f.rgb[3 * p..3 * p + 3];
                g.hit(p)
                    && g.gamma[p] >= s.min_gamma
                    && px.iter().all(|&v| v < s.saturation_level)
                    && px.iter().any(|&v| v >= s.noise_floor)
            })
            .collect();
        frames.push((i, f, mask));
    }
    let train_psi: Vec<PsiModel> = train.iter().map(|&i| inp.psi[i].clone()).collect();
    let index = ViewpointIndex::new(&train_psi);
    let view_rays = ViewRays::new(&inp.case.camera, 1)?;
    let mut models = vec![(
        "paper",
        FrameShadingSource::Paper(inp.psi),
        None::<&CalibratedModel>,
    )];
    if let Some(c) = inp.calibrated {
        models.push(("calibrated", FrameShadingSource::Calibrated(c), Some(c)));
    }
    let mut out = Vec::new();
    for (name, source, calibrated) in models {
        let passes = inp.fusion.method.passes();
        let mut stream = CaseFrames::new(
            inp.case,
            inp.scene,
            inp.rays,
            source,
            inp.cache,
            train.clone(),
            Progress::new(
                &format!("cross-validate {name}"),
                (passes * train.len()) as u64,
                inp.quiet,
            ),
        );
        let fused = fuse(inp.texels, &mut stream, inp.fusion)?;
        stream.progress.finish();
        let image = Frame {
            width: inp.atlas_size[0],
            height: inp.atlas_size[1],
            rgb: fused.filled(inp.texels)?,
        };
        let texture = MipTexture::new(&image, None, inp.texel_mm, &MipOptions::default())?;
        let inputs = RenderInputs {
            scene: inp.scene,
            tri_uv: inp.tri_uv,
            texture: &texture,
            psi: &train_psi,
            index: &index,
            calibrated,
        };
        let opts = RenderOptions {
            shading: ShadingMode::Nearest,
            ..Default::default()
        };
        let mut scores = Vec::new();
        for (i, frame, mask) in &frames {
            let pose = &inp.case.poses[*i].pose.camera_to_world;
            let (pred, hit) = render_view_with(&inputs, &view_rays, pose, &opts)?;
            let truth = MaskedImage {
                frame: frame.clone(),
                mask: mask.clone(),
            };
            let label = format!("frame {i}");
            let s = evaluate_methods(
                &[(
                    name.to_string(),
                    vec![MaskedImage {
                        frame: pred,
                        mask: hit,
                    }],
                )],
                &[truth],
                std::slice::from_ref(&label),
            )?;
            let v = &s[0].views[0];
            scores.push(HeldOutScore {
                frame: *i,
                pixels: v.pixels,
                psnr_db: v.psnr_db,
                ssim: v.ssim,
            });
        }
        let mean = |f: &dyn Fn(&HeldOutScore) -> Option<f64>| {
            let v: Vec<f64> = scores.iter().filter_map(f).collect();
            (!v.is_empty()).then(|| v.iter().sum::<f64>() / v.len() as f64)
        };
        out.push(ModelCrossValidation {
            model: name.to_string(),
            mean_psnr_db: mean(&|s| s.psnr_db),
            mean_ssim: mean(&|s| s.ssim),
            frames: scores,
        });
    }
    Ok(CrossValidation {
        every,
        held_out: held,
        models: out,
    })
}

impl CrossValidation {
    /// The model with the higher mean held-out PSNR ("paper" when none scored).
    pub fn winner(&self) -> &str {
        self.models
            .iter()
            .filter_map(|m| m.mean_psnr_db.map(|p| (m.model.as_str(), p)))
            .max_by(|a, b| a.1.total_cmp(&b.1))
            .map_or("paper", |(m, _)| m)
    }
}

#[cfg(test)]
mod tests {
    use super::held_out_frames;

    #[test]
    fn held_out_frames_have_training_neighbours() {
        assert_eq!(held_out_frames(20, 5, 100), vec![2, 7, 12, 17]);
        let h = held_out_frames(1000, 5, 24);
        assert_eq!(h.len(), 24);
        assert!(h.windows(2).all(|w| w[1] > w[0] + 5));
        assert!(held_out_frames(2, 5, 10).is_empty());
    }
}
