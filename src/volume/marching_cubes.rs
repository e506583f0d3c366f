//! Marching cubes on a scalar volume: the lumen surface at a level between air and wall.
//!
//! Classic Lorensen tables (identical to scikit-image's `method='lorensen'`), one shared vertex
//! per crossed grid edge, vertices interpolated linearly along the edge and mapped to world mm by
//! the volume's affine. Work runs in parallel over z-slabs; each slab keeps only two slices of
//! edge → vertex caches (memory O(slice)), and slabs are stitched by the shared slice between
//! them, whose vertices both slabs emit in the same order.

use rayon::prelude::*;

use super::error::VolumeError;
use super::mc_tables::TRI_TABLE;
use super::Volume;
use crate::math::{Affine, Point3};
use crate::mesh::TriMesh;
use crate::Result;

/// Cell layers per slab: large enough that the one duplicated slice per slab costs little.
const MIN_SLAB_LAYERS: usize = 8;

/// Extract the iso-surface `value == iso` of `vol` as an indexed triangle mesh in world mm.
///
/// Values below `iso` are inside (air, the lumen). Where `region` is given (same grid), voxels
/// with `region == 0` count as above `iso` (tissue), so only surfaces inside the region are
/// extracted; an edge from an in-region air voxel to an out-of-region voxel gets its vertex at
/// the edge midpoint (a finite stand-in for "+infinity" that keeps caps free of zero-area
/// triangles). Triangles wind counter-clockwise seen from the low-value side, so their normals
/// point into the lumen for either sign of the affine's determinant. The mesh is closed except
/// where the surface meets the grid's border.
pub fn marching_cubes(vol: &Volume<f32>, iso: f32, region: Option<&Volume<u8>>) -> Result<TriMesh> {
    if let Some(r) = region {
        if r.dims != vol.dims {
            return Err(VolumeError::GridMismatch {
                stage: "marching cubes",
                what: "region",
                got: r.dims,
                expected: vol.dims,
            }
            .into());
        }
    }
    if !iso.is_finite() {
        return Err(VolumeError::BadIsoLevel(iso).into());
    }
    let [nx, ny, nz] = vol.dims;
    if nx < 2 || ny < 2 || nz < 2 {
        return Ok(TriMesh::default());
    }
    let ctx = Ctx {
        vol: &vol.data,
        region: region.map(|r| r.data.as_slice()),
        nx,
        ny,
        iso,
        affine: affine_f32(&vol.affine),
        flip: vol.affine.fixed_view::<3, 3>(0, 0).determinant() < 0.0,
    };
    let layers = nz - 1;
    let threads = rayon::current_num_threads().max(1);
    // About four slabs per thread balance uneven surface density across z.
    let per = layers
        .div_ceil(4 * threads)
        .max(MIN_SLAB_LAYERS)
        .min(layers);
    let slabs: Vec<(usize, usize)> = (0..layers)
        .step_by(per)
        .map(|z0| (z0, (z0 + per).min(layers)))
        .collect();
    let parts: Vec<SlabMesh> = slabs.par_iter().map(|&(z0, z1)| ctx.slab(z0, z1)).collect();
    Ok(stitch(parts))
}

/// The affine as f32 rows (3x4): vertex transforms run in f32, ample for mm coordinates.
fn affine_f32(a: &Affine) -> [[f32; 4]; 3] {
    let mut m = [[0f32; 4]; 3];
    for (r, row) in m.iter_mut().enumerate() {
        for (c, v) in row.iter_mut().enumerate() {
            *v = a[(r, c)] as f32;
        }
    }
    m
}

/// Shared read-only inputs of all slabs.
struct Ctx<'a> {
    vol: &'a [f32],
    region: Option<&'a [u8]>,
    nx: usize,
    ny: usize,
    iso: f32,
    affine: [[f32; 4]; 3],
    flip: bool,
}

/// One slab's output. Vertices `owned..` are the slab's top slice, owned by the next slab,
/// which emits the same vertices in the same order as its first ones.
struct SlabMesh {
    positions: Vec<Point3<f32>>,
    triangles: Vec<[u32; 3]>,
    owned: usize,
}

/// Row summary: every voxel of the row below, every voxel above, or both kinds.
const ROW_BELOW: u8 = 0;
const ROW_ABOVE: u8 = 1;
const ROW_MIXED: u8 = 2;

/// Per-slice state: above-level flags, row summaries, and vertex ids of the slice's x and y edges.
struct Slice {
    above: Vec<u8>,
    rows: Vec<u8>,
    xid: Vec<u32>,
    yid: Vec<u32>,
}

impl Slice {
    fn new(n: usize, ny: usize) -> Self {
        Slice {
            above: vec![0; n],
            rows: vec![0; ny],
            xid: vec![0; n],
            yid: vec![0; n],
        }
    }
}

impl Ctx<'_> {
    /// Fill the above flags and row summaries of slice `k`.
    // `!(v < iso)` rather than `v >= iso` on purpose: NaN must count as tissue.
    #[allow(clippy::neg_cmp_op_on_partial_ord)]
    fn classify(&self, k: usize, s: &mut Slice) {
        let (nx, ny) = (self.nx, self.ny);
        let base = k * nx * ny;
        for j in 0..ny {
            let row = &mut s.above[j * nx..(j + 1) * nx];
            let off = base + j * nx;
            let vals = &self.vol[off..off + nx];
            match self.region {
                Some(r) => {
                    let reg = &r[off..off + nx];
                    for ((a, &v), &m) in row.iter_mut().zip(vals).zip(reg) {
                        *a = (m == 0 || !(v < self.iso)) as u8;
                    }
                }
                None => {
                    for (a, &v) in row.iter_mut().zip(vals) {
                        // NaN counts as tissue: it must never open a hole into the lumen.
                        *a = !(v < self.iso) as u8;
                    }
                }
            }
            let sum: usize = row.iter().map(|&a| a as usize).sum();
            s.rows[j] = if sum == 0 {
                ROW_BELOW
            } else if sum == nx {
                ROW_ABOVE
            } else {
                ROW_MIXED
            };
        }
    }

    /// World position of the crossing on the edge between voxels `a` and `b` at index `p`
    /// (the position of voxel `a`) plus `t` along `axis`.
    #[inline]
    fn vertex(&self, a: usize, b: usize, ijk: [f32; 3], axis: usize) -> Point3<f32> {
        let (va, vb) = (self.vol[a], self.vol[b]);
        let t = match self.region {
            // An out-of-region end stands for "tissue": put the vertex mid-edge.
            Some(r) if r[a] == 0 || r[b] == 0 => 0.5,
            _ => {
                let t = (self.iso - va) / (vb - va);
                if t.is_finite() {
                    t.clamp(0.0, 1.0)
                } else {
                    0.5
                }
            }
        };
        let mut p = ijk;
        p[axis] += t;
        let m = &self.affine;
        Point3::new(
            m[0][0] * p[0] + m[0][1] * p[1] + m[0][2] * p[2] + m[0][3],
            m[1][0] * p[0] + m[1][1] * p[1] + m[1][2] * p[2] + m[1][3],
            m[2][0] * p[0] + m[2][1] * p[1] + m[2][2] * p[2] + m[2][3],
        )
    }

    /// Emit the vertices of slice `k`'s x and y edges in a fixed order (rows, x edges then y edges).
    fn emit_xy(&self, k: usize, s: &mut Slice, out: &mut Vec<Point3<f32>>) {
        let (nx, ny) = (self.nx, self.ny);
        let base = k * nx * ny;
        let kf = k as f32;
        for j in 0..ny {
            let r = j * nx;
            if s.rows[j] == ROW_MIXED {
                for i in 0..nx - 1 {
                    if s.above[r + i] != s.above[r + i + 1] {
                        s.xid[r + i] = out.len() as u32;
                        out.push(self.vertex(
                            base + r + i,
                            base + r + i + 1,
                            [i as f32, j as f32, kf],
                            0,
                        ));
                    }
                }
            }
            if j + 1 < ny && !(s.rows[j] == s.rows[j + 1] && s.rows[j] != ROW_MIXED) {
                for i in 0..nx {
                    if s.above[r + i] != s.above[r + nx + i] {
                        s.yid[r + i] = out.len() as u32;
                        out.push(self.vertex(
                            base + r + i,
                            base + r + nx + i,
                            [i as f32, j as f32, kf],
                            1,
                        ));
                    }
                }
            }
        }
    }

    /// Emit the vertices of the z edges between slices `k` (`lo`) and `k + 1` (`hi`).
    fn emit_z(
        &self,
        k: usize,
        lo: &Slice,
        hi: &Slice,
        zid: &mut [u32],
        out: &mut Vec<Point3<f32>>,
    ) {
        let (nx, ny) = (self.nx, self.ny);
        let base = k * nx * ny;
        let kf = k as f32;
        for j in 0..ny {
            if lo.rows[j] == hi.rows[j] && lo.rows[j] != ROW_MIXED {
                continue;
            }
            let r = j * nx;
            for i in 0..nx {
                if lo.above[r + i] != hi.above[r + i] {
                    zid[r + i] = out.len() as u32;
                    out.push(self.vertex(
                        base + r + i,
                        base + nx * ny + r + i,
                        [i as f32, j as f32, kf],
                        2,
                    ));
                }
            }
        }
    }

    /// Triangulate the cells between slices `lo` and `hi` using their edge vertex ids.
    fn cells(&self, lo: &Slice, hi: &Slice, zid: &[u32], tris: &mut Vec<[u32; 3]>) {
        let (nx, ny) = (self.nx, self.ny);
        for j in 0..ny - 1 {
            let s = [lo.rows[j], lo.rows[j + 1], hi.rows[j], hi.rows[j + 1]];
            if s[0] != ROW_MIXED && s.iter().all(|&v| v == s[0]) {
                continue;
            }
            let (a, b) = (j * nx, (j + 1) * nx);
            for i in 0..nx - 1 {
                let case = lo.above[a + i] as usize
                    | (lo.above[a + i + 1] as usize) << 1
                    | (lo.above[b + i + 1] as usize) << 2
                    | (lo.above[b + i] as usize) << 3
                    | (hi.above[a + i] as usize) << 4
                    | (hi.above[a + i + 1] as usize) << 5
                    | (hi.above[b + i + 1] as usize) << 6
                    | (hi.above[b + i] as usize) << 7;
                if case == 0 || case == 255 {
                    continue;
                }
                let edge = |e: i8| -> u32 {
                    match e {
                        0 => lo.xid[a + i],
                        1 => lo.yid[a + i + 1],
                        2 => lo.xid[b + i],
                        3 => lo.yid[a + i],
                        4 => hi.xid[a + i],
                        5 => hi.yid[a + i + 1],
                        6 => hi.xid[b + i],
                        7 => hi.yid[a + i],
                        8 => zid[a + i],
                        9 => zid[a + i + 1],
                        10 => zid[b + i + 1],
                        _ => zid[b + i],
                    }
                };
                let row = &TRI_TABLE[case];
                let mut t = 0;
                while t < 15 && row[t] >= 0 {
                    let (p, q, r) = (edge(row[t]), edge(row[t + 1]), edge(row[t + 2]));
                    // The table's normals face the above (tissue) side in a right-handed grid:
                    // reverse them to face the lumen, unless the affine mirrors the grid.
                    tris.push(if self.flip { [p, q, r] } else { [p, r, q] });
                    t += 3;
                }
            }
        }
    }

    /// Mesh the cell layers `z0..z1` (cells between slices k and k+1).
    fn slab(&self, z0: usize, z1: usize) -> SlabMesh {
        let n = self.nx * self.ny;
        let mut lo = Slice::new(n, self.ny);
        let mut hi = Slice::new(n, self.ny);
        let mut zid = vec![0u32; n];
        let mut positions = Vec::new();
        let mut triangles = Vec::new();
        self.classify(z0, &mut lo);
        self.emit_xy(z0, &mut lo, &mut positions);
        let mut owned = positions.len();
        for k in z0..z1 {
            self.classify(k + 1, &mut hi);
            self.emit_z(k, &lo, &hi, &mut zid, &mut positions);
            owned = positions.len();
            self.emit_xy(k + 1, &mut hi, &mut positions);
            self.cells(&lo, &hi, &zid, &mut triangles);
            std::mem::swap(&mut lo, &mut hi);
        }
        SlabMesh {
            positions,
            triangles,
            owned,
        }
    }
}

/// Concatenate slab meshes, mapping each slab's top-slice vertices onto the next slab's first ones.
fn stitch(parts: Vec<SlabMesh>) -> TriMesh {
    let last = parts.len().saturating_sub(1);
    let kept: Vec<usize> = parts
        .iter()
        .enumerate()
        .map(|(s, p)| {
            if s == last {
                p.positions.len()
            } else {
                p.owned
            }
        })
        .collect();
    let mut offsets = Vec::with_capacity(parts.len() + 1);
    offsets.push(0usize);
    for &k in &kept {
        offsets.push(offsets.last().unwrap() + k);
    }
    let mut tri_offsets = vec![0usize];
    for p in &parts {
        tri_offsets.push(tri_offsets.last().unwrap() + p.triangles.len());
    }
    let mut positions = Vec::with_capacity(offsets[parts.len()]);
    for (p, &k) in parts.iter().zip(&kept) {
        positions.extend_from_slice(&p.positions[..k]);
    }
    let mut triangles = vec![[0u32; 3]; tri_offsets[parts.len()]];
    let mut rest: &mut [[u32; 3]] = &mut triangles;
    let mut chunks = Vec::with_capacity(parts.len());
    for p in &parts {
        let (head, tail) = rest.split_at_mut(p.triangles.len());
        chunks.push(head);
        rest = tail;
    }
    chunks.into_par_iter().enumerate().for_each(|(s, dst)| {
        let p = &parts[s];
        let (own, base, next) = (kept[s] as u32, offsets[s] as u32, offsets[s + 1] as u32);
        for (d, t) in dst.iter_mut().zip(&p.triangles) {
            // Local ids past `own` are the next slab's first vertices, in the same order.
            *d = t.map(|v| if v < own { base + v } else { next + (v - own) });
        }
    });
    TriMesh {
        positions,
        triangles,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn non_finite_and_huge_values_give_finite_vertices() {
        // Seeded mix of air, tissue, NaN, ±inf and ±f32::MAX: every vertex stays finite and
        // on its grid edge, and NaN never counts as air (a NaN-only grid has no surface).
        let mut r = crate::rng::Pcg32::new(17, 5);
        let pick = [
            -1000.0,
            40.0,
            f32::NAN,
            f32::INFINITY,
            f32::NEG_INFINITY,
            f32::MAX,
            -f32::MAX,
        ];
        let data: Vec<f32> = (0..9 * 8 * 7)
            .map(|_| pick[(r.uniform() * pick.len() as f64) as usize % pick.len()])
            .collect();
        let v = Volume::from_data([9, 8, 7], Affine::identity(), data).unwrap();
        let m = marching_cubes(&v, -500.0, None).unwrap();
        assert!(!m.triangles.is_empty());
        for p in &m.positions {
            assert!(p.coords.iter().all(|c| c.is_finite()), "{p:?}");
            let off_grid = [p.x, p.y, p.z].iter().filter(|c| c.fract() != 0.0).count();
            assert!(off_grid <= 1, "{p:?} is not on a grid edge");
        }
        let nan = Volume::filled([4, 4, 4], Affine::identity(), f32::NAN);
        assert!(marching_cubes(&nan, -500.0, None)
            .unwrap()
            .triangles
            .is_empty());
    }

    #[test]
    fn single_low_corner_gives_one_inward_triangle() {
        let mut v = Volume::filled([2, 2, 2], Affine::identity(), 1.0f32);
        v.set(0, 0, 0, -1.0);
        let m = marching_cubes(&v, 0.0, None).unwrap();
        assert_eq!(m.triangles.len(), 1);
        assert_eq!(m.positions.len(), 3);
        // The normal must point toward the low corner at the origin.
        let n = m.face_normal(0);
        assert!(n.x < 0.0 && n.y < 0.0 && n.z < 0.0, "normal {n:?}");
        for p in &m.positions {
            assert!((p.x + p.y + p.z - 0.5).abs() < 1e-6);
        }
    }
}
