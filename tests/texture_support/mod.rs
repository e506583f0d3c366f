//! A synthetic textured airway for the fusion tests and benchmark: the atlas-test airway mesh
//! with a known 3-D albedo (mucosa colour with dark vessel lines), frames rendered by ray
//! casting with a physically based light that is NOT Psi (co-located spot light with a cone,
//! inverse square, Lambert + GGX specular, 2x2 supersampling, per-frame auto-gain, noise,
//! clipping, 8-bit sRGB), and each frame's fitted Psi.

#![allow(dead_code)]
#![allow(clippy::needless_range_loop)]

#[path = "../common/airway_mesh.rs"]
pub mod airway_mesh;

#[path = "../common/physics.rs"]
mod physics;
use physics::brdf_cos;

use bronchosim::camera::Camera;
use bronchosim::image::srgb::{linear_to_srgb8, srgb8_to_linear_lut};
use bronchosim::image::Frame;
use bronchosim::math::{Affine, Vector3};
use bronchosim::raycast::{cast_frame_with, GBuffer, RayTable, Scene};
use bronchosim::shading::{
    density_weights, extract_samples, fit_psi, FitOptions, FrameShading, PsiModel, SampleOptions,
    WeightOptions,
};
use bronchosim::texture::atlas::{build_atlas, rasterize_texels, Atlas, AtlasOptions};
use bronchosim::texture::{Observation, TexelSet};
use rayon::prelude::*;

/// Mucosa albedo at a surface point (world mm): base colour, slow variation, vessel lines
/// (where two warped families of planes cut the wall; about 0.5 mm wide).
pub fn albedo(p: [f64; 3]) -> [f64; 3] {
    let base = [0.78, 0.40, 0.34];
    let slow = 1.0 + 0.08 * (0.15 * p[2] + 0.3 * p[0]).sin();
    let v1 = (0.5 * p[2] + 0.9 * (0.3 * p[0] + 0.2 * p[1]).sin())
        .sin()
        .abs();
    let v2 = (0.45 * p[0] + 0.35 * p[1] + 0.7 * (0.25 * p[2]).sin())
        .sin()
        .abs();
    let vessel = v1 < 0.12 || v2 < 0.1;
    let tint = if vessel { [0.5, 0.28, 0.36] } else { [1.0; 3] };
    std::array::from_fn(|c| base[c] * slow * tint[c])
}

pub use bronchosim::rng::SplitMix64 as Rng;

/// Camera → world looking along `forward` from `eye` (OpenCV axes, `down` a hint for +y).
pub fn look(eye: [f64; 3], forward: [f64; 3], down: [f64; 3]) -> Affine {
    let f = Vector3::from(forward).normalize();
    let x = Vector3::from(down).cross(&f).normalize();
    let y = f.cross(&x);
    let mut m = Affine::identity();
    for k in 0..3 {
        m[(k, 0)] = x[k];
        m[(k, 1)] = y[k];
        m[(k, 2)] = f[k];
        m[(k, 3)] = eye[k];
    }
    m
}

/// The scene: mesh, atlas, texels, BVH, camera and its ray tables (1x and 2x for supersampling).
pub struct World {
    pub atlas: Atlas,
    pub texels: TexelSet,
    pub scene: Scene,
    pub camera: Camera,
    rays: RayTable,
    rays_ss: RayTable,
}

/// One rendered frame with what the fusion needs.
pub struct Shot {
    pub frame: Frame,
    pub pose: Affine,
    pub psi: PsiModel,
    pub gbuffer: GBuffer,
}

impl Shot {
    pub fn observation<'a>(&'a self, camera: &'a Camera) -> Observation<'a> {
        Observation {
            frame: &self.frame,
            camera,
            camera_to_world: &self.pose,
            shading: FrameShading::Paper(&self.psi),
            depth: &self.gbuffer.z,
        }
    }
}

impl World {
    /// The airway meshed at `grid_mm`, its atlas at `texel_mm`, a `size` x `size` camera with
    /// a 100° field of view and barrel distortion.
    pub fn new(grid_mm: f32, texel_mm: f64, size: u32) -> World {
        let mesh = airway_mesh::airway_mesh(grid_mm);
        let atlas = build_atlas(
            &mesh,
            &AtlasOptions {
                texel_mm,
                ..Default::default()
            },
        )
        .expect("atlas");
        let geo = rasterize_texels(&atlas, &mesh).expect("texels");
        let texels = TexelSet::new(&geo).expect("texel set");
        let scene = Scene::new(&mesh).expect("scene");
        let f = (size as f64 / 2.0) / 50f64.to_radians().tan();
        let c = (size as f64 - 1.0) / 2.0;
        let camera = Camera {
            width: size,
            height: size,
            fx: f,
            fy: f,
            cx: c,
            cy: c,
            k1: -0.12,
            k2: 0.02,
            p1: 0.0,
            p2: 0.0,
            k3: 0.0,
        };
        // 2x supersampling: sub-pixel (2u + i, 2v + j) sits at (u - 0.25 + i/2, v - 0.25 + j/2).
        let ss = Camera {
            width: 2 * size,
            height: 2 * size,
            fx: 2.0 * f,
            fy: 2.0 * f,
            cx: 2.0 * c + 0.5,
            cy: 2.0 * c + 0.5,
            ..camera
        };
        World {
            atlas,
            texels,
            scene,
            camera,
            rays: RayTable::new(&camera),
            rays_ss: RayTable::new(&ss),
        }
    }

    /// `n` camera poses down the trachea towards the carina, off-axis and tilted.
    pub fn poses(n: usize) -> Vec<Affine> {
        (0..n)
            .map(|i| {
                let t = i as f64 / n.max(2) as f64;
                let phi = 2.4 * i as f64;
                let eye = [2.0 * phi.cos(), 2.0 * phi.sin(), 50.0 - 38.0 * t];
                let tilt = (8.0 + 22.0 * ((1.7 * i as f64).sin().abs())).to_radians();
                let dir = phi + 2.0;
                let fwd = [tilt.sin() * dir.cos(), tilt.sin() * dir.sin(), -tilt.cos()];
                look(eye, fwd, [0.0, 1.0, 0.0])
            })
            .collect()
    }

    /// Render one frame from `pose` and fit its Psi.
    pub fn shoot(&self, pose: &Affine, seed: u64) -> Shot {
        let (w, h) = (self.camera.width as usize, self.camera.height as usize);
        let g = cast_frame_with(&self.scene, &self.rays, pose);
        let gs = cast_frame_with(&self.scene, &self.rays_ss, pose);
        let w2 = 2 * w;
        // Radiance per sub-pixel (before gain).
        let rad: Vec<[f64; 3]> = (0..4 * w * h)
            .into_par_iter()
            .map(|i| {
                if !gs.hit(i) {
                    return [0.0; 3];
                }
                let z = gs.z[i] as f64;
                let gamma = (gs.gamma[i] as f64).max(0.0);
                let cone = (self.rays_ss.dirs[i][2] as f64).max(0.0);
                let light = 300.0 * cone / (z * z);
                let (diff, spec) = brdf_cos(gamma);
                let a = albedo(gs.point[i].map(f64::from));
                a.map(|ac| light * (ac * diff + spec))
            })
            .collect();
        let px: Vec<[f64; 3]> = (0..w * h)
            .map(|i| {
                let (x, y) = (i % w, i / w);
                let mut s = [0.0; 3];
                for (dx, dy) in [(0, 0), (1, 0), (0, 1), (1, 1)] {
                    let r = rad[(2 * y + dy) * w2 + 2 * x + dx];
                    for c in 0..3 {
                        s[c] += 0.25 * r[c];
                    }
                }
                s
            })
            .collect();
        // Auto-gain: the 90th percentile of luminance goes to 0.6.
        let mut lum: Vec<f64> = px
            .iter()
            .map(|v| 0.2126 * v[0] + 0.7152 * v[1] + 0.0722 * v[2])
            .collect();
        let k = (lum.len() as f64 * 0.9) as usize;
        let p90 = *lum.select_nth_unstable_by(k, |a, b| a.total_cmp(b)).1;
        let gain = 0.6 / p90;
        let mut rng = Rng::new(seed);
        let lut = srgb8_to_linear_lut();
        let mut frame = Frame::new(w as u32, h as u32);
        for (i, v) in px.iter().enumerate() {
            for c in 0..3 {
                let x = gain * v[c];
                let sigma = (0.0004 * x + 0.002f64.powi(2)).sqrt();
                let noisy = (x + sigma * rng.normal()).clamp(0.0, 1.0) as f32;
                frame.rgb[3 * i + c] = lut[linear_to_srgb8(noisy) as usize];
            }
        }
        let so = SampleOptions::default();
        let samples = extract_samples(&g.gamma, &g.z, &frame.rgb, &so);
        let wts = density_weights(&samples, &WeightOptions::default());
        let mut psi = fit_psi(&samples, &wts.weights, &FitOptions::default())
            .expect("psi fit")
            .model;
        for r in 0..4 {
            for c in 0..4 {
                psi.camera_to_world[4 * r + c] = pose[(r, c)];
            }
        }
        Shot {
            frame,
            pose: *pose,
            psi,
            gbuffer: g,
        }
    }
}
