//! The border between seen and synthesised texels, in the spirit of Pérez et al.'s seamless
//! cloning (the patch's own gradients kept, the seen values met at the border):
//!
//! * low frequencies: the patches' colour difference to the seen texels they lay over,
//!   smoothed, carried into the synthesised texels and faded out over one patch, so the
//!   synthesised wall continues the seen wall's local brightness and colour;
//! * texel scale: each synthesised texel next to seen ones is shifted by the mean of
//!   `seen - patch` over its seen neighbours (the patch's colour there from its one-texel ring),
//!   so the step across the border is the patch's own step; the shift fades over a few texels.

use super::quilt::{ChartPatch, SEEN, SYNTH};
use crate::texture::blur::{blur_rect, gaussian_kernel};

/// Standard deviation of the smoothing of the difference, as a share of the patch edge.
const SIGMA_PER_PATCH: f32 = 0.2;
/// Texels over which the texel-scale difference at the border fades out.
const SHORT_FADE_TEXELS: f32 = 4.0;

/// Correct the synthesised texels of `p` near its seen texels (`patch`: patch edge, texels).
pub(super) fn correct_border(p: &mut ChartPatch, patch: usize) {
    let (w, h) = (p.w, p.h);
    if !p.over_seen.iter().any(Option::is_some) || !p.state.contains(&SYNTH) {
        return;
    }
    // Normalised convolution of the difference over the seen texels under a patch.
    let kernel = gaussian_kernel((SIGMA_PER_PATCH * patch as f32).max(1.0));
    let mut tmp = Vec::new();
    let mut weight: Vec<f32> = p
        .over_seen
        .iter()
        .map(|o| if o.is_some() { 1.0 } else { 0.0 })
        .collect();
    let mut diff: [Vec<f32>; 3] = std::array::from_fn(|ch| {
        p.over_seen
            .iter()
            .zip(&p.val)
            .map(|(o, v)| o.map_or(0.0, |e| v[ch] - e[ch]))
            .collect()
    });
    blur_rect(&mut weight, w, h, &kernel, &mut tmp);
    for d in &mut diff {
        blur_rect(d, w, h, &kernel, &mut tmp);
    }
    // Low frequencies: seeded on the seen texels the patches lay over.
    let mut smooth = vec![[0.0f32; 3]; w * h];
    let mut seeds = Vec::new();
    for i in 0..w * h {
        if p.state[i] == SEEN && p.over_seen[i].is_some() && weight[i] > 1e-6 {
            smooth[i] = std::array::from_fn(|ch| diff[ch][i] / weight[i]);
            seeds.push(i);
        }
    }
    let d_smooth = spread(&p.state, w, h, &mut smooth, seeds);
    let long = patch as f32;
    let a_long = |i: usize| (1.0 - (d_smooth[i] as f32 - 1.0) / long).clamp(0.0, 1.0);
    // Texel scale: what remains of each border texel's own mismatch, from its seen neighbours.
    let mut raw = vec![[0.0f32; 3]; w * h];
    let mut seeds = Vec::new();
    for i in 0..w * h {
        if let (SYNTH, Some(m)) = (p.state[i], p.at_border[i]) {
            let a = a_long(i);
            raw[i] = std::array::from_fn(|ch| m[ch] - a * smooth[i][ch]);
            seeds.push(i);
        }
    }
    let d_raw = spread(&p.state, w, h, &mut raw, seeds);
    for i in 0..w * h {
        if p.state[i] != SYNTH {
            continue;
        }
        let (al, ar) = (
            if d_smooth[i] == u32::MAX {
                0.0
            } else {
                a_long(i)
            },
            if d_raw[i] == u32::MAX {
                0.0
            } else {
                (1.0 - d_raw[i] as f32 / SHORT_FADE_TEXELS).max(0.0)
            },
        );
        for ch in 0..3 {
            p.val[i][ch] = (p.val[i][ch] + al * smooth[i][ch] + ar * raw[i][ch]).max(0.0);
        }
    }
}

/// Breadth-first waves from `seeds` into the synthesised texels: each reached texel takes the
/// mean of `v` over its already reached 8-neighbours. Returns the wave number of every texel
/// (0 for seeds, `u32::MAX` where none arrived).
fn spread(state: &[u8], w: usize, h: usize, v: &mut [[f32; 3]], seeds: Vec<usize>) -> Vec<u32> {
    let mut dist = vec![u32::MAX; w * h];
    for &i in &seeds {
        dist[i] = 0;
    }
    let mut front = seeds;
    let mut d = 0u32;
    while !front.is_empty() {
        d += 1;
        let mut next = Vec::new();
        for &i in &front {
            for j in neighbours(i, w, h) {
                if state[j] == SYNTH && dist[j] == u32::MAX {
                    dist[j] = d;
                    next.push(j);
                }
            }
        }
        for &j in &next {
            let (mut s, mut n) = ([0.0f32; 3], 0.0f32);
            for k in neighbours(j, w, h) {
                if dist[k] < d {
                    for ch in 0..3 {
                        s[ch] += v[k][ch];
                    }
                    n += 1.0;
                }
            }
            v[j] = s.map(|x| x / n.max(1.0));
        }
        front = next;
    }
    dist
}

/// The 8-neighbours of texel `i` in a `w` x `h` rectangle.
fn neighbours(i: usize, w: usize, h: usize) -> impl Iterator<Item = usize> {
    let (x, y) = ((i % w) as i64, (i / w) as i64);
    (-1..=1i64)
        .flat_map(move |dy| (-1..=1i64).map(move |dx| (x + dx, y + dy)))
        .filter(move |&(nx, ny)| {
            (nx, ny) != (x, y) && nx >= 0 && ny >= 0 && nx < w as i64 && ny < h as i64
        })
        .map(move |(nx, ny)| ny as usize * w + nx as usize)
}
