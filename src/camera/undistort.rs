//! Undistortion of whole images: a per-pixel source map, as cv2.initUndistortRectifyMap
//! (R = I, CV_32FC1). Resampling through it is in `remap` (once) and `remap_plan` (a map
//! reused on every frame).

use super::Camera;
use crate::image::error::ImageError;
use crate::math::Matrix3;
use crate::Result;
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
            .ok_or_else(|| ImageError::Inconsistent {
                stage: "undistortion map",
                message: format!("the new camera matrix is singular: {new_k}"),
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
