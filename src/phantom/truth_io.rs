//! Writers for the phantom's truth files (the per-vertex albedo PLY and the single-channel and
//! linear 16-bit PNGs of the novel views) and the reader of those PNGs.

use crate::image::Frame;
use crate::io::mesh_export::write_ply_with_colours;
use crate::mesh::TriMesh;
use crate::{Error, Result};
use std::path::Path;

/// Binary little-endian PLY: vertex `x y z` (float, world mm), `nx ny nz` (unit, into the
/// lumen), `red green blue` (float, linear albedo in [0, 1]); faces `list uchar uint`.
/// [`crate::io::mesh_export::read_ply`] reads its geometry (it skips the extra properties).
pub fn write_albedo_ply(path: &Path, mesh: &TriMesh, albedo: &[[f32; 3]]) -> Result<()> {
    write_ply_with_colours(
        path,
        mesh,
        Some(albedo),
        "bronchosim phantom truth: lumen mesh (world mm, RAS+) with linear RGB albedo",
    )
}

fn write_png_raw(
    path: &Path,
    width: u32,
    height: u32,
    color: png::ColorType,
    depth: png::BitDepth,
    data: &[u8],
) -> Result<()> {
    let mut bytes = Vec::new();
    {
        let mut enc = png::Encoder::new(&mut bytes, width, height);
        enc.set_color(color);
        enc.set_depth(depth);
        let mut w = enc
            .write_header()
            .map_err(|e| Error::invalid(path, e.to_string()))?;
        w.write_image_data(data)
            .map_err(|e| Error::invalid(path, e.to_string()))?;
    }
    crate::io::atomic::write_bytes_atomic(path, &bytes)
}

/// 8-bit greyscale PNG (e.g. a hit mask, 255 = hit).
pub fn write_gray8_png(path: &Path, width: u32, height: u32, data: &[u8]) -> Result<()> {
    write_png_raw(
        path,
        width,
        height,
        png::ColorType::Grayscale,
        png::BitDepth::Eight,
        data,
    )
}

/// 16-bit greyscale PNG (e.g. depth in units of 0.01 mm).
pub fn write_gray16_png(path: &Path, width: u32, height: u32, data: &[u16]) -> Result<()> {
    let bytes: Vec<u8> = data.iter().flat_map(|v| v.to_be_bytes()).collect();
    write_png_raw(
        path,
        width,
        height,
        png::ColorType::Grayscale,
        png::BitDepth::Sixteen,
        &bytes,
    )
}

/// 16-bit RGB PNG of LINEAR values (code = round(v · 65535), clamped; no sRGB curve).
pub fn write_linear16_png(path: &Path, frame: &Frame) -> Result<()> {
    let bytes: Vec<u8> = frame
        .rgb
        .iter()
        .flat_map(|&v| ((v.clamp(0.0, 1.0) * 65535.0).round() as u16).to_be_bytes())
        .collect();
    write_png_raw(
        path,
        frame.width,
        frame.height,
        png::ColorType::Rgb,
        png::BitDepth::Sixteen,
        &bytes,
    )
}

/// The raw 16-bit codes of a PNG with `channels` samples per pixel (the truth images written
/// by [`write_gray16_png`] and [`write_linear16_png`]), row-major, channels interleaved.
pub fn read_png16(path: &Path, channels: usize) -> Result<Vec<u16>> {
    let file = std::fs::File::open(path).map_err(|e| Error::io(path, e))?;
    let mut r = png::Decoder::new(std::io::BufReader::new(file))
        .read_info()
        .map_err(|e| Error::invalid(path, e.to_string()))?;
    let size = r
        .output_buffer_size()
        .ok_or_else(|| Error::invalid(path, "image too large"))?;
    let mut buf = vec![0u8; size];
    let info = r
        .next_frame(&mut buf)
        .map_err(|e| Error::invalid(path, e.to_string()))?;
    if info.bit_depth != png::BitDepth::Sixteen || info.color_type.samples() != channels {
        return Err(Error::invalid(
            path,
            format!("expected a 16-bit PNG with {channels} channel(s)"),
        ));
    }
    Ok(buf[..info.buffer_size()]
        .chunks_exact(2)
        .map(|b| u16::from_be_bytes([b[0], b[1]]))
        .collect())
}
