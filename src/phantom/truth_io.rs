//! Writers for the phantom's truth files: the per-vertex albedo PLY and the single-channel and
//! linear 16-bit PNGs of the novel views.

use crate::io::atomic::write_atomic;
use crate::io::frames::Frame;
use crate::mesh::TriMesh;
use crate::{Error, Result};
use std::path::Path;

/// Binary little-endian PLY: vertex `x y z` (float, world mm), `nx ny nz` (unit, into the
/// lumen), `red green blue` (float, linear albedo in [0, 1]); faces `list uchar uint`.
/// [`crate::io::mesh_export::read_ply`] reads its geometry (it skips the extra properties).
pub fn write_albedo_ply(path: &Path, mesh: &TriMesh, albedo: &[[f32; 3]]) -> Result<()> {
    if albedo.len() != mesh.positions.len() {
        return Err(Error::invalid(
            path,
            format!(
                "{} albedo values for {} vertices",
                albedo.len(),
                mesh.positions.len()
            ),
        ));
    }
    let normals = mesh.vertex_normals();
    write_atomic(path, |w| {
        write!(
            w,
            "ply\nformat binary_little_endian 1.0\n\
             comment bronchosim phantom truth: lumen mesh (world mm, RAS+) with linear RGB albedo\n\
             element vertex {}\nproperty float x\nproperty float y\nproperty float z\n\
             property float nx\nproperty float ny\nproperty float nz\n\
             property float red\nproperty float green\nproperty float blue\n\
             element face {}\nproperty list uchar uint vertex_indices\nend_header\n",
            mesh.positions.len(),
            mesh.triangles.len()
        )?;
        for ((p, n), a) in mesh.positions.iter().zip(&normals).zip(albedo) {
            for v in [p.x, p.y, p.z, n.x, n.y, n.z, a[0], a[1], a[2]] {
                w.write_all(&v.to_le_bytes())?;
            }
        }
        for t in &mesh.triangles {
            w.write_all(&[3u8])?;
            for v in t {
                w.write_all(&v.to_le_bytes())?;
            }
        }
        Ok(())
    })
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
