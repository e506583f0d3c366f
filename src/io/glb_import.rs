//! Reading a binary glTF 2.0 (GLB) mesh back: the model folder's `airway.glb` is the renderer's
//! source of geometry and texture coordinates, so a model renders from exactly what a
//! simulator, 3D Slicer or a browser loads.
//!
//! Supported: one mesh, one triangle-list primitive, POSITION (float VEC3), optional
//! TEXCOORD_0 (float VEC2), indices (unsigned byte/short/int) or none, byte strides, and a base
//! colour texture embedded as a PNG buffer view. Everything else is refused with an error that
//! names the file.

use std::path::Path;

use gltf_json as json;
use json::validation::Checked;

use crate::math::Point3;
use crate::mesh::TriMesh;
use crate::{Error, Result};

/// The mesh of a GLB file.
#[derive(Clone, Debug)]
pub struct GlbMesh {
    /// Positions (the file's units; bronchosim writes world mm, RAS+) and triangles.
    pub mesh: TriMesh,
    /// TEXCOORD_0 per vertex (u right, v down, glTF convention), when present.
    pub uvs: Option<Vec<[f32; 2]>>,
    /// The PNG of the material's base colour texture, when embedded.
    pub texture_png: Option<Vec<u8>>,
}

/// Read `path` (a .glb file).
pub fn read_glb(path: &Path) -> Result<GlbMesh> {
    let bytes = std::fs::read(path).map_err(|e| Error::io(path, e))?;
    read_glb_bytes(&bytes).map_err(|m| Error::invalid(path, m))
}

/// The little-endian u32 at `at`.
fn u32_at(b: &[u8], at: usize) -> std::result::Result<u32, String> {
    b.get(at..at + 4)
        .map(|s| u32::from_le_bytes([s[0], s[1], s[2], s[3]]))
        .ok_or_else(|| format!("truncated GLB (need byte {}, file has {})", at + 4, b.len()))
}

/// Parse GLB file contents; errors are messages about the file.
pub fn read_glb_bytes(b: &[u8]) -> std::result::Result<GlbMesh, String> {
    if b.get(0..4) != Some(b"glTF") {
        return Err("not a binary glTF file (no \"glTF\" magic)".into());
    }
    let version = u32_at(b, 4)?;
    if version != 2 {
        return Err(format!(
            "glTF container version {version}, only 2 is supported"
        ));
    }
    let total = u32_at(b, 8)? as usize;
    if total > b.len() {
        return Err(format!(
            "header says {total} bytes, the file has {}",
            b.len()
        ));
    }
    let mut at = 12;
    let (mut js, mut bin): (Option<&[u8]>, Option<&[u8]>) = (None, None);
    while at + 8 <= total {
        let len = u32_at(b, at)? as usize;
        let kind = &b[at + 4..at + 8];
        let data = b
            .get(at + 8..at + 8 + len)
            .filter(|_| at + 8 + len <= total)
            .ok_or_else(|| format!("chunk at byte {at} ({len} bytes) runs past the end"))?;
        match kind {
            b"JSON" if js.is_none() => js = Some(data),
            b"BIN\0" if bin.is_none() => bin = Some(data),
            _ => {}
        }
        at += 8 + len;
    }
    let js = js.ok_or("no JSON chunk")?;
    let root = json::Root::from_slice(js).map_err(|e| format!("glTF JSON: {e}"))?;
    let bin = bin.unwrap_or(&[]);
    let [mesh] = root.meshes.as_slice() else {
        return Err(format!(
            "{} meshes; expected exactly one (the lumen)",
            root.meshes.len()
        ));
    };
    let [prim] = mesh.primitives.as_slice() else {
        return Err(format!(
            "the mesh has {} primitives; expected one",
            mesh.primitives.len()
        ));
    };
    if prim.mode != Checked::Valid(json::mesh::Mode::Triangles) {
        return Err("the primitive is not a triangle list".into());
    }
    let reader = Reader { root: &root, bin };
    let attr = |s: json::mesh::Semantic| prim.attributes.get(&Checked::Valid(s));
    let pos_acc = attr(json::mesh::Semantic::Positions).ok_or("the primitive has no POSITION")?;
    let pos = reader.floats(pos_acc.value(), json::accessor::Type::Vec3, "POSITION")?;
    let n = pos.len() / 3;
    let positions: Vec<Point3<f32>> = pos
        .chunks_exact(3)
        .map(|p| Point3::new(p[0], p[1], p[2]))
        .collect();
    let uvs = match attr(json::mesh::Semantic::TexCoords(0)) {
        Some(a) => {
            let t = reader.floats(a.value(), json::accessor::Type::Vec2, "TEXCOORD_0")?;
            if t.len() / 2 != n {
                return Err(format!("{} TEXCOORD_0 for {n} positions", t.len() / 2));
            }
            Some(t.chunks_exact(2).map(|c| [c[0], c[1]]).collect())
        }
        None => None,
    };
    let indices: Vec<u32> = match &prim.indices {
        Some(a) => reader.indices(a.value())?,
        None => (0..n as u32).collect(),
    };
    if indices.len() % 3 != 0 {
        return Err(format!(
            "{} indices is not a whole number of triangles",
            indices.len()
        ));
    }
    if let Some(&bad) = indices.iter().find(|&&i| i as usize >= n) {
        return Err(format!("index {bad} refers past the {n} vertices"));
    }
    let triangles = indices
        .chunks_exact(3)
        .map(|t| [t[0], t[1], t[2]])
        .collect();
    let texture_png = match prim
        .material
        .and_then(|m| root.materials.get(m.value()))
        .and_then(|m| m.pbr_metallic_roughness.base_color_texture.as_ref())
    {
        Some(info) => Some(reader.texture_png(info.index.value())?),
        None => None,
    };
    Ok(GlbMesh {
        mesh: TriMesh {
            positions,
            triangles,
        },
        uvs,
        texture_png,
    })
}

/// Access to the buffer views of a GLB's binary chunk.
struct Reader<'a> {
    root: &'a json::Root,
    bin: &'a [u8],
}

impl Reader<'_> {
    /// Bytes of buffer view `v`, and its stride (0 = tightly packed).
    fn view(&self, v: usize) -> std::result::Result<(&[u8], usize), String> {
        let view = self
            .root
            .buffer_views
            .get(v)
            .ok_or_else(|| format!("buffer view {v} does not exist"))?;
        let buf = self
            .root
            .buffers
            .get(view.buffer.value())
            .ok_or("a buffer view refers to a missing buffer")?;
        if buf.uri.is_some() || view.buffer.value() != 0 {
            return Err("only the GLB's own binary chunk is supported as a buffer".into());
        }
        let off = view.byte_offset.map(|o| o.0 as usize).unwrap_or(0);
        let len = view.byte_length.0 as usize;
        let data = self
            .bin
            .get(off..off.saturating_add(len))
            .ok_or_else(|| format!("buffer view {v} runs past the binary chunk"))?;
        Ok((data, view.byte_stride.map(|s| s.0).unwrap_or(0)))
    }

    /// The elements of accessor `a` as raw little-endian components: (bytes of each element).
    fn elements(
        &self,
        a: usize,
        what: &str,
    ) -> std::result::Result<(Vec<&[u8]>, json::accessor::ComponentType), String> {
        let acc = self
            .root
            .accessors
            .get(a)
            .ok_or_else(|| format!("{what}: accessor {a} does not exist"))?;
        if acc.sparse.is_some() {
            return Err(format!("{what}: sparse accessors are not supported"));
        }
        let (Checked::Valid(ct), Checked::Valid(ty)) = (&acc.component_type, &acc.type_) else {
            return Err(format!("{what}: invalid accessor type"));
        };
        let comp = match ct.0 {
            json::accessor::ComponentType::I8 | json::accessor::ComponentType::U8 => 1,
            json::accessor::ComponentType::I16 | json::accessor::ComponentType::U16 => 2,
            _ => 4,
        };
        let elem = comp * ty.multiplicity();
        let view = acc
            .buffer_view
            .ok_or_else(|| format!("{what}: accessor without a buffer view"))?;
        let (data, stride) = self.view(view.value())?;
        let stride = if stride == 0 { elem } else { stride };
        let off = acc.byte_offset.map(|o| o.0 as usize).unwrap_or(0);
        let count = acc.count.0 as usize;
        let need = if count == 0 {
            0
        } else {
            off + (count - 1) * stride + elem
        };
        if need > data.len() {
            return Err(format!(
                "{what}: {count} elements need {need} bytes, the buffer view has {}",
                data.len()
            ));
        }
        let items = (0..count)
            .map(|i| &data[off + i * stride..off + i * stride + elem])
            .collect();
        Ok((items, ct.0))
    }

    /// A float accessor of type `ty`, flattened.
    fn floats(
        &self,
        a: usize,
        ty: json::accessor::Type,
        what: &str,
    ) -> std::result::Result<Vec<f32>, String> {
        let acc_ty = self.root.accessors.get(a).map(|x| x.type_);
        if acc_ty != Some(Checked::Valid(ty)) {
            return Err(format!("{what}: expected a {ty:?} accessor"));
        }
        let (items, ct) = self.elements(a, what)?;
        if ct != json::accessor::ComponentType::F32 {
            return Err(format!("{what}: only float components are supported"));
        }
        let v: Vec<f32> = items
            .iter()
            .flat_map(|e| {
                e.chunks_exact(4)
                    .map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]]))
            })
            .collect();
        if let Some(bad) = v.iter().find(|x| !x.is_finite()) {
            return Err(format!("{what}: non-finite value {bad}"));
        }
        Ok(v)
    }

    /// An index accessor (unsigned byte, short or int scalars).
    fn indices(&self, a: usize) -> std::result::Result<Vec<u32>, String> {
        let (items, ct) = self.elements(a, "indices")?;
        use json::accessor::ComponentType as C;
        items
            .iter()
            .map(|e| match (ct, e.len()) {
                (C::U8, 1) => Ok(e[0] as u32),
                (C::U16, 2) => Ok(u16::from_le_bytes([e[0], e[1]]) as u32),
                (C::U32, 4) => Ok(u32::from_le_bytes([e[0], e[1], e[2], e[3]])),
                _ => Err("indices: expected unsigned scalar indices".to_string()),
            })
            .collect()
    }

    /// The PNG bytes of texture `t` (an image embedded in a buffer view).
    fn texture_png(&self, t: usize) -> std::result::Result<Vec<u8>, String> {
        let tex = self
            .root
            .textures
            .get(t)
            .ok_or_else(|| format!("texture {t} does not exist"))?;
        let img = self
            .root
            .images
            .get(tex.source.value())
            .ok_or("the texture's image does not exist")?;
        let view = img
            .buffer_view
            .ok_or("the texture image is not embedded (external image files are not supported)")?;
        let (data, _) = self.view(view.value())?;
        if !data.starts_with(b"\x89PNG\r\n\x1a\n") {
            return Err("the embedded texture is not a PNG".into());
        }
        Ok(data.to_vec())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::io::mesh_export::write_glb;

    fn quad() -> TriMesh {
        TriMesh {
            positions: vec![
                Point3::new(0.0, 0.0, 0.0),
                Point3::new(1.0, 0.0, 0.0),
                Point3::new(1.0, 1.0, 0.5),
                Point3::new(0.0, 1.0, 0.0),
            ],
            triangles: vec![[0, 1, 2], [0, 2, 3]],
        }
    }

    #[test]
    fn round_trip_with_uvs_and_texture() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("q.glb");
        let uv = [[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.25, 0.75]];
        let png = b"\x89PNG\r\n\x1a\nnot really the rest".to_vec();
        write_glb(&p, &quad(), Some((&uv, &png))).unwrap();
        let g = read_glb(&p).unwrap();
        assert_eq!(g.mesh, quad());
        assert_eq!(g.uvs.unwrap(), uv.to_vec());
        assert_eq!(g.texture_png.unwrap(), png);
    }

    #[test]
    fn truncated_and_foreign_files_are_refused() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("q.glb");
        write_glb(&p, &quad(), None).unwrap();
        let bytes = std::fs::read(&p).unwrap();
        let e = read_glb_bytes(&bytes[..bytes.len() - 10]).unwrap_err();
        assert!(e.contains("header says") || e.contains("past"), "{e}");
        let e = read_glb_bytes(b"PK\x03\x04zipfile").unwrap_err();
        assert!(e.contains("magic"), "{e}");
        let bad = p.with_extension("bad.glb");
        std::fs::write(&bad, &bytes[..40]).unwrap();
        let msg = read_glb(&bad).unwrap_err().to_string();
        assert!(msg.contains("bad.glb"), "{msg}");
    }
}
