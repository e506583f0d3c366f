//! Binary morphology on 0/1 masks with world-mm balls (anisotropic spacing respected).
//!
//! Dilation and erosion threshold an exact Euclidean distance transform (Felzenszwalb &
//! Huttenlocher's separable lower-envelope algorithm, weighted per axis by the spacing), so
//! their cost does not depend on the radius.

use super::region_grow::flood_fill;
use super::Volume;
use rayon::prelude::*;

/// Squared Euclidean distance (mm²) from every voxel to the nearest voxel where `feature`
/// is true; `f32::INFINITY` when there is none. Voxels outside the grid are not features.
pub fn distance_transform_sq(
    dims: [usize; 3],
    spacing: [f64; 3],
    feature: impl Fn(usize) -> bool + Sync,
) -> Vec<f32> {
    let [nx, ny, nz] = dims;
    let slice = nx * ny;
    let mut d: Vec<f32> = (0..nx * ny * nz)
        .into_par_iter()
        .map(|i| if feature(i) { 0.0 } else { f32::INFINITY })
        .collect();
    let w = spacing.map(|s| (s * s) as f32);
    // x and y passes are independent per slice.
    d.par_chunks_mut(slice).for_each(|s| {
        let mut buf = Scratch::new(nx.max(ny));
        for j in 0..ny {
            let line = &mut s[j * nx..(j + 1) * nx];
            buf.line[..nx].copy_from_slice(line);
            buf.transform(nx, w[0]);
            line.copy_from_slice(&buf.out[..nx]);
        }
        for i in 0..nx {
            for j in 0..ny {
                buf.line[j] = s[i + j * nx];
            }
            buf.transform(ny, w[1]);
            for j in 0..ny {
                s[i + j * nx] = buf.out[j];
            }
        }
    });
    // z pass: columns of one row j at a time, rows in parallel through a gathered copy.
    let cols: Vec<Vec<f32>> = (0..ny)
        .into_par_iter()
        .map(|j| {
            let mut buf = Scratch::new(nz);
            let mut out = vec![0f32; nx * nz];
            for i in 0..nx {
                for k in 0..nz {
                    buf.line[k] = d[i + j * nx + k * slice];
                }
                buf.transform(nz, w[2]);
                out[i * nz..(i + 1) * nz].copy_from_slice(&buf.out[..nz]);
            }
            out
        })
        .collect();
    for (j, out) in cols.iter().enumerate() {
        for i in 0..nx {
            for k in 0..nz {
                d[i + j * nx + k * slice] = out[i * nz + k];
            }
        }
    }
    d
}

/// Per-thread buffers of the 1-D lower-envelope transform.
struct Scratch {
    line: Vec<f32>,
    out: Vec<f32>,
    v: Vec<usize>,
    z: Vec<f32>,
}

impl Scratch {
    fn new(n: usize) -> Self {
        Scratch {
            line: vec![0.0; n],
            out: vec![0.0; n],
            v: vec![0; n],
            z: vec![0.0; n + 1],
        }
    }

    /// out[q] = min_p line[p] + w (q - p)², over the finite entries of `line`.
    fn transform(&mut self, n: usize, w: f32) {
        let f = &self.line;
        let mut k: isize = -1;
        for q in 0..n {
            if !f[q].is_finite() {
                continue;
            }
            loop {
                if k < 0 {
                    k = 0;
                    self.v[0] = q;
                    self.z[0] = f32::NEG_INFINITY;
                    self.z[1] = f32::INFINITY;
                    break;
                }
                let p = self.v[k as usize];
                let s = ((f[q] + w * (q * q) as f32) - (f[p] + w * (p * p) as f32))
                    / (2.0 * w * (q as f32 - p as f32));
                if s <= self.z[k as usize] {
                    k -= 1;
                    continue;
                }
                k += 1;
                self.v[k as usize] = q;
                self.z[k as usize] = s;
                self.z[k as usize + 1] = f32::INFINITY;
                break;
            }
        }
        if k < 0 {
            self.out[..n].fill(f32::INFINITY);
            return;
        }
        let mut j = 0usize;
        for q in 0..n {
            while self.z[j + 1] < q as f32 {
                j += 1;
            }
            let p = self.v[j];
            let dq = q as f32 - p as f32;
            self.out[q] = f[p] + w * dq * dq;
        }
    }
}

/// Dilation by a ball of `radius_mm`: voxels within that world distance of the mask.
pub fn dilate(mask: &Volume<u8>, radius_mm: f64) -> Volume<u8> {
    let m = &mask.data;
    let d = distance_transform_sq(mask.dims, mask.spacing(), |i| m[i] != 0);
    let r2 = (radius_mm * radius_mm) as f32 * (1.0 + 1e-5);
    mask_from(mask, d.par_iter().map(|&v| u8::from(v <= r2)).collect())
}

/// Erosion by a ball of `radius_mm`: voxels farther than that from the background. The
/// outside of the grid does not count as background (a tube leaving the grid stays open).
pub fn erode(mask: &Volume<u8>, radius_mm: f64) -> Volume<u8> {
    let m = &mask.data;
    let d = distance_transform_sq(mask.dims, mask.spacing(), |i| m[i] == 0);
    let r2 = (radius_mm * radius_mm) as f32 * (1.0 + 1e-5);
    mask_from(mask, d.par_iter().map(|&v| u8::from(v > r2)).collect())
}

/// Closing (dilation then erosion) by a ball of `radius_mm`: fills gaps and dents narrower
/// than the ball.
pub fn close(mask: &Volume<u8>, radius_mm: f64) -> Volume<u8> {
    erode(&dilate(mask, radius_mm), radius_mm)
}

/// Fill 3-D holes: background voxels not 6-connected to the grid's border become 1.
pub fn fill_holes(mask: &Volume<u8>) -> Volume<u8> {
    let [nx, ny, nz] = mask.dims;
    let m = &mask.data;
    let mut outside = vec![0u8; m.len()];
    let mut seeds = Vec::new();
    for k in 0..nz {
        for j in 0..ny {
            for i in 0..nx {
                let border =
                    i == 0 || j == 0 || k == 0 || i + 1 == nx || j + 1 == ny || k + 1 == nz;
                if border && m[i + nx * (j + ny * k)] == 0 {
                    seeds.push((i + nx * (j + ny * k)) as u32);
                }
            }
        }
    }
    flood_fill(
        mask.dims,
        &mut outside,
        &seeds,
        1,
        |i| m[i] == 0,
        None,
        usize::MAX,
    );
    mask_from(mask, outside.iter().map(|&o| 1 - o).collect())
}

/// The 6-connected component of the mask that contains `seed` (empty if the seed is not in it).
pub fn component_of(mask: &Volume<u8>, seed: [usize; 3]) -> Volume<u8> {
    let m = &mask.data;
    let mut out = vec![0u8; m.len()];
    let s = mask.index(seed[0], seed[1], seed[2]);
    flood_fill(
        mask.dims,
        &mut out,
        &[s as u32],
        1,
        |i| m[i] != 0,
        None,
        usize::MAX,
    );
    mask_from(mask, out)
}

fn mask_from(like: &Volume<u8>, data: Vec<u8>) -> Volume<u8> {
    Volume {
        dims: like.dims,
        affine: like.affine,
        data,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::math::Affine;

    fn aniso(dims: [usize; 3]) -> Affine {
        let mut a = Affine::identity();
        a[(0, 0)] = -0.5;
        a[(1, 1)] = -0.5;
        a[(2, 2)] = 1.25;
        let _ = dims;
        a
    }

    #[test]
    fn distance_transform_matches_brute_force_with_anisotropic_spacing() {
        let dims = [13, 11, 9];
        let mut r = crate::rng::Pcg32::new(5, 1);
        let feat: Vec<bool> = (0..dims[0] * dims[1] * dims[2])
            .map(|_| r.uniform() < 0.02)
            .collect();
        let sp = [0.5, 0.7, 1.25];
        let d = distance_transform_sq(dims, sp, |i| feat[i]);
        for k in 0..dims[2] {
            for j in 0..dims[1] {
                for i in 0..dims[0] {
                    let mut best = f64::INFINITY;
                    for (n, _) in feat.iter().enumerate().filter(|(_, &f)| f) {
                        let (a, b, c) = (
                            n % dims[0],
                            (n / dims[0]) % dims[1],
                            n / (dims[0] * dims[1]),
                        );
                        let e = ((i as f64 - a as f64) * sp[0]).powi(2)
                            + ((j as f64 - b as f64) * sp[1]).powi(2)
                            + ((k as f64 - c as f64) * sp[2]).powi(2);
                        best = best.min(e);
                    }
                    let got = d[i + dims[0] * (j + dims[1] * k)] as f64;
                    assert!(
                        (got - best).abs() < 1e-3 * (1.0 + best),
                        "({i},{j},{k}) {got} vs {best}"
                    );
                }
            }
        }
    }

    #[test]
    fn dilating_a_point_gives_an_anisotropic_ball_and_closing_fills_a_gap() {
        let dims = [21, 21, 11];
        let mut m = Volume::filled(dims, aniso(dims), 0u8);
        m.set(10, 10, 5, 1);
        let b = dilate(&m, 2.5);
        // Ball of 2.5 mm: 5 voxels along x (0.5 mm), 2 along z (1.25 mm).
        assert_eq!(b.get(15, 10, 5), 1);
        assert_eq!(b.get(16, 10, 5), 0);
        assert_eq!(b.get(10, 10, 7), 1);
        assert_eq!(b.get(10, 10, 8), 0);
        // A bar with a one-voxel gap is closed; a hole inside a cube is filled.
        let mut bar = Volume::filled(dims, aniso(dims), 0u8);
        for i in 3..18 {
            if i != 10 {
                for j in 8..13 {
                    bar.set(i, j, 5, 1);
                }
            }
        }
        let c = close(&bar, 1.0);
        assert_eq!(c.get(10, 10, 5), 1);
        assert_eq!(c.get(10, 5, 5), 0);
        let mut cube = Volume::filled(dims, aniso(dims), 0u8);
        for k in 2..9 {
            for j in 5..15 {
                for i in 5..15 {
                    cube.set(i, j, k, u8::from(!(i == 9 && j == 9 && k == 5)));
                }
            }
        }
        let f = fill_holes(&cube);
        assert_eq!(f.get(9, 9, 5), 1);
        assert_eq!(f.data.iter().filter(|&&v| v == 1).count(), 7 * 10 * 10);
    }
}
