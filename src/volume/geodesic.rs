//! Shortest paths over the voxels of a mask (26-neighbour graph, edge lengths in mm), and the
//! centred path that hugs the middle of a tubular mask.
//!
//! Voxels are flat indices into x-fastest data (`i = x + nx·(y + ny·z)`), as in
//! [`Volume`]. The centred path minimises `Σ length / (dt + 0.5)²` over its edges, `dt` being
//! the distance (mm) from a voxel to the nearest voxel outside the mask (averaged over the
//! edge's two voxels): near the wall an edge costs a lot, along the centre little, so the path
//! follows the medial axis and cuts no corners.

use std::cmp::Reverse;
use std::collections::BinaryHeap;

use super::error::VolumeError;
use crate::volume::morphology::distance_transform_sq;
use crate::volume::Volume;
use crate::Result;

/// The 26 neighbour offsets (voxels) and their lengths (mm) for voxel spacing `sp` (mm).
pub fn neighbours(sp: [f64; 3]) -> Vec<([i64; 3], f32)> {
    let mut v = Vec::with_capacity(26);
    for dz in -1i64..=1 {
        for dy in -1i64..=1 {
            for dx in -1i64..=1 {
                if (dx, dy, dz) != (0, 0, 0) {
                    let l = ((dx as f64 * sp[0]).powi(2)
                        + (dy as f64 * sp[1]).powi(2)
                        + (dz as f64 * sp[2]).powi(2))
                    .sqrt();
                    v.push(([dx, dy, dz], l as f32));
                }
            }
        }
    }
    v
}

/// The flat index of voxel `i` moved by offset `o`, or `None` when that leaves the grid `dims`.
#[inline]
pub fn step(dims: [usize; 3], i: usize, o: &[i64; 3]) -> Option<usize> {
    let (x, y, z) = (
        (i % dims[0]) as i64 + o[0],
        ((i / dims[0]) % dims[1]) as i64 + o[1],
        (i / (dims[0] * dims[1])) as i64 + o[2],
    );
    if x < 0 || y < 0 || z < 0 || x >= dims[0] as i64 || y >= dims[1] as i64 || z >= dims[2] as i64
    {
        return None;
    }
    Some(x as usize + dims[0] * (y as usize + dims[1] * z as usize))
}

/// The result of [`dijkstra`].
#[derive(Clone, Debug)]
pub struct ShortestPaths {
    /// Path cost from the start to every voxel (infinite when not reached).
    pub dist: Vec<f32>,
    /// Predecessor of every reached voxel on its shortest path (`u32::MAX` for the start and
    /// for unreached voxels).
    pub pred: Vec<u32>,
    /// Voxels in the order they were settled (non-decreasing `dist`).
    pub order: Vec<u32>,
}

impl ShortestPaths {
    /// The voxels of the shortest path from the start to `target`, start first; `None` when
    /// `target` was not reached.
    pub fn path_to(&self, target: usize) -> Option<Vec<usize>> {
        if !self.dist.get(target)?.is_finite() {
            return None;
        }
        let mut chain = vec![target];
        let mut v = target;
        while self.pred[v] != u32::MAX {
            v = self.pred[v] as usize;
            chain.push(v);
            if chain.len() > self.pred.len() {
                return None;
            }
        }
        chain.reverse();
        Some(chain)
    }
}

/// Dijkstra over the nonzero voxels of `mask` (grid `dims`, neighbour offsets `nb` from
/// [`neighbours`]) from `start`; `cost(a, b, len)` is the (non-negative) weight of the edge
/// from `a` to `b` of length `len` mm. Stops as soon as `stop` is settled.
pub fn dijkstra(
    mask: &[u8],
    dims: [usize; 3],
    nb: &[([i64; 3], f32)],
    start: usize,
    stop: Option<usize>,
    cost: impl Fn(usize, usize, f32) -> f32,
) -> ShortestPaths {
    let n = mask.len();
    let mut dist = vec![f32::INFINITY; n];
    let mut pred = vec![u32::MAX; n];
    let mut order = Vec::new();
    let mut heap = BinaryHeap::new();
    dist[start] = 0.0;
    heap.push(Reverse((0u32, start as u32)));
    while let Some(Reverse((dbits, v))) = heap.pop() {
        let v = v as usize;
        let d = f32::from_bits(dbits);
        if d > dist[v] {
            continue;
        }
        order.push(v as u32);
        if Some(v) == stop {
            break;
        }
        for (o, len) in nb {
            if let Some(u) = step(dims, v, o) {
                if mask[u] == 0 {
                    continue;
                }
                let nd = d + cost(v, u, *len);
                if nd < dist[u] {
                    dist[u] = nd;
                    pred[u] = v as u32;
                    // Non-negative f32 bits order like the floats themselves.
                    heap.push(Reverse((nd.to_bits(), u as u32)));
                }
            }
        }
    }
    ShortestPaths { dist, pred, order }
}

/// Distance (mm) from every voxel of `mask` to the nearest voxel outside it (0 outside).
pub fn inside_distance(mask: &Volume<u8>) -> Vec<f32> {
    distance_transform_sq(mask.dims, mask.spacing(), |i| mask.data[i] == 0)
        .into_iter()
        .map(f32::sqrt)
        .collect()
}

/// The centred path (flat voxel indices, `start` first) from `start` to `target` through the
/// nonzero voxels of `mask`, with edge cost `length / (dt + 0.5)²`; `dt_inside_mm` is the
/// distance of every voxel to the wall (mm, from [`inside_distance`]). Errors when either end
/// is outside the mask or the two are not connected.
pub fn centred_path(
    mask: &Volume<u8>,
    dt_inside_mm: &[f32],
    start: usize,
    target: usize,
) -> Result<Vec<usize>> {
    let n = mask.len();
    if dt_inside_mm.len() != n {
        return Err(VolumeError::DataLength {
            got: dt_inside_mm.len(),
            dims: mask.dims,
        }
        .into());
    }
    for (what, v) in [("start", start), ("target", target)] {
        if v >= n || mask.data[v] == 0 {
            return Err(VolumeError::OutsideMask { what, voxel: v }.into());
        }
    }
    let nb = neighbours(mask.spacing());
    let sp = dijkstra(
        &mask.data,
        mask.dims,
        &nb,
        start,
        Some(target),
        |a, b, l| {
            let d = 0.5 * (dt_inside_mm[a] + dt_inside_mm[b]) + 0.5;
            l / (d * d)
        },
    );
    sp.path_to(target)
        .ok_or_else(|| VolumeError::NotConnected { start, target }.into())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::math::Affine;

    /// An L-shaped tube of square cross-section 7x7 voxels (1 mm): the centred path from one
    /// end to the other keeps to the middle (3 voxels from the wall), the plain shortest path
    /// cuts the inner corner.
    #[test]
    fn centred_path_keeps_to_the_middle_of_an_l_tube() {
        let dims = [40, 40, 9];
        let mut m = Volume::filled(dims, Affine::identity(), 0u8);
        for z in 1..8 {
            for a in 1..39 {
                for b in 1..8 {
                    m.set(a, b, z, 1); // along x at y 1..7
                    m.set(b, a, z, 1); // along y at x 1..7
                }
            }
        }
        let dt = inside_distance(&m);
        let start = m.index(35, 4, 4);
        let target = m.index(4, 35, 4);
        let path = centred_path(&m, &dt, start, target).unwrap();
        assert_eq!((path[0], *path.last().unwrap()), (start, target));
        let min_dt = path.iter().map(|&v| dt[v]).fold(f32::INFINITY, f32::min);
        assert!(
            min_dt >= 3.0,
            "centred path comes {min_dt} mm near the wall"
        );
        let nb = neighbours(m.spacing());
        let plain = dijkstra(&m.data, dims, &nb, start, Some(target), |_, _, l| l);
        let cut = plain.path_to(target).unwrap();
        let plain_min = cut.iter().map(|&v| dt[v]).fold(f32::INFINITY, f32::min);
        assert!(plain_min <= 1.0, "shortest path keeps {plain_min} mm");
        // Consecutive voxels are 26-neighbours.
        for w in path.windows(2) {
            let d: Vec<i64> = (0..3)
                .map(|k| {
                    let c = |i: usize| [i % 40, (i / 40) % 40, i / 1600][k] as i64;
                    (c(w[0]) - c(w[1])).abs()
                })
                .collect();
            assert!(d.iter().all(|&x| x <= 1) && d.contains(&1));
        }
        // Not connected: a separate blob.
        m.set(20, 20, 4, 1);
        let e = centred_path(&m, &dt, start, m.index(20, 20, 4));
        assert!(e.is_err());
        assert!(centred_path(&m, &dt, start, m.index(30, 30, 4)).is_err());
    }
}
