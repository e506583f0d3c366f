//! [`Scene`]: a lumen mesh ready for ray queries (BVH, vertex normals) and the query API.

use super::bvh::{Bvh, Node, RawHit};
use super::bvh_build::build;
use super::packet::PACKET;
use crate::mesh::error::GeometryError;
use crate::mesh::TriMesh;
use crate::Result;
use rayon::prelude::*;

/// A ray–surface hit.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Hit {
    /// Distance along the ray (mm when the direction is a unit vector).
    pub t: f32,
    /// Index of the triangle hit, in the input [`TriMesh`].
    pub tri: u32,
    /// Barycentric weight of the triangle's second vertex.
    pub u: f32,
    /// Barycentric weight of the triangle's third vertex (the first has `1 - u - v`).
    pub v: f32,
}

/// The BVH in the widest form the CPU runs well.
enum Accel {
    /// Four-wide, SSE (any CPU).
    W4(Bvh<4>),
    /// Eight-wide, AVX; only built when AVX2 was detected at run time.
    W8(Bvh<8>),
}

/// A triangle mesh prepared for ray casting: a four-wide BVH, the triangles and the
/// area-weighted unit vertex normals. Geometry is f32, world mm.
pub struct Scene {
    bvh: Accel,
    /// Vertex positions (mm).
    pub positions: Vec<[f32; 3]>,
    /// Vertex indices per triangle.
    pub triangles: Vec<[u32; 3]>,
    /// Unit vertex normals (area weighted; zero for isolated vertices).
    pub normals: Vec<[f32; 3]>,
}

impl Scene {
    /// Build the BVH (parallel, binned SAH) and the vertex normals of `mesh`.
    ///
    /// Fails when a triangle indexes a missing vertex, a used vertex is not finite, or the
    /// tree would be deeper than the traversal supports.
    pub fn new(mesh: &TriMesh) -> Result<Scene> {
        Self::build(mesh, wide8())
    }

    /// As [`Scene::new`] but always with the portable four-wide (SSE) BVH, whatever the CPU;
    /// for comparisons and tests of that path.
    pub fn new_four_wide(mesh: &TriMesh) -> Result<Scene> {
        Self::build(mesh, false)
    }

    fn build(mesh: &TriMesh, eight_wide: bool) -> Result<Scene> {
        let nv = mesh.positions.len();
        let positions: Vec<[f32; 3]> = mesh.positions.iter().map(|p| [p.x, p.y, p.z]).collect();
        let mut tris = Vec::with_capacity(mesh.triangles.len());
        for (i, t) in mesh.triangles.iter().enumerate() {
            if t.iter().any(|&v| v as usize >= nv) {
                return Err(GeometryError::VertexIndex {
                    stage: "ray-casting scene",
                    triangle: i,
                    vertices: nv,
                }
                .into());
            }
            let v = t.map(|k| positions[k as usize]);
            if v.iter().flatten().any(|c| !c.is_finite()) {
                return Err(GeometryError::NonFiniteVertex {
                    stage: "ray-casting scene",
                    triangle: i,
                }
                .into());
            }
            tris.push(v);
        }
        let bvh = if eight_wide {
            build::<8>(&tris).map(Accel::W8)
        } else {
            build::<4>(&tris).map(Accel::W4)
        }
        .ok_or_else(|| GeometryError::Degenerate {
            stage: "ray-casting scene",
            message: format!(
                "BVH too deep for the traversal stack ({} triangles); degenerate geometry?",
                tris.len()
            ),
        })?;
        let normals = mesh
            .vertex_normals()
            .iter()
            .map(|n| [n.x, n.y, n.z])
            .collect();
        Ok(Scene {
            bvh,
            positions,
            triangles: mesh.triangles.clone(),
            normals,
        })
    }

    /// BVH size for diagnostics: inner nodes, leaf blocks of four triangles, and bytes.
    pub fn stats(&self) -> String {
        let (w, n, l, nb) = match &self.bvh {
            Accel::W4(b) => (
                4,
                b.nodes.len(),
                b.leaves.len(),
                std::mem::size_of::<Node<4>>(),
            ),
            Accel::W8(b) => (
                8,
                b.nodes.len(),
                b.leaves.len(),
                std::mem::size_of::<Node<8>>(),
            ),
        };
        format!(
            "{w}-wide: {n} nodes, {l} leaf blocks ({:.2} triangles per block), {:.1} MB",
            self.triangles.len() as f64 / l.max(1) as f64,
            (n * nb + l * std::mem::size_of::<super::triangle::Tri4>()) as f64 / 1e6
        )
    }

    /// Number of triangles.
    pub fn triangle_count(&self) -> usize {
        self.triangles.len()
    }

    /// Nearest hit with `0 < t < tmax` of the ray `origin + t dir` (mm; `dir` need not be
    /// unit, `t` is in units of `dir`). Triangles are two-sided.
    #[inline]
    pub fn closest_hit(&self, origin: [f32; 3], dir: [f32; 3], tmax: f32) -> Option<Hit> {
        let h: Option<RawHit> = match &self.bvh {
            Accel::W4(b) => b.closest_hit(origin, dir, tmax),
            // SAFETY: W8 is only built when AVX2 was detected.
            #[cfg(target_arch = "x86_64")]
            Accel::W8(b) => unsafe { b.closest_hit(origin, dir, tmax) },
            #[cfg(not(target_arch = "x86_64"))]
            Accel::W8(_) => unreachable!("eight-wide BVH is only built on x86_64"),
        };
        h.map(|h| Hit {
            t: h.t,
            tri: h.tri,
            u: h.u,
            v: h.v,
        })
    }

    /// True when anything is hit with `0 < t < tmax` (visibility query; no ordering).
    #[inline]
    pub fn any_hit(&self, origin: [f32; 3], dir: [f32; 3], tmax: f32) -> bool {
        match &self.bvh {
            Accel::W4(b) => b.any_hit(origin, dir, tmax),
            // SAFETY: W8 is only built when AVX2 was detected.
            #[cfg(target_arch = "x86_64")]
            Accel::W8(b) => unsafe { b.any_hit(origin, dir, tmax) },
            #[cfg(not(target_arch = "x86_64"))]
            Accel::W8(_) => unreachable!("eight-wide BVH is only built on x86_64"),
        }
    }

    /// [`Scene::closest_hit`] for rays that share one origin (a camera's pixels), on the calling
    /// thread: consecutive groups of 16 rays are traced together as one packet, which is
    /// fastest when they are coherent (neighbouring pixels). Each `out[i]` gets the nearest hit
    /// along `dirs[i]` with `0 < t < tmax` — the same as `closest_hit(origin, dirs[i], tmax)`
    /// (the same triangle unless two tie at exactly the same `t`).
    ///
    /// # Panics
    /// When `out.len() != dirs.len()` (a caller bug, not an input error).
    pub fn closest_hits_common_origin(
        &self,
        origin: [f32; 3],
        dirs: &[[f32; 3]],
        tmax: f32,
        out: &mut [Option<Hit>],
    ) {
        assert_eq!(
            dirs.len(),
            out.len(),
            "closest_hits_common_origin: one output per ray"
        );
        const CHUNK: usize = 64;
        let mut raw = [None; CHUNK];
        for (d, o) in dirs.chunks(CHUNK).zip(out.chunks_mut(CHUNK)) {
            let raw = &mut raw[..d.len()];
            match &self.bvh {
                Accel::W4(b) => b.closest_hits_packets(origin, d, tmax, raw),
                // SAFETY: W8 is only built when AVX2 was detected.
                #[cfg(target_arch = "x86_64")]
                Accel::W8(b) => unsafe { b.closest_hits_packets(origin, d, tmax, raw) },
                #[cfg(not(target_arch = "x86_64"))]
                Accel::W8(_) => unreachable!("eight-wide BVH is only built on x86_64"),
            }
            for (o, r) in o.iter_mut().zip(raw.iter()) {
                *o = r.map(|h| Hit {
                    t: h.t,
                    tri: h.tri,
                    u: h.u,
                    v: h.v,
                });
            }
        }
    }

    /// Rows of the tiles [`Scene::closest_hits_image_rows`] traces together; blocks of a
    /// multiple of this many rows trace fastest.
    pub const TILE_ROWS: usize = PACKET / 4;

    /// [`Scene::closest_hits_common_origin`] for an image block: `dirs` holds rows of
    /// `row_len` rays each (row-major, e.g. [`Scene::TILE_ROWS`] rows of a camera's pixels).
    /// The rays are traced in tiles of four columns by `TILE_ROWS` rows — more compact packets
    /// than a stretch of one row — and `out` is in the order of `dirs`.
    ///
    /// # Panics
    /// When `out.len() != dirs.len()`, or `row_len` is 0 or does not divide `dirs.len()`.
    pub fn closest_hits_image_rows(
        &self,
        origin: [f32; 3],
        dirs: &[[f32; 3]],
        row_len: usize,
        tmax: f32,
        out: &mut [Option<Hit>],
    ) {
        assert!(
            dirs.len() == out.len() && row_len > 0 && dirs.len() % row_len == 0,
            "closest_hits_image_rows: {} rays, {} outputs, rows of {row_len}",
            dirs.len(),
            out.len()
        );
        const CHUNK: usize = 64;
        let mut idx = [0usize; CHUNK];
        let mut d = [[0f32; 3]; CHUNK];
        let mut h = [None; CHUNK];
        let mut n = 0;
        let rows = dirs.len() / row_len;
        let mut flush = |idx: &[usize], d: &[[f32; 3]], h: &mut [Option<Hit>]| {
            self.closest_hits_common_origin(origin, d, tmax, h);
            for (&i, &hit) in idx.iter().zip(h.iter()) {
                out[i] = hit;
            }
        };
        for y0 in (0..rows).step_by(Self::TILE_ROWS) {
            let y1 = (y0 + Self::TILE_ROWS).min(rows);
            for x0 in (0..row_len).step_by(4) {
                let x1 = (x0 + 4).min(row_len);
                for y in y0..y1 {
                    for x in x0..x1 {
                        let i = y * row_len + x;
                        idx[n] = i;
                        d[n] = dirs[i];
                        n += 1;
                        if n == CHUNK {
                            flush(&idx, &d, &mut h);
                            n = 0;
                        }
                    }
                }
            }
        }
        if n > 0 {
            flush(&idx[..n], &d[..n], &mut h[..n]);
        }
    }

    /// [`Scene::closest_hit`] for many rays in parallel; `origins` and `dirs` have equal length.
    pub fn closest_hits(
        &self,
        origins: &[[f32; 3]],
        dirs: &[[f32; 3]],
        tmax: f32,
    ) -> Vec<Option<Hit>> {
        origins
            .par_iter()
            .zip(dirs.par_iter())
            .with_min_len(256)
            .map(|(o, d)| self.closest_hit(*o, *d, tmax))
            .collect()
    }

    /// [`Scene::any_hit`] for many rays in parallel, each with its own `tmax`.
    pub fn any_hits(&self, origins: &[[f32; 3]], dirs: &[[f32; 3]], tmax: &[f32]) -> Vec<bool> {
        origins
            .par_iter()
            .zip(dirs.par_iter())
            .zip(tmax.par_iter())
            .with_min_len(256)
            .map(|((o, d), t)| self.any_hit(*o, *d, *t))
            .collect()
    }

    /// Interpolated unit vertex normal at barycentrics (u, v) of triangle `tri` (not flipped).
    #[inline]
    pub fn shading_normal(&self, tri: u32, u: f32, v: f32) -> [f32; 3] {
        let [a, b, c] = self.triangles[tri as usize];
        let (na, nb, nc) = (
            self.normals[a as usize],
            self.normals[b as usize],
            self.normals[c as usize],
        );
        let w = 1.0 - u - v;
        let n = [
            w * na[0] + u * nb[0] + v * nc[0],
            w * na[1] + u * nb[1] + v * nc[1],
            w * na[2] + u * nb[2] + v * nc[2],
        ];
        let l = (n[0] * n[0] + n[1] * n[1] + n[2] * n[2]).sqrt();
        if l > 0.0 {
            [n[0] / l, n[1] / l, n[2] / l]
        } else {
            n
        }
    }
}

/// True when the eight-wide AVX traversal can run (x86_64 with AVX2, unless the environment
/// variable BRONCHOSIM_BVH4 is set, which forces the portable four-wide BVH for comparison).
fn wide8() -> bool {
    #[cfg(target_arch = "x86_64")]
    {
        std::env::var_os("BRONCHOSIM_BVH4").is_none() && is_x86_feature_detected!("avx2")
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        false
    }
}
