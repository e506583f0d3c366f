//! Smoothing and gradients of a CT: the surface normals the CT holds at a finer scale than
//! the decimated lumen mesh (issue 18 item 2).

use super::Volume;
use crate::math::{Point3, Vector3};
use rayon::prelude::*;

/// Separable Gaussian blur in place with `sigma` voxels along each grid axis (0 leaves that
/// axis alone), edges clamped.
pub fn gaussian_blur(v: &mut Volume<f32>, sigma: [f64; 3]) {
    let [nx, ny, _] = v.dims;
    let strides = [1usize, nx, nx * ny];
    for (axis, &stride) in strides.iter().enumerate() {
        if sigma[axis] <= 0.0 {
            continue;
        }
        let kern = kernel(sigma[axis]);
        let r = (kern.len() / 2) as i64;
        let n = v.dims[axis];
        let src = v.data.clone();
        // Every voxel reads its line in `src`: independent, so parallel over slices.
        v.data
            .par_chunks_mut(nx * ny)
            .enumerate()
            .for_each(|(k, out)| {
                for j in 0..ny {
                    for i in 0..nx {
                        let c = [i, j, k][axis] as i64;
                        let base = i + nx * (j + ny * k) - c as usize * stride;
                        let mut acc = 0.0;
                        for (t, &w) in kern.iter().enumerate() {
                            let p = (c + t as i64 - r).clamp(0, n as i64 - 1) as usize;
                            acc += w * src[base + p * stride];
                        }
                        out[i + nx * j] = acc;
                    }
                }
            });
    }
}

/// Separable Gaussian blur with `sigma_mm` in world millimetres (the grid's spacing per axis).
pub fn gaussian_blur_mm(v: &mut Volume<f32>, sigma_mm: f64) {
    let s = v.spacing();
    gaussian_blur(v, std::array::from_fn(|a| sigma_mm / s[a].max(1e-9)));
}

/// Normalised Gaussian kernel of `sigma` samples, radius 3 sigma.
fn kernel(sigma: f64) -> Vec<f32> {
    let r = (3.0 * sigma).ceil() as i64;
    let mut k: Vec<f32> = (-r..=r)
        .map(|x| (-(x * x) as f64 / (2.0 * sigma * sigma)).exp() as f32)
        .collect();
    let s: f32 = k.iter().sum();
    k.iter_mut().for_each(|w| *w /= s);
    k
}

/// The world-space gradient (HU per mm) of the trilinearly interpolated volume at `xyz`, by
/// central differences of half a voxel along each grid axis; `None` near or outside the grid.
pub fn gradient_world(v: &Volume<f32>, xyz: Point3<f64>) -> Option<Vector3<f64>> {
    let p = v.world_to_index(xyz);
    let h = 0.5;
    let mut g_index = Vector3::zeros();
    for a in 0..3 {
        let mut e = Vector3::zeros();
        e[a] = h;
        let hi = f64::from(v.sample_index(p + e)?);
        let lo = f64::from(v.sample_index(p - e)?);
        g_index[a] = (hi - lo) / (2.0 * h);
    }
    // index = A^-1 (world - t): d/dworld = A^-T d/dindex.
    let a = v.affine.fixed_view::<3, 3>(0, 0).into_owned();
    let inv = a.try_inverse()?;
    let g = inv.transpose() * g_index;
    g.iter().all(|x| x.is_finite()).then_some(g)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::math::Affine;

    /// A linear ramp on an anisotropic, rotated grid: the gradient is the ramp's, in world
    /// units; a blur keeps a linear ramp as it is away from the edges.
    #[test]
    fn gradient_of_a_ramp_in_world_units() {
        let mut affine = Affine::identity();
        // Axes: x 0.7 mm, y 0.7 mm along -y world, z 1.2 mm.
        affine[(0, 0)] = 0.7;
        affine[(1, 1)] = -0.7;
        affine[(2, 2)] = 1.2;
        affine[(0, 3)] = -5.0;
        let dims = [20, 20, 20];
        let ramp = Vector3::new(3.0, -2.0, 5.0);
        let mut v = Volume::filled(dims, affine, 0.0f32);
        for k in 0..20 {
            for j in 0..20 {
                for i in 0..20 {
                    let w = v.index_to_world(Point3::new(i as f64, j as f64, k as f64));
                    v.set(i, j, k, ramp.dot(&w.coords) as f32);
                }
            }
        }
        gaussian_blur_mm(&mut v, 1.0);
        let at = v.index_to_world(Point3::new(10.3, 9.6, 10.1));
        let g = gradient_world(&v, at).unwrap();
        assert!((g - ramp).norm() < 1e-3 * ramp.norm(), "{g:?}");
        assert!(gradient_world(&v, v.index_to_world(Point3::new(19.9, 5.0, 5.0))).is_none());
    }
}
