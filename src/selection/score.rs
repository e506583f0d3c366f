//! What one decoded frame says about itself, cheaply (one pass over its pixels): how sharp it
//! is in its least sharp direction (motion blur smears one direction), and how much of it is
//! saturated or dark. Sharpness depends on the content, so it is judged against the frame's
//! neighbours in time later ([`super::judge`]), never against a fixed threshold.

use crate::image::Frame;

/// Options of [`score_frame`].
#[derive(Clone, Debug)]
pub struct ScoreOptions {
    /// The luminance is averaged over square blocks first so that the frame is about this
    /// wide (pixels): the mucosa's detail then spans as many pixels at any resolution, and
    /// the sensor noise shrinks with the block.
    pub reduced_width: u32,
    /// A channel at or above this linear value is saturated (8-bit 255 decodes to 1.0).
    pub saturated: f32,
    /// Linear luminance below this is dark (about sRGB 13/255).
    pub dark: f32,
}

impl Default for ScoreOptions {
    fn default() -> Self {
        ScoreOptions {
            reduced_width: 320,
            saturated: 0.999,
            dark: 0.004,
        }
    }
}

/// The per-frame measurements.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct FrameStats {
    /// Detail in the frame's least sharp direction (x, y or a diagonal): mean squared second
    /// difference of the luminance over usable pixels, divided by their mean luminance
    /// squared (dimensionless). 0 when no pixel is usable.
    pub sharpness: f64,
    /// The same in the sharpest direction (a blurred frame keeps it, a flat one does not).
    pub sharpness_max: f64,
    /// Share of the image pixels (inside the mask) with a saturated channel.
    pub saturated_share: f64,
    /// Share of the image pixels whose luminance is dark.
    pub dark_share: f64,
    /// Share of all pixels inside the mask.
    pub image_share: f64,
}

/// Rec. 709 luminance of linear RGB.
#[inline]
fn luminance(c: &[f32]) -> f32 {
    0.2126 * c[0] + 0.7152 * c[1] + 0.0722 * c[2]
}

/// Score `frame` (linear RGB); `mask` (one flag per pixel, row-major, `None` for all) marks
/// the image pixels.
pub fn score_frame(frame: &Frame, mask: Option<&[bool]>, opts: &ScoreOptions) -> FrameStats {
    let (w, h) = (frame.width as usize, frame.height as usize);
    let n = w * h;
    if n == 0 {
        return FrameStats::default();
    }
    let inside = |i: usize| mask.is_none_or(|m| m.get(i).copied().unwrap_or(false));
    // Pass 1: exposure shares, and each pixel's luminance (NaN where it cannot be used).
    let (mut image, mut sat, mut dark) = (0usize, 0usize, 0usize);
    let mut lum = vec![f32::NAN; n];
    for (i, c) in frame.rgb.chunks_exact(3).enumerate() {
        if !inside(i) {
            continue;
        }
        image += 1;
        let l = luminance(c);
        if c.iter().any(|&v| v >= opts.saturated) {
            sat += 1;
        } else if l < opts.dark {
            dark += 1;
        } else {
            lum[i] = l;
        }
    }
    let block = ((frame.width as f64 / opts.reduced_width.max(1) as f64).round() as usize).max(1);
    let (small, sw, sh) = reduce(&lum, w, h, block);
    let (sharpness, sharpness_max) = directional_energy(&small, sw, sh);
    let img = image.max(1) as f64;
    FrameStats {
        sharpness,
        sharpness_max,
        saturated_share: sat as f64 / img,
        dark_share: dark as f64 / img,
        image_share: image as f64 / n as f64,
    }
}

/// Block means of `lum` over `block` × `block` pixels (NaN when any pixel of the block is
/// unusable, so saturated highlights and the mask's edge make no gradients).
fn reduce(lum: &[f32], w: usize, h: usize, block: usize) -> (Vec<f32>, usize, usize) {
    if block <= 1 {
        return (lum.to_vec(), w, h);
    }
    let (sw, sh) = (w / block, h / block);
    let mut out = vec![0f32; sw * sh];
    for (k, o) in out.iter_mut().enumerate() {
        let (bx, by) = (k % sw * block, k / sw * block);
        let mut s = 0f32;
        for y in by..by + block {
            s += lum[y * w + bx..y * w + bx + block].iter().sum::<f32>();
        }
        *o = s / (block * block) as f32;
    }
    (out, sw, sh)
}

/// Mean squared second difference of `lum` along x, y and both diagonals over the pixels
/// whose two neighbours are usable, each divided by the mean luminance squared (diagonals
/// also by 2, their step being sqrt(2) pixels); returns the (least, largest) of the four.
/// Second differences ignore the smooth fall-off of the light, so what is left is the
/// mucosa's detail, which motion blur removes along its direction.
fn directional_energy(lum: &[f32], w: usize, h: usize) -> (f64, f64) {
    const DIRS: [(isize, isize); 4] = [(1, 0), (0, 1), (1, 1), (1, -1)];
    let mut sum = [0f64; 4];
    let mut count = [0usize; 4];
    let (mut lsum, mut ln) = (0f64, 0usize);
    for y in 1..h.saturating_sub(1) {
        for x in 1..w.saturating_sub(1) {
            let l = lum[y * w + x];
            if l.is_nan() {
                continue;
            }
            lsum += l as f64;
            ln += 1;
            for (d, &(dx, dy)) in DIRS.iter().enumerate() {
                let a = lum[(y as isize + dy) as usize * w + (x as isize + dx) as usize];
                let b = lum[(y as isize - dy) as usize * w + (x as isize - dx) as usize];
                let g = (a - 2.0 * l + b) as f64;
                if !g.is_nan() {
                    sum[d] += g * g;
                    count[d] += 1;
                }
            }
        }
    }
    let mean = lsum / ln.max(1) as f64;
    if ln == 0 || mean <= 0.0 {
        return (0.0, 0.0);
    }
    let e: Vec<f64> = (0..4)
        .map(|d| {
            let step = if d >= 2 { 0.5 } else { 1.0 };
            step * sum[d] / count[d].max(1) as f64 / (mean * mean)
        })
        .collect();
    let lo = e.iter().cloned().fold(f64::INFINITY, f64::min);
    let hi = e.iter().cloned().fold(0.0, f64::max);
    (lo, hi)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A frame of random-looking texture (a hash per pixel, so every direction has detail).
    fn textured(w: u32, h: u32) -> Frame {
        let mut f = Frame::new(w, h);
        for y in 0..h {
            for x in 0..w {
                let v =
                    ((x.wrapping_mul(73856093) ^ y.wrapping_mul(19349663)) % 997) as f32 / 997.0;
                f.set(x, y, [0.1 + 0.3 * v; 3]);
            }
        }
        f
    }

    /// Box blur of `f` along x over `len` pixels (a horizontal motion blur).
    fn blur_x(f: &Frame, len: u32) -> Frame {
        let mut out = f.clone();
        for y in 0..f.height {
            for x in 0..f.width {
                let mut acc = 0.0;
                for k in 0..len {
                    acc += f.get((x + k).min(f.width - 1), y)[0];
                }
                out.set(x, y, [acc / len as f32; 3]);
            }
        }
        out
    }

    #[test]
    fn motion_blur_lowers_the_least_sharp_direction() {
        let opts = ScoreOptions::default();
        let f = textured(64, 64);
        let sharp = score_frame(&f, None, &opts);
        let blurred = score_frame(&blur_x(&f, 6), None, &opts);
        // On white-ish noise (variance v) a sharp frame's least direction is a diagonal (second
        // difference variance 6v, halved); a 6-pixel box blur along x leaves 4 samples / 6 in
        // the x second difference: 4v/36, 1/27 of the sharp frame's 3v.
        assert!(
            blurred.sharpness < 0.2 * sharp.sharpness,
            "{blurred:?} vs {sharp:?}"
        );
        // Along y the blur averages 6 independent pixels: 6v / 6, a sixth of 6v, not zero.
        assert!(blurred.sharpness_max > 0.1 * sharp.sharpness_max);
        // Scale-free: twice the light, the same sharpness.
        let mut bright = f.clone();
        bright.rgb.iter_mut().for_each(|v| *v *= 2.0);
        let s2 = score_frame(&bright, None, &opts);
        assert!((s2.sharpness / sharp.sharpness - 1.0).abs() < 1e-5);
    }

    #[test]
    fn exposure_shares_count_inside_the_mask() {
        let mut f = textured(10, 10);
        for x in 0..10 {
            f.set(x, 0, [1.0, 0.5, 0.5]); // saturated row
            f.set(x, 1, [0.001; 3]); // dark row
        }
        let s = score_frame(&f, None, &ScoreOptions::default());
        assert!((s.saturated_share - 0.1).abs() < 1e-12);
        assert!((s.dark_share - 0.1).abs() < 1e-12);
        // The mask leaves out the saturated row: 90 image pixels, 10 of them dark.
        let mask: Vec<bool> = (0..100).map(|i| i >= 10).collect();
        let s = score_frame(&f, Some(&mask), &ScoreOptions::default());
        assert_eq!(s.saturated_share, 0.0);
        assert!((s.dark_share - 10.0 / 90.0).abs() < 1e-12);
        assert!((s.image_share - 0.9).abs() < 1e-12);
    }
}
