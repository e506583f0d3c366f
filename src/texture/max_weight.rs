//! Pass 2 of [`super::FusionMethod::MaxWeightSmoothed`] (the paper's final fusion): each
//! frame's suppressed weight map (the texels it won in pass 1) blurred in the texture domain,
//! per chart, and used to blend its de-lit values.

// Parallel arrays indexed by channel read clearer than zips.
#![allow(clippy::needless_range_loop)]

use rayon::prelude::*;

use super::blur::{blur_rect, gaussian_kernel};
use super::delight::{DelightOptions, FrameCtx};
use super::fusion::FrameStream;
use super::pass::{Acc, CameraCache, Seen};
use super::texels::{TexelRect, TexelSet};
use crate::Result;

/// Pass 2: re-read the frames that won somewhere, in order, and accumulate their values
/// weighted by their blurred suppressed weight maps into `acc`. `seen` holds pass 1's winners.
pub(super) fn blend_pass<S: FrameStream + ?Sized>(
    texels: &TexelSet,
    frames: &mut S,
    delight: &DelightOptions,
    cams: &mut CameraCache,
    seen: &[Seen],
    sigma_texels: f32,
    acc: &mut [Acc],
) -> Result<()> {
    let n = texels.len();
    let nf = frames.frame_count();
    // Texels ordered by winning frame (then slot, hence chart): the pass walks this list
    // with one cursor instead of keeping per-frame lists.
    let mut order: Vec<u32> = (0..n as u32)
        .filter(|&s| seen[s as usize].best_frame != u32::MAX)
        .collect();
    order.par_sort_unstable_by_key(|&s| (seen[s as usize].best_frame, s));
    let kernel = gaussian_kernel(sigma_texels);
    let radius = (kernel.len() / 2) as u32;
    let mut cursor = 0usize;
    for f in 0..nf {
        let end = cursor
            + order[cursor..]
                .iter()
                .take_while(|&&s| seen[s as usize].best_frame == f as u32)
                .count();
        let won = &order[cursor..end];
        cursor = end;
        if won.is_empty() {
            continue; // this frame won nowhere: its smoothed weight map is zero
        }
        let obs = frames.observation(f)?;
        let ctx = FrameCtx::new(&obs, delight, cams.angle(obs.camera))?;
        blend_frame(texels, &ctx, won, seen, &kernel, radius, acc);
    }
    Ok(())
}

/// Pass 2 of one frame: per chart where it won, blur its suppressed weight map over the
/// winners' rectangle grown by the kernel radius and accumulate the blurred weight times the
/// frame's de-lit value on the texels it sees (parallel over charts).
fn blend_frame(
    texels: &TexelSet,
    ctx: &FrameCtx,
    won: &[u32],
    seen: &[Seen],
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
                map[y * bw + x] = seen[s as usize].best_w;
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
