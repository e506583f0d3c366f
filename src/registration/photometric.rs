//! The model a frame is registered against: the lumen mesh, its texture and the calibrated
//! light, rendered from a pose as a set of surface points (the G-buffer of a ray grid), each
//! with its albedo. A frame f is predicted as `g_f (albedo S(gamma, theta, z) + a)`.

use super::light::LightEval;
use super::pose::rotation_of;
use crate::camera::pose::camera_centre;
use crate::camera::Camera;
use crate::math::{Affine, Vector3};
use crate::raycast::{cast_frame_with, RayTable, Scene};
use crate::render::MipTexture;
use crate::shading::CalibratedModel;
use crate::shading::LUMA;
use crate::{Error, Result};

/// Borrowed pieces of a built model (what `bronchosim build` has in memory, or
/// [`crate::model::Model`] after loading).
#[derive(Clone, Copy)]
pub struct ModelParts<'a> {
    /// The lumen mesh, ready for ray casting (world mm).
    pub scene: &'a Scene,
    /// UV corners of every triangle of `scene`.
    pub tri_uv: &'a [[[f32; 2]; 3]],
    /// The relative albedo (linear); `None` registers against a uniform albedo (the shading
    /// of the geometry alone).
    pub texture: Option<&'a MipTexture>,
    /// The calibrated light.
    pub light: &'a CalibratedModel,
    /// The camera that took the frames (distortion included).
    pub camera: &'a Camera,
}

/// The rays of one pyramid level, every `stride`-th pixel in each direction.
#[derive(Clone, Debug)]
pub struct RayGrid {
    /// Pyramid level (0 = full resolution).
    pub level: usize,
    /// Pixel step of the grid at that level.
    pub stride: usize,
    /// The grid's rays (camera frame), row-major over the grid.
    pub rays: RayTable,
    /// Angle one level pixel subtends at each grid ray (radians): the texture's footprint.
    pub pixel_angle: Vec<f32>,
}

impl RayGrid {
    /// The grid of `camera` at `level` with `stride`.
    pub fn new(camera: &Camera, level: usize, stride: usize) -> RayGrid {
        Self::with_jitter(camera, level, stride, false)
    }

    /// [`RayGrid::new`], each ray moved off its pixel centre by a fixed pseudo-random
    /// sub-pixel offset (up to half a pixel each way) when `jitter`.
    pub fn with_jitter(camera: &Camera, level: usize, stride: usize, jitter: bool) -> RayGrid {
        let cam = camera.at_level(level);
        let stride = stride.max(1);
        let (gw, gh) = (
            (cam.width as usize).div_ceil(stride),
            (cam.height as usize).div_ceil(stride),
        );
        let mut dirs = Vec::with_capacity(gw * gh);
        let mut pixel_angle = Vec::with_capacity(gw * gh);
        for gy in 0..gh {
            for gx in 0..gw {
                let (jx, jy) = if jitter {
                    sub_pixel_offset(gx, gy, level)
                } else {
                    (0.0, 0.0)
                };
                let (x, y) = ((gx * stride) as f64 + jx, (gy * stride) as f64 + jy);
                let d = cam.pixel_ray(x, y);
                let dx = cam.pixel_ray(x + 1.0, y);
                let dy = cam.pixel_ray(x, y + 1.0);
                let a = d.angle(&dx).max(d.angle(&dy));
                dirs.push([d.x as f32, d.y as f32, d.z as f32]);
                pixel_angle.push(a as f32);
            }
        }
        RayGrid {
            level,
            stride,
            rays: RayTable {
                width: gw as u32,
                height: gh as u32,
                dirs,
            },
            pixel_angle,
        }
    }
}

/// A fixed pseudo-random offset in [-0.5, 0.5) pixels on each axis for grid ray (gx, gy)
/// of `level` (splitmix64 of the three).
fn sub_pixel_offset(gx: usize, gy: usize, level: usize) -> (f64, f64) {
    let mut z = (gx as u64) ^ ((gy as u64) << 24) ^ ((level as u64) << 48);
    z = z.wrapping_add(0x9e37_79b9_7f4a_7c15);
    z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
    z ^= z >> 31;
    let unit = |bits: u64| (bits & 0xff_ffff) as f64 / f64::from(1u32 << 24) - 0.5;
    (unit(z), unit(z >> 32))
}

/// A built model ready for registration.
pub struct PhotometricModel<'a> {
    /// The pieces.
    pub parts: ModelParts<'a>,
    /// The light with its derivatives.
    pub light: LightEval,
}

impl<'a> PhotometricModel<'a> {
    /// Check the pieces fit together.
    pub fn new(parts: ModelParts<'a>) -> Result<PhotometricModel<'a>> {
        if parts.tri_uv.len() != parts.scene.triangle_count() {
            return Err(Error::Other(format!(
                "registration: {} triangle UVs for a mesh of {} triangles",
                parts.tri_uv.len(),
                parts.scene.triangle_count()
            )));
        }
        parts
            .light
            .validate()
            .map_err(|m| Error::Other(format!("registration: calibrated light: {m}")))?;
        parts
            .camera
            .validate()
            .map_err(|m| Error::Other(format!("registration: camera: {m}")))?;
        Ok(PhotometricModel {
            light: LightEval::new(parts.light),
            parts,
        })
    }
}

/// One surface point the model renders, in world coordinates.
#[derive(Clone, Copy, Debug)]
pub struct ModelPoint {
    /// Surface point (world mm).
    pub x: Vector3<f64>,
    /// Unit normal facing the rendering camera (world).
    pub n: Vector3<f64>,
    /// Relative albedo per channel (1 with a uniform albedo).
    pub albedo: [f32; 3],
    /// What it sends back to the rendering camera at unit gain (the light times `albedo`,
    /// without the view's offset).
    pub radiance: [f64; 3],
    /// Index of the grid ray that found it (row-major over the grid).
    pub ray: u32,
}

/// What the model shows from one pose at one grid.
#[derive(Clone, Debug)]
pub struct ModelView {
    /// Surface points whose shading can be trusted (gamma at least the minimum).
    pub points: Vec<ModelPoint>,
    /// Per grid ray, the index of its point in `points` (`u32::MAX` for none).
    pub index: Vec<u32>,
    /// Grid width (rays).
    pub grid_width: usize,
    /// The light added to every point (inter-reflection `kappa L` of this view plus the
    /// model's view-independent ambient), per channel, at unit gain.
    pub offset: [f64; 3],
    /// Fraction of the grid's rays that hit the surface.
    pub hit_fraction: f64,
    /// Fraction of the hits seen from the lumen side (near 1 for a camera inside the airway).
    pub inside_fraction: f64,
}

impl PhotometricModel<'_> {
    /// Ray cast `grid` from `pose` (camera → world) and collect the surface points with gamma
    /// at least `min_gamma`.
    pub fn view(&self, grid: &RayGrid, pose: &Affine, min_gamma: f32) -> ModelView {
        let p = &self.parts;
        let g = cast_frame_with(p.scene, &grid.rays, pose);
        let centre = camera_centre(pose).coords;
        let (mut hits, mut inside) = (0usize, 0usize);
        let mut lum_sum = 0.0f64;
        let mut points = Vec::with_capacity(g.z.len());
        let mut index = vec![u32::MAX; g.z.len()];
        let to_cam = rotation_of(pose).transpose();
        for (i, slot) in index.iter_mut().enumerate() {
            if !g.hit(i) {
                continue;
            }
            hits += 1;
            let [bu, bv] = g.bary[i];
            let n0 = p.scene.shading_normal(g.tri[i], bu, bv);
            let x = Vector3::new(g.point[i][0], g.point[i][1], g.point[i][2]).cast::<f64>();
            let dir = x - centre;
            // The mesh's normals face into the lumen: seen from inside, rays meet them head-on.
            if dir.dot(&Vector3::new(n0[0], n0[1], n0[2]).cast::<f64>()) < 0.0 {
                inside += 1;
            }
            let gamma = g.gamma[i];
            let n = Vector3::new(g.normal[i][0], g.normal[i][1], g.normal[i][2]).cast::<f64>();
            let albedo = match p.texture {
                Some(tex) => {
                    let [a, b, c] = p.tri_uv[g.tri[i] as usize];
                    let wa = 1.0 - bu - bv;
                    let u = wa * a[0] + bu * b[0] + bv * c[0];
                    let v = wa * a[1] + bu * b[1] + bv * c[1];
                    let fp = g.z[i] * grid.pixel_angle[i] / gamma.max(0.05);
                    tex.sample(u, v, tex.lod(fp))
                }
                None => [1.0; 3],
            };
            let s = self.light.radiance(&(to_cam * dir), &(to_cam * n), albedo);
            lum_sum += (0..3).map(|c| LUMA[c] * s[c]).sum::<f64>();
            if gamma >= min_gamma {
                *slot = points.len() as u32;
                points.push(ModelPoint {
                    x,
                    n,
                    albedo,
                    radiance: s,
                    ray: i as u32,
                });
            }
        }
        let ambient = p.light.new_view_ambient();
        let lum_ambient: f64 = (0..3).map(|c| LUMA[c] * ambient[c]).sum();
        let mean = if hits > 0 { lum_sum / hits as f64 } else { 0.0 };
        let inter = p.light.view_interreflection(mean + lum_ambient);
        let n = g.z.len().max(1) as f64;
        ModelView {
            points,
            index,
            grid_width: grid.rays.width as usize,
            offset: std::array::from_fn(|c| inter[c] + ambient[c]),
            hit_fraction: hits as f64 / n,
            inside_fraction: inside as f64 / hits.max(1) as f64,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Point3;

    #[test]
    fn jittered_rays_stay_within_half_a_pixel_of_their_grid_pixel() {
        let camera = Camera {
            width: 96,
            height: 80,
            fx: 70.0,
            fy: 70.0,
            cx: 47.5,
            cy: 39.5,
            k1: -0.2,
            k2: 0.05,
            p1: 0.001,
            p2: -0.001,
            k3: 0.0,
        };
        let (level, stride) = (1, 2);
        let cam = camera.at_level(level);
        let plain = RayGrid::new(&camera, level, stride);
        let jittered = RayGrid::with_jitter(&camera, level, stride, true);
        assert_eq!(plain.rays.dirs.len(), jittered.rays.dirs.len());
        let width = plain.rays.width as usize;
        let mut offsets = Vec::new();
        for (i, d) in jittered.rays.dirs.iter().enumerate() {
            let p = Point3::new(f64::from(d[0]), f64::from(d[1]), f64::from(d[2]));
            let px = cam.project(&p).unwrap();
            let (gx, gy) = ((i % width * stride) as f64, (i / width * stride) as f64);
            let (ox, oy) = (px.x - gx, px.y - gy);
            assert!(
                ox.abs() <= 0.5 + 1e-4 && oy.abs() <= 0.5 + 1e-4,
                "{ox} {oy}"
            );
            offsets.push((ox, oy));
        }
        // Spread over the pixel, not at its centre: uniform on [-0.5, 0.5) has mean 0 and
        // mean |offset| 0.25.
        let count = offsets.len() as f64;
        let mean = offsets.iter().map(|o| o.0 + o.1).sum::<f64>() / (2.0 * count);
        let mean_abs = offsets.iter().map(|o| o.0.abs() + o.1.abs()).sum::<f64>() / (2.0 * count);
        assert!(mean.abs() < 0.03, "{mean}");
        assert!((mean_abs - 0.25).abs() < 0.03, "{mean_abs}");
        // The same offsets every time (runs are reproducible), none without them.
        let again = RayGrid::with_jitter(&camera, level, stride, true);
        assert_eq!(again.rays.dirs, jittered.rays.dirs);
        let unjittered = RayGrid::with_jitter(&camera, level, stride, false);
        assert_eq!(unjittered.rays.dirs, plain.rays.dirs);
    }
}
