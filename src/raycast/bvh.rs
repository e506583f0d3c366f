//! A wide BVH (W = 4 or 8 child boxes per node, tested at once with SIMD) whose leaves are
//! one or more consecutive blocks of four triangles ([`Tri4`]), and its closest-hit and
//! any-hit traversal.
//!
//! W = 8 uses AVX (256-bit) box tests and is chosen at run time when the CPU has AVX2;
//! W = 4 uses SSE through `wide` and runs everywhere. Built by [`super::bvh_build`].

use super::triangle::{intersect4, ShearedRay, Tri4};
use std::mem::MaybeUninit;
use wide::{f32x4, CmpLe};

/// Child handle: an inner node index, a leaf with [`LEAF`] set, or [`EMPTY`]. A leaf handle
/// holds the index of its first [`Tri4`] block in the low [`LEAF_SHIFT`] bits and the number of
/// blocks minus one in the bits above.
pub(crate) const LEAF: u32 = 1 << 31;
/// Bit position of a leaf's block count.
pub(crate) const LEAF_SHIFT: u32 = 28;
/// Most blocks in one leaf.
pub(crate) const LEAF_BLOCKS: usize = 8;

/// The blocks of leaf handle `h`.
#[inline(always)]
pub(crate) fn leaf_blocks(h: u32) -> std::ops::Range<usize> {
    let first = (h & ((1 << LEAF_SHIFT) - 1)) as usize;
    first..first + ((h >> LEAF_SHIFT) & (LEAF_BLOCKS as u32 - 1)) as usize + 1
}
/// An unused child slot (its box is empty so it is never entered).
pub(crate) const EMPTY: u32 = u32::MAX;
/// Traversal stack entries; the build rejects trees that could overflow it.
pub(crate) const STACK: usize = 256;

/// One BVH node: the boxes of W children in structure-of-arrays form.
#[derive(Clone, Copy, Debug)]
#[repr(C, align(64))]
pub(crate) struct Node<const W: usize> {
    /// `b[0..3]` = min x, y, z; `b[3..6]` = max x, y, z (mm), one lane per child.
    pub b: [[f32; W]; 6],
    /// Child handles.
    pub child: [u32; W],
}

/// The acceleration structure: nodes, triangle blocks and the root node (always index 0).
#[derive(Clone, Debug, Default)]
pub struct Bvh<const W: usize> {
    pub(crate) nodes: Vec<Node<W>>,
    pub(crate) leaves: Vec<Tri4>,
}

/// A ray prepared for traversal: origin, reciprocal direction, near/far plane selectors, shear.
#[derive(Clone, Copy)]
pub(crate) struct TravRay {
    /// For axis a: which of `b` holds the near plane, and the far plane.
    near: [usize; 3],
    far: [usize; 3],
    inv: [f32; 3],
    shear: ShearedRay,
}

/// Robust box test factor (Ize 2013): far distances are inflated by 1 + 2γ(3) so that rounding
/// never culls a box the ray touches.
pub(crate) const FAR_SCALE: f32 =
    1.0 + 2.0 * 3.0 * f32::EPSILON * 0.5 / (1.0 - 3.0 * f32::EPSILON * 0.5);

impl TravRay {
    #[inline(always)]
    fn new(org: [f32; 3], dir: [f32; 3]) -> Self {
        let mut inv = [0.0; 3];
        let mut near = [0; 3];
        let mut far = [0; 3];
        for a in 0..3 {
            // A zero component becomes a tiny one so that (box - org) * inv never makes 0 * inf.
            let d = if dir[a] == 0.0 {
                1e-30f32.copysign(dir[a])
            } else {
                dir[a]
            };
            inv[a] = 1.0 / d;
            let neg = (d < 0.0) as usize;
            near[a] = a + 3 * neg;
            far[a] = a + 3 * (1 - neg);
        }
        TravRay {
            near,
            far,
            inv,
            shear: ShearedRay::new(org, dir),
        }
    }
}

/// Box tests of one node: entry distances and the mask of children entered before `tmax`.
trait BoxTest<const W: usize> {
    fn boxes(&self, n: &Node<W>, tmax: f32) -> ([f32; W], u32);
}

/// SSE box test of four children.
struct Sse {
    ray: TravRay,
    org: [f32x4; 3],
    inv: [f32x4; 3],
}

impl BoxTest<4> for Sse {
    #[inline(always)]
    fn boxes(&self, n: &Node<4>, tmax: f32) -> ([f32; 4], u32) {
        // (b - o) * inv, not b * inv - o * inv: its rounding error is relative to t (Ize 2013).
        let t = |p: usize, a: usize| (f32x4::from(n.b[p]) - self.org[a]) * self.inv[a];
        let r = &self.ray;
        let tn = t(r.near[0], 0)
            .fast_max(t(r.near[1], 1))
            .fast_max(t(r.near[2], 2));
        let tf = t(r.far[0], 0)
            .fast_min(t(r.far[1], 1))
            .fast_min(t(r.far[2], 2));
        let tn = tn.fast_max(f32x4::splat(0.0));
        let tf = (tf * f32x4::splat(FAR_SCALE)).fast_min(f32x4::splat(tmax));
        (tn.to_array(), tn.cmp_le(tf).move_mask() as u32)
    }
}

/// AVX box test of eight children (only constructed after AVX2 was detected).
#[cfg(target_arch = "x86_64")]
struct Avx {
    ray: TravRay,
    org: [std::arch::x86_64::__m256; 3],
    inv: [std::arch::x86_64::__m256; 3],
}

#[cfg(target_arch = "x86_64")]
impl BoxTest<8> for Avx {
    #[inline(always)]
    fn boxes(&self, n: &Node<8>, tmax: f32) -> ([f32; 8], u32) {
        use std::arch::x86_64::*;
        // SAFETY: Avx is only built inside functions compiled with AVX2 after detection; the
        // loads read whole [f32; 8] arrays.
        unsafe {
            let t = |p: usize, a: usize| {
                _mm256_mul_ps(
                    _mm256_sub_ps(_mm256_loadu_ps(n.b[p].as_ptr()), self.org[a]),
                    self.inv[a],
                )
            };
            let r = &self.ray;
            let tn = _mm256_max_ps(
                _mm256_max_ps(t(r.near[0], 0), t(r.near[1], 1)),
                t(r.near[2], 2),
            );
            let tf = _mm256_min_ps(
                _mm256_min_ps(t(r.far[0], 0), t(r.far[1], 1)),
                t(r.far[2], 2),
            );
            let tn = _mm256_max_ps(tn, _mm256_setzero_ps());
            let tf = _mm256_min_ps(
                _mm256_mul_ps(tf, _mm256_set1_ps(FAR_SCALE)),
                _mm256_set1_ps(tmax),
            );
            let mask = _mm256_movemask_ps(_mm256_cmp_ps::<_CMP_LE_OQ>(tn, tf)) as u32;
            let mut out = [0f32; 8];
            _mm256_storeu_ps(out.as_mut_ptr(), tn);
            (out, mask)
        }
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

impl<const W: usize> Bvh<W> {
    /// Hint the cache to load a child (node or leaf) that traversal will visit soon.
    #[inline(always)]
    fn prefetch(&self, h: u32) {
        #[cfg(target_arch = "x86_64")]
        unsafe {
            use std::arch::x86_64::{_mm_prefetch, _MM_HINT_T0};
            let (p, lines) = if h & LEAF == 0 {
                (self.nodes.as_ptr().add(h as usize) as *const i8, W / 2)
            } else {
                let b = leaf_blocks(h);
                (
                    self.leaves.as_ptr().add(b.start) as *const i8,
                    (b.len() * std::mem::size_of::<Tri4>()).div_ceil(64),
                )
            };
            // SAFETY: prefetch never faults; the handle indexes an existing node or leaf.
            for l in 0..lines {
                _mm_prefetch::<_MM_HINT_T0>(p.add(64 * l));
            }
        }
    }

    #[inline(always)]
    fn closest_in<B: BoxTest<W>>(&self, bt: &B, ray: &TravRay, tmax: f32) -> Option<RawHit> {
        let mut best: Option<RawHit> = None;
        let mut tbest = tmax;
        let mut stack: [MaybeUninit<(u32, f32)>; STACK] = [MaybeUninit::uninit(); STACK];
        let mut sp = 0usize;
        let mut node = 0u32;
        loop {
            // Descend: always into the nearest child, pushing the others far-to-near.
            while node & LEAF == 0 {
                let n = &self.nodes[node as usize];
                let (tn, mask) = bt.boxes(n, tbest);
                if mask == 0 {
                    node = EMPTY;
                    break;
                }
                if mask & (mask - 1) == 0 {
                    node = n.child[mask.trailing_zeros() as usize];
                    continue;
                }
                // Two or more: insertion sort of the entered children, far → near.
                let mut c = [(0u32, 0f32); W];
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
                for &e in &c[..k - 1] {
                    self.prefetch(e.0);
                    stack[sp] = MaybeUninit::new(e);
                    sp += 1;
                }
                node = c[k - 1].0;
                self.prefetch(node);
            }
            if node != EMPTY {
                for tri in &self.leaves[leaf_blocks(node)] {
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
            }
            // Pop the next entry that can still hold a nearer hit.
            loop {
                if sp == 0 {
                    return best;
                }
                sp -= 1;
                // SAFETY: entries below sp were written by the pushes above.
                let (h, d) = unsafe { stack[sp].assume_init() };
                if d <= tbest {
                    node = h;
                    break;
                }
            }
        }
    }

    #[inline(always)]
    fn any_in<B: BoxTest<W>>(&self, bt: &B, ray: &TravRay, tmax: f32) -> bool {
        let mut stack: [MaybeUninit<u32>; STACK] = [MaybeUninit::uninit(); STACK];
        let mut sp = 0usize;
        let mut node = 0u32;
        loop {
            while node & LEAF == 0 {
                let n = &self.nodes[node as usize];
                let (_, mut mask) = bt.boxes(n, tmax);
                if mask == 0 {
                    node = EMPTY;
                    break;
                }
                node = n.child[mask.trailing_zeros() as usize];
                mask &= mask - 1;
                while mask != 0 {
                    stack[sp] = MaybeUninit::new(n.child[mask.trailing_zeros() as usize]);
                    sp += 1;
                    mask &= mask - 1;
                }
            }
            if node != EMPTY
                && self.leaves[leaf_blocks(node)]
                    .iter()
                    .any(|tri| intersect4(&ray.shear, tri, tmax).is_some())
            {
                return true;
            }
            if sp == 0 {
                return false;
            }
            sp -= 1;
            // SAFETY: entries below sp were written above.
            node = unsafe { stack[sp].assume_init() };
        }
    }
}

impl Bvh<4> {
    fn sse(org: [f32; 3], dir: [f32; 3]) -> (Sse, TravRay) {
        let ray = TravRay::new(org, dir);
        let bt = Sse {
            ray,
            org: org.map(f32x4::splat),
            inv: ray.inv.map(f32x4::splat),
        };
        (bt, ray)
    }

    /// Nearest hit with `0 < t < tmax` along `org + t dir`.
    pub fn closest_hit(&self, org: [f32; 3], dir: [f32; 3], tmax: f32) -> Option<RawHit> {
        if self.leaves.is_empty() {
            return None;
        }
        let (bt, ray) = Self::sse(org, dir);
        self.closest_in(&bt, &ray, tmax)
    }

    /// True when any triangle is hit with `0 < t < tmax` (visibility / shadow query).
    pub fn any_hit(&self, org: [f32; 3], dir: [f32; 3], tmax: f32) -> bool {
        if self.leaves.is_empty() {
            return false;
        }
        let (bt, ray) = Self::sse(org, dir);
        self.any_in(&bt, &ray, tmax)
    }
}

#[cfg(target_arch = "x86_64")]
impl Bvh<8> {
    #[inline(always)]
    unsafe fn avx(org: [f32; 3], dir: [f32; 3]) -> (Avx, TravRay) {
        use std::arch::x86_64::_mm256_set1_ps;
        let ray = TravRay::new(org, dir);
        let bt = Avx {
            ray,
            org: org.map(|x| _mm256_set1_ps(x)),
            inv: ray.inv.map(|x| _mm256_set1_ps(x)),
        };
        (bt, ray)
    }

    /// Nearest hit with `0 < t < tmax`.
    ///
    /// # Safety
    /// The CPU must support AVX2 (checked by the caller with `is_x86_feature_detected!`).
    #[target_feature(enable = "avx2")]
    pub unsafe fn closest_hit(&self, org: [f32; 3], dir: [f32; 3], tmax: f32) -> Option<RawHit> {
        if self.leaves.is_empty() {
            return None;
        }
        let (bt, ray) = Self::avx(org, dir);
        self.closest_in(&bt, &ray, tmax)
    }

    /// True when any triangle is hit with `0 < t < tmax`.
    ///
    /// # Safety
    /// The CPU must support AVX2.
    #[target_feature(enable = "avx2")]
    pub unsafe fn any_hit(&self, org: [f32; 3], dir: [f32; 3], tmax: f32) -> bool {
        if self.leaves.is_empty() {
            return false;
        }
        let (bt, ray) = Self::avx(org, dir);
        self.any_in(&bt, &ray, tmax)
    }
}
