//! Image quilting (Efros & Freeman 2001) of one chart's unseen texels, constrained by its seen
//! texels: raster-order slots, candidate patches scored on every known texel of the slot, the
//! minimum-error boundary cut through the overlaps with earlier patches.

use super::exemplar::Exemplar;
use super::SynthesisOptions;
use crate::rng::{splitmix64, SplitMix64};
use crate::texture::texels::{TexelRect, TexelSet};

/// Texel state within a chart's rectangle.
pub(super) const OUTSIDE: u8 = 0;
/// Seen by a frame (a constraint, never changed).
pub(super) const SEEN: u8 = 1;
/// Unseen, not yet synthesised.
pub(super) const UNKNOWN: u8 = 2;
/// Synthesised.
pub(super) const SYNTH: u8 = 3;

/// One chart's rectangle after quilting: values, states and what the patches put over seen
/// texels (for the border correction).
pub(super) struct ChartPatch {
    /// The chart's rectangle in the atlas.
    pub rect: TexelRect,
    /// Rectangle width (texels).
    pub w: usize,
    /// Rectangle height (texels).
    pub h: usize,
    /// State per texel ([`OUTSIDE`], [`SEEN`], [`UNKNOWN`], [`SYNTH`]).
    pub state: Vec<u8>,
    /// Linear RGB per texel (seen values, then synthesised ones).
    pub val: Vec<[f32; 3]>,
    /// The last patch's colour over each seen texel it covered.
    pub over_seen: Vec<Option<[f32; 3]>>,
    /// Per synthesised texel next to seen ones: the mean of `seen - patch` over its seen
    /// 4-neighbours, with the patch that gave the texel its value.
    pub at_border: Vec<Option<[f32; 3]>>,
}

impl ChartPatch {
    /// Copy the synthesised texels into the atlas and mark them.
    pub fn write_back(&self, rgb: &mut [f32], synthesised: &mut [bool], atlas_w: usize) {
        for y in 0..self.h {
            for x in 0..self.w {
                let i = y * self.w + x;
                if self.state[i] != SYNTH {
                    continue;
                }
                let t = (y + self.rect.y0 as usize) * atlas_w + x + self.rect.x0 as usize;
                rgb[3 * t..3 * t + 3].copy_from_slice(&self.val[i]);
                synthesised[t] = true;
            }
        }
    }
}

/// Quilt chart `c` (see the module docs).
pub(super) fn quilt_chart(
    rgb: &[f32],
    covered: &[bool],
    texels: &TexelSet,
    chart_map: &[u32],
    ex: &Exemplar,
    c: usize,
    opts: &SynthesisOptions,
) -> ChartPatch {
    let rect = texels.chart_rect[c];
    let aw = texels.width as usize;
    let (w, h) = ((rect.x1 - rect.x0) as usize, (rect.y1 - rect.y0) as usize);
    let mut p = ChartPatch {
        rect,
        w,
        h,
        state: vec![OUTSIDE; w * h],
        val: vec![[0.0; 3]; w * h],
        over_seen: vec![None; w * h],
        at_border: vec![None; w * h],
    };
    for y in 0..h {
        for x in 0..w {
            let t = (y + rect.y0 as usize) * aw + x + rect.x0 as usize;
            if chart_map[t] != c as u32 {
                continue;
            }
            let i = y * w + x;
            if covered[t] {
                p.state[i] = SEEN;
                p.val[i] = [rgb[3 * t], rgb[3 * t + 1], rgb[3 * t + 2]];
            } else {
                p.state[i] = UNKNOWN;
            }
        }
    }
    let b = ex.patch;
    let ov = (b / 4).max(2);
    let step = b - ov;
    let (cols, rows) = (
        w.saturating_sub(ov).div_ceil(step).max(1),
        h.saturating_sub(ov).div_ceil(step).max(1),
    );
    let mut rng = SplitMix64::new(splitmix64(opts.seed ^ (c as u64).wrapping_mul(0x9E37_79B9)));
    // Source (top-left atlas index) of each slot, for the coherence candidates.
    let mut source: Vec<Option<u32>> = vec![None; cols * rows];
    let mut scratch = Scratch::default();
    for row in 0..rows {
        for col in 0..cols {
            let (sx, sy) = (col * step, row * step);
            let slot = Slot {
                x0: sx,
                y0: sy,
                x1: (sx + b).min(w),
                y1: (sy + b).min(h),
            };
            if !slot.any(&p, UNKNOWN) {
                continue;
            }
            let centre = slot_point(&p, &slot, texels, aw);
            let mut coherent = Vec::with_capacity(2);
            if col > 0 {
                coherent.push((source[row * cols + col - 1], step as i64, 0));
            }
            if row > 0 {
                coherent.push((source[(row - 1) * cols + col], 0, step as i64));
            }
            scratch.candidates.clear();
            for (src, dx, dy) in coherent {
                if let Some(s) = src {
                    let (x, y) = (
                        (s as usize % ex.width) as i64 + dx,
                        (s as usize / ex.width) as i64 + dy,
                    );
                    if ex.is_valid(x, y) {
                        scratch
                            .candidates
                            .push((y as usize * ex.width + x as usize) as u32);
                    }
                }
            }
            if let Some(q) = centre {
                ex.nearest(
                    q,
                    opts.near_candidates,
                    &mut scratch.candidates,
                    &mut scratch.near,
                );
            }
            for _ in 0..opts.random_candidates {
                let i = (rng.next_u64() % ex.len() as u64) as usize;
                scratch.candidates.push(ex.position(i));
            }
            if scratch.candidates.is_empty() {
                scratch.candidates.push(ex.position(0));
            }
            let chosen = choose(&p, &slot, ex, &mut scratch, opts.tolerance, &mut rng);
            source[row * cols + col] = Some(chosen);
            paste(&mut p, &slot, ex, chosen, ov, &mut scratch);
        }
    }
    p
}

/// A slot's footprint within the chart's rectangle, `x0..x1` × `y0..y1`.
struct Slot {
    x0: usize,
    y0: usize,
    x1: usize,
    y1: usize,
}

impl Slot {
    fn any(&self, p: &ChartPatch, state: u8) -> bool {
        (self.y0..self.y1).any(|y| (self.x0..self.x1).any(|x| p.state[y * p.w + x] == state))
    }
}

/// Reusable buffers of one chart's quilting.
#[derive(Default)]
struct Scratch {
    candidates: Vec<u32>,
    near: Vec<(f32, u32)>,
    known: Vec<(usize, usize, [f32; 3])>,
    costs: Vec<(f32, u32)>,
    err: Vec<f32>,
    cum: Vec<f32>,
}

/// The 3-D point of the chart texel nearest the slot's centre (world mm).
fn slot_point(p: &ChartPatch, s: &Slot, texels: &TexelSet, aw: usize) -> Option<[f32; 3]> {
    let (cx, cy) = ((s.x0 + s.x1) as f32 / 2.0, (s.y0 + s.y1) as f32 / 2.0);
    let mut best: Option<(f32, usize)> = None;
    for y in s.y0..s.y1 {
        for x in s.x0..s.x1 {
            if p.state[y * p.w + x] == OUTSIDE {
                continue;
            }
            let d = (x as f32 + 0.5 - cx).powi(2) + (y as f32 + 0.5 - cy).powi(2);
            if best.is_none_or(|(bd, _)| d < bd) {
                best = Some((d, (y + p.rect.y0 as usize) * aw + x + p.rect.x0 as usize));
            }
        }
    }
    let (_, t) = best?;
    let s = texels.slot_of_texel[t];
    (s != u32::MAX).then(|| texels.point[s as usize])
}

/// The candidate to paste, a random one among those whose cost is within `1 + tol` of the
/// best (Efros & Freeman's choice). The cost is the squared colour difference over the slot's
/// known texels divided by the summed colour variance of the candidate and of the known texels
/// there: two unrelated patches then cost about the same whatever their contrast, so a few
/// hundred candidates do not favour bland patches (a raw sum of squares would: a flat patch is
/// nearer to anything than another textured patch is), while true continuations still cost
/// about nothing.
fn choose(
    p: &ChartPatch,
    s: &Slot,
    ex: &Exemplar,
    sc: &mut Scratch,
    tol: f32,
    rng: &mut SplitMix64,
) -> u32 {
    sc.known.clear();
    for y in s.y0..s.y1 {
        for x in s.x0..s.x1 {
            let i = y * p.w + x;
            if p.state[i] == SEEN || p.state[i] == SYNTH {
                sc.known.push((x - s.x0, y - s.y0, p.val[i]));
            }
        }
    }
    let n = sc.known.len() as f32;
    let known_var = variance_sum(sc.known.iter().map(|k| k.2), n);
    sc.costs.clear();
    for &pos in &sc.candidates {
        let (mut ssd, mut s1, mut s2) = (0.0f32, [0.0f32; 3], 0.0f32);
        for &(dx, dy, v) in &sc.known {
            let e = ex.texel(pos, dx as i64, dy as i64);
            for ch in 0..3 {
                ssd += (e[ch] - v[ch]).powi(2);
                s1[ch] += e[ch];
                s2 += e[ch] * e[ch];
            }
        }
        let cand_var = if n > 0.0 {
            s2 - (s1[0] * s1[0] + s1[1] * s1[1] + s1[2] * s1[2]) / n
        } else {
            0.0
        };
        // The floor keeps the cost finite where both sides are flat (a gutter-free blank).
        let cost = ssd / (cand_var + known_var + 1e-6 * n.max(1.0));
        sc.costs.push((cost, pos));
    }
    let best = sc.costs.iter().map(|c| c.0).fold(f32::INFINITY, f32::min);
    let bound = best * (1.0 + tol);
    sc.costs.retain(|&(c, _)| c <= bound);
    sc.costs[(rng.next_u64() % sc.costs.len() as u64) as usize].1
}

/// `sum |v|^2 - |sum v|^2 / n` over colours (n times the summed per-channel variance).
fn variance_sum(values: impl Iterator<Item = [f32; 3]>, n: f32) -> f32 {
    if n == 0.0 {
        return 0.0;
    }
    let (mut s1, mut s2) = ([0.0f32; 3], 0.0f32);
    for v in values {
        for ch in 0..3 {
            s1[ch] += v[ch];
            s2 += v[ch] * v[ch];
        }
    }
    s2 - (s1[0] * s1[0] + s1[1] * s1[1] + s1[2] * s1[2]) / n
}

/// Paste patch `pos` into the slot: unknown texels take it; texels synthesised by earlier
/// patches take it only past the minimum-error cuts through the left and top overlaps of width
/// `ov`; seen texels keep their value (the patch's colour over them is kept for the border).
fn paste(p: &mut ChartPatch, s: &Slot, ex: &Exemplar, pos: u32, ov: usize, sc: &mut Scratch) {
    let (bw, bh) = (s.x1 - s.x0, s.y1 - s.y0);
    let err = |p: &ChartPatch, dx: usize, dy: usize| -> f32 {
        let i = (s.y0 + dy) * p.w + s.x0 + dx;
        if p.state[i] != SYNTH {
            return 0.0;
        }
        let (e, v) = (ex.texel(pos, dx as i64, dy as i64), p.val[i]);
        (e[0] - v[0]).powi(2) + (e[1] - v[1]).powi(2) + (e[2] - v[2]).powi(2)
    };
    // Vertical cut through the left overlap: per row, the last column that keeps the old value.
    let ovx = ov.min(bw);
    sc.err.clear();
    sc.err.extend(
        (0..bh)
            .flat_map(|dy| (0..ovx).map(move |dx| (dx, dy)))
            .map(|(dx, dy)| err(p, dx, dy)),
    );
    let cut_x = min_cut(&sc.err, ovx, bh, &mut sc.cum);
    // Horizontal cut through the top overlap: per column, the last row that keeps the old value.
    let ovy = ov.min(bh);
    sc.err.clear();
    sc.err.extend(
        (0..bw)
            .flat_map(|dx| (0..ovy).map(move |dy| (dx, dy)))
            .map(|(dx, dy)| err(p, dx, dy)),
    );
    let cut_y = min_cut(&sc.err, ovy, bw, &mut sc.cum);
    for dy in 0..bh {
        for dx in 0..bw {
            let i = (s.y0 + dy) * p.w + s.x0 + dx;
            let e = ex.texel(pos, dx as i64, dy as i64);
            let take = match p.state[i] {
                UNKNOWN => true,
                SYNTH => dx as i64 > cut_x[dy] && dy as i64 > cut_y[dx],
                SEEN => {
                    p.over_seen[i] = Some(e);
                    false
                }
                _ => false,
            };
            if take {
                p.val[i] = e;
                p.state[i] = SYNTH;
                p.at_border[i] = border_mismatch(p, s.x0 + dx, s.y0 + dy, |ox, oy| {
                    ex.texel(pos, dx as i64 + ox, dy as i64 + oy)
                });
            }
        }
    }
}

/// Mean of `seen - patch` over the seen 4-neighbours of texel (x, y) (`patch(ox, oy)`: the
/// patch's colour at offset (ox, oy) from it); `None` when no neighbour was seen.
fn border_mismatch(
    p: &ChartPatch,
    x: usize,
    y: usize,
    patch: impl Fn(i64, i64) -> [f32; 3],
) -> Option<[f32; 3]> {
    let mut sum = [0.0f32; 3];
    let mut n = 0.0f32;
    for (ox, oy) in [(-1i64, 0i64), (1, 0), (0, -1), (0, 1)] {
        let (nx, ny) = (x as i64 + ox, y as i64 + oy);
        if nx < 0 || ny < 0 || nx >= p.w as i64 || ny >= p.h as i64 {
            continue;
        }
        let j = ny as usize * p.w + nx as usize;
        if p.state[j] == SEEN {
            let e = patch(ox, oy);
            for ch in 0..3 {
                sum[ch] += p.val[j][ch] - e[ch];
            }
            n += 1.0;
        }
    }
    (n > 0.0).then(|| sum.map(|v| v / n))
}

/// Minimum-error path through an overlap strip of `across` x `along` texels (`err` indexed
/// `[along][across]`), moving at most one texel across per step (Efros & Freeman's dynamic
/// programme). Returns, per position along the strip, the last index across that keeps the
/// old value; -1 everywhere when the strip has no error (nothing synthesised under it).
fn min_cut(err: &[f32], across: usize, along: usize, cum: &mut Vec<f32>) -> Vec<i64> {
    if across == 0 || err.iter().all(|&e| e == 0.0) {
        return vec![-1; along];
    }
    cum.clear();
    cum.extend_from_slice(err);
    for a in 1..along {
        for k in 0..across {
            let lo = k.saturating_sub(1);
            let hi = (k + 1).min(across - 1);
            let m = (lo..=hi)
                .map(|j| cum[(a - 1) * across + j])
                .fold(f32::INFINITY, f32::min);
            cum[a * across + k] += m;
        }
    }
    let mut cut = vec![0i64; along];
    let last = &cum[(along - 1) * across..along * across];
    let mut k = (0..across)
        .min_by(|&i, &j| last[i].total_cmp(&last[j]))
        .unwrap_or(0);
    for a in (0..along).rev() {
        cut[a] = k as i64;
        if a > 0 {
            let lo = k.saturating_sub(1);
            let hi = (k + 1).min(across - 1);
            k = (lo..=hi)
                .min_by(|&i, &j| cum[(a - 1) * across + i].total_cmp(&cum[(a - 1) * across + j]))
                .unwrap_or(k);
        }
    }
    // The cut texel itself takes the new patch: keep old strictly left of it.
    cut.iter().map(|&k| k - 1).collect()
}
