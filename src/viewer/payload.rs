//! The model data the viewer embeds (`model-data.js`): a JSON description (shading, texture,
//! camera, centre-line path, field grid, where each array lies) and one binary block holding
//! the mesh, the albedo atlas and the inside-distance field, zlib-compressed and base64-encoded
//! so that the page reads it from file:// without fetch (browsers refuse fetch on file://).
//!
//! Binary sections (little endian, each 4-byte aligned, in the order of `sections`):
//! `positions` f32 x 3 per vertex (world mm), `normals` f32 x 3 (unit, the smooth normals the
//! ray caster interpolates), `uvs` f32 x 2 (atlas, v down), `indices` u32 x 3 per triangle,
//! `texture` u8 RGB sRGB codes row by row, each byte stored as its difference to the texel on
//! its left (mod 256; compresses about twice as well), `field` u8 distances, and when the
//! model has coverage.png, `coverage` u8 per atlas texel (255: a frame saw it, 0: synthesised
//! or filled; the page can mark those walls).

use std::io::Write;

use base64::Engine;
use serde::Serialize;

use super::field::{LumenField, FIELD_STEP_MM};
use crate::camera::Camera;
use crate::image::srgb::linear_to_srgb8;
use crate::image::Frame;
use crate::math::Affine;
use crate::shading::paper::PsiLookup;
use crate::shading::{FittedShading, ShadingKind};
use crate::Result;

/// Where one array lies in the decompressed binary block.
#[derive(Clone, Debug, Serialize)]
pub struct Section {
    /// "positions", "normals", "uvs", "indices", "texture", "field" or "coverage".
    pub name: &'static str,
    /// Byte offset.
    pub offset: usize,
    /// Byte length.
    pub length: usize,
}

/// The shading the viewer's fragment shader evaluates (exactly `render`'s).
#[derive(Clone, Debug, Serialize)]
#[serde(tag = "kind", rename_all = "lowercase")]
pub enum ShadingData {
    /// `rho_c(gamma) s(theta) / z^2 + ambient_c` (+ the specular term), then `kappa_c` times the view's own mean
    /// luminance on every surface pixel (see `CalibratedModel::view_interreflection`).
    Calibrated {
        /// Bernstein coefficients of rho per channel (linear intensity x mm²).
        rho: [Vec<f64>; 3],
        /// Bernstein coefficients of s in t = (1 - cos theta) / (1 - cos_theta_edge).
        s: Vec<f64>,
        /// cos of the largest off-axis angle of the fit (s is constant beyond it).
        cos_theta_edge: f64,
        /// The new-view ambient term per channel (linear intensity).
        ambient: [f64; 3],
        /// kappa_c of the inter-reflection term, when fitted.
        interreflection: Option<[f64; 3]>,
        /// The specular term `k_c spec_alpha(gamma) s(theta) / z^2` added without the albedo.
        specular: Option<crate::shading::calibrated::SpecularLobe>,
        /// The learnt auto-exposure: `gain = exp(a + b ln(clamp(L, lo, hi)))`.
        auto_exposure: Option<ExposureData>,
    },
    /// The paper's Psi of the fitted viewpoints, blended as `render` blends them.
    Paper {
        /// Every fitted viewpoint.
        viewpoints: Vec<PsiData>,
        /// Viewpoints blended (1 = the paper's nearest viewpoint).
        k: usize,
        /// Weight of the viewing direction in the blend penalty (mm per unit of 1 - cos).
        direction_mm: f64,
    },
}

/// [`crate::shading::calibrated::AutoExposure`] for the page.
#[derive(Clone, Debug, Serialize)]
pub struct ExposureData {
    /// a (natural log of the gain at unit brightness).
    pub a: f64,
    /// b (slope of log gain against log brightness).
    pub b: f64,
    /// Brightness range of the fit [lo, hi] (mean linear luminance).
    pub light_range: [f64; 2],
}

/// One viewpoint's Psi (see `PsiModel`).
#[derive(Clone, Debug, Serialize)]
pub struct PsiData {
    /// Camera → world, row-major.
    pub camera_to_world: [f64; 16],
    /// Depth mapped to r = 0 (mm).
    pub z_min: f64,
    /// Depth mapped to r = 1 (mm).
    pub z_max: f64,
    /// rho coefficients per channel.
    pub c: [[f64; 4]; 3],
    /// varrho coefficients d_1..d_3 per channel.
    pub d: [[f64; 3]; 3],
}

impl ShadingData {
    /// The shading of the model's new views; `lookup` is how `render` picks the paper's Psi.
    pub fn of(shading: &FittedShading, lookup: PsiLookup) -> Option<ShadingData> {
        match shading.model {
            ShadingKind::Calibrated => {
                let c = shading.calibrated.as_ref()?;
                Some(ShadingData::Calibrated {
                    rho: c.rho.clone(),
                    s: c.s.clone(),
                    cos_theta_edge: c.cos_theta_edge,
                    ambient: c.new_view_ambient(),
                    interreflection: c.interreflection,
                    specular: c.specular,
                    auto_exposure: c.auto_exposure.as_ref().map(|ae| ExposureData {
                        a: ae.log_gain_at_unit_light,
                        b: ae.slope,
                        light_range: ae.light_range,
                    }),
                })
            }
            ShadingKind::Paper => Some(ShadingData::Paper {
                viewpoints: shading
                    .viewpoints
                    .iter()
                    .map(|p| PsiData {
                        camera_to_world: p.camera_to_world,
                        z_min: p.z_min,
                        z_max: p.z_max,
                        c: p.c,
                        d: p.d,
                    })
                    .collect(),
                k: match lookup {
                    PsiLookup::Nearest => 1,
                    PsiLookup::KNearest { k } => k.max(1),
                },
                direction_mm: shading.viewpoint_index().direction_mm,
            }),
        }
    }
}

/// The texture as the page rebuilds it: the relative albedo is `srgb_to_linear(code) /
/// (albedo_scale * colour_balance_c)`, mip-mapped like `render`'s `MipTexture`.
#[derive(Clone, Debug, Serialize)]
pub struct TextureData {
    /// Atlas width (texels).
    pub width: u32,
    /// Atlas height (texels).
    pub height: u32,
    /// Texel edge on the surface (mm).
    pub texel_mm: f64,
    /// albedo_scale of model.json.
    pub albedo_scale: f32,
    /// colour_balance of model.json.
    pub colour_balance: [f32; 3],
    /// Coarsest mip level (as `MipOptions::max_level`).
    pub max_level: u32,
}

/// The field's grid for the page.
#[derive(Clone, Debug, Serialize)]
pub struct FieldData {
    /// Samples along x, y, z.
    pub dims: [usize; 3],
    /// Index → world (mm), row-major 4 x 4.
    pub index_to_world: [f64; 16],
    /// mm per stored unit.
    pub step_mm: f64,
}

/// The JSON half of `model-data.js`.
#[derive(Clone, Debug, Serialize)]
pub struct Meta {
    /// Layout version of this description.
    pub format: u32,
    /// The bronchosim that wrote it.
    pub generator: String,
    /// The model folder's name (shown in the page).
    pub model_name: String,
    /// The new views' shading.
    pub shading: ShadingData,
    /// The albedo atlas.
    pub texture: TextureData,
    /// The training camera (pinhole part; the viewer draws without lens distortion).
    pub camera: CameraData,
    /// Vertices and triangles of the mesh.
    pub counts: [usize; 2],
    /// The autopilot's poses along the centre line (camera → world, row-major, OpenCV axes).
    pub path: Vec<[f64; 16]>,
    /// Length of the centre-line path (mm).
    pub path_length_mm: f64,
    /// The inside-distance field's grid.
    pub field: FieldData,
    /// The binary block's arrays.
    pub sections: Vec<Section>,
}

/// A pinhole camera for the page.
#[derive(Clone, Debug, Serialize)]
pub struct CameraData {
    /// Width (pixels).
    pub width: u32,
    /// Height (pixels).
    pub height: u32,
    /// Focal length x (pixels).
    pub fx: f64,
    /// Focal length y (pixels).
    pub fy: f64,
    /// Principal point x (pixels, pixel centres at integers).
    pub cx: f64,
    /// Principal point y (pixels).
    pub cy: f64,
}

impl From<&Camera> for CameraData {
    fn from(c: &Camera) -> CameraData {
        CameraData {
            width: c.width,
            height: c.height,
            fx: c.fx,
            fy: c.fy,
            cx: c.cx,
            cy: c.cy,
        }
    }
}

/// Row-major 16 numbers of a 4 x 4 matrix.
pub fn row_major(m: &Affine) -> [f64; 16] {
    std::array::from_fn(|i| m[(i / 4, i % 4)])
}

/// The arrays of the binary block.
pub struct Arrays<'a> {
    /// Vertex positions (world mm).
    pub positions: &'a [[f32; 3]],
    /// Unit vertex normals.
    pub normals: &'a [[f32; 3]],
    /// Vertex UVs.
    pub uvs: &'a [[f32; 2]],
    /// Triangles.
    pub indices: &'a [[u32; 3]],
    /// The atlas (linear RGB, the GLB's texture as decoded).
    pub texture: &'a Frame,
    /// The inside-distance field.
    pub field: &'a LumenField,
    /// coverage.png (atlas-sized; white where a frame saw the texel), when the model has it.
    pub coverage: Option<&'a Frame>,
}

/// Pack the arrays into one block; returns the block and where each array lies.
pub fn pack(arrays: &Arrays) -> (Vec<u8>, Vec<Section>) {
    let mut bin = Vec::new();
    let mut sections = Vec::new();
    let mut push = |name: &'static str, bytes: &mut dyn Iterator<Item = u8>| {
        while bin.len() % 4 != 0 {
            bin.push(0);
        }
        let offset = bin.len();
        bin.extend(bytes);
        sections.push(Section {
            name,
            offset,
            length: bin.len() - offset,
        });
    };
    let f32s = |v: &[f32]| v.iter().flat_map(|x| x.to_le_bytes()).collect::<Vec<u8>>();
    push(
        "positions",
        &mut f32s(arrays.positions.as_flattened()).into_iter(),
    );
    push(
        "normals",
        &mut f32s(arrays.normals.as_flattened()).into_iter(),
    );
    push("uvs", &mut f32s(arrays.uvs.as_flattened()).into_iter());
    let idx: Vec<u8> = arrays
        .indices
        .as_flattened()
        .iter()
        .flat_map(|v| v.to_le_bytes())
        .collect();
    push("indices", &mut idx.into_iter());
    push("texture", &mut texture_codes(arrays.texture).into_iter());
    push("field", &mut arrays.field.data.iter().copied());
    if let Some(c) = arrays.coverage {
        push("coverage", &mut coverage_codes(c).into_iter());
    }
    (bin, sections)
}

/// The atlas's 8-bit sRGB codes (exact for the 8-bit PNG the build writes), each stored as its
/// difference to the same channel of the texel on its left.
fn texture_codes(t: &Frame) -> Vec<u8> {
    let w = t.width as usize;
    let codes: Vec<u8> = t.rgb.iter().map(|&v| linear_to_srgb8(v)).collect();
    let mut out = codes.clone();
    for (i, o) in out.iter_mut().enumerate() {
        if (i / 3) % w != 0 {
            *o = codes[i].wrapping_sub(codes[i - 3]);
        }
    }
    out
}

/// 255 where coverage.png says a frame saw the texel, 0 elsewhere, row by row.
fn coverage_codes(c: &Frame) -> Vec<u8> {
    c.rgb
        .chunks_exact(3)
        .map(|p| if p[0] > 0.5 { 255 } else { 0 })
        .collect()
}

/// `model-data.js`: the description and the zlib-compressed, base64-encoded block.
pub fn data_js(meta: &Meta, bin: &[u8]) -> Result<String> {
    let mut z = flate2::write::ZlibEncoder::new(Vec::new(), flate2::Compression::best());
    z.write_all(bin)
        .and_then(|_| z.flush())
        .map_err(|e| crate::Error::Other(format!("compressing the viewer data: {e}")))?;
    let zipped = z
        .finish()
        .map_err(|e| crate::Error::Other(format!("compressing the viewer data: {e}")))?;
    let b64 = base64::engine::general_purpose::STANDARD.encode(zipped);
    let json = serde_json::to_string(meta)
        .map_err(|e| crate::Error::Other(format!("the viewer's model description: {e}")))?;
    Ok(format!(
        "// bronchosim viewer data: the model description and its arrays (zlib, base64).\n\
         window.BRONCHOSIM_MODEL = {{\"meta\": {json},\n\"data\": \"{b64}\"}};\n"
    ))
}

/// Stored distance step of the field (mm).
pub fn field_data(field: &LumenField) -> FieldData {
    FieldData {
        dims: field.dims,
        index_to_world: row_major(&field.affine),
        step_mm: FIELD_STEP_MM,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn texture_deltas_undo_to_the_codes() {
        let mut f = Frame::new(3, 2);
        let lut = crate::image::srgb::srgb8_to_linear_lut();
        let codes = [
            10u8, 200, 30, 0, 255, 7, 99, 98, 97, 1, 2, 3, 250, 5, 128, 64, 32, 16,
        ];
        for (v, c) in f.rgb.iter_mut().zip(codes) {
            *v = lut[c as usize];
        }
        let d = texture_codes(&f);
        // Undo as the page does: running sum along each row, per channel.
        let mut back = d.clone();
        for i in 0..back.len() {
            if (i / 3) % 3 != 0 {
                back[i] = back[i].wrapping_add(back[i - 3]);
            }
        }
        assert_eq!(back, codes);
        assert_ne!(d, codes);
    }

    #[test]
    fn coverage_is_one_byte_per_texel() {
        let mut f = Frame::new(2, 2);
        f.rgb[3..6].copy_from_slice(&[1.0; 3]);
        f.rgb[9..12].copy_from_slice(&[0.4; 3]);
        assert_eq!(coverage_codes(&f), vec![0, 255, 0, 0]);
    }
}
