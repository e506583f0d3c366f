//! The AVX2 kernels of packet traversal ([`super::packet`]): eight-wide node tests and the
//! triangle test of eight rays against one triangle per step. Only used on x86_64 after AVX2
//! was detected at run time.
#![cfg(target_arch = "x86_64")]

use super::bvh::{Node, RawHit, FAR_SCALE};
use super::packet::{per_ray, Best, Packet, PacketOps, HALVES, PACKET};
use super::triangle::{edges_f64, Tri4};

/// AVX2 version (eight children per node); only constructed after AVX2 was detected.
#[cfg(target_arch = "x86_64")]
pub(super) struct Avx;

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
                let (near, far) = if p.ilo[a] < 0.0 {
                    (3 + a, a)
                } else {
                    (a, 3 + a)
                };
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
        let mut mask = 0;
        for h in 0..HALVES {
            // SAFETY: as above; the loads read eight floats inside [f32; PACKET] arrays.
            unsafe {
                let mut tn = _mm256_setzero_ps();
                let mut tf = _mm256_set1_ps(f32::INFINITY);
                for a in 0..3 {
                    let inv = _mm256_loadu_ps(p.inv[a].as_ptr().add(8 * h));
                    let t0 = _mm256_mul_ps(_mm256_set1_ps(b[a] - p.org[a]), inv);
                    let t1 = _mm256_mul_ps(_mm256_set1_ps(b[3 + a] - p.org[a]), inv);
                    tn = _mm256_max_ps(tn, _mm256_min_ps(t0, t1));
                    tf = _mm256_min_ps(tf, _mm256_max_ps(t0, t1));
                }
                let tf = _mm256_min_ps(
                    _mm256_mul_ps(tf, _mm256_set1_ps(FAR_SCALE)),
                    _mm256_loadu_ps(tbest.as_ptr().add(8 * h)),
                );
                mask |= (_mm256_movemask_ps(_mm256_cmp_ps::<_CMP_LE_OQ>(tn, tf)) as u32) << (8 * h);
            }
        }
        mask
    }

    /// Eight rays against one triangle per step, when the rays share their axis permutation:
    /// per lane the same operations in the same order as [`intersect4`], so the results are
    /// bit-identical; taking the triangles in lane order with a strict `t < best` keeps
    /// intersect4's choice among equal distances.
    #[inline(always)]
    fn leaf(&self, p: &Packet, tri: &Tri4, rays: u32, tb: &mut Best) -> bool {
        let mut changed = false;
        for h in 0..HALVES {
            let group = rays & (0xff << (8 * h));
            if group == 0 {
                continue;
            }
            changed |= if !p.same_k[h] || group.count_ones() < 3 {
                per_ray(p, tri, group, tb)
            } else {
                avx_leaf8(p, tri, h, group >> (8 * h), tb)
            };
        }
        changed
    }
}

/// The eight rays of group `h` whose bits are set in `rays` against the triangles of `tri`
/// (see [`Avx::leaf`]); they must share their axis permutation.
#[cfg(target_arch = "x86_64")]
#[inline(always)]
fn avx_leaf8(p: &Packet, tri: &Tri4, h: usize, rays: u32, tb: &mut Best) -> bool {
    {
        use std::arch::x86_64::*;
        let [kx, ky, kz] = p.shear[8 * h].k;
        let o = p.org;
        let mut changed = false;
        // SAFETY: as above; the loads read whole [f32; 8] arrays.
        unsafe {
            let (sx, sy, sz) = (
                _mm256_loadu_ps(p.s[0].as_ptr().add(8 * h)),
                _mm256_loadu_ps(p.s[1].as_ptr().add(8 * h)),
                _mm256_loadu_ps(p.s[2].as_ptr().add(8 * h)),
            );
            let zero = _mm256_setzero_ps();
            for j in 0..4 {
                // Padding lanes repeat the last triangle: nothing new after the first repeat.
                if j > 0 && tri.id[j] == tri.id[j - 1] {
                    break;
                }
                let c = |i: usize, k: usize| tri.v[i][k].as_array_ref()[j] - o[k];
                let (az, bz, cz) = (
                    _mm256_set1_ps(c(0, kz)),
                    _mm256_set1_ps(c(1, kz)),
                    _mm256_set1_ps(c(2, kz)),
                );
                let e = |i: usize, k: usize, s: __m256, z: __m256| {
                    _mm256_sub_ps(_mm256_set1_ps(c(i, k)), _mm256_mul_ps(s, z))
                };
                let (ax, ay) = (e(0, kx, sx, az), e(0, ky, sy, az));
                let (bx, by) = (e(1, kx, sx, bz), e(1, ky, sy, bz));
                let (cx, cy) = (e(2, kx, sx, cz), e(2, ky, sy, cz));
                let mut u = _mm256_sub_ps(_mm256_mul_ps(cx, by), _mm256_mul_ps(cy, bx));
                let mut v = _mm256_sub_ps(_mm256_mul_ps(ax, cy), _mm256_mul_ps(ay, cx));
                let mut w = _mm256_sub_ps(_mm256_mul_ps(bx, ay), _mm256_mul_ps(by, ax));
                let zmask = _mm256_movemask_ps(_mm256_or_ps(
                    _mm256_or_ps(
                        _mm256_cmp_ps::<_CMP_EQ_OQ>(u, zero),
                        _mm256_cmp_ps::<_CMP_EQ_OQ>(v, zero),
                    ),
                    _mm256_cmp_ps::<_CMP_EQ_OQ>(w, zero),
                )) as u32
                    & rays;
                if zmask != 0 {
                    // Rare: a ray through an edge or vertex; redo those lanes in f64.
                    let arr = |x: __m256| {
                        let mut a = [0f32; 8];
                        _mm256_storeu_ps(a.as_mut_ptr(), x);
                        a
                    };
                    let (axa, aya, bxa, bya, cxa, cya) =
                        (arr(ax), arr(ay), arr(bx), arr(by), arr(cx), arr(cy));
                    let (mut ua, mut va, mut wa) = (arr(u), arr(v), arr(w));
                    let mut m = zmask;
                    while m != 0 {
                        let r = m.trailing_zeros() as usize;
                        m &= m - 1;
                        (ua[r], va[r], wa[r]) =
                            edges_f64(axa[r], aya[r], bxa[r], bya[r], cxa[r], cya[r]);
                    }
                    u = _mm256_loadu_ps(ua.as_ptr());
                    v = _mm256_loadu_ps(va.as_ptr());
                    w = _mm256_loadu_ps(wa.as_ptr());
                }
                let lt = |x: __m256| _mm256_cmp_ps::<_CMP_LT_OQ>(x, zero);
                let gt = |x: __m256| _mm256_cmp_ps::<_CMP_GT_OQ>(x, zero);
                let any_neg = _mm256_or_ps(_mm256_or_ps(lt(u), lt(v)), lt(w));
                let any_pos = _mm256_or_ps(_mm256_or_ps(gt(u), gt(v)), gt(w));
                let det = _mm256_add_ps(_mm256_add_ps(u, v), w);
                let ts = _mm256_add_ps(
                    _mm256_add_ps(
                        _mm256_mul_ps(u, _mm256_mul_ps(sz, az)),
                        _mm256_mul_ps(v, _mm256_mul_ps(sz, bz)),
                    ),
                    _mm256_mul_ps(w, _mm256_mul_ps(sz, cz)),
                );
                let t = _mm256_div_ps(ts, det);
                let inside = _mm256_andnot_ps(_mm256_and_ps(any_neg, any_pos), gt(t));
                let ok = _mm256_and_ps(
                    inside,
                    _mm256_cmp_ps::<_CMP_LT_OQ>(t, _mm256_loadu_ps(tb.t.as_ptr().add(8 * h))),
                );
                let mut m = _mm256_movemask_ps(ok) as u32 & rays;
                if m == 0 {
                    continue;
                }
                let mut ta = [0f32; 8];
                let mut da = [0f32; 8];
                let mut va = [0f32; 8];
                let mut wa = [0f32; 8];
                _mm256_storeu_ps(ta.as_mut_ptr(), t);
                _mm256_storeu_ps(da.as_mut_ptr(), det);
                _mm256_storeu_ps(va.as_mut_ptr(), v);
                _mm256_storeu_ps(wa.as_mut_ptr(), w);
                while m != 0 {
                    let r = m.trailing_zeros() as usize;
                    m &= m - 1;
                    tb.t[8 * h + r] = ta[r];
                    tb.hit[8 * h + r] = Some(RawHit {
                        t: ta[r],
                        tri: tri.id[j],
                        u: va[r] / da[r],
                        v: wa[r] / da[r],
                    });
                }
                changed = true;
            }
        }
        changed
    }
}
