//! Binary glTF 2.0 (GLB) export of the lumen mesh: a glTF document built accessor by accessor
//! over one binary chunk, then framed as a GLB container.

use gltf_json as json;
use json::accessor::{ComponentType, Type};
use json::validation::Checked::Valid;
use std::path::Path;

use super::check_mesh;
use crate::io::atomic::write_atomic;
use crate::math::Point3;
use crate::mesh::TriMesh;
use crate::{Error, Result};

/// Binary glTF 2.0: one mesh with POSITION (world mm, RAS+; glTF's metre and +Y-up conventions are
/// deliberately not applied), NORMAL (into the lumen), u32 indices and, when `texture` is given,
/// TEXCOORD_0 (u right, v down, as glTF defines) with the PNG embedded as the base colour.
pub fn write_glb(path: &Path, mesh: &TriMesh, texture: Option<(&[[f32; 2]], &[u8])>) -> Result<()> {
    use json::mesh::Semantic;
    check_mesh(path, mesh, texture.map(|t| t.0))?;
    // Smooth across the atlas's chart seams (split vertices share their position).
    let normals = mesh.seamless_vertex_normals();
    let n = mesh.positions.len();
    let mut glb = GlbBuilder::new();
    let xyz = |p: &Point3<f32>| [p.x, p.y, p.z];
    let bounds = Some(position_bounds(mesh));
    let pos = glb.f32_accessor(mesh.positions.iter().flat_map(xyz), n, Type::Vec3, bounds);
    let nrm_values = normals.iter().flat_map(|v| [v.x, v.y, v.z]);
    let nrm = glb.f32_accessor(nrm_values, n, Type::Vec3, None);
    let mut attributes = std::collections::BTreeMap::new();
    attributes.insert(Valid(Semantic::Positions), pos);
    attributes.insert(Valid(Semantic::Normals), nrm);
    let mut material = None;
    if let Some((uv, png)) = texture {
        let tc = glb.f32_accessor(uv.iter().flat_map(|t| [t[0], t[1]]), n, Type::Vec2, None);
        attributes.insert(Valid(Semantic::TexCoords(0)), tc);
        material = Some(glb.base_colour_material(png));
    }
    let indices = glb.index_accessor(&mesh.triangles);
    glb.add_lumen_scene(attributes, indices, material);
    let (js, bin) = glb.into_chunks(path)?;
    write_glb_chunks(path, &js, &bin)
}

/// Smallest and largest vertex coordinate per axis (mm), zeros for an empty mesh (glTF requires
/// POSITION to carry min and max).
fn position_bounds(mesh: &TriMesh) -> ([f32; 3], [f32; 3]) {
    if mesh.positions.is_empty() {
        return ([0.0; 3], [0.0; 3]);
    }
    let mut lo = [f32::INFINITY; 3];
    let mut hi = [f32::NEG_INFINITY; 3];
    for p in &mesh.positions {
        for a in 0..3 {
            lo[a] = lo[a].min(p[a]);
            hi[a] = hi[a].max(p[a]);
        }
    }
    (lo, hi)
}

/// A glTF document under construction and its binary chunk, which holds every buffer view.
struct GlbBuilder {
    root: json::Root,
    bin: Vec<u8>,
    buffer: json::Index<json::Buffer>,
}

impl GlbBuilder {
    /// A document with the asset header and the one buffer (the GLB's BIN chunk).
    fn new() -> Self {
        let mut root = json::Root {
            asset: json::Asset {
                version: "2.0".into(),
                generator: Some(format!("bronchosim {}", env!("CARGO_PKG_VERSION"))),
                copyright: None,
                extensions: None,
                extras: Default::default(),
                min_version: None,
            },
            ..Default::default()
        };
        let buffer = root.push(json::Buffer {
            byte_length: 0u64.into(),
            name: None,
            uri: None,
            extensions: None,
            extras: Default::default(),
        });
        GlbBuilder {
            root,
            bin: Vec::new(),
            buffer,
        }
    }

    /// Pad the binary chunk to 4 bytes: glTF aligns every view and the chunk's end.
    fn align_bin(&mut self) {
        while self.bin.len() % 4 != 0 {
            self.bin.push(0);
        }
    }

    /// Append `bytes` to the binary chunk (4-byte aligned) and add a buffer view on them.
    fn view(
        &mut self,
        bytes: &[u8],
        target: Option<json::buffer::Target>,
    ) -> json::Index<json::buffer::View> {
        self.align_bin();
        let offset = self.bin.len();
        self.bin.extend_from_slice(bytes);
        self.root.push(json::buffer::View {
            buffer: self.buffer,
            byte_length: bytes.len().into(),
            byte_offset: Some(offset.into()),
            byte_stride: None,
            name: None,
            target: target.map(Valid),
            extensions: None,
            extras: Default::default(),
        })
    }

    /// An accessor of `count` elements of type `ty` on `view`, with optional min and max.
    fn accessor(
        &mut self,
        view: json::Index<json::buffer::View>,
        count: usize,
        ct: ComponentType,
        ty: Type,
        bounds: Option<([f32; 3], [f32; 3])>,
    ) -> json::Index<json::Accessor> {
        self.root.push(json::Accessor {
            buffer_view: Some(view),
            byte_offset: None,
            count: count.into(),
            component_type: Valid(json::accessor::GenericComponentType(ct)),
            extensions: None,
            extras: Default::default(),
            type_: Valid(ty),
            min: bounds.map(|b| json::Value::from(b.0.to_vec())),
            max: bounds.map(|b| json::Value::from(b.1.to_vec())),
            name: None,
            normalized: false,
            sparse: None,
        })
    }

    /// A vertex attribute: `count` elements of type `ty` made of the f32 `values`.
    fn f32_accessor(
        &mut self,
        values: impl Iterator<Item = f32>,
        count: usize,
        ty: Type,
        bounds: Option<([f32; 3], [f32; 3])>,
    ) -> json::Index<json::Accessor> {
        let bytes: Vec<u8> = values.flat_map(|x| x.to_le_bytes()).collect();
        let target = Some(json::buffer::Target::ArrayBuffer);
        let v = self.view(&bytes, target);
        self.accessor(v, count, ComponentType::F32, ty, bounds)
    }

    /// The u32 triangle indices.
    fn index_accessor(&mut self, triangles: &[[u32; 3]]) -> json::Index<json::Accessor> {
        let bytes: Vec<u8> = triangles
            .iter()
            .flatten()
            .flat_map(|v| v.to_le_bytes())
            .collect();
        let v = self.view(&bytes, Some(json::buffer::Target::ElementArrayBuffer));
        let count = 3 * triangles.len();
        self.accessor(v, count, ComponentType::U32, Type::Scalar, None)
    }

    /// Embed `png` and make a double-sided, non-metallic material with it as base colour
    /// (linear filtering, clamped at the atlas's edges).
    fn base_colour_material(&mut self, png: &[u8]) -> json::Index<json::Material> {
        let v = self.view(png, None);
        let image = self.root.push(json::Image {
            buffer_view: Some(v),
            mime_type: Some(json::image::MimeType("image/png".into())),
            name: None,
            uri: None,
            extensions: None,
            extras: Default::default(),
        });
        let sampler = self.root.push(json::texture::Sampler {
            mag_filter: Some(Valid(json::texture::MagFilter::Linear)),
            min_filter: Some(Valid(json::texture::MinFilter::LinearMipmapLinear)),
            wrap_s: Valid(json::texture::WrappingMode::ClampToEdge),
            wrap_t: Valid(json::texture::WrappingMode::ClampToEdge),
            ..Default::default()
        });
        let tex = self.root.push(json::Texture {
            name: None,
            sampler: Some(sampler),
            source: image,
            extensions: None,
            extras: Default::default(),
        });
        let mut m = json::Material {
            double_sided: true,
            ..Default::default()
        };
        m.pbr_metallic_roughness.base_color_texture = Some(json::texture::Info {
            index: tex,
            tex_coord: 0,
            extensions: None,
            extras: Default::default(),
        });
        m.pbr_metallic_roughness.metallic_factor = json::material::StrengthFactor(0.0);
        self.root.push(m)
    }

    /// The "lumen" mesh (one triangle primitive), its node and the default scene.
    fn add_lumen_scene(
        &mut self,
        attributes: std::collections::BTreeMap<
            json::validation::Checked<json::mesh::Semantic>,
            json::Index<json::Accessor>,
        >,
        indices: json::Index<json::Accessor>,
        material: Option<json::Index<json::Material>>,
    ) {
        let mesh = self.root.push(json::Mesh {
            extensions: None,
            extras: Default::default(),
            name: Some("lumen".into()),
            primitives: vec![json::mesh::Primitive {
                attributes,
                extensions: None,
                extras: Default::default(),
                indices: Some(indices),
                material,
                mode: Valid(json::mesh::Mode::Triangles),
                targets: None,
            }],
            weights: None,
        });
        let node = self.root.push(json::Node {
            mesh: Some(mesh),
            name: Some("lumen".into()),
            ..Default::default()
        });
        let scene = self.root.push(json::Scene {
            extensions: None,
            extras: Default::default(),
            name: None,
            nodes: vec![node],
        });
        self.root.scene = Some(scene);
    }

    /// The JSON chunk (space-padded to 4 bytes) and the BIN chunk (zero-padded), with the
    /// buffer's length set.
    fn into_chunks(mut self, path: &Path) -> Result<(Vec<u8>, Vec<u8>)> {
        self.align_bin();
        self.root.buffers[0].byte_length = self.bin.len().into();
        let mut js = json::serialize::to_vec(&self.root)
            .map_err(|e| Error::invalid(path, format!("glTF JSON: {e}")))?;
        while js.len() % 4 != 0 {
            js.push(b' ');
        }
        Ok((js, self.bin))
    }
}

/// The GLB container: 12-byte header, then the JSON and BIN chunks with their 8-byte headers.
fn write_glb_chunks(path: &Path, js: &[u8], bin: &[u8]) -> Result<()> {
    let total = 12 + 8 + js.len() + 8 + bin.len();
    if total > u32::MAX as usize {
        return Err(Error::Other(format!(
            "{}: mesh too large for a GLB ({total} bytes)",
            path.display()
        )));
    }
    write_atomic(path, |w| {
        w.write_all(b"glTF")?;
        w.write_all(&2u32.to_le_bytes())?;
        w.write_all(&(total as u32).to_le_bytes())?;
        w.write_all(&(js.len() as u32).to_le_bytes())?;
        w.write_all(b"JSON")?;
        w.write_all(js)?;
        w.write_all(&(bin.len() as u32).to_le_bytes())?;
        w.write_all(b"BIN\0")?;
        w.write_all(bin)
    })
}
