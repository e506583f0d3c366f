//! PNG decoding into linear [`Frame`]s and encoding back to sRGB (8 or 16 bit).

use std::fs::File;
use std::io::{BufReader, BufWriter};
use std::path::Path;

use crate::image::error::ImageError;
use crate::image::srgb::{
    linear_to_srgb16, linear_to_srgb8, srgb16_to_linear_lut, srgb8_to_linear_lut,
};
use crate::image::Frame;
use crate::{Error, Result};

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
    let data: Vec<u8> = frame.rgb.iter().map(|&v| linear_to_srgb8(v)).collect();
    write_png(path, frame, png::BitDepth::Eight, &data)
}

/// Write `frame` as a 16-bit sRGB RGB PNG (linear values clamped to 0..=1).
pub fn write_png_srgb16(path: &Path, frame: &Frame) -> Result<()> {
    check_frame(path, frame)?;
    let data: Vec<u8> = frame
        .rgb
        .iter()
        .flat_map(|&v| linear_to_srgb16(v).to_be_bytes())
        .collect();
    write_png(path, frame, png::BitDepth::Sixteen, &data)
}

fn check_frame(path: &Path, frame: &Frame) -> Result<()> {
    let expected = 3 * frame.width as usize * frame.height as usize;
    if frame.rgb.len() != expected || frame.width == 0 || frame.height == 0 {
        return Err(Error::invalid(
            path,
            format!(
                "cannot write a {}x{} frame holding {} values (expected {expected}, non-empty)",
                frame.width,
                frame.height,
                frame.rgb.len()
            ),
        ));
    }
    Ok(())
}

fn write_png(path: &Path, frame: &Frame, depth: png::BitDepth, data: &[u8]) -> Result<()> {
    let file = File::create(path).map_err(|e| Error::io(path, e))?;
    let failed = |e: png::EncodingError| match e {
        png::EncodingError::IoError(io) => Error::io(path, io),
        other => ImageError::Encoding {
            stage: path.display().to_string(),
            message: other.to_string(),
        }
        .into(),
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
