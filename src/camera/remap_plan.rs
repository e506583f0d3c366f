//! [`RemapPlan`]: a bilinear remap through an [`UndistortMap`] prepared once for a source size
//! (the taps of every output pixel), so that resampling each frame of a video is only gathers
//! and arithmetic (as cv2.convertMaps does for cv2.remap).

use super::UndistortMap;
use crate::image::error::ImageError;
use crate::Result;
use rayon::prelude::*;
use std::mem::MaybeUninit;

/// A bilinear remap through an [`UndistortMap`] prepared for one source image size: per output
/// pixel, the index of its top-left source pixel and the interpolation fractions (1/65536
/// pixel), so that resampling a frame is only gathers and arithmetic. Build it once per camera
/// and reuse it for every frame (as cv2.convertMaps does for cv2.remap).
#[derive(Clone, Debug, PartialEq)]
pub struct RemapPlan {
    width: u32,
    height: u32,
    src_width: u32,
    src_height: u32,
    taps: Vec<Tap>,
    /// Source position (x, y) of each pixel whose taps are not all inside the source.
    border: Vec<[f32; 2]>,
}

impl RemapPlan {
    /// Prepare resampling through `map` from a source of `src_width` x `src_height` pixels.
    /// Fails when the map's arrays do not hold `width * height` entries, or when the source
    /// has 2^31 pixels or more.
    pub fn new(map: &UndistortMap, src_width: u32, src_height: u32) -> Result<Self> {
        check_map(map, src_width, src_height)?;
        let (w, n) = (map.width as usize, map.map_x.len());
        let mut taps: Vec<Tap> = Vec::with_capacity(n);
        if w > 0 {
            let (sw, sh) = (src_width as usize, src_height as usize);
            taps.spare_capacity_mut()[..n]
                .par_chunks_mut(w * BAND_ROWS)
                .zip(map.map_x.par_chunks(w * BAND_ROWS))
                .zip(map.map_y.par_chunks(w * BAND_ROWS))
                .for_each(|((t, mx), my)| {
                    let mut row = vec![Tap::default(); w];
                    for ((t, mx), my) in t.chunks_mut(w).zip(mx.chunks(w)).zip(my.chunks(w)) {
                        taps_row(mx, my, sw, sh, &mut row);
                        for (d, &s) in t.iter_mut().zip(&row) {
                            d.write(s);
                        }
                    }
                });
            // SAFETY: the chunks cover taps[..n] and every element was written.
            unsafe { taps.set_len(n) };
        }
        let mut border = Vec::new();
        for (i, t) in taps.iter_mut().enumerate() {
            if t.index == BORDER {
                // n < 2^31 (checked), so the border count fits beside the flag.
                t.index = BORDER | border.len() as u32;
                border.push([map.map_x[i], map.map_y[i]]);
            }
        }
        Ok(Self {
            width: map.width,
            height: map.height,
            src_width,
            src_height,
            taps,
            border,
        })
    }

    /// Output size (width, height) in pixels.
    pub fn output_size(&self) -> (u32, u32) {
        (self.width, self.height)
    }

    /// Source size (width, height) in pixels this plan reads.
    pub fn source_size(&self) -> (u32, u32) {
        (self.src_width, self.src_height)
    }

    /// Resample `src` (`channels` interleaved f32 per pixel, row-major, of the plan's source
    /// size) as [`remap_bilinear`] does, into a new image of the plan's output size.
    pub fn remap(&self, src: &[f32], channels: usize, fill: f32) -> Result<Vec<f32>> {
        let n = self.taps.len() * channels;
        let mut out: Vec<f32> = Vec::with_capacity(n);
        self.remap_uninit(src, channels, fill, &mut out.spare_capacity_mut()[..n])?;
        // SAFETY: remap_uninit succeeded, so it wrote all n elements.
        unsafe { out.set_len(n) };
        Ok(out)
    }

    /// Like [`RemapPlan::remap`], writing into `out` (`width * height * channels` values),
    /// so that a frame loop allocates nothing.
    pub fn remap_into(
        &self,
        src: &[f32],
        channels: usize,
        fill: f32,
        out: &mut [f32],
    ) -> Result<()> {
        // SAFETY: MaybeUninit<f32> has the layout of f32, and remap_uninit only writes
        // initialised values, so `out` stays a valid &mut [f32].
        let out = unsafe {
            std::slice::from_raw_parts_mut(out.as_mut_ptr() as *mut MaybeUninit<f32>, out.len())
        };
        self.remap_uninit(src, channels, fill, out)
    }

    /// The body of [`RemapPlan::remap_into`]; on success every element of `out` is written.
    fn remap_uninit(
        &self,
        src: &[f32],
        channels: usize,
        fill: f32,
        out: &mut [MaybeUninit<f32>],
    ) -> Result<()> {
        let img = Image::new(src, self.src_width, self.src_height, channels, fill)?;
        if out.len() != self.taps.len() * channels {
            return Err(ImageError::BufferSize {
                stage: "remap",
                what: "the output buffer",
                got: out.len(),
                expected: self.width as usize * self.height as usize * channels,
            }
            .into());
        }
        let w = self.width as usize;
        if w == 0 {
            return Ok(());
        }
        out.par_chunks_mut(w * channels * BAND_ROWS)
            .zip(self.taps.par_chunks(w * BAND_ROWS))
            .for_each(|(o, t)| {
                gather_dispatch(&img, t, o, |_, index| {
                    self.border[(index & !BORDER) as usize]
                })
            });
        Ok(())
    }
}

/// Output rows per parallel task: enough work to amortise scheduling, small enough to balance
/// two to a few dozen threads on 1024 rows.
const BAND_ROWS: usize = 16;
/// Flag in [`Tap::index`] for a pixel that takes the border path (a tap outside the source, or
/// the source's last pixel, past which the 3-channel kernel would read one value).
const BORDER: u32 = 1 << 31;

/// Check that `data` holds a `width` x `height` image of `channels` (at least 1) values a pixel.
pub(super) fn check_source(data: &[f32], width: u32, height: u32, channels: usize) -> Result<()> {
    let n = width as usize * height as usize;
    if channels == 0 || data.len() != n * channels {
        return Err(ImageError::BufferSize {
            stage: "remap",
            what: "the source image",
            got: data.len(),
            expected: n * channels.max(1),
        }
        .into());
    }
    Ok(())
}

pub(super) fn check_map(map: &UndistortMap, src_width: u32, src_height: u32) -> Result<()> {
    let n = map.width as usize * map.height as usize;
    if map.map_x.len() != n || map.map_y.len() != n {
        return Err(ImageError::BufferSize {
            stage: "remap",
            what: "the map",
            got: map.map_x.len().min(map.map_y.len()),
            expected: n,
        }
        .into());
    }
    if src_width as u64 * src_height as u64 >= BORDER as u64 || n as u64 >= BORDER as u64 {
        return Err(ImageError::Inconsistent {
            stage: "remap",
            message: format!(
                "{src_width} x {src_height} source or {n}-pixel map too large (2^31 pixels at most)"
            ),
        }
        .into());
    }
    Ok(())
}

/// The source image of a remap.
struct Image<'a> {
    data: &'a [f32],
    w: usize,
    h: usize,
    c: usize,
    fill: f32,
}

impl<'a> Image<'a> {
    fn new(data: &'a [f32], width: u32, height: u32, c: usize, fill: f32) -> Result<Self> {
        let (w, h) = (width as usize, height as usize);
        check_source(data, width, height, c)?;
        Ok(Self {
            data,
            w,
            h,
            c,
            fill,
        })
    }

    /// Bilinear sample at (x, y) near or beyond the border: taps outside contribute `fill`.
    #[cold]
    fn sample_border_into(&self, x: f32, y: f32, out: &mut [MaybeUninit<f32>]) {
        let mut buf = [0f32; 16];
        let mut heap = Vec::new();
        let px = if self.c <= 16 {
            &mut buf[..self.c]
        } else {
            heap.resize(self.c, 0.0);
            &mut heap[..]
        };
        self.sample_border(x, y, px);
        for (o, &v) in out.iter_mut().zip(px.iter()) {
            o.write(v);
        }
    }

    fn sample_border(&self, x: f32, y: f32, out: &mut [f32]) {
        let (w, h) = (self.w as f32, self.h as f32);
        // False for NaN; keeps huge values away from the integer casts' saturation.
        if !(x > -1.0 && y > -1.0 && x < w && y < h) {
            out.fill(self.fill);
            return;
        }
        let (x0, y0) = (x.floor(), y.floor());
        let (ax, ay) = (x - x0, y - y0);
        let (x0, y0) = (x0 as i64, y0 as i64);
        let c = self.c;
        out.fill(0.0);
        for (dy, dx, wt) in [
            (0, 0, (1.0 - ax) * (1.0 - ay)),
            (0, 1, ax * (1.0 - ay)),
            (1, 0, (1.0 - ax) * ay),
            (1, 1, ax * ay),
        ] {
            let (xi, yi) = (x0 + dx, y0 + dy);
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

/// One output pixel's bilinear footprint: the index (pixels) of the top-left source tap and
/// the fractions in 1/65536 pixel, or `BORDER` (| a border list index) for the slow path.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
struct Tap {
    index: u32,
    fx: u16,
    fy: u16,
}

impl Tap {
    /// The tap of source position (x, y) in a `w` x `h` source; BORDER unless all four taps
    /// lie inside and the bottom-right one is not the source's last pixel.
    #[inline(always)]
    fn new(x: f32, y: f32, w: usize, h: usize) -> Self {
        // Branch-free, in i32 (w, h < 2^31, checked), so that a row of taps vectorises.
        // False for NaN; keeps huge values away from the integer casts' saturation.
        let near = x >= 0.0 && y >= 0.0 && x < w as f32 && y < h as f32;
        let (wi, hi) = (w as i32, h as i32);
        // floor() by truncation (x, y >= 0 when used): f32::floor and f32::round are libm
        // calls on baseline x86-64.
        let (x0, y0) = (x as i32, y as i32);
        let inside = near & (x0 < wi - 1) & (y0 < hi - 1) & !((x0 == wi - 2) & (y0 == hi - 2));
        let frac = |a: f32| ((a * 65536.0 + 0.5) as i32).min(65535) as u16;
        Self {
            index: if inside {
                (y0 as u32).wrapping_mul(w as u32).wrapping_add(x0 as u32)
            } else {
                BORDER
            },
            fx: frac(x - x0 as f32),
            fy: frac(y - y0 as f32),
        }
    }
}

/// Taps of one row of map positions, with AVX2 when the CPU has it.
fn taps_row(mx: &[f32], my: &[f32], w: usize, h: usize, taps: &mut [Tap]) {
    #[cfg(target_arch = "x86_64")]
    if std::arch::is_x86_feature_detected!("avx2") {
        // SAFETY: the CPU supports AVX2, checked just above.
        unsafe { taps_row_avx2(mx, my, w, h, taps) };
        return;
    }
    taps_row_body(mx, my, w, h, taps);
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
unsafe fn taps_row_avx2(mx: &[f32], my: &[f32], w: usize, h: usize, taps: &mut [Tap]) {
    taps_row_body(mx, my, w, h, taps);
}

#[inline(always)]
fn taps_row_body(mx: &[f32], my: &[f32], w: usize, h: usize, taps: &mut [Tap]) {
    for ((t, &x), &y) in taps.iter_mut().zip(mx).zip(my) {
        *t = Tap::new(x, y, w, h);
    }
}

/// [`gather`] for the channel count of `img` (constant for 1, 3 and 4, so the per-pixel
/// loads and arithmetic are fixed-size vector operations), with AVX2 when the CPU has it.
fn gather_dispatch(
    img: &Image,
    taps: &[Tap],
    out: &mut [MaybeUninit<f32>],
    border_xy: impl Fn(usize, u32) -> [f32; 2],
) {
    #[cfg(target_arch = "x86_64")]
    if std::arch::is_x86_feature_detected!("avx2") {
        // SAFETY: the CPU supports AVX2, checked just above.
        unsafe {
            match img.c {
                1 => gather_avx2::<1>(img, taps, out, &border_xy),
                3 => gather_avx2::<3>(img, taps, out, &border_xy),
                4 => gather_avx2::<4>(img, taps, out, &border_xy),
                _ => gather_avx2::<0>(img, taps, out, &border_xy),
            }
        }
        return;
    }
    match img.c {
        1 => gather::<1>(img, taps, out, &border_xy),
        3 => gather::<3>(img, taps, out, &border_xy),
        4 => gather::<4>(img, taps, out, &border_xy),
        _ => gather::<0>(img, taps, out, &border_xy),
    }
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
unsafe fn gather_avx2<const C: usize>(
    img: &Image,
    taps: &[Tap],
    out: &mut [MaybeUninit<f32>],
    border_xy: &impl Fn(usize, u32) -> [f32; 2],
) {
    gather::<C>(img, taps, out, border_xy);
}

/// Four consecutive values of `data` from `i`.
#[inline(always)]
fn load4(data: &[f32], i: usize) -> [f32; 4] {
    data[i..i + 4].try_into().expect("4 values")
}

/// Bilinear samples of `taps` into `out` (`taps.len()` pixels of `img.c` values). `C` is the
/// channel count, or 0 for any. `border_xy(k, index)` gives the source position of pixel `k`
/// when its tap is a BORDER one.
#[inline(always)]
fn gather<const C: usize>(
    img: &Image,
    taps: &[Tap],
    out: &mut [MaybeUninit<f32>],
    border_xy: &impl Fn(usize, u32) -> [f32; 2],
) {
    let c = img.c;
    let data = img.data;
    let row = img.w * c;
    const S: f32 = 1.0 / 65536.0;
    let n = taps.len();
    for (k, t) in taps.iter().enumerate() {
        if t.index & BORDER != 0 {
            let [x, y] = border_xy(k, t.index);
            img.sample_border_into(x, y, &mut out[k * c..(k + 1) * c]);
            continue;
        }
        let (ax, ay) = (t.fx as f32 * S, t.fy as f32 * S);
        let i = t.index as usize * c;
        let j = i + row;
        match C {
            1 => {
                let (p00, p01, p10, p11) = (data[i], data[i + 1], data[j], data[j + 1]);
                let top = p00 + ax * (p01 - p00);
                let bot = p10 + ax * (p11 - p10);
                out[k].write(top + ay * (bot - top));
            }
            3 | 4 => {
                // Four lanes even for RGB: the fourth lane holds the next pixel's first value
                // (Tap::new keeps the source's last pixel out of this path, so the loads stay
                // inside `data`); its result is overwritten by the next pixel's store.
                let (p00, p01) = (load4(data, i), load4(data, i + C));
                let (p10, p11) = (load4(data, j), load4(data, j + C));
                let mut v = [0f32; 4];
                for l in 0..4 {
                    let top = p00[l] + ax * (p01[l] - p00[l]);
                    let bot = p10[l] + ax * (p11[l] - p10[l]);
                    v[l] = top + ay * (bot - top);
                }
                let o = k * C;
                let lanes = if C == 4 || k + 1 < n { 4 } else { 3 };
                for (d, &x) in out[o..o + lanes].iter_mut().zip(&v) {
                    d.write(x);
                }
            }
            _ => {
                for l in 0..c {
                    let (p00, p01) = (data[i + l], data[i + c + l]);
                    let (p10, p11) = (data[j + l], data[j + c + l]);
                    let top = p00 + ax * (p01 - p00);
                    let bot = p10 + ax * (p11 - p10);
                    out[k * c + l].write(top + ay * (bot - top));
                }
            }
        }
    }
}
