//! Writing the texture: `albedo.png` (the atlas, sRGB 8-bit), `coverage.png` (which texels a
//! frame saw) and `airway.glb` (the atlas mesh with UVs and the albedo embedded).
//!
//! UV convention: atlas texel (x, y) covers u in [x, x + 1] / width and v in [y, y + 1] /
//! height, and row y = 0 is stored first; PNG stores the top row first and glTF puts UV (0, 0)
//! at the image's top-left corner with v growing down. So atlas UVs go to glTF unchanged.

use std::path::Path;

use super::atlas::Atlas;
use crate::image::error::ImageError;
use crate::image::srgb::linear_to_srgb8;
use crate::io::atomic::write_bytes_atomic;
use crate::io::mesh_export::write_glb;
use crate::Result;

/// Linear value the 99th percentile of the albedo is mapped to before sRGB encoding: the
/// fused albedo has an arbitrary global scale (Psi absorbs the camera gain).
pub const ALBEDO_PERCENTILE_TARGET: f32 = 0.9;

/// The albedo atlas encoded as a PNG.
#[derive(Clone, Debug)]
pub struct AlbedoImage {
    /// 8-bit sRGB RGB PNG file contents.
    pub png: Vec<u8>,
    /// Factor applied to the linear albedo before encoding (stored = scale × fused).
    pub scale: f32,
}

/// Encode a linear RGB atlas (`3 * width * height` values) as an sRGB 8-bit PNG after one
/// global scale that maps the 99th percentile of the channel values of the `covered` texels
/// to [`ALBEDO_PERCENTILE_TARGET`] (all texels when none is covered).
pub fn encode_albedo(
    rgb: &[f32],
    width: u32,
    height: u32,
    covered: &[bool],
) -> Result<AlbedoImage> {
    let n = width as usize * height as usize;
    if rgb.len() != 3 * n || covered.len() != n || n == 0 {
        return Err(ImageError::BufferSize {
            stage: "albedo encoding",
            what: "the atlas (RGB values, then coverage flags x 3)",
            got: rgb.len().min(3 * covered.len()),
            expected: 3 * n,
        }
        .into());
    }
    let any = covered.iter().any(|&c| c);
    let mut vals: Vec<f32> = (0..n)
        .filter(|&i| covered[i] || !any)
        .flat_map(|i| rgb[3 * i..3 * i + 3].iter().copied())
        .filter(|v| v.is_finite())
        .collect();
    let p99 = if vals.is_empty() {
        0.0
    } else {
        let k = ((vals.len() - 1) as f64 * 0.99).round() as usize;
        *vals.select_nth_unstable_by(k, |a, b| a.total_cmp(b)).1
    };
    let scale = if p99 > 0.0 {
        ALBEDO_PERCENTILE_TARGET / p99
    } else {
        1.0
    };
    let data: Vec<u8> = rgb.iter().map(|&v| linear_to_srgb8(v * scale)).collect();
    let png = encode_png(width, height, png::ColorType::Rgb, &data, true)?;
    Ok(AlbedoImage { png, scale })
}

/// Encode a coverage mask as an 8-bit grey PNG (255 = seen by a frame, 0 = not).
pub fn encode_coverage(covered: &[bool], width: u32, height: u32) -> Result<Vec<u8>> {
    if covered.len() != width as usize * height as usize {
        return Err(ImageError::BufferSize {
            stage: "coverage encoding",
            what: "the coverage flags",
            got: covered.len(),
            expected: width as usize * height as usize,
        }
        .into());
    }
    let data: Vec<u8> = covered.iter().map(|&c| if c { 255 } else { 0 }).collect();
    encode_png(width, height, png::ColorType::Grayscale, &data, false)
}

fn encode_png(w: u32, h: u32, color: png::ColorType, data: &[u8], srgb: bool) -> Result<Vec<u8>> {
    let failed = |e: png::EncodingError| ImageError::Encoding {
        stage: "texture PNG".into(),
        message: e.to_string(),
    };
    let mut out = Vec::new();
    {
        let mut enc = png::Encoder::new(&mut out, w, h);
        enc.set_color(color);
        enc.set_depth(png::BitDepth::Eight);
        enc.set_compression(png::Compression::Fast);
        if srgb {
            enc.set_source_srgb(png::SrgbRenderingIntent::Perceptual);
        }
        let mut writer = enc.write_header().map_err(failed)?;
        writer.write_image_data(data).map_err(failed)?;
        writer.finish().map_err(failed)?;
    }
    Ok(out)
}

/// What [`write_texture_outputs`] wrote.
#[derive(Clone, Debug, PartialEq)]
pub struct TextureOutputs {
    /// Scale applied to the linear albedo in `albedo.png` (see [`encode_albedo`]).
    pub albedo_scale: f32,
    /// Texels seen by at least one frame.
    pub covered_texels: usize,
}

/// Write `albedo.png`, `coverage.png` and `airway.glb` into `dir`.
///
/// `filled_rgb` is the fused atlas with its holes filled (`FusedTexture::filled`), `covered`
/// the coverage mask (atlas-sized); the mesh and UVs are the atlas's.
pub fn write_texture_outputs(
    dir: &Path,
    atlas: &Atlas,
    filled_rgb: &[f32],
    covered: &[bool],
) -> Result<TextureOutputs> {
    let albedo = encode_albedo(filled_rgb, atlas.width, atlas.height, covered)?;
    let coverage = encode_coverage(covered, atlas.width, atlas.height)?;
    write_bytes_atomic(&dir.join("albedo.png"), &albedo.png)?;
    write_bytes_atomic(&dir.join("coverage.png"), &coverage)?;
    write_glb(
        &dir.join("airway.glb"),
        &atlas.mesh,
        Some((&atlas.uv, &albedo.png)),
    )?;
    Ok(TextureOutputs {
        albedo_scale: albedo.scale,
        covered_texels: covered.iter().filter(|&&c| c).count(),
    })
}
