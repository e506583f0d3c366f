//! Undistortion of whole images: a per-pixel source map, as cv2.initUndistortRectifyMap
//! (R = I, CV_32FC1), and bilinear resampling through it, as cv2.remap (INTER_LINEAR,
//! BORDER_CONSTANT): once ([`remap_bilinear`]) or, for a map reused on every frame, through a
//! [`RemapPlan`] built once.

use super::Camera;
use crate::math::Matrix3;
use crate::{Error, Result};
use rayon::prelude::*;
use std::mem::MaybeUninit;

/// For each pixel of an ideal pinhole image, the position (pixels) in the distorted camera
/// image that it sees. Row-major, `width * height` entries each.
#[derive(Clone, Debug, PartialEq)]
pub struct UndistortMap {
    /// Width of the undistorted (output) image in pixels.
    pub width: u32,
    /// Height of the undistorted (output) image in pixels.
    pub height: u32,
    /// Source column in the distorted image (pixels, centres at integers).
    pub map_x: Vec<f32>,
    /// Source row in the distorted image (pixels, centres at integers).
    pub map_y: Vec<f32>,
}

impl UndistortMap {
    /// Map for the undistorted image of `camera` with the same K and size
    /// (cv2.initUndistortRectifyMap(K, D, I, K, size, CV_32FC1)).
    pub fn for_camera(camera: &Camera) -> Result<Self> {
        Self::new(camera, &camera.k_matrix(), camera.width, camera.height)
    }

    /// Map for an undistorted image of `width` x `height` pixels seen by the pinhole camera
    /// matrix `new_k`, sampling the distorted image of `camera`; computed in f64 and stored in
    /// f32 like cv2.initUndistortRectifyMap(K, D, R = I, new_k, (width, height), CV_32FC1).
    pub fn new(camera: &Camera, new_k: &Matrix3<f64>, width: u32, height: u32) -> Result<Self> {
        let ir = new_k
            .try_inverse()
            .filter(|m| m.iter().all(|v| v.is_finite()))
            .ok_or_else(|| {
                Error::Other(format!(
                    "undistortion map: new camera matrix is singular: {new_k}"
                ))
            })?;
        let (w, h) = (width as usize, height as usize);
        let n = w * h;
        if n == 0 {
            return Ok(Self {
                width,
                height,
                map_x: Vec::new(),
                map_y: Vec::new(),
            });
        }
        // Not zero-filled first: every element is written exactly once below.
        let mut map_x: Vec<f32> = Vec::with_capacity(n);
        let mut map_y: Vec<f32> = Vec::with_capacity(n);
        let c = *camera;
        // The normalised ray of pixel (u, v) is ir * (u, v, 1): linear in u along a row, so each
        // row starts from (x0, y0, w0) and steps by the first column of ir.
        let (dx, dy, dw) = (ir[(0, 0)], ir[(1, 0)], ir[(2, 0)]);
        let affine = dw == 0.0 && ir[(2, 1)] == 0.0;
        let cols: Vec<f64> = (0..w).map(|u| u as f64).collect();
        map_x.spare_capacity_mut()[..n]
            .par_chunks_mut(w)
            .zip(map_y.spare_capacity_mut()[..n].par_chunks_mut(w))
            .enumerate()
            .for_each(|(v, (row_x, row_y))| {
                let vf = v as f64;
                let x0 = ir[(0, 1)] * vf + ir[(0, 2)];
                let y0 = ir[(1, 1)] * vf + ir[(1, 2)];
                let w0 = ir[(2, 1)] * vf + ir[(2, 2)];
                if affine {
                    let iw = 1.0 / w0;
                    let row = Row {
                        x0: x0 * iw,
                        dx: dx * iw,
                        y0: y0 * iw,
                        dy: dy * iw,
                    };
                    distort_row(&c, &row, &cols, row_x, row_y);
                } else {
                    for (u, (mx, my)) in row_x.iter_mut().zip(row_y.iter_mut()).enumerate() {
                        let uf = u as f64;
                        let iw = 1.0 / (w0 + dw * uf);
                        let (x, y) = ((x0 + dx * uf) * iw, (y0 + dy * uf) * iw);
                        let (px, py) = distort_pixel(&c, x, y);
                        mx.write(px as f32);
                        my.write(py as f32);
                    }
                }
            });
        // SAFETY: the rows cover [..n] of both maps and each row writes all its elements.
        unsafe {
            map_x.set_len(n);
            map_y.set_len(n);
        }
        Ok(Self {
            width,
            height,
            map_x,
            map_y,
        })
    }

    /// Per output pixel, true when the source position lies inside the distorted image of
    /// `src_width` x `src_height` pixels, i.e. every bilinear tap reads a real pixel.
    pub fn validity_mask(&self, src_width: u32, src_height: u32) -> Vec<bool> {
        let (wm, hm) = (src_width as f32 - 1.0, src_height as f32 - 1.0);
        self.map_x
            .par_iter()
            .zip(self.map_y.par_iter())
            .map(|(&x, &y)| (0.0..=wm).contains(&x) && (0.0..=hm).contains(&y))
            .collect()
    }
}

/// A map row with an affine pixel → ray relation: x = x0 + dx u, y = y0 + dy u.
struct Row {
    x0: f64,
    dx: f64,
    y0: f64,
    dy: f64,
}

/// Fill one map row; uses AVX2 (4 doubles per instruction) when the CPU has it, the same
/// code compiled for the baseline x86-64 (SSE2) otherwise. Results are bit-identical: no FMA
/// contraction happens without an explicit mul_add.
fn distort_row(
    c: &Camera,
    row: &Row,
    cols: &[f64],
    row_x: &mut [MaybeUninit<f32>],
    row_y: &mut [MaybeUninit<f32>],
) {
    #[cfg(target_arch = "x86_64")]
    if std::arch::is_x86_feature_detected!("avx2") {
        // SAFETY: the CPU supports AVX2, checked just above.
        unsafe { distort_row_avx2(c, row, cols, row_x, row_y) };
        return;
    }
    distort_row_body(c, row, cols, row_x, row_y);
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
unsafe fn distort_row_avx2(
    c: &Camera,
    row: &Row,
    cols: &[f64],
    row_x: &mut [MaybeUninit<f32>],
    row_y: &mut [MaybeUninit<f32>],
) {
    distort_row_body(c, row, cols, row_x, row_y);
}

/// The row loop over flat slices, written so the compiler vectorises it (no integer → float
/// conversion inside: the column coordinates come precomputed in `cols`).
#[inline(always)]
fn distort_row_body(
    c: &Camera,
    row: &Row,
    cols: &[f64],
    row_x: &mut [MaybeUninit<f32>],
    row_y: &mut [MaybeUninit<f32>],
) {
    for ((mx, my), &u) in row_x.iter_mut().zip(row_y.iter_mut()).zip(cols) {
        let (px, py) = distort_pixel(c, row.x0 + row.dx * u, row.y0 + row.dy * u);
        mx.write(px as f32);
        my.write(py as f32);
    }
}

/// Distorted pixel of the normalised undistorted point (x, y) (the formula of
/// cv2.initUndistortRectifyMap, identical to [`Camera::distort_normalized`] followed by K).
#[inline(always)]
fn distort_pixel(c: &Camera, x: f64, y: f64) -> (f64, f64) {
    let (x2, y2, xy2) = (x * x, y * y, 2.0 * x * y);
    let r2 = x2 + y2;
    let radial = 1.0 + r2 * (c.k1 + r2 * (c.k2 + r2 * c.k3));
    let xd = x * radial + c.p1 * xy2 + c.p2 * (r2 + 2.0 * x2);
    let yd = y * radial + c.p1 * (r2 + 2.0 * y2) + c.p2 * xy2;
    (c.fx * xd + c.cx, c.fy * yd + c.cy)
}

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
    if channels == 0 || src.len() != sw * sh * channels {
        return Err(Error::Other(format!(
            "remap: source image has {} values, expected {sw} x {sh} x {channels}",
            src.len()
        )));
    }
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
            return Err(Error::Other(format!(
                "remap: output buffer has {} values, expected {} x {} x {channels}",
                out.len(),
                self.width,
                self.height
            )));
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

fn check_map(map: &UndistortMap, src_width: u32, src_height: u32) -> Result<()> {
    let n = map.width as usize * map.height as usize;
    if map.map_x.len() != n || map.map_y.len() != n {
        return Err(Error::Other(format!(
            "remap: map of {} x {} pixels holds {} / {} positions",
            map.width,
            map.height,
            map.map_x.len(),
            map.map_y.len()
        )));
    }
    if src_width as u64 * src_height as u64 >= BORDER as u64 || n as u64 >= BORDER as u64 {
        return Err(Error::Other(format!(
            "remap: {src_width} x {src_height} source or {n}-pixel map too large (2^31 pixels at most)"
        )));
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
        if c == 0 || data.len() != w * h * c {
            return Err(Error::Other(format!(
                "remap: source image has {} values, expected {w} x {h} x {c}",
                data.len()
            )));
        }
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

// ---- One-shot tiled remap (remap_bilinear): taps computed per tile from the map. ----

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
