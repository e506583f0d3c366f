//! Frames and pixel masks reduced by a power of two: the working resolution of the build's
//! fitting and registration passes (`workflow::build`), matching
//! [`crate::camera::Camera::at_level`].

use super::Frame;

/// `frame` averaged over blocks of `2^level × 2^level` pixels (the last rows and columns that
/// do not fill a block are dropped, as in [`crate::camera::Camera::at_level`]). A channel that
/// is saturated (`>= saturation_level`) in any pixel of a block is saturated (1.0) in the
/// result: its average would hide a clipped value that the fits must leave out.
pub fn reduce_frame(frame: &Frame, level: usize, saturation_level: f32) -> Frame {
    if level == 0 {
        return frame.clone();
    }
    let s = 1usize << level;
    let (w, h) = (frame.width as usize, frame.height as usize);
    let (nw, nh) = (w >> level, h >> level);
    let inv = 1.0 / (s * s) as f32;
    let mut out = Frame::new(nw as u32, nh as u32);
    for y in 0..nh {
        for x in 0..nw {
            let mut sum = [0.0f32; 3];
            let mut saturated = [false; 3];
            for dy in 0..s {
                let row = 3 * ((s * y + dy) * w + s * x);
                for px in frame.rgb[row..row + 3 * s].chunks_exact(3) {
                    for c in 0..3 {
                        sum[c] += px[c];
                        saturated[c] |= px[c] >= saturation_level;
                    }
                }
            }
            let o = 3 * (y * nw + x);
            for c in 0..3 {
                out.rgb[o + c] = if saturated[c] { 1.0 } else { sum[c] * inv };
            }
        }
    }
    out
}

/// `mask` (`width × height` flags, row-major) reduced like [`reduce_frame`]: a reduced pixel is
/// usable when every pixel of its block is.
pub fn reduce_mask(mask: &[bool], width: usize, height: usize, level: usize) -> Vec<bool> {
    let s = 1usize << level;
    let (nw, nh) = (width >> level, height >> level);
    (0..nw * nh)
        .map(|i| {
            let (x, y) = (i % nw, i / nw);
            (0..s).all(|dy| mask[(s * y + dy) * width + s * x..][..s].iter().all(|&m| m))
        })
        .collect()
}

/// `frame`, a reduction by `2^level`, brought back to `width × height` by bilinear
/// interpolation between the reduced pixels' centres (a reduced pixel `u` is centred on
/// full-resolution `2^level u + (2^level - 1) / 2`, as in [`reduce_frame`]); beyond the outer
/// centres the edge values are extended.
pub fn expand_frame(frame: &Frame, level: usize, width: u32, height: u32) -> Frame {
    if level == 0 && frame.width == width && frame.height == height {
        return frame.clone();
    }
    let s = (1u32 << level) as f64;
    let off = (s - 1.0) / 2.0;
    let mut out = Frame::new(width, height);
    for y in 0..height {
        let v = ((y as f64 - off) / s).clamp(0.0, frame.height as f64 - 1.0);
        for x in 0..width {
            let u = ((x as f64 - off) / s).clamp(0.0, frame.width as f64 - 1.0);
            if let Some(px) = frame.bilinear(u, v) {
                out.set(x, y, px);
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn blocks_are_averaged_and_saturation_survives() {
        let mut f = Frame::new(5, 4);
        for y in 0..4 {
            for x in 0..5 {
                f.set(x, y, [0.1 * x as f32, 0.1 * y as f32, 0.2]);
            }
        }
        f.set(2, 2, [0.2, 1.0, 0.2]);
        let r = reduce_frame(&f, 1, 0.999);
        assert_eq!((r.width, r.height), (2, 2));
        let a = r.get(0, 0);
        assert!((a[0] - 0.05).abs() < 1e-6 && (a[1] - 0.05).abs() < 1e-6);
        assert!((a[2] - 0.2).abs() < 1e-6);
        // Block (1, 1) holds the pixel saturated in green only.
        let b = r.get(1, 1);
        assert_eq!(b[1], 1.0);
        assert!((b[0] - 0.25).abs() < 1e-6 && (b[2] - 0.2).abs() < 1e-6);
        assert_eq!(reduce_frame(&f, 0, 0.999), f);
    }

    #[test]
    fn expanding_a_reduced_ramp_gives_the_ramp_back() {
        let (w, h) = (16u32, 8u32);
        let mut f = Frame::new(w, h);
        for y in 0..h {
            for x in 0..w {
                f.set(x, y, [0.01 * x as f32, 0.02 * y as f32, 0.5]);
            }
        }
        let e = expand_frame(&reduce_frame(&f, 1, 2.0), 1, w, h);
        assert_eq!((e.width, e.height), (w, h));
        // Between the outer reduced centres (0.5 .. w - 1.5) a linear ramp is exact; beyond
        // them the edge value is held.
        for y in 1..h - 1 {
            for x in 1..w - 1 {
                let (a, b) = (e.get(x, y), f.get(x, y));
                assert!(
                    (a[0] - b[0]).abs() < 1e-5 && (a[1] - b[1]).abs() < 1e-5,
                    "{x},{y}"
                );
            }
        }
        assert!((e.get(0, 0)[0] - 0.005).abs() < 1e-6);
    }

    #[test]
    fn a_masked_out_pixel_masks_its_block() {
        let mut m = vec![true; 4 * 4];
        m[5] = false; // (1, 1)
        assert_eq!(reduce_mask(&m, 4, 4, 1), vec![false, true, true, true]);
        assert_eq!(reduce_mask(&m, 4, 4, 2), vec![false]);
    }
}
