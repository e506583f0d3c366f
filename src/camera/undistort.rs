//! Undistortion of whole images: a per-pixel source map, as cv2.initUndistortRectifyMap
//! (R = I, CV_32FC1), and bilinear resampling through it, as cv2.remap (INTER_LINEAR,
//! BORDER_CONSTANT).

use super::Camera;
use crate::math::Matrix3;
use crate::{Error, Result};
use rayon::prelude::*;

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
        let mut map_x = vec![0f32; w * h];
        let mut map_y = vec![0f32; w * h];
        if w == 0 || h == 0 {
            return Ok(Self {
                width,
                height,
                map_x,
                map_y,
            });
        }
        let c = *camera;
        // The normalised ray of pixel (u, v) is ir * (u, v, 1): linear in u along a row, so each
        // row starts from (x0, y0, w0) and steps by the first column of ir.
        let (dx, dy, dw) = (ir[(0, 0)], ir[(1, 0)], ir[(2, 0)]);
        let affine = dw == 0.0 && ir[(2, 1)] == 0.0;
        map_x
            .par_chunks_mut(w)
            .zip(map_y.par_chunks_mut(w))
            .enumerate()
            .for_each(|(v, (row_x, row_y))| {
                let vf = v as f64;
                let x0 = ir[(0, 1)] * vf + ir[(0, 2)];
                let y0 = ir[(1, 1)] * vf + ir[(1, 2)];
                let w0 = ir[(2, 1)] * vf + ir[(2, 2)];
                if affine {
                    let inv_w = 1.0 / w0;
                    distort_row(
                        &c,
                        row_x,
                        row_y,
                        x0 * inv_w,
                        dx * inv_w,
                        y0 * inv_w,
                        dy * inv_w,
                    );
                } else {
                    for (u, (mx, my)) in row_x.iter_mut().zip(row_y.iter_mut()).enumerate() {
                        let uf = u as f64;
                        let iw = 1.0 / (w0 + dw * uf);
                        let (x, y) = ((x0 + dx * uf) * iw, (y0 + dy * uf) * iw);
                        let (px, py) = distort_pixel(&c, x, y);
                        (*mx, *my) = (px as f32, py as f32);
                    }
                }
            });
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

/// One map row with an affine pixel → ray relation: x = x0 + dx u, y = y0 + dy u.
/// Written as a plain loop over slices so the compiler can vectorise it.
#[inline]
fn distort_row(
    c: &Camera,
    row_x: &mut [f32],
    row_y: &mut [f32],
    x0: f64,
    dx: f64,
    y0: f64,
    dy: f64,
) {
    for (u, (mx, my)) in row_x.iter_mut().zip(row_y.iter_mut()).enumerate() {
        let uf = u as f64;
        let (px, py) = distort_pixel(c, x0 + dx * uf, y0 + dy * uf);
        *mx = px as f32;
        *my = py as f32;
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
/// exact. Returns an error when `src` has the wrong length.
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
    let src = Source {
        data: src,
        w: sw,
        h: sh,
        fill,
    };
    let out = match channels {
        1 => remap_impl::<1>(&src, map),
        3 => remap_impl::<3>(&src, map),
        4 => remap_impl::<4>(&src, map),
        n => remap_dyn(&src, map, n),
    };
    Ok(out)
}

struct Source<'a> {
    data: &'a [f32],
    w: usize,
    h: usize,
    fill: f32,
}

impl Source<'_> {
    /// Bilinear sample at (x, y) into `out` (`out.len()` channels); the fast path when all four
    /// taps are inside, else per-tap with `fill` outside.
    #[inline(always)]
    fn sample(&self, x: f32, y: f32, out: &mut [f32]) {
        let c = out.len();
        let (xf, yf) = (x.floor(), y.floor());
        let (ax, ay) = (x - xf, y - yf);
        // Range check in float first: casting NaN or huge values to isize would be meaningless.
        if !(xf >= -1.0 && yf >= -1.0 && xf < self.w as f32 && yf < self.h as f32) {
            out.fill(self.fill);
            return;
        }
        let (x0, y0) = (xf as isize, yf as isize);
        let (w, h) = (self.w as isize, self.h as isize);
        let (w00, w01, w10, w11) = (
            (1.0 - ax) * (1.0 - ay),
            ax * (1.0 - ay),
            (1.0 - ax) * ay,
            ax * ay,
        );
        if x0 >= 0 && y0 >= 0 && x0 + 1 < w && y0 + 1 < h {
            let i = (y0 as usize * self.w + x0 as usize) * c;
            let j = i + self.w * c;
            let (r0, r1) = (&self.data[i..i + 2 * c], &self.data[j..j + 2 * c]);
            for k in 0..c {
                out[k] = w00 * r0[k] + w01 * r0[c + k] + w10 * r1[k] + w11 * r1[c + k];
            }
            return;
        }
        out.fill(0.0);
        for (dy, dx, wt) in [(0, 0, w00), (0, 1, w01), (1, 0, w10), (1, 1, w11)] {
            let (xi, yi) = (x0 + dx, y0 + dy);
            if xi >= 0 && yi >= 0 && xi < w && yi < h {
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

fn remap_impl<const C: usize>(src: &Source, map: &UndistortMap) -> Vec<f32> {
    let w = map.width as usize;
    let mut out = vec![0f32; map.map_x.len() * C];
    if w == 0 {
        return out;
    }
    out.par_chunks_mut(w * C)
        .zip(map.map_x.par_chunks(w).zip(map.map_y.par_chunks(w)))
        .for_each(|(row, (mx, my))| {
            for ((px, &x), &y) in row.chunks_exact_mut(C).zip(mx).zip(my) {
                src.sample(x, y, px);
            }
        });
    out
}

fn remap_dyn(src: &Source, map: &UndistortMap, c: usize) -> Vec<f32> {
    let w = map.width as usize;
    let mut out = vec![0f32; map.map_x.len() * c];
    if w == 0 {
        return out;
    }
    out.par_chunks_mut(w * c)
        .zip(map.map_x.par_chunks(w).zip(map.map_y.par_chunks(w)))
        .for_each(|(row, (mx, my))| {
            for ((px, &x), &y) in row.chunks_exact_mut(c).zip(mx).zip(my) {
                src.sample(x, y, px);
            }
        });
    out
}
