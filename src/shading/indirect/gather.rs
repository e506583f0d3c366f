//! The once-reflected light of the light at the lens, gathered at surface points by casting
//! cosine-weighted hemisphere rays into the lumen mesh.
//!
//! A point y of the wall that the camera at c would see shows the intensity
//! `alb(y) rho(gamma_y) s(theta_y) / |y - c|^2` (the calibrated light's direct term, camera units
//! at the reference gain): for a Lambertian wall that is its radiance toward every direction,
//! so it is also the radiance it sends to any other point x of the wall. The irradiance x
//! receives from all of them, over pi, is the mean of that radiance over cosine-weighted
//! directions around x's normal (the pi of the cosine-weighted pdf cancels the pi of the
//! Lambertian BRDF):
//!
//! `E(x) = mean over K rays x -> y of alb(y) rho(gamma_y) s(theta_y) / |y - c|^2 [V(y, c)]`.
//!
//! E is in the units of the direct term, so a pixel seeing x predicts
//! `g alb(x) (rho s / z^2 + k E(x))` with k the mean absolute albedo of the wall (the fraction of
//! the light a bounce keeps; the fit adjusts it per channel, and it absorbs the second and
//! later bounces). Rays that leave through the mesh's open ends bring nothing.
//!
//! Beyond the largest off-axis angle the fit saw, the light's profile `s` is unknown; the wall
//! beside the camera lies there and, being near, weighs much in E. The profile is tapered
//! linearly in cos theta from its edge value to 0 at 90° off the axis (a lens-mounted light
//! sends nothing backward; the phantom's cone is cos theta there, issue 18's Mitsuba spot is 0
//! beyond 70°).

// `!(x > t)` on floats is deliberate: it also rejects NaN.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

use rayon::prelude::*;

use crate::raycast::Scene;
use crate::render::MipTexture;
use crate::rng::Pcg32;
use crate::shading::calibrated::CalibratedModel;

/// How the light is gathered.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GatherOptions {
    /// Rays per point, rounded up to a square (stratified m x m over the hemisphere).
    pub rays: usize,
    /// Test the visibility of each hit point from the light (one shadow ray each). In a tube
    /// nearly every wall point a bounce reaches is seen by the light too.
    pub visibility: bool,
    /// Seed of the jitter; the same point gets the same rays in every gather.
    pub seed: u64,
}

impl Default for GatherOptions {
    fn default() -> Self {
        GatherOptions {
            rays: 36,
            visibility: false,
            seed: 0x1d1ec7,
        }
    }
}

/// The albedo of the wall at a hit point, relative to its mean (the mean is folded into rho).
pub trait SurfaceAlbedo: Sync {
    /// Relative albedo per channel at barycentrics (u, v) of triangle `tri`.
    fn albedo(&self, tri: u32, u: f32, v: f32) -> [f32; 3];
}

/// A uniform wall (relative albedo 1).
pub struct UniformAlbedo;

impl SurfaceAlbedo for UniformAlbedo {
    fn albedo(&self, _tri: u32, _u: f32, _v: f32) -> [f32; 3] {
        [1.0; 3]
    }
}

/// The albedo of a fused texture, divided by its mean per channel (so the direct term's rho
/// keeps the mean albedo, as in the fit).
pub struct TextureAlbedo<'a> {
    texture: &'a MipTexture,
    tri_uv: &'a [[[f32; 2]; 3]],
    inv_mean: [f32; 3],
}

impl<'a> TextureAlbedo<'a> {
    /// The albedo of `texture`, whose triangle `t` has UV corners `tri_uv[t]`. The mean is taken
    /// over the texels that hold something (non-zero), on a 128 x 128 grid of the atlas.
    pub fn new(texture: &'a MipTexture, tri_uv: &'a [[[f32; 2]; 3]]) -> TextureAlbedo<'a> {
        let n = 128;
        let (mut sum, mut count) = ([0f64; 3], [0usize; 3]);
        for j in 0..n {
            for i in 0..n {
                let a = texture
                    .sample_bilinear((i as f32 + 0.5) / n as f32, (j as f32 + 0.5) / n as f32);
                for c in 0..3 {
                    if a[c] > 0.0 {
                        sum[c] += f64::from(a[c]);
                        count[c] += 1;
                    }
                }
            }
        }
        let inv_mean = std::array::from_fn(|c| {
            let m = sum[c] / count[c].max(1) as f64;
            if m > 0.0 {
                (1.0 / m) as f32
            } else {
                1.0
            }
        });
        TextureAlbedo {
            texture,
            tri_uv,
            inv_mean,
        }
    }
}

impl SurfaceAlbedo for TextureAlbedo<'_> {
    fn albedo(&self, tri: u32, u: f32, v: f32) -> [f32; 3] {
        let Some([a, b, c]) = self.tri_uv.get(tri as usize) else {
            return [1.0; 3];
        };
        let w = 1.0 - u - v;
        let tu = w * a[0] + u * b[0] + v * c[0];
        let tv = w * a[1] + u * b[1] + v * c[1];
        let s = self.texture.sample_bilinear(tu, tv);
        std::array::from_fn(|k| (s[k] * self.inv_mean[k]).max(0.0))
    }
}

/// The light at the lens: where it is and which way it points (world mm, unit axis).
#[derive(Debug, Clone, Copy)]
pub struct LensLight<'a> {
    /// The fitted light (rho and s; gains and inter-reflection terms are not used).
    pub model: &'a CalibratedModel,
    /// The camera centre (world mm).
    pub centre: [f64; 3],
    /// The optical axis (world, unit).
    pub axis: [f64; 3],
}

impl LensLight<'_> {
    /// The light's profile at `cos_theta` off the axis, tapered beyond the fitted edge (see the
    /// module documentation). Unitless, >= 0.
    pub fn profile(&self, cos_theta: f64) -> f64 {
        let m = self.model;
        let edge = m.cos_theta_edge;
        let s = if cos_theta >= edge || edge <= 0.0 {
            m.s(cos_theta)
        } else {
            m.s(edge) * cos_theta.max(0.0) / edge
        };
        s.max(0.0)
    }

    /// The intensity per channel a unit-albedo wall point `y` with normal `n` (either side)
    /// shows the camera: `rho(gamma) s(theta) / r^2` (reference gain), and the distance r (mm).
    /// `None` when `y` is at the lens.
    pub fn lit(&self, y: [f64; 3], n: [f64; 3]) -> Option<([f64; 3], f64)> {
        let d = sub(y, self.centre);
        let r = norm(d);
        if !(r > 1e-6) {
            return None;
        }
        let gamma = (dot(n, d) / r).abs().min(1.0);
        let cos_theta = dot(self.axis, d) / r;
        let k = self.profile(cos_theta) / (r * r);
        Some((
            std::array::from_fn(|c| self.model.rho(c, gamma).max(0.0) * k),
            r,
        ))
    }
}

/// The gathered light `E` (per channel, camera units at the reference gain) at every point
/// `points[i]` with normal `normals[i]` (either orientation: the side facing the light is
/// used), parallel over points. `point_ids[i]` seeds each point's rays.
pub fn gather_points(
    scene: &Scene,
    light: &LensLight,
    albedo: &dyn SurfaceAlbedo,
    points: &[[f32; 3]],
    normals: &[[f32; 3]],
    point_ids: &[u64],
    opts: &GatherOptions,
) -> Vec<[f32; 3]> {
    points
        .par_iter()
        .zip(normals.par_iter())
        .zip(point_ids.par_iter())
        .with_min_len(8)
        .map(|((p, n), &id)| gather_one(scene, light, albedo, *p, *n, id, opts))
        .collect()
}

/// [`gather_points`] at one point.
pub fn gather_one(
    scene: &Scene,
    light: &LensLight,
    albedo: &dyn SurfaceAlbedo,
    p: [f32; 3],
    n: [f32; 3],
    id: u64,
    opts: &GatherOptions,
) -> [f32; 3] {
    let x = p.map(f64::from);
    let mut nx = n.map(f64::from);
    let ln = norm(nx);
    if !(ln > 0.0) {
        return [0.0; 3];
    }
    nx = nx.map(|v| v / ln);
    // The lit side faces the light.
    if dot(nx, sub(light.centre, x)) < 0.0 {
        nx = nx.map(|v| -v);
    }
    let (t1, t2) = basis(nx);
    let m = (opts.rays.max(1) as f64).sqrt().ceil() as usize;
    let mut rng = Pcg32::new(opts.seed, id);
    // An offset along the normal keeps the rays off their own triangle (mm).
    let eps = 1e-3;
    let org = [0, 1, 2].map(|k| (x[k] + eps * nx[k]) as f32);
    let mut acc = [0f64; 3];
    for a in 0..m {
        for b in 0..m {
            let u1 = (a as f64 + rng.uniform()) / m as f64;
            let u2 = (b as f64 + rng.uniform()) / m as f64;
            // Malley's method: uniform on the disc, lifted to the hemisphere.
            let r = u1.sqrt();
            let phi = std::f64::consts::TAU * u2;
            let (lx, ly, lz) = (r * phi.cos(), r * phi.sin(), (1.0 - u1).max(0.0).sqrt());
            let d = [0, 1, 2].map(|k| lx * t1[k] + ly * t2[k] + lz * nx[k]);
            let df = d.map(|v| v as f32);
            let Some(hit) = scene.closest_hit(org, df, f32::INFINITY) else {
                continue;
            };
            let y = [0, 1, 2].map(|k| f64::from(org[k]) + f64::from(hit.t) * d[k]);
            let ny = scene.shading_normal(hit.tri, hit.u, hit.v).map(f64::from);
            // The side of y that x sees must be the side the light reaches.
            let to_c = sub(light.centre, y);
            if dot(ny, to_c) * dot(ny, sub(x, y)) <= 0.0 {
                continue;
            }
            let Some((rad, dist)) = light.lit(y, ny) else {
                continue;
            };
            if opts.visibility {
                let side = dot(ny, to_c).signum();
                let o = [0, 1, 2].map(|k| (y[k] + side * eps * ny[k]) as f32);
                let dir = to_c.map(|v| (v / dist) as f32);
                if scene.any_hit(o, dir, (dist - 2.0 * eps) as f32) {
                    continue;
                }
            }
            let alb = albedo.albedo(hit.tri, hit.u, hit.v);
            for c in 0..3 {
                acc[c] += f64::from(alb[c]) * rad[c];
            }
        }
    }
    let k = 1.0 / (m * m) as f64;
    acc.map(|v| (v * k) as f32)
}

fn sub(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

fn dot(a: [f64; 3], b: [f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

fn norm(a: [f64; 3]) -> f64 {
    dot(a, a).sqrt()
}

/// Two unit vectors completing the unit `n` to an orthonormal basis (Duff et al. 2017).
fn basis(n: [f64; 3]) -> ([f64; 3], [f64; 3]) {
    let s = if n[2] >= 0.0 { 1.0 } else { -1.0 };
    let a = -1.0 / (s + n[2]);
    let b = n[0] * n[1] * a;
    (
        [1.0 + s * n[0] * n[0] * a, s * b, -s * n[0]],
        [b, s + n[1] * n[1] * a, -n[1]],
    )
}
