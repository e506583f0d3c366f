//! Watertight ray–triangle intersection (Woop, Benthin, Wald, "Watertight Ray/Triangle
//! Intersection", JCGT 2013), two-sided, for one triangle and for four triangles at once.
//!
//! The ray is sheared so that it points along +z from the origin; the three edge functions are
//! then 2-D cross products of the sheared vertices. A shared edge gives bit-identical edge
//! functions of opposite sign in its two triangles, so a ray through the edge is never lost
//! between them. When an edge function is exactly zero it is recomputed in f64 (as the paper
//! does) so the sign decision is consistent.

use wide::{f32x4, CmpEq, CmpGt, CmpLt};

/// A ray prepared for the watertight test: the shear constants and the permuted origin.
#[derive(Clone, Copy, Debug)]
pub struct ShearedRay {
    /// Ray origin (mm).
    pub org: [f32; 3],
    /// Index of the dominant direction axis, and the two others (kx, ky, kz).
    pub k: [usize; 3],
    /// Shear constants `Sx = d[kx] / d[kz]`, `Sy = d[ky] / d[kz]`, `Sz = 1 / d[kz]`.
    pub s: [f32; 3],
}

impl ShearedRay {
    /// Prepare a ray with origin `org` (mm) and non-zero direction `dir`.
    #[inline]
    pub fn new(org: [f32; 3], dir: [f32; 3]) -> Self {
        let k = Self::axes(dir);
        Self::with_sz(org, dir, k, 1.0 / dir[k[2]])
    }

    /// As [`ShearedRay::new`] given the reciprocal direction `inv` (`inv[a] = 1 / dir[a]` where
    /// `dir[a] != 0`): saves the division, same result bit for bit.
    #[inline]
    pub(crate) fn with_inv(org: [f32; 3], dir: [f32; 3], inv: [f32; 3]) -> Self {
        let k = Self::axes(dir);
        let sz = if dir[k[2]] != 0.0 {
            inv[k[2]]
        } else {
            1.0 / dir[k[2]]
        };
        Self::with_sz(org, dir, k, sz)
    }

    /// The dominant axis kz of `dir` and the two others, ordered to keep the winding.
    #[inline(always)]
    fn axes(dir: [f32; 3]) -> [usize; 3] {
        let a = [dir[0].abs(), dir[1].abs(), dir[2].abs()];
        let kz = if a[0] > a[1] {
            if a[0] > a[2] {
                0
            } else {
                2
            }
        } else if a[1] > a[2] {
            1
        } else {
            2
        };
        let mut kx = (kz + 1) % 3;
        let mut ky = (kx + 1) % 3;
        // Keep the winding of the sheared triangle (matters only for the sign of det).
        if dir[kz] < 0.0 {
            std::mem::swap(&mut kx, &mut ky);
        }
        [kx, ky, kz]
    }

    #[inline(always)]
    fn with_sz(org: [f32; 3], dir: [f32; 3], k: [usize; 3], sz: f32) -> Self {
        ShearedRay {
            org,
            k,
            s: [dir[k[0]] * sz, dir[k[1]] * sz, sz],
        }
    }
}

/// Result of a single-triangle test: distance and barycentrics of v1 and v2.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TriHit {
    /// Ray parameter (mm when the direction is unit).
    pub t: f32,
    /// Barycentric weight of the triangle's second vertex.
    pub u: f32,
    /// Barycentric weight of the triangle's third vertex.
    pub v: f32,
}

/// Edge functions in f64, used when the f32 ones are exactly zero (paper, section 3).
#[inline(never)]
pub(crate) fn edges_f64(ax: f32, ay: f32, bx: f32, by: f32, cx: f32, cy: f32) -> (f32, f32, f32) {
    let (ax, ay, bx, by, cx, cy) = (
        ax as f64, ay as f64, bx as f64, by as f64, cx as f64, cy as f64,
    );
    (
        (cx * by - cy * bx) as f32,
        (ax * cy - ay * cx) as f32,
        (bx * ay - by * ax) as f32,
    )
}

/// Two-sided watertight test of one triangle; hits with `0 < t < tmax` are reported.
#[inline]
pub fn intersect(
    ray: &ShearedRay,
    v0: [f32; 3],
    v1: [f32; 3],
    v2: [f32; 3],
    tmax: f32,
) -> Option<TriHit> {
    let [kx, ky, kz] = ray.k;
    let [sx, sy, sz] = ray.s;
    let o = ray.org;
    let a = [v0[kx] - o[kx], v0[ky] - o[ky], v0[kz] - o[kz]];
    let b = [v1[kx] - o[kx], v1[ky] - o[ky], v1[kz] - o[kz]];
    let c = [v2[kx] - o[kx], v2[ky] - o[ky], v2[kz] - o[kz]];
    let (ax, ay) = (a[0] - sx * a[2], a[1] - sy * a[2]);
    let (bx, by) = (b[0] - sx * b[2], b[1] - sy * b[2]);
    let (cx, cy) = (c[0] - sx * c[2], c[1] - sy * c[2]);
    let mut u = cx * by - cy * bx;
    let mut v = ax * cy - ay * cx;
    let mut w = bx * ay - by * ax;
    if u == 0.0 || v == 0.0 || w == 0.0 {
        (u, v, w) = edges_f64(ax, ay, bx, by, cx, cy);
    }
    if (u < 0.0 || v < 0.0 || w < 0.0) && (u > 0.0 || v > 0.0 || w > 0.0) {
        return None;
    }
    let det = u + v + w;
    if det == 0.0 {
        return None;
    }
    let t_scaled = u * (sz * a[2]) + v * (sz * b[2]) + w * (sz * c[2]);
    let t = t_scaled / det;
    if !(t > 0.0 && t < tmax) {
        return None;
    }
    Some(TriHit {
        t,
        u: v / det,
        v: w / det,
    })
}

/// Four triangles in structure-of-arrays form: `v[vertex][axis]` holds one lane per triangle.
#[derive(Clone, Copy, Debug, Default)]
#[repr(C, align(16))]
pub struct Tri4 {
    /// Vertex coordinates (mm): `v[i][axis]`, lane j = triangle j.
    pub v: [[f32x4; 3]; 3],
    /// Original triangle index per lane (padding lanes repeat a real triangle).
    pub id: [u32; 4],
}

/// Two-sided watertight test of four triangles; returns the nearest lane hit with
/// `0 < t < tmax` as (lane, t, u, v).
#[inline(always)]
pub fn intersect4(ray: &ShearedRay, tri: &Tri4, tmax: f32) -> Option<(usize, f32, f32, f32)> {
    let [kx, ky, kz] = ray.k;
    let (ox, oy, oz) = (
        f32x4::splat(ray.org[kx]),
        f32x4::splat(ray.org[ky]),
        f32x4::splat(ray.org[kz]),
    );
    let (sx, sy, sz) = (
        f32x4::splat(ray.s[0]),
        f32x4::splat(ray.s[1]),
        f32x4::splat(ray.s[2]),
    );
    let az = tri.v[0][kz] - oz;
    let bz = tri.v[1][kz] - oz;
    let cz = tri.v[2][kz] - oz;
    let ax = (tri.v[0][kx] - ox) - sx * az;
    let ay = (tri.v[0][ky] - oy) - sy * az;
    let bx = (tri.v[1][kx] - ox) - sx * bz;
    let by = (tri.v[1][ky] - oy) - sy * bz;
    let cx = (tri.v[2][kx] - ox) - sx * cz;
    let cy = (tri.v[2][ky] - oy) - sy * cz;
    let mut u = cx * by - cy * bx;
    let mut v = ax * cy - ay * cx;
    let mut w = bx * ay - by * ax;
    let zero = f32x4::splat(0.0);
    let zmask = u.cmp_eq(zero) | v.cmp_eq(zero) | w.cmp_eq(zero);
    if zmask.any() {
        // Rare: a ray through an edge or vertex; redo those lanes in f64.
        let m = zmask.move_mask();
        let (axa, aya, bxa, bya, cxa, cya) = (
            ax.to_array(),
            ay.to_array(),
            bx.to_array(),
            by.to_array(),
            cx.to_array(),
            cy.to_array(),
        );
        let (mut ua, mut va, mut wa) = (u.to_array(), v.to_array(), w.to_array());
        for j in 0..4 {
            if m & (1 << j) != 0 {
                (ua[j], va[j], wa[j]) = edges_f64(axa[j], aya[j], bxa[j], bya[j], cxa[j], cya[j]);
            }
        }
        (u, v, w) = (f32x4::from(ua), f32x4::from(va), f32x4::from(wa));
    }
    let any_neg = u.cmp_lt(zero) | v.cmp_lt(zero) | w.cmp_lt(zero);
    let any_pos = u.cmp_gt(zero) | v.cmp_gt(zero) | w.cmp_gt(zero);
    let det = u + v + w;
    let t_scaled = u * (sz * az) + v * (sz * bz) + w * (sz * cz);
    let t = t_scaled / det;
    // NaN t (det == 0) fails both comparisons, so degenerate lanes drop out here.
    let ok = !(any_neg & any_pos) & t.cmp_gt(zero) & t.cmp_lt(f32x4::splat(tmax));
    let mask = ok.move_mask();
    if mask == 0 {
        return None;
    }
    let ta = t.to_array();
    let mut best = usize::MAX;
    let mut bt = tmax;
    for (j, &tj) in ta.iter().enumerate() {
        if mask & (1 << j) != 0 && tj < bt {
            bt = tj;
            best = j;
        }
    }
    let d = det.to_array()[best];
    Some((best, bt, v.to_array()[best] / d, w.to_array()[best] / d))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn tri4_of(tris: &[[[f32; 3]; 3]]) -> Tri4 {
        let mut t = Tri4::default();
        for (i, vert) in t.v.iter_mut().enumerate() {
            for (a, axis) in vert.iter_mut().enumerate() {
                let lanes: [f32; 4] = std::array::from_fn(|j| tris[j.min(tris.len() - 1)][i][a]);
                *axis = f32x4::from(lanes);
            }
        }
        t
    }

    #[test]
    fn hit_from_both_sides_with_barycentrics() {
        let (v0, v1, v2) = ([0.0, 0.0, 5.0], [1.0, 0.0, 5.0], [0.0, 1.0, 5.0]);
        let up = ShearedRay::new([0.25, 0.5, 0.0], [0.0, 0.0, 1.0]);
        let h = intersect(&up, v0, v1, v2, f32::INFINITY).unwrap();
        assert_eq!(h.t, 5.0);
        assert!((h.u - 0.25).abs() < 1e-6 && (h.v - 0.5).abs() < 1e-6);
        let down = ShearedRay::new([0.25, 0.5, 10.0], [0.0, 0.0, -1.0]);
        let h = intersect(&down, v0, v1, v2, f32::INFINITY).unwrap();
        assert_eq!(h.t, 5.0);
        assert!((h.u - 0.25).abs() < 1e-6 && (h.v - 0.5).abs() < 1e-6);
        // Behind the origin and beyond tmax are misses.
        assert!(intersect(&up, v0, v1, v2, 4.9).is_none());
        let away = ShearedRay::new([0.25, 0.5, 0.0], [0.0, 0.0, -1.0]);
        assert!(intersect(&away, v0, v1, v2, f32::INFINITY).is_none());
    }

    #[test]
    fn four_wide_matches_scalar() {
        let tris = [
            [[0.0, 0.0, 5.0], [1.0, 0.0, 5.0], [0.0, 1.0, 5.0]],
            [[0.0, 0.0, 3.0], [1.0, 0.0, 3.0], [0.0, 1.0, 3.0]],
            [[5.0, 5.0, 1.0], [6.0, 5.0, 1.0], [5.0, 6.0, 1.0]],
        ];
        let t4 = tri4_of(&tris);
        let r = ShearedRay::new([0.2, 0.3, 0.0], [0.01, 0.02, 1.0]);
        let (lane, t, u, v) = intersect4(&r, &t4, f32::INFINITY).unwrap();
        let s = intersect(&r, tris[1][0], tris[1][1], tris[1][2], f32::INFINITY).unwrap();
        assert_eq!(lane, 1);
        assert_eq!((t, u, v), (s.t, s.u, s.v));
    }
}
