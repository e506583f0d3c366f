//! [`Frame`]: one image in linear light, the type every stage that reads or writes pixels
//! meets at (decoding and encoding live in `io::png` and `io::video`).

/// One image in linear light: `rgb` holds `width * height` interleaved R, G, B values,
/// row-major from the top-left pixel, each in 0..=1 (1 = the sensor's maximum code, so a
/// channel equal to 1.0 is saturated). Pixel centres are at integer coordinates (OpenCV).
#[derive(Clone, Debug, PartialEq)]
pub struct Frame {
    /// Width in pixels.
    pub width: u32,
    /// Height in pixels.
    pub height: u32,
    /// Interleaved linear R, G, B, `3 * width * height` values.
    pub rgb: Vec<f32>,
}

impl Frame {
    /// A black frame of `width` x `height` pixels.
    pub fn new(width: u32, height: u32) -> Self {
        Frame {
            width,
            height,
            rgb: vec![0.0; 3 * width as usize * height as usize],
        }
    }

    /// Linear R, G, B of pixel (`x`, `y`); panics when outside the frame (a programming error).
    #[inline]
    pub fn get(&self, x: u32, y: u32) -> [f32; 3] {
        assert!(
            x < self.width && y < self.height,
            "pixel ({x}, {y}) outside the frame"
        );
        let i = 3 * (y as usize * self.width as usize + x as usize);
        [self.rgb[i], self.rgb[i + 1], self.rgb[i + 2]]
    }

    /// Set pixel (`x`, `y`) to linear R, G, B; panics when outside the frame.
    #[inline]
    pub fn set(&mut self, x: u32, y: u32, value: [f32; 3]) {
        assert!(
            x < self.width && y < self.height,
            "pixel ({x}, {y}) outside the frame"
        );
        let i = 3 * (y as usize * self.width as usize + x as usize);
        self.rgb[i..i + 3].copy_from_slice(&value);
    }

    /// Bilinear sample at continuous pixel coordinates (`x`, `y`), pixel centres at integers.
    ///
    /// Returns `None` outside the image's footprint `[-0.5, width - 0.5] x [-0.5, height - 0.5]`
    /// (or for NaN); within half a pixel of the border the edge pixels are extended.
    #[inline]
    pub fn bilinear(&self, x: f64, y: f64) -> Option<[f32; 3]> {
        let (w, h) = (self.width as f64, self.height as f64);
        // Written so that NaN fails every comparison and is rejected.
        if !(x >= -0.5 && x <= w - 0.5 && y >= -0.5 && y <= h - 0.5) || self.rgb.is_empty() {
            return None;
        }
        let x = x.clamp(0.0, w - 1.0);
        let y = y.clamp(0.0, h - 1.0);
        // Clamped to >= 0: truncation is floor.
        let (x0, y0) = (x as usize, y as usize);
        let x1 = (x0 + 1).min(self.width as usize - 1);
        let y1 = (y0 + 1).min(self.height as usize - 1);
        let (fx, fy) = ((x - x0 as f64) as f32, (y - y0 as f64) as f32);
        let stride = self.width as usize;
        let px = |xx: usize, yy: usize| 3 * (yy * stride + xx);
        let (a, b, c, d) = (px(x0, y0), px(x1, y0), px(x0, y1), px(x1, y1));
        let mut out = [0.0f32; 3];
        for (k, o) in out.iter_mut().enumerate() {
            let top = self.rgb[a + k] + fx * (self.rgb[b + k] - self.rgb[a + k]);
            let bottom = self.rgb[c + k] + fx * (self.rgb[d + k] - self.rgb[c + k]);
            *o = top + fy * (bottom - top);
        }
        Some(out)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bilinear_interpolates_and_rejects_outside() {
        let mut f = Frame::new(2, 2);
        f.set(0, 0, [0.0, 0.0, 0.0]);
        f.set(1, 0, [1.0, 0.0, 0.0]);
        f.set(0, 1, [0.0, 1.0, 0.0]);
        f.set(1, 1, [1.0, 1.0, 1.0]);
        let v = f.bilinear(0.25, 0.5).unwrap();
        assert!((v[0] - 0.25).abs() < 1e-6 && (v[1] - 0.5).abs() < 1e-6);
        assert!((v[2] - 0.125).abs() < 1e-6);
        assert_eq!(f.bilinear(-0.5, -0.5).unwrap(), [0.0, 0.0, 0.0]);
        assert!(f.bilinear(-0.6, 0.0).is_none());
        assert!(f.bilinear(0.0, 1.6).is_none());
        assert!(f.bilinear(f64::NAN, 0.0).is_none());
    }
}
