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
//! Memory is O(texels) in both methods, independent of the number of frames: the frames are
//! streamed ([`FrameStream`]) and re-read in pass 2 instead of keeping their de-lit values.

// Parallel arrays indexed by channel read clearer than zips.
#![allow(clippy::needless_range_loop)]

use rayon::prelude::*;

use super::atlas::fill_uncovered;
use super::blur::{blur_rect, gaussian_kernel};
use super::delight::{max_ray_angle, DelightOptions, FrameCtx, Observation};
use super::synthesis::{complete_unseen, SynthesisOptions, SynthesisStats};
use super::texels::{TexelRect, TexelSet, BLOCK};
use crate::camera::Camera;
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
}

/// The fusion methods by name (the command line's `--fusion`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum FusionKind {
    /// The average weighted by the predicted intensity (`FusionMethod::WeightedAverage`).
    Average,
    /// The paper's max-weight choice with smoothed weights (`FusionMethod::MaxWeightSmoothed`).
    Max,
}

/// Default power of the predicted intensity in the weighted average (inverse-variance weights).
pub const DEFAULT_WEIGHT_EXPONENT: f32 = 2.0;

/// Default smoothing of the max-weight maps (texels).
pub const DEFAULT_SIGMA_TEXELS: f32 = 2.0;

impl FusionMethod {
    /// The method `kind`; `weight_exponent` (1 or more) is the weighted average's.
    pub fn of_kind(kind: FusionKind, weight_exponent: f32) -> FusionMethod {
        match kind {
            FusionKind::Average => FusionMethod::WeightedAverage { weight_exponent },
            FusionKind::Max => FusionMethod::MaxWeightSmoothed {
                sigma_texels: DEFAULT_SIGMA_TEXELS,
            },
        }
    }

    /// Streaming passes over the frames [`fuse`] makes with this method.
    pub fn passes(&self) -> usize {
        match self {
            FusionMethod::MaxWeightSmoothed { .. } => 2,
            FusionMethod::WeightedAverage { .. } => 1,
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

/// Running sum of one texel: weighted value and weight.
#[derive(Clone, Copy, Default)]
struct Acc {
    rgb: [f32; 3],
    w: f32,
}

/// Best frame of one texel so far.
#[derive(Clone, Copy)]
struct Best {
    w: f32,
    frame: u32,
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
    let mut seen = vec![0u32; n];
    let mut acc = vec![Acc::default(); n];
    let mut state_bytes = n * (std::mem::size_of::<u32>() + std::mem::size_of::<Acc>());
    match opts.method {
        FusionMethod::WeightedAverage { weight_exponent } => {
            for f in 0..nf {
                let obs = frames.observation(f)?;
                let ctx = FrameCtx::new(&obs, &opts.delight, cams.angle(obs.camera))?;
                for_visible_blocks(texels, &ctx, &mut acc, &mut seen, |a, s, v, w| {
                    let w = match weight_exponent {
                        1.0 => w,
                        2.0 => w * w,
                        e => w.powf(e),
                    };
                    for ch in 0..3 {
                        a.rgb[ch] += w * v[ch];
                    }
                    a.w += w;
                    *s += 1;
                });
            }
        }
        FusionMethod::MaxWeightSmoothed { sigma_texels } => {
            // Pass 1: non-maximum suppression.
            let mut best = vec![
                Best {
                    w: 0.0,
                    frame: u32::MAX
                };
                n
            ];
            for f in 0..nf {
                let obs = frames.observation(f)?;
                let ctx = FrameCtx::new(&obs, &opts.delight, cams.angle(obs.camera))?;
                for_visible_blocks(texels, &ctx, &mut best, &mut seen, |b, s, _, w| {
                    if w > b.w {
                        *b = Best { w, frame: f as u32 };
                    }
                    *s += 1;
                });
            }
            // Texels ordered by winning frame (then slot, hence chart): pass 2 walks this list
            // with one cursor instead of keeping per-frame lists.
            let mut order: Vec<u32> = (0..n as u32)
                .filter(|&s| best[s as usize].frame != u32::MAX)
                .collect();
            order.par_sort_unstable_by_key(|&s| (best[s as usize].frame, s));
            state_bytes += n * std::mem::size_of::<Best>() + n * std::mem::size_of::<u32>();
            // Pass 2: blend with the smoothed suppressed weight maps.
            let kernel = gaussian_kernel(sigma_texels);
            let radius = (kernel.len() / 2) as u32;
            let mut cursor = 0usize;
            for f in 0..nf {
                let end = cursor
                    + order[cursor..]
                        .iter()
                        .take_while(|&&s| best[s as usize].frame == f as u32)
                        .count();
                let won = &order[cursor..end];
                cursor = end;
                if won.is_empty() {
                    continue; // this frame won nowhere: its smoothed weight map is zero
                }
                let obs = frames.observation(f)?;
                let ctx = FrameCtx::new(&obs, &opts.delight, cams.angle(obs.camera))?;
                blend_frame(texels, &ctx, won, &best, &kernel, radius, &mut acc);
            }
        }
    }
    // Output in atlas layout.
    let (w, h) = (texels.width as usize, texels.height as usize);
    let mut out = FusedTexture {
        width: texels.width,
        height: texels.height,
        rgb: vec![0.0; 3 * w * h],
        covered: vec![false; w * h],
        frames_seen: vec![0; w * h],
        stats: FusionStats {
            frames: nf,
            chart_texels: n,
            covered_texels: 0,
            state_bytes,
        },
    };
    for (s, a) in acc.iter().enumerate() {
        let t = texels.texel[s] as usize;
        out.frames_seen[t] = seen[s];
        if a.w > 0.0 {
            for ch in 0..3 {
                out.rgb[3 * t + ch] = a.rgb[ch] / a.w;
            }
            out.covered[t] = true;
            out.stats.covered_texels += 1;
        }
    }
    Ok(out)
}

/// The view-cone angle of the last camera (cameras rarely change within a video).
#[derive(Default)]
struct CameraCache {
    last: Option<(Camera, f64)>,
}

impl CameraCache {
    fn angle(&mut self, cam: &Camera) -> f64 {
        match self.last {
            Some((c, a)) if c == *cam => a,
            _ => {
                let a = max_ray_angle(cam);
                self.last = Some((*cam, a));
                a
            }
        }
    }
}

/// De-light every texel of the blocks the frame can see (parallel over blocks) and hand each
/// valid `(value, weight)` to `update` with the texel's state and seen-counter.
fn for_visible_blocks<T: Send>(
    texels: &TexelSet,
    ctx: &FrameCtx,
    state: &mut [T],
    seen: &mut [u32],
    update: impl Fn(&mut T, &mut u32, [f32; 3], f32) + Sync,
) {
    state
        .par_chunks_mut(BLOCK)
        .zip(seen.par_chunks_mut(BLOCK))
        .enumerate()
        .for_each(|(b, (st, sn))| {
            if !ctx.block_visible(&texels.blocks[b]) {
                return;
            }
            let s0 = b * BLOCK;
            for k in 0..st.len() {
                if let Some((v, w)) = ctx.texel(texels.point[s0 + k], texels.normal[s0 + k]) {
                    update(&mut st[k], &mut sn[k], v, w);
                }
            }
        });
}

/// Pass 2 of one frame: per chart where it won, blur its suppressed weight map over the
/// winners' rectangle grown by the kernel radius and accumulate the blurred weight times the
/// frame's de-lit value on the texels it sees (parallel over charts).
fn blend_frame(
    texels: &TexelSet,
    ctx: &FrameCtx,
    won: &[u32],
    best: &[Best],
    kernel: &[f32],
    radius: u32,
    acc: &mut [Acc],
) {
    // Runs of `won` by chart (slots are ordered by chart).
    let mut runs: Vec<(u32, &[u32])> = Vec::new();
    let mut i = 0;
    while i < won.len() {
        let c = texels.chart[won[i] as usize];
        let j = i + won[i..]
            .iter()
            .take_while(|&&s| texels.chart[s as usize] == c)
            .count();
        runs.push((c, &won[i..j]));
        i = j;
    }
    // Disjoint mutable slices of the accumulators, one per chart in `runs` (increasing).
    let mut tasks = Vec::with_capacity(runs.len());
    let mut rest = acc;
    let mut offset = 0usize;
    for (c, slots) in runs {
        let (lo, hi) = (
            texels.chart_start[c as usize] as usize,
            texels.chart_start[c as usize + 1] as usize,
        );
        let (_, tail) = rest.split_at_mut(lo - offset);
        let (mine, tail) = tail.split_at_mut(hi - lo);
        rest = tail;
        offset = hi;
        tasks.push((c, slots, lo, mine));
    }
    let w = texels.width;
    tasks.into_par_iter().for_each_init(
        || (Vec::new(), Vec::new()),
        |(map, tmp), (c, slots, lo, mine)| {
            let cr = texels.chart_rect[c as usize];
            let mut r = TexelRect {
                x0: u32::MAX,
                y0: u32::MAX,
                x1: 0,
                y1: 0,
            };
            for &s in slots {
                let t = texels.texel[s as usize];
                let (x, y) = (t % w, t / w);
                r.x0 = r.x0.min(x);
                r.y0 = r.y0.min(y);
                r.x1 = r.x1.max(x + 1);
                r.y1 = r.y1.max(y + 1);
            }
            let r = TexelRect {
                x0: r.x0.saturating_sub(radius).max(cr.x0),
                y0: r.y0.saturating_sub(radius).max(cr.y0),
                x1: (r.x1 + radius).min(cr.x1),
                y1: (r.y1 + radius).min(cr.y1),
            };
            let (bw, bh) = ((r.x1 - r.x0) as usize, (r.y1 - r.y0) as usize);
            map.clear();
            map.resize(bw * bh, 0.0f32);
            for &s in slots {
                let t = texels.texel[s as usize];
                let (x, y) = ((t % w - r.x0) as usize, (t / w - r.y0) as usize);
                map[y * bw + x] = best[s as usize].w;
            }
            // Only this chart's texels hold weights, so the blur never mixes charts.
            blur_rect(map, bw, bh, kernel, tmp);
            for y in 0..bh {
                for x in 0..bw {
                    let b = map[y * bw + x];
                    if b <= 0.0 {
                        continue;
                    }
                    let t = (y + r.y0 as usize) * w as usize + x + r.x0 as usize;
                    let s = texels.slot_of_texel[t];
                    if s == u32::MAX || texels.chart[s as usize] != c {
                        continue;
                    }
                    let s = s as usize;
                    if let Some((v, _)) = ctx.texel(texels.point[s], texels.normal[s]) {
                        let a = &mut mine[s - lo];
                        for ch in 0..3 {
                            a.rgb[ch] += b * v[ch];
                        }
                        a.w += b;
                    }
                }
            }
        },
    );
}
