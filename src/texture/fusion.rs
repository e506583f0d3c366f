//! Fusion of the de-lit frames into one albedo atlas (paper §2.4), streaming over frames.
//!
//! * [`FusionMethod::WeightedAverage`] (the paper's first attempt, blurry, with exponent 1): one
//!   pass, `sum_f w_f^e v_f / sum_f w_f^e` with `w_f` the intensity Psi predicts for the texel.
//! * [`FusionMethod::MaxWeightSmoothed`] (the paper's final method): pass 1 keeps per texel
//!   the largest weight and its frame (non-maximum suppression); the texels are then ordered
//!   by winning frame; pass 2 re-reads the frames in order, and for frame f blurs its
//!   suppressed weight map `W_f = w_f [argmax = f]` in the texture domain (per chart, only
//!   around the texels f won) and accumulates `sum_f blur(W_f) v_f / sum_f blur(W_f)` over the
//!   texels f sees.
//!
//! * [`FusionMethod::RobustAverage`]: the weighted average, then passes that re-weight each
//!   observation by its agreement with the previous pass's average (`robust`).
//!
//! * [`FusionMethod::MultiBand`]: the broad average's low frequencies and a sharp average's
//!   high frequencies (`multiband`).
//!
//! Memory is O(texels) in both methods, independent of the number of frames: the frames are
//! streamed ([`FrameStream`]) and re-read in pass 2 instead of keeping their de-lit values.

// Parallel arrays indexed by channel read clearer than zips.
#![allow(clippy::needless_range_loop)]

use super::atlas::fill_uncovered;
use super::delight::{DelightOptions, FrameCtx, Observation};
use super::max_weight::blend_pass;
use super::multiband::{multiband_pass, MultiBandOptions};
use super::pass::{for_visible_blocks, weight_power, Acc, CameraCache, Seen};
use super::robust::{reweight_passes, RobustOptions};
use super::synthesis::{complete_unseen, SynthesisOptions, SynthesisStats};
use super::texels::TexelSet;
use crate::image::ImageError;
use crate::{Error, Result};

/// How the frames' de-lit values are combined.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum FusionMethod {
    /// Per texel keep only the frame of maximal weight, smooth each frame's suppressed weight
    /// map with a Gaussian of `sigma_texels` (standard deviation in texels, truncated at
    /// 3 sigma, within the chart) and blend with the smoothed weights (paper, final method).
    MaxWeightSmoothed {
        /// Standard deviation of the weight-map smoothing (texels).
        sigma_texels: f32,
    },
    /// Average weighted by the predicted intensity raised to `weight_exponent`. Exponent 1 is
    /// the paper's first attempt (blurry). Exponent 2 is the inverse-variance weight when a
    /// de-lit value's error is an intensity error of constant size divided by the shading
    /// (read noise, unmodelled inter-reflection, shading errors from the CT mesh's normals):
    /// close, frontal, well-lit views count more, and the texture is sharper.
    WeightedAverage {
        /// Power of the predicted intensity used as the weight (1 or more).
        weight_exponent: f32,
    },
    /// The weighted average, then `rounds` passes that re-weight every observation by how
    /// well it agrees with the previous pass's average (iteratively reweighted least squares,
    /// Cauchy loss): a frame that is misregistered, blurred or wrongly shaded at a texel
    /// disagrees with the consensus of the others there and counts less, so the texture keeps
    /// the detail the agreeing frames share. Weights change smoothly with the disagreement,
    /// so no seam appears where one frame starts to count less.
    RobustAverage {
        /// Power of the predicted intensity in the weight, as [`FusionMethod::WeightedAverage`].
        weight_exponent: f32,
        /// Relative difference `|v - m| / |m|` (RGB norms, unitless) at which an observation's
        /// weight is halved.
        residual_scale: f32,
        /// Re-weighting passes (each reads every frame once more).
        rounds: u32,
    },
    /// The low frequencies of the weighted average with `weight_exponent` and the high
    /// frequencies of the one with `detail_exponent` (near the best frame's values), split by
    /// a Gaussian of `sigma_texels` within the chart (`multiband`). One pass.
    MultiBand {
        /// Power of the predicted intensity in the broad average (low band).
        weight_exponent: f32,
        /// Power of the predicted intensity in the sharp average (high band).
        detail_exponent: f32,
        /// Standard deviation of the band split (texels).
        sigma_texels: f32,
    },
}

/// The fusion methods by name (the command line's `--fusion`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum FusionKind {
    /// The average weighted by the predicted intensity (`FusionMethod::WeightedAverage`).
    Average,
    /// The paper's max-weight choice with smoothed weights (`FusionMethod::MaxWeightSmoothed`).
    Max,
    /// The weighted average re-weighted by agreement with the consensus
    /// (`FusionMethod::RobustAverage`).
    Robust,
    /// The average's low frequencies and the best frames' high frequencies
    /// (`FusionMethod::MultiBand`).
    MultiBand,
}

/// Default power of the predicted intensity in the weighted average (inverse-variance weights).
pub const DEFAULT_WEIGHT_EXPONENT: f32 = 2.0;

/// Default smoothing of the max-weight maps (texels).
pub const DEFAULT_SIGMA_TEXELS: f32 = 2.0;

/// Default relative disagreement that halves an observation's weight in the robust average.
pub const DEFAULT_RESIDUAL_SCALE: f32 = 0.3;

/// Default re-weighting passes of the robust average.
pub const DEFAULT_ROBUST_ROUNDS: u32 = 2;

/// Default power of the predicted intensity in the multi-band fusion's sharp average.
pub const DEFAULT_DETAIL_EXPONENT: f32 = 8.0;

/// Default band split of the multi-band fusion (texels).
pub const DEFAULT_BAND_SIGMA_TEXELS: f32 = 4.0;

impl FusionMethod {
    /// The method `kind`; `weight_exponent` (1 or more) is the weighted average's.
    pub fn of_kind(kind: FusionKind, weight_exponent: f32) -> FusionMethod {
        match kind {
            FusionKind::Average => FusionMethod::WeightedAverage { weight_exponent },
            FusionKind::Max => FusionMethod::MaxWeightSmoothed {
                sigma_texels: DEFAULT_SIGMA_TEXELS,
            },
            FusionKind::Robust => FusionMethod::RobustAverage {
                weight_exponent,
                residual_scale: DEFAULT_RESIDUAL_SCALE,
                rounds: DEFAULT_ROBUST_ROUNDS,
            },
            FusionKind::MultiBand => FusionMethod::MultiBand {
                weight_exponent,
                detail_exponent: DEFAULT_DETAIL_EXPONENT,
                sigma_texels: DEFAULT_BAND_SIGMA_TEXELS,
            },
        }
    }

    /// Streaming passes over the frames [`fuse`] makes with this method.
    pub fn passes(&self) -> usize {
        match self {
            FusionMethod::MaxWeightSmoothed { .. } => 2,
            FusionMethod::WeightedAverage { .. } | FusionMethod::MultiBand { .. } => 1,
            FusionMethod::RobustAverage { rounds, .. } => 1 + *rounds as usize,
        }
    }
}

/// Options of [`fuse`].
///
/// Steps: de-light every texel in every frame ([`DelightOptions`]), then combine by `method`.
#[derive(Clone, Debug, PartialEq)]
pub struct FusionOptions {
    /// The combination. Default `MaxWeightSmoothed { sigma_texels: 2.0 }`.
    pub method: FusionMethod,
    /// Visibility tolerances and pixel thresholds of the de-lighting.
    pub delight: DelightOptions,
}

impl Default for FusionOptions {
    fn default() -> Self {
        FusionOptions {
            method: FusionMethod::MaxWeightSmoothed {
                sigma_texels: DEFAULT_SIGMA_TEXELS,
            },
            delight: DelightOptions::default(),
        }
    }
}

/// The frames to fuse, read in index order, once per pass (twice for
/// [`FusionMethod::MaxWeightSmoothed`]). A video reader implements it by decoding (or
/// re-decoding) frame `index` and returning views of its own buffers.
pub trait FrameStream {
    /// Number of frames.
    fn frame_count(&self) -> usize;
    /// Frame `index` (0-based; called with increasing indices within a pass).
    fn observation(&mut self, index: usize) -> Result<Observation<'_>>;
}

/// Frames already in memory.
impl FrameStream for [Observation<'_>] {
    fn frame_count(&self) -> usize {
        self.len()
    }
    fn observation(&mut self, index: usize) -> Result<Observation<'_>> {
        self.get(index).copied().ok_or_else(|| {
            ImageError::Inconsistent {
                stage: "fusion",
                message: format!("frame {index} requested from {} frames", self.len()),
            }
            .into()
        })
    }
}

/// Counts of a fusion.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct FusionStats {
    /// Frames read per pass.
    pub frames: usize,
    /// Texels with chart data.
    pub chart_texels: usize,
    /// Chart texels seen by at least one frame.
    pub covered_texels: usize,
    /// Heap bytes of the per-texel fusion state (excluding the [`TexelSet`] and the output).
    /// It does not depend on the number of frames.
    pub state_bytes: usize,
}

/// The fused atlas.
#[derive(Clone, Debug, Default)]
pub struct FusedTexture {
    /// Atlas size (texels).
    pub width: u32,
    /// Atlas height (texels).
    pub height: u32,
    /// Linear relative albedo, interleaved RGB, `3 * width * height` values, row y = 0 first;
    /// zero where not covered (see [`FusedTexture::filled`]).
    pub rgb: Vec<f32>,
    /// Texel seen by at least one frame (atlas-sized).
    pub covered: Vec<bool>,
    /// Frames that gave the texel a value (atlas-sized).
    pub frames_seen: Vec<u32>,
    /// The frame of largest predicted intensity at each covered texel (atlas-sized,
    /// `u32::MAX` where not covered): the frame that dominates it.
    pub dominant_frame: Vec<u32>,
    /// Counts.
    pub stats: FusionStats,
}

impl FusedTexture {
    /// The atlas with uncovered texels filled from their chart's neighbours and the gutter
    /// filled from the charts ([`fill_uncovered`]), for display and bilinear lookups.
    pub fn filled(&self, texels: &TexelSet) -> Result<Vec<f32>> {
        let mut rgb = self.rgb.clone();
        fill_uncovered(
            &mut rgb,
            self.width as usize,
            self.height as usize,
            &self.covered,
            &texels.chart_map(),
        )?;
        Ok(rgb)
    }

    /// The atlas with uncovered chart texels synthesised from the covered ones (or filled, per
    /// `opts.mode`) and the gutter filled ([`complete_unseen`]); `texel_mm` is the atlas's
    /// texel edge (mm). Also returns the counts and which texels were synthesised.
    pub fn completed(
        &self,
        texels: &TexelSet,
        texel_mm: f64,
        opts: &SynthesisOptions,
    ) -> Result<(Vec<f32>, SynthesisStats, Vec<bool>)> {
        let mut rgb = self.rgb.clone();
        let (stats, synthesised) =
            complete_unseen(&mut rgb, &self.covered, texels, texel_mm, opts)?;
        Ok((rgb, stats, synthesised))
    }
}

/// Fuse the frames of `frames` into the atlas of `texels` (see the module documentation).
pub fn fuse<S: FrameStream + ?Sized>(
    texels: &TexelSet,
    frames: &mut S,
    opts: &FusionOptions,
) -> Result<FusedTexture> {
    let n = texels.len();
    let nf = frames.frame_count();
    if nf > u32::MAX as usize - 1 {
        return Err(Error::BadOptions {
            stage: "fusion",
            message: format!("{nf} frames is too many"),
        });
    }
    let mut cams = CameraCache::default();
    let mut seen = vec![Seen::default(); n];
    let mut acc = vec![Acc::default(); n];
    let mut state_bytes = n * (std::mem::size_of::<Seen>() + std::mem::size_of::<Acc>());
    if let FusionMethod::MultiBand {
        weight_exponent,
        detail_exponent,
        sigma_texels,
    } = opts.method
    {
        let bands = MultiBandOptions {
            weight_exponent,
            detail_exponent,
            sigma_texels,
        };
        state_bytes += multiband_pass(
            texels,
            frames,
            &opts.delight,
            &mut cams,
            &bands,
            &mut seen,
            &mut acc,
        )?;
        return Ok(output(texels, &acc, &seen, nf, state_bytes));
    }
    // Pass 1: the weighted average (max-weight only needs `seen`; the robust average starts
    // from the plain mean of the frames, its consensus).
    let exponent = match opts.method {
        FusionMethod::WeightedAverage { weight_exponent }
        | FusionMethod::MultiBand {
            weight_exponent, ..
        } => weight_exponent,
        FusionMethod::MaxWeightSmoothed { .. } => 1.0,
        FusionMethod::RobustAverage { .. } => 0.0,
    };
    for f in 0..nf {
        let obs = frames.observation(f)?;
        let ctx = FrameCtx::new(&obs, &opts.delight, cams.angle(obs.camera))?;
        let seen = Some((seen.as_mut_slice(), f as u32));
        for_visible_blocks(texels, &ctx, &mut acc, seen, |a, v, w| {
            let w = weight_power(w, exponent);
            for ch in 0..3 {
                a.rgb[ch] += w * v[ch];
            }
            a.w += w;
        });
    }
    match opts.method {
        FusionMethod::WeightedAverage { .. } | FusionMethod::MultiBand { .. } => {}
        FusionMethod::MaxWeightSmoothed { sigma_texels } => {
            acc.iter_mut().for_each(|a| *a = Acc::default());
            blend_pass(
                texels,
                frames,
                &opts.delight,
                &mut cams,
                &seen,
                sigma_texels,
                &mut acc,
            )?;
            state_bytes += n * std::mem::size_of::<u32>();
        }
        FusionMethod::RobustAverage {
            weight_exponent,
            residual_scale,
            rounds,
        } => {
            let robust = RobustOptions {
                weight_exponent,
                residual_scale,
                rounds,
            };
            state_bytes +=
                reweight_passes(texels, frames, &opts.delight, &mut cams, &robust, &mut acc)?;
        }
    }
    Ok(output(texels, &acc, &seen, nf, state_bytes))
}

/// The fused values in atlas layout, with the counts.
fn output(
    texels: &TexelSet,
    acc: &[Acc],
    seen: &[Seen],
    frames: usize,
    state_bytes: usize,
) -> FusedTexture {
    let (w, h) = (texels.width as usize, texels.height as usize);
    let mut out = FusedTexture {
        width: texels.width,
        height: texels.height,
        rgb: vec![0.0; 3 * w * h],
        covered: vec![false; w * h],
        frames_seen: vec![0; w * h],
        dominant_frame: vec![u32::MAX; w * h],
        stats: FusionStats {
            frames,
            chart_texels: texels.len(),
            covered_texels: 0,
            state_bytes,
        },
    };
    for (s, a) in acc.iter().enumerate() {
        let t = texels.texel[s] as usize;
        out.frames_seen[t] = seen[s].count;
        if a.w > 0.0 {
            for ch in 0..3 {
                out.rgb[3 * t + ch] = a.rgb[ch] / a.w;
            }
            out.covered[t] = true;
            out.dominant_frame[t] = seen[s].best_frame;
            out.stats.covered_texels += 1;
        }
    }
    out
}
