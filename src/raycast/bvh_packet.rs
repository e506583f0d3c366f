//! Packet traversal: P rays walk the BVH together, for coherent rays (neighbouring camera
//! pixels). Each node is fetched once for the packet and the P box tests are independent, so
//! they overlap in the pipeline instead of waiting on one ray's chain of memory loads.

use super::bvh::{BoxTest, Bvh, RawHit, TravRay, EMPTY, LEAF, STACK};
use super::triangle::intersect4;
use std::mem::MaybeUninit;

/// Rays per packet.
pub(crate) const P: usize = 8;

/// A stack entry: a node and each ray's entry distance (+inf for rays that do not enter it).
#[derive(Clone, Copy)]
struct Entry {
    node: u32,
    tn: [f32; P],
}

impl<const W: usize> Bvh<W> {
    /// Closest hits of P rays; `bt[r]`/`rays[r]` prepared per ray; `tmax` per ray.
    #[inline(always)]
    pub(super) fn closest_packet<B: BoxTest<W>>(
        &self,
        bt: &[B; P],
        rays: &[TravRay; P],
        tmax: [f32; P],
    ) -> [Option<RawHit>; P] {
        let mut best = [None; P];
        let mut tbest = tmax;
        let mut stack: [MaybeUninit<Entry>; STACK] = [MaybeUninit::uninit(); STACK];
        stack[0] = MaybeUninit::new(Entry { node: 0, tn: [0.0; P] });
        let mut sp = 1usize;
        while sp > 0 {
            sp -= 1;
            // SAFETY: entries below sp were written by the pushes.
            let e = unsafe { stack[sp].assume_init() };
            let mut active = 0u32;
            for r in 0..P {
                active |= ((e.tn[r] <= tbest[r]) as u32) << r;
            }
            if active == 0 || e.node == EMPTY {
                continue;
            }
            if e.node & LEAF != 0 {
                let tri = &self.leaves[(e.node & !LEAF) as usize];
                let mut m = active;
                while m != 0 {
                    let r = m.trailing_zeros() as usize;
                    m &= m - 1;
                    if let Some((lane, t, u, v)) = intersect4(&rays[r].shear, tri, tbest[r]) {
                        tbest[r] = t;
                        best[r] = Some(RawHit { t, tri: tri.id[lane], u, v });
                    }
                }
                continue;
            }
            let n = &self.nodes[e.node as usize];
            let mut ctn = [[f32::INFINITY; P]; W];
            let mut key = [f32::INFINITY; W];
            let mut any = 0u32;
            let mut m = active;
            while m != 0 {
                let r = m.trailing_zeros() as usize;
                m &= m - 1;
                let (tn, mask) = bt[r].boxes(n, tbest[r]);
                any |= mask;
                for j in 0..W {
                    if mask & (1 << j) != 0 {
                        ctn[j][r] = tn[j];
                        key[j] = key[j].min(tn[j]);
                    }
                }
            }
            // Push entered children far → near so the nearest (by any ray) is popped first.
            let mut c = [(0usize, 0f32); W];
            let mut k = 0;
            let mut mm = any;
            while mm != 0 {
                let j = mm.trailing_zeros() as usize;
                mm &= mm - 1;
                let mut i = k;
                while i > 0 && c[i - 1].1 < key[j] {
                    c[i] = c[i - 1];
                    i -= 1;
                }
                c[i] = (j, key[j]);
                k += 1;
            }
            for &(j, _) in &c[..k] {
                self.prefetch(n.child[j]);
                stack[sp] = MaybeUninit::new(Entry { node: n.child[j], tn: ctn[j] });
                sp += 1;
            }
        }
        best
    }
}

impl Bvh<4> {
    /// Closest hits of a packet of P rays (coherent rays profit; any rays are correct).
    pub fn closest_hit_packet(
        &self,
        org: &[[f32; 3]; P],
        dir: &[[f32; 3]; P],
        tmax: f32,
    ) -> [Option<RawHit>; P] {
        if self.leaves.is_empty() {
            return [None; P];
        }
        let prepared: [_; P] = std::array::from_fn(|r| Self::sse(org[r], dir[r]));
        let bt: [_; P] = std::array::from_fn(|r| prepared[r].0);
        let rays: [_; P] = std::array::from_fn(|r| prepared[r].1);
        self.closest_packet(&bt, &rays, [tmax; P])
    }
}

#[cfg(target_arch = "x86_64")]
impl Bvh<8> {
    /// Closest hits of a packet of P rays.
    ///
    /// # Safety
    /// The CPU must support AVX2.
    #[target_feature(enable = "avx2")]
    pub unsafe fn closest_hit_packet(
        &self,
        org: &[[f32; 3]; P],
        dir: &[[f32; 3]; P],
        tmax: f32,
    ) -> [Option<RawHit>; P] {
        if self.leaves.is_empty() {
            return [None; P];
        }
        let prepared: [_; P] = std::array::from_fn(|r| Self::avx(org[r], dir[r]));
        let bt: [_; P] = std::array::from_fn(|r| prepared[r].0);
        let rays: [_; P] = std::array::from_fn(|r| prepared[r].1);
        self.closest_packet(&bt, &rays, [tmax; P])
    }
}
