//! The observed frame as an image pyramid for direct alignment: each level holds the frame
//! divided by its gain (linear RGB), its central-difference gradients, which pixels may be
//! sampled, and the camera of that level.

use crate::camera::Camera;
use crate::image::Frame;
use crate::{Error, Result};

/// Values stored per pixel: R, G, B, then d/dx of R, G, B, then d/dy of R, G, B.
const STRIDE: usize = 9;

/// One level of the pyramid.
#[derive(Clone, Debug)]
pub struct ImageLevel {
    /// Width (pixels).
    pub width: usize,
    /// Height (pixels).
    pub height: usize,
    /// The camera whose pixels these are (intrinsics scaled, same distortion).
    pub camera: Camera,
    /// [`STRIDE`] values per pixel, row-major.
    data: Vec<f32>,
    /// True where the pixel's value obeys the model (not saturated, inside the mask).
    valid: Vec<bool>,
    /// True where the pixel and its four neighbours are valid (its gradient is sound).
    ok: Vec<bool>,
}

/// A value and its image gradient at a sub-pixel position: `[value; 3]`, `[d/dx; 3]`,
/// `[d/dy; 3]` (per pixel of the level).
pub type Sample = ([f32; 3], [f32; 3], [f32; 3]);

impl ImageLevel {
    /// Bilinear value and gradient at level-pixel coordinates (x, y), pixel centres at
    /// integers; `None` when any of the four pixels around it may not be sampled.
    #[inline]
    pub fn sample(&self, x: f64, y: f64) -> Option<Sample> {
        // Only pixels with a weight need to be usable, and the border is extended by EDGE: a
        // point at a pixel centre (where the model's points are rendered) does not depend on
        // which side round-off puts it.
        const EDGE: f32 = 1e-3;
        let (wmax, hmax) = ((self.width - 1) as f64, (self.height - 1) as f64);
        let e = f64::from(EDGE);
        if !(x >= -e && y >= -e && x <= wmax + e && y <= hmax + e) {
            return None;
        }
        let (x, y) = (x.clamp(0.0, wmax), y.clamp(0.0, hmax));
        // The last column and row are reached with a weight of 1 on them (continuous there).
        let (x0, y0) = (
            (x as usize).min(self.width - 2),
            (y as usize).min(self.height - 2),
        );
        let (fx, fy) = ((x - x0 as f64) as f32, (y - y0 as f64) as f32);
        let i = y0 * self.width + x0;
        let w = self.width;
        let (need_x0, need_x1) = (fx < 1.0 - EDGE, fx > EDGE);
        let (need_y0, need_y1) = (fy < 1.0 - EDGE, fy > EDGE);
        let usable = (!(need_x0 && need_y0) || self.ok[i])
            && (!(need_x1 && need_y0) || self.ok[i + 1])
            && (!(need_x0 && need_y1) || self.ok[i + w])
            && (!(need_x1 && need_y1) || self.ok[i + w + 1]);
        if !usable {
            return None;
        }
        let d = &self.data;
        let (a, b, c, e) = (
            STRIDE * i,
            STRIDE * (i + 1),
            STRIDE * (i + w),
            STRIDE * (i + w + 1),
        );
        let mut out = [0.0f32; STRIDE];
        for (k, o) in out.iter_mut().enumerate() {
            let top = d[a + k] + fx * (d[b + k] - d[a + k]);
            let bot = d[c + k] + fx * (d[e + k] - d[c + k]);
            *o = top + fy * (bot - top);
        }
        Some((
            [out[0], out[1], out[2]],
            [out[3], out[4], out[5]],
            [out[6], out[7], out[8]],
        ))
    }

    /// Whether pixel (x, y) may be sampled.
    pub fn usable(&self, x: usize, y: usize) -> bool {
        x < self.width && y < self.height && self.ok[y * self.width + x]
    }
}

/// Options of [`ObservedPyramid::new`].
#[derive(Clone, Debug)]
pub struct PyramidOptions {
    /// Levels below the full image (level L has 2^L times fewer pixels per side).
    pub levels: usize,
    /// Linear value at or above which a channel is saturated: the pixel, and any coarse pixel
    /// it falls in, is not used (specular highlights do not obey the model).
    pub saturation_level: f32,
}

impl Default for PyramidOptions {
    fn default() -> Self {
        PyramidOptions {
            levels: 4,
            saturation_level: 0.999,
        }
    }
}

/// The pyramid of one observed frame.
#[derive(Clone, Debug)]
pub struct ObservedPyramid {
    /// Level 0 is the frame itself.
    pub levels: Vec<ImageLevel>,
}

impl ObservedPyramid {
    /// Build the pyramid of `frame` (linear RGB) divided by `gain`, taken by `camera`;
    /// `mask` (one flag per pixel, row-major) marks the pixels that may be used (e.g. the
    /// scope's circular field of view), `None` for all.
    pub fn new(
        frame: &Frame,
        camera: &Camera,
        gain: f64,
        mask: Option<&[bool]>,
        opts: &PyramidOptions,
    ) -> Result<ObservedPyramid> {
        let (w, h) = (frame.width as usize, frame.height as usize);
        if (frame.width, frame.height) != (camera.width, camera.height) {
            return Err(Error::Other(format!(
                "registration: frame is {w}x{h} but the camera is {}x{}",
                camera.width, camera.height
            )));
        }
        if mask.is_some_and(|m| m.len() != w * h) {
            return Err(Error::Other(format!(
                "registration: the mask has {} flags for a {w}x{h} frame",
                mask.map_or(0, |m| m.len())
            )));
        }
        if !(gain.is_finite() && gain > 0.0) {
            return Err(Error::Other(format!(
                "registration: frame gain must be positive, got {gain}"
            )));
        }
        let inv = (1.0 / gain) as f32;
        let rgb: Vec<f32> = frame.rgb.iter().map(|v| v * inv).collect();
        let valid: Vec<bool> = (0..w * h)
            .map(|i| {
                mask.is_none_or(|m| m[i])
                    && frame.rgb[3 * i..3 * i + 3]
                        .iter()
                        .all(|v| v.is_finite() && *v < opts.saturation_level)
            })
            .collect();
        let mut levels = vec![make_level(rgb, valid, w, h, *camera)];
        for l in 1..=opts.levels {
            let prev = levels.last().expect("level 0 exists");
            let (pw, ph) = (prev.width, prev.height);
            let (nw, nh) = (pw / 2, ph / 2);
            if nw < 4 || nh < 4 {
                break;
            }
            let mut rgb = vec![0.0f32; 3 * nw * nh];
            let mut valid = vec![true; nw * nh];
            for y in 0..nh {
                for x in 0..nw {
                    let o = y * nw + x;
                    for (dx, dy) in [(0, 0), (1, 0), (0, 1), (1, 1)] {
                        let i = (2 * y + dy) * pw + 2 * x + dx;
                        valid[o] &= prev.valid[i];
                        for c in 0..3 {
                            rgb[3 * o + c] += 0.25 * prev.data[STRIDE * i + c];
                        }
                    }
                }
            }
            levels.push(make_level(rgb, valid, nw, nh, camera.at_level(l)));
        }
        Ok(ObservedPyramid { levels })
    }
}

/// A level from its values (RGB interleaved) and per-pixel validity: gradients by central
/// differences (one-sided at the border), `ok` = the pixel and its four neighbours valid.
fn make_level(rgb: Vec<f32>, valid: Vec<bool>, w: usize, h: usize, camera: Camera) -> ImageLevel {
    let mut data = vec![0.0f32; STRIDE * w * h];
    for y in 0..h {
        for x in 0..w {
            let i = y * w + x;
            let (xl, xr) = (x.saturating_sub(1), (x + 1).min(w - 1));
            let (yu, yd) = (y.saturating_sub(1), (y + 1).min(h - 1));
            let (sx, sy) = ((xr - xl).max(1) as f32, (yd - yu).max(1) as f32);
            for c in 0..3 {
                data[STRIDE * i + c] = rgb[3 * i + c];
                data[STRIDE * i + 3 + c] =
                    (rgb[3 * (y * w + xr) + c] - rgb[3 * (y * w + xl) + c]) / sx;
                data[STRIDE * i + 6 + c] =
                    (rgb[3 * (yd * w + x) + c] - rgb[3 * (yu * w + x) + c]) / sy;
            }
        }
    }
    let ok = (0..w * h)
        .map(|i| {
            let (x, y) = (i % w, i / w);
            valid[i]
                && (x == 0 || valid[i - 1])
                && (x + 1 == w || valid[i + 1])
                && (y == 0 || valid[i - w])
                && (y + 1 == h || valid[i + w])
        })
        .collect();
    ImageLevel {
        width: w,
        height: h,
        camera,
        data,
        valid,
        ok,
    }
}
