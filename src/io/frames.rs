//! Video frames as linear RGB floats: PNG decoding and encoding, and the sRGB transfer curve.
//!
//! Frames are decoded from sRGB to linear intensity at load and encoded back at write
//! (DESIGN.md, conventions); everything in between works in linear light.

use std::fs::File;
use std::io::{BufReader, BufWriter};
use std::path::Path;
use std::sync::OnceLock;

use crate::{Error, Result};

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
        let (x0, y0) = (x.floor() as usize, y.floor() as usize);
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

/// sRGB-encoded value (0..=1) to linear light, the exact IEC 61966-2-1 piecewise curve.
#[inline]
pub fn srgb_to_linear(encoded: f32) -> f32 {
    srgb_to_linear_f64(encoded as f64) as f32
}

/// Linear light (0..=1) to an sRGB-encoded value, the exact IEC 61966-2-1 inverse curve.
/// Values outside 0..=1 are clamped.
#[inline]
pub fn linear_to_srgb(linear: f32) -> f32 {
    linear_to_srgb_f64(linear as f64) as f32
}

fn srgb_to_linear_f64(c: f64) -> f64 {
    if c <= 0.04045 {
        c / 12.92
    } else {
        ((c + 0.055) / 1.055).powf(2.4)
    }
}

fn linear_to_srgb_f64(l: f64) -> f64 {
    let l = l.clamp(0.0, 1.0);
    if l <= 0.0031308 {
        12.92 * l
    } else {
        1.055 * l.powf(1.0 / 2.4) - 0.055
    }
}

/// Linear value of every 8-bit sRGB code.
pub fn srgb8_to_linear_lut() -> &'static [f32; 256] {
    static LUT: OnceLock<[f32; 256]> = OnceLock::new();
    LUT.get_or_init(|| std::array::from_fn(|c| srgb_to_linear_f64(c as f64 / 255.0) as f32))
}

/// Linear value of every 16-bit sRGB code (65536 entries, 256 KiB, built once).
pub fn srgb16_to_linear_lut() -> &'static [f32] {
    static LUT: OnceLock<Vec<f32>> = OnceLock::new();
    LUT.get_or_init(|| {
        (0..=u16::MAX)
            .map(|c| srgb_to_linear_f64(c as f64 / 65535.0) as f32)
            .collect()
    })
}

/// Exact, fast linear → sRGB code quantiser for codes `0..=max`.
///
/// `thresholds[k]` is the linear value of the encoded code `k + 0.5`, so code `c` is the
/// answer exactly when `thresholds[c - 1] <= x < thresholds[c]`: rounding happens in the encoded
/// domain and every LUT value maps back to its own code. A 4096-bucket table of the encoded
/// curve, interpolated, gives a guess within about one code; a short walk fixes it (no `powf`).
struct Quantiser {
    max: usize,
    guess: Vec<f32>,
    thresholds: Vec<f32>,
}

const GUESS_BUCKETS: usize = 4096;

impl Quantiser {
    fn new(max: usize) -> Self {
        let guess = (0..=GUESS_BUCKETS)
            .map(|i| (linear_to_srgb_f64(i as f64 / GUESS_BUCKETS as f64) * max as f64) as f32)
            .collect();
        let thresholds = (0..max)
            .map(|k| srgb_to_linear_f64((k as f64 + 0.5) / max as f64) as f32)
            .collect();
        Quantiser {
            max,
            guess,
            thresholds,
        }
    }

    #[inline]
    fn code(&self, x: f32) -> usize {
        if x.is_nan() || x <= 0.0 {
            return 0;
        }
        if x >= 1.0 {
            return self.max;
        }
        let t = x * GUESS_BUCKETS as f32;
        let i = (t as usize).min(GUESS_BUCKETS - 1);
        let f = t - i as f32;
        let g = self.guess[i] + f * (self.guess[i + 1] - self.guess[i]);
        let mut c = ((g + 0.5) as usize).min(self.max);
        while c < self.max && x >= self.thresholds[c] {
            c += 1;
        }
        while c > 0 && x < self.thresholds[c - 1] {
            c -= 1;
        }
        c
    }
}

fn quantiser8() -> &'static Quantiser {
    static Q: OnceLock<Quantiser> = OnceLock::new();
    Q.get_or_init(|| Quantiser::new(255))
}

fn quantiser16() -> &'static Quantiser {
    static Q: OnceLock<Quantiser> = OnceLock::new();
    Q.get_or_init(|| Quantiser::new(65535))
}

/// Linear light to the nearest 8-bit sRGB code, rounding in the encoded domain (clamped; NaN
/// gives 0). Exact inverse of [`srgb8_to_linear_lut`].
#[inline]
pub fn linear_to_srgb8(linear: f32) -> u8 {
    quantiser8().code(linear) as u8
}

/// Linear light to the nearest 16-bit sRGB code, rounding in the encoded domain (clamped; NaN
/// gives 0). Exact inverse of [`srgb16_to_linear_lut`].
#[inline]
pub fn linear_to_srgb16(linear: f32) -> u16 {
    quantiser16().code(linear) as u16
}

/// Read a PNG (8 or 16 bit; grey, grey+alpha, RGB, RGBA or palette) into linear RGB.
/// Grey is copied to R = G = B; alpha is dropped. The samples are taken as sRGB-encoded.
pub fn read_png(path: &Path) -> Result<Frame> {
    let file = File::open(path).map_err(|e| Error::io(path, e))?;
    decode_png(BufReader::new(file), path)
}

/// [`read_png`] of PNG file contents held in memory (e.g. a texture embedded in a GLB);
/// `name` is the file errors name.
pub fn decode_png_bytes(bytes: &[u8], name: &Path) -> Result<Frame> {
    decode_png(std::io::Cursor::new(bytes), name)
}

fn decode_png<R: std::io::BufRead + std::io::Seek>(input: R, path: &Path) -> Result<Frame> {
    let bad = |e: png::DecodingError| Error::invalid(path, format!("not a readable PNG: {e}"));
    let mut decoder = png::Decoder::new(input);
    // Palettes, low bit depths and tRNS become plain 8/16-bit grey/RGB(A) samples.
    decoder.set_transformations(png::Transformations::EXPAND);
    let mut reader = decoder.read_info().map_err(bad)?;
    let size = reader
        .output_buffer_size()
        .ok_or_else(|| Error::invalid(path, "PNG too large for this machine"))?;
    let mut buf = vec![0u8; size];
    let info = reader.next_frame(&mut buf).map_err(bad)?;
    let (width, height) = (info.width, info.height);
    let channels = match info.color_type {
        png::ColorType::Grayscale => 1,
        png::ColorType::GrayscaleAlpha => 2,
        png::ColorType::Rgb => 3,
        png::ColorType::Rgba => 4,
        png::ColorType::Indexed => {
            return Err(Error::invalid(path, "palette PNG was not expanded"));
        }
    };
    let n = width as usize * height as usize;
    let mut rgb = vec![0.0f32; 3 * n];
    match info.bit_depth {
        png::BitDepth::Sixteen => {
            let lut = srgb16_to_linear_lut();
            let line = info.line_size;
            for (y, row) in buf.chunks_exact(line).take(height as usize).enumerate() {
                let out = &mut rgb[3 * y * width as usize..3 * (y + 1) * width as usize];
                for (px, o) in row.chunks_exact(2 * channels).zip(out.chunks_exact_mut(3)) {
                    let s = |k: usize| lut[u16::from_be_bytes([px[2 * k], px[2 * k + 1]]) as usize];
                    if channels < 3 {
                        o.fill(s(0));
                    } else {
                        o.copy_from_slice(&[s(0), s(1), s(2)]);
                    }
                }
            }
        }
        png::BitDepth::Eight => {
            let lut = srgb8_to_linear_lut();
            let line = info.line_size;
            for (y, row) in buf.chunks_exact(line).take(height as usize).enumerate() {
                let out = &mut rgb[3 * y * width as usize..3 * (y + 1) * width as usize];
                for (px, o) in row.chunks_exact(channels).zip(out.chunks_exact_mut(3)) {
                    if channels < 3 {
                        o.fill(lut[px[0] as usize]);
                    } else {
                        o.copy_from_slice(&[
                            lut[px[0] as usize],
                            lut[px[1] as usize],
                            lut[px[2] as usize],
                        ]);
                    }
                }
            }
        }
        other => {
            return Err(Error::unsupported(
                path,
                format!("PNG bit depth {other:?} after expansion"),
            ));
        }
    }
    Ok(Frame { width, height, rgb })
}

/// Write `frame` as an 8-bit sRGB RGB PNG (linear values clamped to 0..=1).
pub fn write_png_srgb8(path: &Path, frame: &Frame) -> Result<()> {
    check_frame(path, frame)?;
    let q = quantiser8();
    let data: Vec<u8> = frame.rgb.iter().map(|&v| q.code(v) as u8).collect();
    write_png(path, frame, png::BitDepth::Eight, &data)
}

/// Write `frame` as a 16-bit sRGB RGB PNG (linear values clamped to 0..=1).
pub fn write_png_srgb16(path: &Path, frame: &Frame) -> Result<()> {
    check_frame(path, frame)?;
    let q = quantiser16();
    let data: Vec<u8> = frame
        .rgb
        .iter()
        .flat_map(|&v| (q.code(v) as u16).to_be_bytes())
        .collect();
    write_png(path, frame, png::BitDepth::Sixteen, &data)
}

fn check_frame(path: &Path, frame: &Frame) -> Result<()> {
    let expected = 3 * frame.width as usize * frame.height as usize;
    if frame.rgb.len() != expected || frame.width == 0 || frame.height == 0 {
        return Err(Error::Other(format!(
            "{}: cannot write a {}x{} frame holding {} values (expected {expected}, non-empty)",
            path.display(),
            frame.width,
            frame.height,
            frame.rgb.len()
        )));
    }
    Ok(())
}

fn write_png(path: &Path, frame: &Frame, depth: png::BitDepth, data: &[u8]) -> Result<()> {
    let file = File::create(path).map_err(|e| Error::io(path, e))?;
    let failed = |e: png::EncodingError| match e {
        png::EncodingError::IoError(io) => Error::io(path, io),
        other => Error::Other(format!("{}: PNG encoding failed: {other}", path.display())),
    };
    let mut encoder = png::Encoder::new(BufWriter::new(file), frame.width, frame.height);
    encoder.set_color(png::ColorType::Rgb);
    encoder.set_depth(depth);
    // fdeflate: several times faster than the default with a similar file size.
    encoder.set_compression(png::Compression::Fast);
    // Mark the samples as sRGB so viewers do not apply another gamma.
    encoder.set_source_srgb(png::SrgbRenderingIntent::Perceptual);
    let mut writer = encoder.write_header().map_err(failed)?;
    writer.write_image_data(data).map_err(failed)?;
    writer.finish().map_err(failed)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn codes_round_trip_exactly() {
        for c in 0..=255u8 {
            assert_eq!(linear_to_srgb8(srgb8_to_linear_lut()[c as usize]), c);
        }
        let lut16 = srgb16_to_linear_lut();
        for c in 0..=u16::MAX {
            assert_eq!(linear_to_srgb16(lut16[c as usize]), c, "code {c}");
        }
        assert_eq!(linear_to_srgb8(-1.0), 0);
        assert_eq!(linear_to_srgb8(2.0), 255);
        assert_eq!(linear_to_srgb8(f32::NAN), 0);
        assert_eq!(linear_to_srgb16(f32::NAN), 0);
        assert_eq!(linear_to_srgb16(1.5), 65535);
    }

    #[test]
    fn quantiser_matches_formula_rounding() {
        // Away from code boundaries (f32 thresholds hold a boundary to ~0.003 code) the fast
        // quantiser equals rounding the exact f64 curve.
        for i in 0..=200_000u32 {
            let x = i as f32 / 200_000.0;
            for (max, got) in [
                (255.0, linear_to_srgb8(x) as f64),
                (65535.0, linear_to_srgb16(x) as f64),
            ] {
                let exact = linear_to_srgb_f64(x as f64) * max;
                if (exact - exact.floor() - 0.5).abs() > 0.01 {
                    assert_eq!(got, exact.round(), "x = {x}, max {max}");
                }
            }
        }
    }

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
