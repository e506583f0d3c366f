//! Honest self-assessment without ground truth (issue 8, item 4): hold out every k-th frame
//! from texture fusion, render each held-out frame from its pose as a new view, and compare it
//! with the recorded frame (after one least-squares gain per channel) on the pixels that obey
//! the shading model. Done for both shading models, each with its own de-lit texture.
//!
//! Protocol, the same for both models: the held-out frames give no texture; the paper's new
//! view takes the Psi of the nearest *training* viewpoint (the held-out frame's own Psi is not
//! used); the calibrated light's rho and s are shared by all frames (7 numbers fitted on the
//! whole video; the held-out frame's own gain is replaced by the gain fit of the comparison).

use super::error::BuildError;
use super::frames::Resolution;
use super::options::BuildOptions;
use super::scene::BuildScene;
use crate::image::Frame;
use crate::model::manifest::{CrossValidation, HeldOutScore, ModelCrossValidation};
use crate::render::{
    evaluate_methods, render_view_with, MaskedImage, MipOptions, MipTexture, RenderInputs,
    RenderOptions, ViewRays,
};
use crate::shading::paper::{PsiLookup, PsiModel};
use crate::shading::{FittedShading, ShadingKind};
use crate::texture::fusion::fuse;
use crate::Result;
use rayon::prelude::*;

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

/// Cross-validate every model `shading` holds (`opts.cross_validate_every`, at most
/// `opts.cross_validate_max_frames` held-out frames).
pub fn cross_validate(
    scene: &BuildScene,
    shading: &FittedShading,
    opts: &BuildOptions,
) -> Result<CrossValidation> {
    let n = scene.frame_count();
    let every = opts.cross_validate_every;
    let held = held_out_frames(n, every, opts.cross_validate_max_frames);
    if held.is_empty() {
        return Err(BuildError::TooFewFramesToHoldOut { frames: n, every }.into());
    }
    let train: Vec<usize> = (0..n).filter(|i| !held.contains(i)).collect();
    let frames = held_out_observations(scene, &held, opts)?;
    // New views of held-out frames take the paper's Psi of the training viewpoints only.
    // (None without Psi: the calibrated light alone is cross-validated.)
    let train_psi: Vec<PsiModel> = train
        .iter()
        .filter_map(|&i| shading.viewpoints.get(i).cloned())
        .collect();
    let train_shading = FittedShading::new(shading.model, train_psi, shading.calibrated.clone());
    let view_rays = ViewRays::new(&scene.camera, 1)?;
    let mut models = Vec::new();
    for kind in shading.kinds() {
        let shaders = shading.frame_shaders(kind)?;
        let mut stream = scene.frames(
            Resolution::Working,
            shaders,
            train.clone(),
            &format!("cross-validate {kind}"),
            opts.fusion.method.passes(),
            opts.quiet,
        );
        let fused = fuse(&scene.texels, &mut stream, &opts.fusion)?;
        stream.progress.finish();
        let image = Frame {
            width: scene.atlas.width,
            height: scene.atlas.height,
            rgb: fused.filled(&scene.texels)?,
        };
        let texture = MipTexture::new(&image, None, opts.atlas.texel_mm, &MipOptions::default())?;
        let inputs = RenderInputs {
            scene: &scene.scene,
            tri_uv: &scene.tri_uv,
            texture: &texture,
            shading: &train_shading,
            kind,
        };
        let render = RenderOptions {
            psi_lookup: PsiLookup::Nearest,
            ..Default::default()
        };
        let scores = frames
            .par_iter()
            .map(|(i, frame, mask)| {
                let (pred, hit) = render_view_with(&inputs, &view_rays, &scene.poses[*i], &render)?;
                score_frame(kind, scene.frame_numbers[*i], pred, hit, frame, mask)
            })
            .collect::<Result<Vec<_>>>()?;
        let mean = |f: &dyn Fn(&HeldOutScore) -> Option<f64>| {
            let v: Vec<f64> = scores.iter().filter_map(f).collect();
            (!v.is_empty()).then(|| v.iter().sum::<f64>() / v.len() as f64)
        };
        models.push(ModelCrossValidation {
            model: kind,
            mean_psnr_db: mean(&|s| s.psnr_db),
            mean_ssim: mean(&|s| s.ssim),
            frames: scores,
        });
    }
    Ok(CrossValidation {
        every,
        held_out: held,
        models,
    })
}

/// The held-out frames and, for each, the pixels that obey the shading model.
fn held_out_observations(
    scene: &BuildScene,
    held: &[usize],
    opts: &BuildOptions,
) -> Result<Vec<(usize, Frame, Vec<bool>)>> {
    let s = &opts.samples;
    let mut frames = Vec::with_capacity(held.len());
    for (i, f) in scene.case.frames_at(held)? {
        let f = scene.working_frame(f);
        let g = scene.cast(i);
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
    Ok(frames)
}

/// One held-out frame's prediction `pred` (hit mask `hit`) against the recorded `frame`.
fn score_frame(
    kind: ShadingKind,
    i: usize,
    pred: Frame,
    hit: Vec<bool>,
    frame: &Frame,
    mask: &[bool],
) -> Result<HeldOutScore> {
    let truth = MaskedImage {
        frame: frame.clone(),
        mask: mask.to_vec(),
    };
    let label = format!("frame {i}");
    let s = evaluate_methods(
        &[(
            kind.to_string(),
            vec![MaskedImage {
                frame: pred,
                mask: hit,
            }],
        )],
        &[truth],
        std::slice::from_ref(&label),
    )?;
    let v = &s[0].views[0];
    Ok(HeldOutScore {
        frame: i,
        pixels: v.pixels,
        psnr_db: v.psnr_db,
        ssim: v.ssim,
    })
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
