//! [`super::FusionMethod::MultiBand`]: two weighted averages in one pass over the frames, a
//! broad one (every frame that sees a texel, weights `w^e`) and a sharp one (weights
//! `w^detail`, close to the single best frame), split into frequency bands in the texture
//! domain: the low band of the broad average and the high band of the sharp one
//! (`sharp + G * (broad - sharp)`, G a Gaussian within the chart).
//!
//! Why: averaging many frames cancels their low-frequency shading errors (what new views are
//! most sensitive to), but every frame seen from farther or more obliquely resamples the fine
//! detail coarsely and blurs it; the best frames alone keep the detail. Both weights change
//! continuously over a frame, and the bands are split by a smooth filter, so no seam appears
//! where one frame stops dominating.

// Parallel arrays indexed by channel read clearer than zips.
#![allow(clippy::needless_range_loop)]

use rayon::prelude::*;

use super::blur::{blur_rect, gaussian_kernel};
use super::delight::{DelightOptions, FrameCtx};
use super::fusion::FrameStream;
use super::pass::{for_visible_blocks, weight_power, Acc, CameraCache, Seen};
use super::texels::TexelSet;
use crate::Result;

/// Parameters of the band split (see [`super::FusionMethod::MultiBand`]).
pub(super) struct MultiBandOptions {
    pub(super) weight_exponent: f32,
    pub(super) detail_exponent: f32,
    pub(super) sigma_texels: f32,
}

/// The pass over the frames and the band split: the fused value of every texel in `acc`
/// (weight 1 where seen, 0 elsewhere); `seen` as the other methods' first pass.
pub(super) fn multiband_pass<S: FrameStream + ?Sized>(
    texels: &TexelSet,
    frames: &mut S,
    delight: &DelightOptions,
    cams: &mut CameraCache,
    opts: &MultiBandOptions,
    seen: &mut [Seen],
    acc: &mut [Acc],
) -> Result<usize> {
    let mut both = vec![[Acc::default(); 2]; acc.len()];
    let (e, d) = (opts.weight_exponent, opts.detail_exponent);
    for f in 0..frames.frame_count() {
        let obs = frames.observation(f)?;
        let ctx = FrameCtx::new(&obs, delight, cams.angle(obs.camera))?;
        for_visible_blocks(
            texels,
            &ctx,
            &mut both,
            Some((seen, f as u32)),
            |a, v, w| {
                for (acc, w) in a.iter_mut().zip([weight_power(w, e), weight_power(w, d)]) {
                    for ch in 0..3 {
                        acc.rgb[ch] += w * v[ch];
                    }
                    acc.w += w;
                }
            },
        );
    }
    split_bands(texels, &both, opts.sigma_texels, acc);
    Ok(both.len() * std::mem::size_of::<[Acc; 2]>())
}

/// `sharp + G * (broad - sharp)` per chart (parallel over charts), G normalised over the
/// chart's covered texels so that the border of the seen region takes no dark halo.
fn split_bands(texels: &TexelSet, both: &[[Acc; 2]], sigma: f32, acc: &mut [Acc]) {
    let kernel = gaussian_kernel(sigma);
    let w = texels.width as usize;
    let mut tasks: Vec<(usize, &mut [Acc])> = Vec::with_capacity(texels.chart_rect.len());
    let mut rest = acc;
    for c in 0..texels.chart_rect.len() {
        let len = (texels.chart_start[c + 1] - texels.chart_start[c]) as usize;
        let (mine, tail) = rest.split_at_mut(len);
        rest = tail;
        tasks.push((c, mine));
    }
    tasks.into_par_iter().for_each_init(
        || (Vec::new(), Vec::new()),
        |(maps, tmp): &mut (Vec<Vec<f32>>, Vec<f32>), (c, mine)| {
            let lo = texels.chart_start[c] as usize;
            let r = texels.chart_rect[c];
            let (bw, bh) = ((r.x1 - r.x0) as usize, (r.y1 - r.y0) as usize);
            let at = |s: usize| {
                let t = texels.texel[s] as usize;
                (t / w - r.y0 as usize) * bw + t % w - r.x0 as usize
            };
            // Maps 0..3: the band difference per channel, 3: the covered mask.
            maps.resize_with(4, Vec::new);
            for m in maps.iter_mut() {
                m.clear();
                m.resize(bw * bh, 0.0);
            }
            for k in 0..mine.len() {
                let [broad, sharp] = both[lo + k];
                if !(broad.w > 0.0 && sharp.w > 0.0) {
                    continue;
                }
                let i = at(lo + k);
                for ch in 0..3 {
                    maps[ch][i] = broad.rgb[ch] / broad.w - sharp.rgb[ch] / sharp.w;
                }
                maps[3][i] = 1.0;
            }
            for m in maps.iter_mut() {
                blur_rect(m, bw, bh, &kernel, tmp);
            }
            for (k, out) in mine.iter_mut().enumerate() {
                let [_, sharp] = both[lo + k];
                *out = Acc::default();
                let i = at(lo + k);
                if !(sharp.w > 0.0 && maps[3][i] > 0.0) {
                    continue;
                }
                for ch in 0..3 {
                    out.rgb[ch] = sharp.rgb[ch] / sharp.w + maps[ch][i] / maps[3][i];
                }
                out.w = 1.0;
            }
        },
    );
}
