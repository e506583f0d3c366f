//! Loading a model folder for new views: the lumen mesh and UVs from airway.glb (exactly what a
//! simulator or browser loads), the albedo embedded in it, the shading from shading.json and
//! the numbers that tie them together from model.json.

use std::path::{Path, PathBuf};

use super::manifest::{ModelManifest, MODEL_FORMAT_VERSION};
use crate::io::glb_import::read_glb;
use crate::io::png::{decode_png_bytes, read_png};
use crate::mesh::TriMesh;
use crate::raycast::Scene;
use crate::render::{MipOptions, MipTexture, RenderInputs};
use crate::shading::{FittedShading, ShadingKind};
use crate::{Error, Result};

/// A built model, ready to render.
pub struct Model {
    /// The model folder.
    pub dir: PathBuf,
    /// model.json.
    pub manifest: ModelManifest,
    /// shading.json.
    pub shading: FittedShading,
    /// The lumen mesh with seam vertices merged (smooth normals), triangles in the GLB's order.
    pub mesh: TriMesh,
    /// UV corners of every triangle (atlas convention, [0, 1]).
    pub tri_uv: Vec<[[f32; 2]; 3]>,
    /// The relative albedo the shading multiplies (linear), with its mip chain.
    pub texture: MipTexture,
    /// The paper's texture when the model's shading is calibrated (albedo_paper.png).
    pub paper_texture: Option<MipTexture>,
    /// The mesh, ready for ray casting.
    pub scene: Scene,
}

/// Read and parse a JSON file of the model folder.
fn read_json<T: serde::de::DeserializeOwned>(path: &Path, what: &str) -> Result<T> {
    let text = std::fs::read_to_string(path).map_err(|e| match e.kind() {
        std::io::ErrorKind::NotFound => Error::missing(path, what.to_string()),
        _ => Error::io(path, e),
    })?;
    serde_json::from_str(&text).map_err(|e| Error::invalid(path, format!("{what}: {e}")))
}

/// A texture PNG (linear after decoding) divided back to the relative albedo the shading
/// multiplies: `png / (albedo_scale · colour_balance)`, with its mip chain.
fn relative_texture(
    mut image: crate::image::Frame,
    scale: f32,
    balance: [f32; 3],
    texel_mm: f64,
    manifest: &Path,
) -> Result<MipTexture> {
    if !(scale > 0.0 && balance.iter().all(|&k| k > 0.0 && k.is_finite())) {
        return Err(Error::invalid(
            manifest,
            format!("albedo_scale {scale} and colour_balance {balance:?} must be positive"),
        ));
    }
    for px in image.rgb.chunks_exact_mut(3) {
        for ch in 0..3 {
            px[ch] /= scale * balance[ch];
        }
    }
    MipTexture::new(&image, None, texel_mm, &MipOptions::default())
}

impl Model {
    /// Load the model folder `dir` (written by `bronchosim build`).
    pub fn load(dir: &Path) -> Result<Model> {
        if !dir.is_dir() {
            return Err(Error::missing(
                dir,
                "a model folder (from `bronchosim build`)",
            ));
        }
        let mpath = dir.join("model.json");
        let version: serde_json::Value = read_json(&mpath, "the model manifest")?;
        match version.get("format_version").and_then(|v| v.as_u64()) {
            Some(v) if v == MODEL_FORMAT_VERSION as u64 => {}
            Some(v) => {
                return Err(Error::unsupported(
                    &mpath,
                    format!(
                        "model format_version {v}; this bronchosim reads version \
                         {MODEL_FORMAT_VERSION} (rebuild the model with this version)"
                    ),
                ))
            }
            None => return Err(Error::invalid(&mpath, "no format_version")),
        }
        let manifest: ModelManifest = read_json(&mpath, "the model manifest")?;
        let spath = dir.join("shading.json");
        let shading: FittedShading = read_json(&spath, "the shading model")?;
        shading.validate().map_err(|m| Error::invalid(&spath, m))?;
        let gpath = dir.join("airway.glb");
        let glb = read_glb(&gpath)?;
        let uvs = glb
            .uvs
            .ok_or_else(|| Error::invalid(&gpath, "the mesh has no TEXCOORD_0"))?;
        let png = glb
            .texture_png
            .ok_or_else(|| Error::invalid(&gpath, "no embedded base colour texture"))?;
        let image = decode_png_bytes(&png, &gpath)?;
        let texture = relative_texture(
            image,
            manifest.albedo_scale,
            manifest.colour_balance,
            manifest.texel_mm,
            &mpath,
        )?;
        let paper_texture = match &manifest.paper_texture {
            Some(extra) => {
                let p = dir.join(&extra.file);
                let t = relative_texture(
                    read_png(&p)?,
                    extra.albedo_scale,
                    extra.colour_balance,
                    manifest.texel_mm,
                    &mpath,
                )?;
                if (t.width, t.height) != (texture.width, texture.height) {
                    return Err(Error::invalid(
                        &p,
                        format!(
                            "{}x{} texels, airway.glb's texture {}x{}",
                            t.width, t.height, texture.width, texture.height
                        ),
                    ));
                }
                Some(t)
            }
            None => None,
        };
        let tri_uv = glb
            .mesh
            .triangles
            .iter()
            .map(|t| t.map(|v| uvs[v as usize]))
            .collect();
        let (mesh, _) = glb.mesh.welded();
        let scene = Scene::new(&mesh)?;
        Ok(Model {
            dir: dir.to_path_buf(),
            manifest,
            shading,
            mesh,
            tri_uv,
            texture,
            paper_texture,
            scene,
        })
    }

    /// The calibrated light when it is the model's shading.
    pub fn calibrated(&self) -> Option<&crate::shading::CalibratedModel> {
        match self.shading.model {
            ShadingKind::Calibrated => self.shading.calibrated.as_ref(),
            ShadingKind::Paper => None,
        }
    }

    /// What a frame is registered against ([`crate::registration`]): the mesh, the texture,
    /// the calibrated light and the camera; `None` when the model's shading is not calibrated.
    pub fn registration_parts(&self) -> Option<crate::registration::ModelParts<'_>> {
        Some(crate::registration::ModelParts {
            scene: &self.scene,
            tri_uv: &self.tri_uv,
            texture: Some(&self.texture),
            light: self.calibrated()?,
            camera: &self.manifest.camera,
        })
    }

    /// The inputs of [`crate::render::render_view`] for the paper's method: Psi of the fitted
    /// viewpoints and the paper's texture, also when the model's shading is calibrated.
    pub fn paper_render_inputs(&self) -> RenderInputs<'_> {
        RenderInputs {
            kind: ShadingKind::Paper,
            texture: self.paper_texture.as_ref().unwrap_or(&self.texture),
            ..self.render_inputs()
        }
    }

    /// What [`crate::render::render_view`] needs.
    pub fn render_inputs(&self) -> RenderInputs<'_> {
        RenderInputs {
            scene: &self.scene,
            tri_uv: &self.tri_uv,
            texture: &self.texture,
            shading: &self.shading,
            kind: self.shading.model,
        }
    }
}
