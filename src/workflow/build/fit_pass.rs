//! The first pass over the video (paper, Fig. 1: back-project, fit Psi): every frame is ray
//! cast from its pose, its pixels that obey the model are sampled, the paper's Psi is fitted
//! to them, and a subsample is pooled for the calibrated light.

use super::error::BuildError;
use super::light_refit::sample_uvs;
use super::options::BuildOptions;
use super::scene::BuildScene;
use crate::camera::Pose;
use crate::image::Frame;
use crate::math::Affine;
use crate::model::manifest::FrameFit;
use crate::raycast::GBuffer;
use crate::shading::calibrated::{pool_frames, FrameData, PoolOptions, PooledSamples};
use crate::shading::paper::{fit_psi, PsiModel};
use crate::shading::ExclusionCounts;
use crate::shading::{density_weights, extract_samples, SampleSet, WeightOptions};
use crate::workflow::progress::Progress;
use crate::workflow::report::ReportFrame;
use crate::Result;
use rayon::prelude::*;

/// What the first pass gives every later stage.
pub struct FitPass {
    /// The paper's Psi of every frame (poses order).
    pub psi: Vec<PsiModel>,
    /// Fit quality of every frame.
    pub fits: Vec<FrameFit>,
    /// Sum per channel of the pixels that obey the model: the colour the per-channel shading
    /// divides out of the texture, put back by the colour balance.
    pub pixel_sum: [f64; 3],
    /// A few frames with their G-buffers and samples, for the report's Fig. 2 and 3.
    pub report_frames: Vec<ReportFrame>,
}

/// The samples the calibrated light is fitted to, pooled over the video.
pub struct LightSamples {
    /// The pooled samples.
    pub pooled: PooledSamples,
    /// Where each pooled sample lies in the atlas (only kept when the light is refitted
    /// against the fused texture).
    pub uv: Vec<[f32; 2]>,
}

/// Ray cast, sample and fit every frame; keep each frame's depth in the scene's cache.
pub fn fit_pass(scene: &mut BuildScene, opts: &BuildOptions) -> Result<(FitPass, LightSamples)> {
    let n = scene.frame_count();
    let mut pass = FitPass {
        psi: Vec::with_capacity(n),
        fits: Vec::with_capacity(n),
        pixel_sum: [0.0; 3],
        report_frames: Vec::new(),
    };
    let mut light = LightSamples {
        pooled: PooledSamples::default(),
        uv: Vec::new(),
    };
    let pool_for_light =
        opts.shading != Some(crate::shading::ShadingKind::Paper) || opts.cross_validate_every > 0;
    // The pooled fit's memory and time grow with its samples: a long video keeps fewer per frame.
    let pool = PoolOptions {
        max_per_frame: opts
            .pool
            .max_per_frame
            .min((opts.max_pooled_samples / n.max(1)).max(1000)),
        ..opts.pool.clone()
    };
    let report_every = (n / 3).max(1);
    let progress = Progress::new("fit Psi", n as u64, opts.quiet);
    // Frames are decoded in order (a video is one stream) and fitted a batch at a time in
    // parallel; the results are merged in frame order, so they do not depend on the threads.
    // At most 16 frames are in flight (a 1280x720 frame with its G-buffer is about 25 MB).
    let batch = (2 * rayon::current_num_threads()).clamp(2, 16);
    let mut source = scene.case.frame_source()?.enumerate();
    loop {
        let frames: Vec<(usize, Result<Frame>)> = source.by_ref().take(batch).collect();
        if frames.is_empty() {
            break;
        }
        let scene_ref: &BuildScene = scene;
        let fitted: Vec<Result<FittedFrame>> = frames
            .into_par_iter()
            .map(|(i, frame)| fit_one(scene_ref, i, frame?, opts, &pool, pool_for_light))
            .collect();
        for f in fitted {
            let f = f?;
            let i = f.index;
            for (ch, sum) in pass.pixel_sum.iter_mut().enumerate() {
                *sum += f.samples.rgb[ch].iter().map(|&v| v as f64).sum::<f64>();
            }
            if let Some(part) = f.pooled {
                light.uv.extend(f.uv);
                light.pooled.append(part)?;
            }
            scene.cache.offer(i, &f.gbuffer.z);
            if i % report_every == 0 && pass.report_frames.len() < 3 {
                pass.report_frames.push(ReportFrame {
                    index: i,
                    frame: f.frame,
                    gbuffer: f.gbuffer,
                    samples: f.samples,
                    psi: f.psi.clone(),
                });
            }
            pass.psi.push(f.psi);
            pass.fits.push(f.fit);
            progress.inc();
        }
    }
    progress.finish();
    Ok((pass, light))
}

/// One frame's share of the first pass.
struct FittedFrame {
    index: usize,
    frame: Frame,
    gbuffer: GBuffer,
    samples: SampleSet,
    psi: PsiModel,
    fit: FrameFit,
    /// The frame's samples pooled for the calibrated light, when it is fitted.
    pooled: Option<PooledSamples>,
    /// Where the pooled samples lie in the atlas (only when the light is refitted).
    uv: Vec<[f32; 2]>,
}

/// Ray cast frame `i` (decoded as recorded), sample it and fit its Psi.
fn fit_one(
    scene: &BuildScene,
    i: usize,
    frame: Frame,
    opts: &BuildOptions,
    pool: &PoolOptions,
    pool_for_light: bool,
) -> Result<FittedFrame> {
    let frame = scene.working_frame(frame);
    let g = scene.cast(i);
    let (samples, psi, mut fit) =
        fit_frame(&frame, &g, &scene.poses[i], opts).map_err(|e| match e {
            FrameFitError::Unusable(samples, excluded) => BuildError::FrameUnusable {
                frame: i,
                name: scene.frame_name(i),
                samples,
                excluded,
            },
            FrameFitError::Fit(e) => BuildError::FrameFit {
                frame: i,
                name: scene.frame_name(i),
                source: Box::new(e),
            },
        })?;
    fit.frame = scene.frame_numbers[i];
    let (mut pooled, mut uv) = (None, Vec::new());
    if pool_for_light {
        let data = FrameData {
            gamma: &g.gamma,
            z: &g.z,
            cos_theta: &scene.cos_theta,
            rgb: &frame.rgb,
            texel: None,
            width: frame.width as usize,
        };
        let part = pool_frames(&[data], pool)?;
        if opts.refine_light > 0 {
            uv = sample_uvs(&part.pixel, &g, &scene.tri_uv);
        }
        pooled = Some(part);
    }
    Ok(FittedFrame {
        index: i,
        frame,
        gbuffer: g,
        samples,
        psi,
        fit,
        pooled,
        uv,
    })
}

/// Why a frame could not be fitted.
enum FrameFitError {
    /// Too few pixels obey the model (their count, and why the others were left out).
    Unusable(usize, ExclusionCounts),
    /// The fit itself failed.
    Fit(crate::Error),
}

/// The pixels of a frame that obey the model, and the fitted Psi.
fn fit_frame(
    frame: &Frame,
    g: &GBuffer,
    pose: &Affine,
    opts: &BuildOptions,
) -> std::result::Result<(SampleSet, PsiModel, FrameFit), FrameFitError> {
    let samples = extract_samples(&g.gamma, &g.z, &frame.rgb, &opts.samples);
    if samples.len() < 50 {
        return Err(FrameFitError::Unusable(samples.len(), samples.excluded));
    }
    let weights = density_weights(&samples, &WeightOptions::default());
    let fit = fit_psi(&samples, &weights.weights, &opts.fit).map_err(FrameFitError::Fit)?;
    let mut model = fit.model;
    model.camera_to_world = Pose::new(*pose).row_major();
    let r2 = r_squared(&samples, &model);
    let ff = FrameFit {
        frame: 0,
        samples: samples.len(),
        rms: model.rms_residual,
        r2,
        constrained: fit.channels.iter().any(|c| c.constrained),
    };
    Ok((samples, model, ff))
}

/// R² of Psi against the samples' pixel values, per channel (unweighted).
fn r_squared(s: &SampleSet, m: &PsiModel) -> [f64; 3] {
    let mut out = [0.0; 3];
    for (ch, o) in out.iter_mut().enumerate() {
        let vals = &s.rgb[ch];
        let mean = vals.iter().map(|&v| v as f64).sum::<f64>() / vals.len().max(1) as f64;
        let (mut ss_res, mut ss_tot) = (0.0, 0.0);
        for ((&g, &z), &v) in s.gamma.iter().zip(&s.z).zip(vals.iter()) {
            let p = m.eval(ch, g as f64, z as f64);
            let v = v as f64;
            ss_res += (v - p) * (v - p);
            ss_tot += (v - mean) * (v - mean);
        }
        *o = if ss_tot > 0.0 {
            1.0 - ss_res / ss_tot
        } else {
            0.0
        };
    }
    out
}
