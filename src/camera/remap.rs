//! Bilinear resampling of one image through an [`UndistortMap`], as cv2.remap (INTER_LINEAR,
//! BORDER_CONSTANT), in one pass over output tiles with the taps computed on the fly.

use super::remap_plan::{check_map, check_source};
use super::UndistortMap;
use crate::Result;
use rayon::prelude::*;
use std::mem::MaybeUninit;

/// Resample an interleaved image (`channels` f32 values per pixel, row-major,
/// `src_width` x `src_height`) through `map` with bilinear interpolation, in parallel over
/// rows. Taps outside the source take the value `fill` (cv2.BORDER_CONSTANT), so output
/// pixels whose source is outside the image are `fill`; see [`UndistortMap::validity_mask`].
/// Unlike cv2.remap, which rounds the interpolation weights to 1/32 pixel, the weights are
/// exact. Returns an error when `src` has the wrong length. To resample many frames through
/// one map, build a [`RemapPlan`] once instead (faster per frame; weights to 1/65536 pixel).
pub fn remap_bilinear(
    src: &[f32],
    src_width: u32,
    src_height: u32,
    channels: usize,
    map: &UndistortMap,
    fill: f32,
) -> Result<Vec<f32>> {
    let (sw, sh) = (src_width as usize, src_height as usize);
    check_source(src, src_width, src_height, channels)?;
    check_map(map, src_width, src_height)?;
    // One pass over output tiles, computing taps on the fly (exact f32 weights); no plan kept.
    let src = Source {
        data: src,
        w: sw,
        h: sh,
        fill,
    };
    let out = match channels {
        1 => remap_tiled::<1>(&src, map, 1),
        3 => remap_tiled::<3>(&src, map, 3),
        4 => remap_tiled::<4>(&src, map, 4),
        n => remap_tiled::<0>(&src, map, n),
    };
    Ok(out)
}

struct Source<'a> {
    data: &'a [f32],
    w: usize,
    h: usize,
    fill: f32,
}

/// Bilinear footprint of one output pixel: top-left tap (x0, y0) and fractions (ax, ay);
/// x0 = i32::MIN marks a position with no tap inside the image (or NaN).
#[derive(Clone, Copy, Default)]
struct Taps {
    x0: i32,
    y0: i32,
    ax: f32,
    ay: f32,
}

impl Source<'_> {
    /// Branch-free so that a row of taps vectorises.
    #[inline(always)]
    fn taps(&self, x: f32, y: f32) -> Taps {
        // False for NaN; keeps huge values away from the integer casts' saturation.
        let near = x > -1.0 && y > -1.0 && x < self.w as f32 && y < self.h as f32;
        // floor() by truncation: f32::floor is a libm call on baseline x86-64 (no SSE4.1).
        let (xt, yt) = (x as i32, y as i32);
        let (x0, y0) = (xt - (x < xt as f32) as i32, yt - (y < yt as f32) as i32);
        let (ax, ay) = (x - x0 as f32, y - y0 as f32);
        Taps {
            x0: if near { x0 } else { i32::MIN },
            y0,
            ax,
            ay,
        }
    }

    /// True when all four taps lie inside the image.
    #[inline(always)]
    fn interior(&self, t: Taps) -> bool {
        t.x0 >= 0 && t.y0 >= 0 && t.x0 as usize + 1 < self.w && t.y0 as usize + 1 < self.h
    }

    /// Bilinear sample with all four taps inside (`out.len()` channels), as two horizontal
    /// lerps and one vertical.
    #[inline(always)]
    fn sample_interior(&self, t: Taps, out: &mut [f32]) {
        let c = out.len();
        let i = (t.y0 as usize * self.w + t.x0 as usize) * c;
        let j = i + self.w * c;
        let (r0, r1) = (&self.data[i..i + 2 * c], &self.data[j..j + 2 * c]);
        for (k, o) in out.iter_mut().enumerate() {
            let top = r0[k] + t.ax * (r0[c + k] - r0[k]);
            let bot = r1[k] + t.ax * (r1[c + k] - r1[k]);
            *o = top + t.ay * (bot - top);
        }
    }

    /// Bilinear sample near or beyond the border: taps outside contribute `fill`.
    #[cold]
    fn sample_border(&self, t: Taps, out: &mut [f32]) {
        if t.x0 == i32::MIN {
            out.fill(self.fill);
            return;
        }
        let c = out.len();
        let (ax, ay) = (t.ax, t.ay);
        out.fill(0.0);
        for (dy, dx, wt) in [
            (0, 0, (1.0 - ax) * (1.0 - ay)),
            (0, 1, ax * (1.0 - ay)),
            (1, 0, (1.0 - ax) * ay),
            (1, 1, ax * ay),
        ] {
            let (xi, yi) = (t.x0 as i64 + dx, t.y0 as i64 + dy);
            if xi >= 0 && yi >= 0 && (xi as usize) < self.w && (yi as usize) < self.h {
                let i = (yi as usize * self.w + xi as usize) * c;
                for (o, &s) in out.iter_mut().zip(&self.data[i..i + c]) {
                    *o += wt * s;
                }
            } else {
                for o in out.iter_mut() {
                    *o += wt * self.fill;
                }
            }
        }
    }
}

/// Output tile: 32 rows x 64 columns, whose source region (~100 KB of RGB f32) stays in L2.
/// Row by row, a strongly distorted map walks across many source rows (one cache line per
/// pixel); tiles keep reads local, as OpenCV's remap does.
const TILE_ROWS: usize = 32;
const TILE_COLS: usize = 64;

/// Tiled remap, parallel over bands of [`TILE_ROWS`] output rows. `C` is the channel count
/// (a constant, so the channel loops unroll), or 0 to use `c_dyn`.
fn remap_tiled<const C: usize>(src: &Source, map: &UndistortMap, c_dyn: usize) -> Vec<f32> {
    let c = if C == 0 { c_dyn } else { C };
    let w = map.width as usize;
    let n = map.map_x.len() * c;
    if w == 0 {
        return vec![0.0; n];
    }
    // Not zero-filled first: every element is written exactly once below (saves a 16 MB
    // memset per 1280x1024 RGB frame).
    let mut out: Vec<f32> = Vec::with_capacity(n);
    out.spare_capacity_mut()[..n]
        .par_chunks_mut(w * c * TILE_ROWS)
        .enumerate()
        .for_each(|(band_index, band)| {
            #[cfg(target_arch = "x86_64")]
            if std::arch::is_x86_feature_detected!("avx2") {
                // SAFETY: the CPU supports AVX2, checked just above.
                unsafe { remap_band_avx2::<C>(src, map, band_index, band, c_dyn) };
                return;
            }
            remap_band::<C>(src, map, band_index, band, c_dyn);
        });
    // SAFETY: the bands cover out[..n] and remap_band writes every element of its band.
    unsafe { out.set_len(n) };
    out
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
unsafe fn remap_band_avx2<const C: usize>(
    src: &Source,
    map: &UndistortMap,
    band_index: usize,
    band: &mut [MaybeUninit<f32>],
    c_dyn: usize,
) {
    remap_band::<C>(src, map, band_index, band, c_dyn);
}

/// One band of output rows, tile by tile; each tile row in two passes: the taps of all its
/// pixels (vectorised), then the gathers. Writes every element of `band`.
#[inline(always)]
fn remap_band<const C: usize>(
    src: &Source,
    map: &UndistortMap,
    band_index: usize,
    band: &mut [MaybeUninit<f32>],
    c_dyn: usize,
) {
    let c = if C == 0 { c_dyn } else { C };
    let w = map.width as usize;
    let row0 = band_index * TILE_ROWS;
    let rows = band.len() / (w * c);
    let mut taps = [Taps::default(); TILE_COLS];
    let mut px = [0f32; 16];
    let mut px_dyn = vec![0f32; if C == 0 || C > 16 { c } else { 0 }];
    for u0 in (0..w).step_by(TILE_COLS) {
        let u1 = (u0 + TILE_COLS).min(w);
        for r in 0..rows {
            let m = (row0 + r) * w;
            let (mx, my) = (&map.map_x[m + u0..m + u1], &map.map_y[m + u0..m + u1]);
            for (t, (&x, &y)) in taps.iter_mut().zip(mx.iter().zip(my)) {
                *t = src.taps(x, y);
            }
            let out_row = &mut band[(r * w + u0) * c..(r * w + u1) * c];
            for (dst, &t) in out_row.chunks_exact_mut(c).zip(&taps) {
                let val = if C == 0 || C > 16 {
                    &mut px_dyn[..]
                } else {
                    &mut px[..C]
                };
                if src.interior(t) {
                    src.sample_interior(t, val);
                } else {
                    src.sample_border(t, val);
                }
                for (d, &v) in dst.iter_mut().zip(val.iter()) {
                    d.write(v);
                }
            }
        }
    }
}
