//! Coherent packet traversal: eight rays from one origin (a tile of camera pixels) walk the
//! wide BVH together.
//!
//! Inner nodes are tested once for the whole packet with interval arithmetic: per axis the
//! packet's reciprocal directions span `[ilo, ihi]`, so the earliest possible entry into a child
//! box is `max_a min((near_a - o_a)·ilo_a, (near_a - o_a)·ihi_a)` and the latest possible exit
//! `min_a max((far_a - o_a)·ilo_a, (far_a - o_a)·ihi_a)`. Because rounding is monotone, these are
//! exactly the smallest entry and the largest exit any single ray of the packet computes in
//! [`super::bvh`], so a box is never culled that one of the rays would have entered. An axis on
//! which the packet's directions change sign gives no bound and is skipped.
//!
//! Leaves are tested per ray: the leaf's box against the eight rays at once (one SIMD lane per
//! ray, the same arithmetic as the single-ray box test), then the watertight four-triangle test
//! for each ray that enters it before its current nearest hit. Every ray therefore tests a
//! superset of the leaves single-ray traversal tests and gets the same nearest hit (the same
//! triangle unless two triangles tie at exactly the same distance).

use super::bvh::{Bvh, Node, RawHit, EMPTY, FAR_SCALE, LEAF, STACK};
use super::triangle::{intersect4, ShearedRay};
use std::mem::MaybeUninit;
use wide::{f32x4, f32x8, CmpLe};

/// Rays per packet.
pub(crate) const PACKET: usize = 8;

/// Eight rays with a common origin, prepared for traversal.
#[derive(Clone, Copy)]
pub(crate) struct Packet {
    org: [f32; 3],
    /// Reciprocal direction per axis, one lane per ray (zero components made tiny as in
    /// single-ray traversal).
    inv: [[f32; PACKET]; 3],
    /// Smallest and largest reciprocal direction of the packet per axis.
    ilo: [f32; 3],
    ihi: [f32; 3],
    /// Axes on which the directions change sign (no interval bound).
    mixed: [bool; 3],
    shear: [ShearedRay; PACKET],
}

impl Packet {
    /// Rays from `org` along `dirs` (1 to 8 of them; missing lanes repeat the first ray).
    #[inline(always)]
    pub(crate) fn new(org: [f32; 3], dirs: &[[f32; 3]]) -> Packet {
        debug_assert!(!dirs.is_empty() && dirs.len() <= PACKET);
        let mut inv = [[0f32; PACKET]; 3];
        let mut shear = [ShearedRay::new(org, dirs[0]); PACKET];
        for r in 0..PACKET {
            let d = dirs[if r < dirs.len() { r } else { 0 }];
            for a in 0..3 {
                // As TravRay::new: a zero component becomes a tiny one of the same sign.
                let c = if d[a] == 0.0 {
                    1e-30f32.copysign(d[a])
                } else {
                    d[a]
                };
                inv[a][r] = 1.0 / c;
            }
            if r > 0 {
                shear[r] = ShearedRay::new(org, d);
            }
        }
        let mut ilo = [0f32; 3];
        let mut ihi = [0f32; 3];
        let mut mixed = [false; 3];
        for a in 0..3 {
            ilo[a] = inv[a].iter().copied().fold(f32::INFINITY, f32::min);
            ihi[a] = inv[a].iter().copied().fold(f32::NEG_INFINITY, f32::max);
            mixed[a] = ilo[a] < 0.0 && ihi[a] > 0.0;
        }
        Packet {
            org,
            inv,
            ilo,
            ihi,
            mixed,
            shear,
        }
    }
}

/// The SIMD parts of packet traversal for W-wide nodes.
trait PacketOps<const W: usize> {
    /// Interval test of the W children for the whole packet: the packet's earliest entry
    /// distance per child and the mask of children some ray may enter before `tmax`.
    fn node(&self, p: &Packet, n: &Node<W>, tmax: f32) -> ([f32; W], u32);
    /// Per-ray test of one box `[min xyz, max xyz]`: mask of the rays that enter it before
    /// their own `tbest`.
    fn rays(&self, p: &Packet, b: [f32; 6], tbest: &[f32; PACKET]) -> u32;
}

/// Portable version: SSE through `wide` (four children per node).
struct Portable;

impl PacketOps<4> for Portable {
    #[inline(always)]
    fn node(&self, p: &Packet, n: &Node<4>, tmax: f32) -> ([f32; 4], u32) {
        let mut tn = f32x4::splat(0.0);
        let mut tf = f32x4::splat(f32::INFINITY);
        for a in 0..3 {
            if p.mixed[a] {
                continue;
            }
            let (near, far) = if p.ilo[a] < 0.0 { (3 + a, a) } else { (a, 3 + a) };
            let o = f32x4::splat(p.org[a]);
            let (lo, hi) = (f32x4::splat(p.ilo[a]), f32x4::splat(p.ihi[a]));
            let dn = f32x4::from(n.b[near]) - o;
            let df = f32x4::from(n.b[far]) - o;
            tn = tn.fast_max((dn * lo).fast_min(dn * hi));
            tf = tf.fast_min((df * lo).fast_max(df * hi));
        }
        let tf = (tf * f32x4::splat(FAR_SCALE)).fast_min(f32x4::splat(tmax));
        (tn.to_array(), tn.cmp_le(tf).move_mask() as u32)
    }

    #[inline(always)]
    fn rays(&self, p: &Packet, b: [f32; 6], tbest: &[f32; PACKET]) -> u32 {
        let mut tn = f32x8::splat(0.0);
        let mut tf = f32x8::splat(f32::INFINITY);
        for a in 0..3 {
            let inv = f32x8::from(p.inv[a]);
            let t0 = (f32x8::splat(b[a] - p.org[a])) * inv;
            let t1 = (f32x8::splat(b[3 + a] - p.org[a])) * inv;
            tn = tn.fast_max(t0.fast_min(t1));
            tf = tf.fast_min(t0.fast_max(t1));
        }
        let tf = (tf * f32x8::splat(FAR_SCALE)).fast_min(f32x8::from(*tbest));
        tn.cmp_le(tf).move_mask() as u32
    }
}

/// AVX2 version (eight children per node); only constructed after AVX2 was detected.
#[cfg(target_arch = "x86_64")]
struct Avx;

#[cfg(target_arch = "x86_64")]
impl PacketOps<8> for Avx {
    #[inline(always)]
    fn node(&self, p: &Packet, n: &Node<8>, tmax: f32) -> ([f32; 8], u32) {
        use std::arch::x86_64::*;
        // SAFETY: Avx only exists inside functions compiled with AVX2 after detection; the
        // loads read whole [f32; 8] arrays.
        unsafe {
            let mut tn = _mm256_setzero_ps();
            let mut tf = _mm256_set1_ps(f32::INFINITY);
            for a in 0..3 {
                if p.mixed[a] {
                    continue;
                }
                let (near, far) = if p.ilo[a] < 0.0 { (3 + a, a) } else { (a, 3 + a) };
                let o = _mm256_set1_ps(p.org[a]);
                let (lo, hi) = (_mm256_set1_ps(p.ilo[a]), _mm256_set1_ps(p.ihi[a]));
                let dn = _mm256_sub_ps(_mm256_loadu_ps(n.b[near].as_ptr()), o);
                let df = _mm256_sub_ps(_mm256_loadu_ps(n.b[far].as_ptr()), o);
                tn = _mm256_max_ps(
                    tn,
                    _mm256_min_ps(_mm256_mul_ps(dn, lo), _mm256_mul_ps(dn, hi)),
                );
                tf = _mm256_min_ps(
                    tf,
                    _mm256_max_ps(_mm256_mul_ps(df, lo), _mm256_mul_ps(df, hi)),
                );
            }
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

    #[inline(always)]
    fn rays(&self, p: &Packet, b: [f32; 6], tbest: &[f32; PACKET]) -> u32 {
        use std::arch::x86_64::*;
        // SAFETY: as above; the loads read whole [f32; 8] arrays.
        unsafe {
            let mut tn = _mm256_setzero_ps();
            let mut tf = _mm256_set1_ps(f32::INFINITY);
            for a in 0..3 {
                let inv = _mm256_loadu_ps(p.inv[a].as_ptr());
                let t0 = _mm256_mul_ps(_mm256_set1_ps(b[a] - p.org[a]), inv);
                let t1 = _mm256_mul_ps(_mm256_set1_ps(b[3 + a] - p.org[a]), inv);
                tn = _mm256_max_ps(tn, _mm256_min_ps(t0, t1));
                tf = _mm256_min_ps(tf, _mm256_max_ps(t0, t1));
            }
            let tf = _mm256_min_ps(
                _mm256_mul_ps(tf, _mm256_set1_ps(FAR_SCALE)),
                _mm256_loadu_ps(tbest.as_ptr()),
            );
            _mm256_movemask_ps(_mm256_cmp_ps::<_CMP_LE_OQ>(tn, tf)) as u32
        }
    }
}

impl<const W: usize> Bvh<W> {
    /// Nearest hits of the `valid` rays of packet `p` with `0 < t < tmax`.
    #[inline(always)]
    fn closest_packet<O: PacketOps<W>>(
        &self,
        ops: &O,
        p: &Packet,
        valid: u32,
        tmax: f32,
    ) -> [Option<RawHit>; PACKET] {
        let mut best: [Option<RawHit>; PACKET] = [None; PACKET];
        // Invalid lanes get a negative bound so that they never enter a leaf.
        let mut tbest: [f32; PACKET] =
            std::array::from_fn(|r| if valid >> r & 1 != 0 { tmax } else { -1.0 });
        let mut tpk = tmax;
        // Entries: (child handle, parent node * W + slot, packet entry distance).
        let mut stack: [MaybeUninit<(u32, u32, f32)>; STACK] = [MaybeUninit::uninit(); STACK];
        let mut sp = 0usize;
        let mut node = 0u32;
        let mut slot = 0u32;
        loop {
            while node & LEAF == 0 {
                let n = &self.nodes[node as usize];
                let (tn, mut mask) = ops.node(p, n, tpk);
                // All axes of a packet can change sign (arbitrary directions): the interval
                // test then bounds nothing, so unused slots are skipped here.
                for (j, &c) in n.child.iter().enumerate() {
                    if c == EMPTY {
                        mask &= !(1 << j);
                    }
                }
                if mask == 0 {
                    node = EMPTY;
                    break;
                }
                let base = node * W as u32;
                if mask & (mask - 1) == 0 {
                    let j = mask.trailing_zeros();
                    node = n.child[j as usize];
                    slot = base + j;
                    continue;
                }
                // Two or more: insertion sort far → near, push all but the nearest.
                let mut c = [(0u32, 0u32, 0f32); W];
                let mut k = 0;
                let mut m = mask;
                while m != 0 {
                    let j = m.trailing_zeros() as usize;
                    m &= m - 1;
                    let e = (n.child[j], base + j as u32, tn[j]);
                    let mut i = k;
                    while i > 0 && c[i - 1].2 < e.2 {
                        c[i] = c[i - 1];
                        i -= 1;
                    }
                    c[i] = e;
                    k += 1;
                }
                for &e in &c[..k - 1] {
                    stack[sp] = MaybeUninit::new(e);
                    sp += 1;
                }
                (node, slot) = (c[k - 1].0, c[k - 1].1);
            }
            if node != EMPTY {
                let parent = &self.nodes[slot as usize / W];
                let j = slot as usize % W;
                let b = std::array::from_fn(|i| parent.b[i][j]);
                let mut rays = ops.rays(p, b, &tbest) & valid;
                if rays != 0 {
                    let tri = &self.leaves[(node & !LEAF) as usize];
                    let mut changed = false;
                    while rays != 0 {
                        let r = rays.trailing_zeros() as usize;
                        rays &= rays - 1;
                        if let Some((lane, t, u, v)) = intersect4(&p.shear[r], tri, tbest[r]) {
                            tbest[r] = t;
                            best[r] = Some(RawHit {
                                t,
                                tri: tri.id[lane],
                                u,
                                v,
                            });
                            changed = true;
                        }
                    }
                    if changed {
                        tpk = tbest.iter().copied().fold(f32::NEG_INFINITY, f32::max);
                    }
                }
            }
            loop {
                if sp == 0 {
                    return best;
                }
                sp -= 1;
                // SAFETY: entries below sp were written by the pushes above.
                let (h, s, d) = unsafe { stack[sp].assume_init() };
                if d <= tpk {
                    (node, slot) = (h, s);
                    break;
                }
            }
        }
    }

    /// Trace `dirs` from `org` in packets of eight, writing the nearest hits to `out`.
    #[inline(always)]
    fn packets_with<O: PacketOps<W>>(
        &self,
        ops: &O,
        org: [f32; 3],
        dirs: &[[f32; 3]],
        tmax: f32,
        out: &mut [Option<RawHit>],
    ) {
        for (d, o) in dirs.chunks(PACKET).zip(out.chunks_mut(PACKET)) {
            if self.leaves.is_empty() {
                o.fill(None);
                continue;
            }
            let p = Packet::new(org, d);
            let valid = (1u32 << d.len()) - 1;
            let h = self.closest_packet(ops, &p, valid, tmax);
            o.copy_from_slice(&h[..d.len()]);
        }
    }
}

impl Bvh<4> {
    /// Nearest hits with `0 < t < tmax` of the rays `org + t dirs[i]`, traced in packets of
    /// eight consecutive rays (coherent rays, e.g. a row of pixels, trace fastest).
    /// `out.len()` must equal `dirs.len()`.
    pub fn closest_hits_packets(
        &self,
        org: [f32; 3],
        dirs: &[[f32; 3]],
        tmax: f32,
        out: &mut [Option<RawHit>],
    ) {
        self.packets_with(&Portable, org, dirs, tmax, out)
    }
}

#[cfg(target_arch = "x86_64")]
impl Bvh<8> {
    /// As [`Bvh::<4>::closest_hits_packets`], eight-wide with AVX2.
    ///
    /// # Safety
    /// The CPU must support AVX2 (checked by the caller with `is_x86_feature_detected!`).
    #[target_feature(enable = "avx2")]
    pub unsafe fn closest_hits_packets(
        &self,
        org: [f32; 3],
        dirs: &[[f32; 3]],
        tmax: f32,
        out: &mut [Option<RawHit>],
    ) {
        self.packets_with(&Avx, org, dirs, tmax, out)
    }
}
