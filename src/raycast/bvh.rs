//! A 4-wide BVH (four child boxes per node, tested at once with SSE through `wide`) whose leaves
//! are blocks of four triangles ([`Tri4`]), and its closest-hit and any-hit traversal.
//!
//! Built by [`super::bvh_build`]: binned SAH on a binary tree, collapsed to four-wide nodes.

use super::triangle::{intersect4, ShearedRay, Tri4};
use wide::{f32x4, CmpLe};

/// Child handle: an inner node index, a leaf block index with [`LEAF`] set, or [`EMPTY`].
pub(crate) const LEAF: u32 = 1 << 31;
/// An unused child slot (its box is empty so it is never entered).
pub(crate) const EMPTY: u32 = u32::MAX;

/// One BVH node: the boxes of four children in structure-of-arrays form.
#[derive(Clone, Copy, Debug)]
#[repr(C, align(64))]
pub(crate) struct Node4 {
    /// `b[0..3]` = min x, y, z; `b[3..6]` = max x, y, z (mm), one lane per child.
    pub b: [f32x4; 6],
    /// Child handles.
    pub child: [u32; 4],
}

/// The acceleration structure: nodes, triangle blocks and the root handle.
#[derive(Clone, Debug, Default)]
pub struct Bvh4 {
    pub(crate) nodes: Vec<Node4>,
    pub(crate) leaves: Vec<Tri4>,
    pub(crate) root: u32,
}

/// A ray prepared for traversal: reciprocal direction, near-plane selectors and shear.
#[derive(Clone, Copy)]
struct TravRay {
    /// For axis a: which of `b` holds the near plane, and the far plane.
    near: [usize; 3],
    far: [usize; 3],
    inv: [f32x4; 3],
    org: [f32x4; 3],
    shear: ShearedRay,
}

/// Robust box test factor (Ize 2013): far distances are inflated by 1 + 2γ(3) so that rounding
/// never culls a box the ray touches.
const FAR_SCALE: f32 = 1.0 + 2.0 * 3.0 * f32::EPSILON * 0.5 / (1.0 - 3.0 * f32::EPSILON * 0.5);

impl TravRay {
    #[inline(always)]
    fn new(org: [f32; 3], dir: [f32; 3]) -> Self {
        let mut inv = [f32x4::splat(0.0); 3];
        let mut org4 = [f32x4::splat(0.0); 3];
        let mut near = [0; 3];
        let mut far = [0; 3];
        for a in 0..3 {
            // A zero component becomes a tiny one so that (box - org) * inv never makes 0 * inf.
            let d = if dir[a] == 0.0 {
                1e-30f32.copysign(dir[a])
            } else {
                dir[a]
            };
            let i = 1.0 / d;
            inv[a] = f32x4::splat(i);
            org4[a] = f32x4::splat(org[a]);
            let neg = (d < 0.0) as usize;
            near[a] = a + 3 * neg;
            far[a] = a + 3 * (1 - neg);
        }
        TravRay {
            near,
            far,
            inv,
            org: org4,
            shear: ShearedRay::new(org, dir),
        }
    }

    /// Entry distances of the four child boxes and the mask of those entered before `tmax`.
    #[inline(always)]
    fn boxes(&self, n: &Node4, tmax: f32) -> (f32x4, i32) {
        // (b - o) * inv, not b * inv - o * inv: its rounding error is relative to t (Ize 2013).
        let t = |p: usize, a: usize| (n.b[p] - self.org[a]) * self.inv[a];
        let tn = t(self.near[0], 0)
            .fast_max(t(self.near[1], 1))
            .fast_max(t(self.near[2], 2));
        let tf = t(self.far[0], 0)
            .fast_min(t(self.far[1], 1))
            .fast_min(t(self.far[2], 2));
        let tn = tn.fast_max(f32x4::splat(0.0));
        let tf = (tf * f32x4::splat(FAR_SCALE)).fast_min(f32x4::splat(tmax));
        (tn, tn.cmp_le(tf).move_mask())
    }
}

/// A closest hit inside the BVH: distance, original triangle id, barycentrics of v1 and v2.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RawHit {
    /// Ray parameter (mm for a unit direction).
    pub t: f32,
    /// Triangle index in the input mesh.
    pub tri: u32,
    /// Barycentric weight of the triangle's second vertex.
    pub u: f32,
    /// Barycentric weight of the triangle's third vertex.
    pub v: f32,
}

const STACK: usize = 64;

impl Bvh4 {
    /// Hint the cache to load a child (node or leaf) that traversal will visit soon.
    #[inline(always)]
    fn prefetch(&self, h: u32) {
        #[cfg(target_arch = "x86_64")]
        unsafe {
            use std::arch::x86_64::{_mm_prefetch, _MM_HINT_T0};
            let p = if h & LEAF == 0 {
                self.nodes.as_ptr().add(h as usize) as *const i8
            } else {
                self.leaves.as_ptr().add((h & !LEAF) as usize) as *const i8
            };
            // SAFETY: prefetch never faults; the handle indexes an existing node or leaf.
            _mm_prefetch::<_MM_HINT_T0>(p);
            _mm_prefetch::<_MM_HINT_T0>(p.add(64));
        }
    }
}

impl Bvh4 {
    /// Nearest hit with `0 < t < tmax` along `org + t dir`.
    pub fn closest_hit(&self, org: [f32; 3], dir: [f32; 3], tmax: f32) -> Option<RawHit> {
        if self.leaves.is_empty() {
            return None;
        }
        let ray = TravRay::new(org, dir);
        let mut best: Option<RawHit> = None;
        let mut tbest = tmax;
        let mut stack = [(0u32, 0f32); STACK];
        let mut sp = 0usize;
        let mut node = self.root;
        loop {
            // Descend: always into the nearest child, pushing the others far-to-near.
            while node & LEAF == 0 {
                let n = &self.nodes[node as usize];
                let (tn, mask) = ray.boxes(n, tbest);
                if mask == 0 {
                    node = EMPTY;
                    break;
                }
                let tn = tn.to_array();
                if mask & (mask - 1) == 0 {
                    node = n.child[mask.trailing_zeros() as usize];
                    continue;
                }
                // Two or more: sort the entered children by distance (at most 4, insertion sort).
                let mut c = [(0u32, 0f32); 4];
                let mut k = 0;
                let mut m = mask;
                while m != 0 {
                    let j = m.trailing_zeros() as usize;
                    m &= m - 1;
                    let e = (n.child[j], tn[j]);
                    let mut i = k;
                    while i > 0 && c[i - 1].1 < e.1 {
                        c[i] = c[i - 1];
                        i -= 1;
                    }
                    c[i] = e;
                    k += 1;
                }
                // c is sorted far→near: push all but the last, descend into the last.
                for &e in &c[..k - 1] {
                    self.prefetch(e.0);
                    stack[sp] = e;
                    sp += 1;
                }
                node = c[k - 1].0;
                self.prefetch(node);
            }
            if node != EMPTY {
                let tri = &self.leaves[(node & !LEAF) as usize];
                if let Some((lane, t, u, v)) = intersect4(&ray.shear, tri, tbest) {
                    tbest = t;
                    best = Some(RawHit {
                        t,
                        tri: tri.id[lane],
                        u,
                        v,
                    });
                }
            }
            // Pop the next entry that can still hold a nearer hit.
            loop {
                if sp == 0 {
                    return best;
                }
                sp -= 1;
                let (h, d) = stack[sp];
                if d <= tbest {
                    node = h;
                    break;
                }
            }
        }
    }

    /// True when any triangle is hit with `0 < t < tmax` (visibility / shadow query).
    pub fn any_hit(&self, org: [f32; 3], dir: [f32; 3], tmax: f32) -> bool {
        if self.leaves.is_empty() {
            return false;
        }
        let ray = TravRay::new(org, dir);
        let mut stack = [0u32; STACK];
        let mut sp = 0usize;
        let mut node = self.root;
        loop {
            while node & LEAF == 0 {
                let n = &self.nodes[node as usize];
                let (_, mut mask) = ray.boxes(n, tmax);
                if mask == 0 {
                    node = EMPTY;
                    break;
                }
                node = n.child[mask.trailing_zeros() as usize];
                mask &= mask - 1;
                while mask != 0 {
                    stack[sp] = n.child[mask.trailing_zeros() as usize];
                    sp += 1;
                    mask &= mask - 1;
                }
            }
            if node != EMPTY
                && intersect4(&ray.shear, &self.leaves[(node & !LEAF) as usize], tmax).is_some()
            {
                return true;
            }
            if sp == 0 {
                return false;
            }
            sp -= 1;
            node = stack[sp];
        }
    }
}
