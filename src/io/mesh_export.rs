//! Mesh files: binary PLY, Wavefront OBJ and binary glTF 2.0 (GLB), all in world mm (RAS+).
//!
//! Every writer is atomic: it writes a temporary file in the target's folder and renames it into
//! place, so an interrupted run never leaves a truncated mesh behind.

use crate::io::atomic::write_atomic;
use std::io::{BufRead, BufReader, Read};
use std::path::Path;

use crate::math::Point3;
use crate::mesh::TriMesh;
use crate::{Error, Result};

mod glb;
pub use glb::write_glb;

/// Fail when a triangle refers past the vertex list or the UVs do not match the vertices.
fn check_mesh(path: &Path, mesh: &TriMesh, uvs: Option<&[[f32; 2]]>) -> Result<()> {
    let n = mesh.positions.len();
    if let Some(t) = mesh
        .triangles
        .iter()
        .find(|t| t.iter().any(|&v| v as usize >= n))
    {
        return Err(Error::invalid(
            path,
            format!("cannot write a mesh whose triangle {t:?} refers past its {n} vertices"),
        ));
    }
    if let Some(uv) = uvs {
        if uv.len() != n {
            return Err(Error::invalid(
                path,
                format!("{} UVs given for {n} vertices", uv.len()),
            ));
        }
    }
    Ok(())
}

/// Binary little-endian PLY: vertex x y z nx ny nz (float, mm; normals unit, into the lumen),
/// faces as `list uchar uint`.
pub fn write_ply(path: &Path, mesh: &TriMesh) -> Result<()> {
    write_ply_with_colours(path, mesh, None, "bronchosim lumen mesh, world mm (RAS+)")
}

/// [`write_ply`] with an optional float `red green blue` per vertex (e.g. linear albedo in
/// [0, 1]) after the normals, and the header comment `comment`. [`read_ply`] reads the
/// geometry back (it skips the extra properties).
pub fn write_ply_with_colours(
    path: &Path,
    mesh: &TriMesh,
    colours: Option<&[[f32; 3]]>,
    comment: &str,
) -> Result<()> {
    check_mesh(path, mesh, None)?;
    if let Some(c) = colours {
        if c.len() != mesh.positions.len() {
            return Err(Error::invalid(
                path,
                format!("{} colours for {} vertices", c.len(), mesh.positions.len()),
            ));
        }
    }
    let normals = mesh.vertex_normals();
    let colour_props = if colours.is_some() {
        "property float red\nproperty float green\nproperty float blue\n"
    } else {
        ""
    };
    write_atomic(path, |w| {
        write!(
            w,
            "ply\nformat binary_little_endian 1.0\ncomment {comment}\n\
             element vertex {}\nproperty float x\nproperty float y\nproperty float z\n\
             property float nx\nproperty float ny\nproperty float nz\n{colour_props}\
             element face {}\nproperty list uchar uint vertex_indices\nend_header\n",
            mesh.positions.len(),
            mesh.triangles.len()
        )?;
        for (i, (p, n)) in mesh.positions.iter().zip(&normals).enumerate() {
            for v in [p.x, p.y, p.z, n.x, n.y, n.z] {
                w.write_all(&v.to_le_bytes())?;
            }
            if let Some(c) = colours {
                for v in c[i] {
                    w.write_all(&v.to_le_bytes())?;
                }
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

/// Read a binary little-endian PLY with float vertex properties (x, y, z first) and triangle
/// faces (`list uchar int|uint`), as [`write_ply`] writes it. Other properties are skipped.
pub fn read_ply(path: &Path) -> Result<TriMesh> {
    let f = std::fs::File::open(path).map_err(|e| Error::io(path, e))?;
    let mut r = BufReader::new(f);
    let bad = |m: &str| Error::invalid(path, m.to_string());
    let mut line = String::new();
    let (mut nv, mut nf, mut vprops, mut in_vertex, mut binary) =
        (0usize, 0usize, Vec::<String>::new(), false, false);
    let mut header_lines = 0;
    loop {
        line.clear();
        if r.read_line(&mut line).map_err(|e| Error::io(path, e))? == 0 {
            return Err(bad("PLY header has no end_header"));
        }
        header_lines += 1;
        if header_lines == 1 && line.trim() != "ply" {
            return Err(bad("not a PLY file (first line is not 'ply')"));
        }
        let w: Vec<&str> = line.split_whitespace().collect();
        match w.as_slice() {
            ["format", "binary_little_endian", _] => binary = true,
            ["format", ..] => {
                return Err(Error::unsupported(
                    path,
                    "only binary_little_endian PLY is read",
                ))
            }
            ["element", "vertex", n] => {
                nv = n.parse().map_err(|_| bad("bad vertex count"))?;
                in_vertex = true;
            }
            ["element", "face", n] => {
                nf = n.parse().map_err(|_| bad("bad face count"))?;
                in_vertex = false;
            }
            ["property", "float" | "float32", name] if in_vertex => vprops.push(name.to_string()),
            ["property", t, _] if in_vertex => {
                return Err(Error::unsupported(
                    path,
                    format!("vertex property type {t} (only float)"),
                ))
            }
            ["property", "list", "uchar" | "uint8", "int" | "uint" | "int32" | "uint32", _] => {}
            ["property", ..] => {
                return Err(Error::unsupported(
                    path,
                    "face property other than list uchar int",
                ))
            }
            ["end_header"] => break,
            _ => {}
        }
    }
    if !binary || vprops.len() < 3 || vprops[..3] != ["x", "y", "z"] {
        return Err(bad(
            "PLY needs binary_little_endian and float x y z as the first vertex properties",
        ));
    }
    let stride = 4 * vprops.len();
    let mut vbuf = vec![0u8; nv * stride];
    r.read_exact(&mut vbuf)
        .map_err(|_| bad("PLY vertex data is truncated"))?;
    let f32at = |o: usize| f32::from_le_bytes([vbuf[o], vbuf[o + 1], vbuf[o + 2], vbuf[o + 3]]);
    let positions = (0..nv)
        .map(|i| {
            Point3::new(
                f32at(i * stride),
                f32at(i * stride + 4),
                f32at(i * stride + 8),
            )
        })
        .collect();
    let mut triangles = Vec::with_capacity(nf);
    let mut fbuf = [0u8; 13];
    for _ in 0..nf {
        r.read_exact(&mut fbuf)
            .map_err(|_| bad("PLY face data is truncated"))?;
        if fbuf[0] != 3 {
            return Err(Error::unsupported(
                path,
                format!("a face with {} vertices (only triangles)", fbuf[0]),
            ));
        }
        let v = |k: usize| {
            u32::from_le_bytes([
                fbuf[1 + 4 * k],
                fbuf[2 + 4 * k],
                fbuf[3 + 4 * k],
                fbuf[4 + 4 * k],
            ])
        };
        let t = [v(0), v(1), v(2)];
        if t.iter().any(|&i| i as usize >= nv) {
            return Err(bad("a face refers past the vertex list"));
        }
        triangles.push(t);
    }
    Ok(TriMesh {
        positions,
        triangles,
    })
}

/// Wavefront OBJ: `v` (mm), `vn` (unit, into the lumen), optional `vt` (u, v with v up, as OBJ
/// expects), and 1-based `f` lines.
pub fn write_obj(path: &Path, mesh: &TriMesh, uvs: Option<&[[f32; 2]]>) -> Result<()> {
    check_mesh(path, mesh, uvs)?;
    let normals = mesh.vertex_normals();
    write_atomic(path, |w| {
        writeln!(
            w,
            "# bronchosim lumen mesh, world mm (RAS+), normals face into the lumen"
        )?;
        for p in &mesh.positions {
            writeln!(w, "v {} {} {}", p.x, p.y, p.z)?;
        }
        for n in &normals {
            writeln!(w, "vn {} {} {}", n.x, n.y, n.z)?;
        }
        if let Some(uv) = uvs {
            for t in uv {
                // Texture rows run top-down (glTF convention); OBJ's v runs bottom-up.
                writeln!(w, "vt {} {}", t[0], 1.0 - t[1])?;
            }
        }
        for t in &mesh.triangles {
            let [a, b, c] = t.map(|v| v + 1);
            if uvs.is_some() {
                writeln!(w, "f {a}/{a}/{a} {b}/{b}/{b} {c}/{c}/{c}")?;
            } else {
                writeln!(w, "f {a}//{a} {b}//{b} {c}//{c}")?;
            }
        }
        Ok(())
    })
}
