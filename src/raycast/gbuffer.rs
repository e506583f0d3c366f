//! The per-frame geometry buffer: what each pixel of a camera sees of the lumen.

use super::scene::Scene;
use crate::camera::Camera;
use crate::math::Affine;
use rayon::prelude::*;

/// Unit ray directions in camera coordinates for every pixel of a camera (row-major,
/// pixel centres at integer coordinates, lens distortion undone). Computed once per camera
/// and shared by every frame of a video.
#[derive(Clone, Debug)]
pub struct RayTable {
    /// Image width (pixels).
    pub width: u32,
    /// Image height (pixels).
    pub height: u32,
    /// Unit direction per pixel, camera coordinates (+x right, +y down, +z forward).
    pub dirs: Vec<[f32; 3]>,
}

impl RayTable {
    /// Tabulate [`Camera::pixel_ray`] for every pixel (parallel over rows).
    pub fn new(camera: &Camera) -> RayTable {
        let (w, h) = (camera.width as usize, camera.height as usize);
        let dirs = (0..w * h)
            .into_par_iter()
            .with_min_len(1024)
            .map(|i| {
                let d = camera.pixel_ray((i % w) as f64, (i / w) as f64);
                [d.x as f32, d.y as f32, d.z as f32]
            })
            .collect();
        RayTable {
            width: camera.width,
            height: camera.height,
            dirs,
        }
    }
}

/// What each pixel sees; all vectors are row-major with `width * height` entries, world mm.
/// Pixels without a hit have `tri == u32::MAX`, `z = +inf`, `point` NaN, `normal` zero,
/// `gamma = 0`, `bary = [0, 0]`.
#[derive(Clone, Debug, Default)]
pub struct GBuffer {
    /// Image width (pixels).
    pub width: u32,
    /// Image height (pixels).
    pub height: u32,
    /// Euclidean distance from the camera centre to the surface point (mm).
    pub z: Vec<f32>,
    /// Surface point (world mm).
    pub point: Vec<[f32; 3]>,
    /// Interpolated unit vertex normal, flipped to face the camera.
    pub normal: Vec<[f32; 3]>,
    /// Cosine between the direction to the viewpoint and `normal` (in [0, 1]).
    pub gamma: Vec<f32>,
    /// Triangle hit (index into the mesh), `u32::MAX` for none.
    pub tri: Vec<u32>,
    /// Barycentric weights of the triangle's second and third vertices.
    pub bary: Vec<[f32; 2]>,
}

impl GBuffer {
    /// True when pixel `i` (row-major index) sees the surface.
    #[inline]
    pub fn hit(&self, i: usize) -> bool {
        self.tri[i] != u32::MAX
    }

    /// Make the pixels where `image` is false (outside a scope's field of view, under burnt-in
    /// text) see nothing, as pixels without a hit; `image` is row-major, one flag per pixel.
    pub fn mask_out(&mut self, image: &[bool]) {
        for (i, _) in image.iter().enumerate().filter(|(_, &m)| !m) {
            if i < self.tri.len() {
                self.z[i] = MISS.z;
                self.point[i] = MISS.point;
                self.normal[i] = MISS.normal;
                self.gamma[i] = MISS.gamma;
                self.tri[i] = MISS.tri;
                self.bary[i] = MISS.bary;
            }
        }
    }

    /// Number of pixels that see the surface.
    pub fn hit_count(&self) -> usize {
        self.tri.iter().filter(|&&t| t != u32::MAX).count()
    }
}

/// One pixel's record before the buffer is split into planes.
#[derive(Clone, Copy)]
struct Px {
    z: f32,
    point: [f32; 3],
    normal: [f32; 3],
    gamma: f32,
    tri: u32,
    bary: [f32; 2],
}

const MISS: Px = Px {
    z: f32::INFINITY,
    point: [f32::NAN; 3],
    normal: [0.0; 3],
    gamma: 0.0,
    tri: u32::MAX,
    bary: [0.0; 2],
};

/// Ray cast one frame: `camera_to_world` maps camera coordinates to world mm (rigid).
/// Builds the camera's [`RayTable`]; for a video, build it once and use [`cast_frame_with`].
pub fn cast_frame(scene: &Scene, camera: &Camera, camera_to_world: &Affine) -> GBuffer {
    cast_frame_with(scene, &RayTable::new(camera), camera_to_world)
}

/// Ray cast one frame with precomputed pixel rays (parallel over bands of image rows, traced
/// in packets of neighbouring rays by [`Scene::closest_hits_image_rows`]).
pub fn cast_frame_with(scene: &Scene, rays: &RayTable, camera_to_world: &Affine) -> GBuffer {
    let m = camera_to_world;
    let org = [m[(0, 3)] as f32, m[(1, 3)] as f32, m[(2, 3)] as f32];
    let r = |d: &[f32; 3]| -> [f32; 3] {
        let v = [0, 1, 2]
            .map(|i| m[(i, 0)] * d[0] as f64 + m[(i, 1)] * d[1] as f64 + m[(i, 2)] * d[2] as f64);
        let l = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
        [(v[0] / l) as f32, (v[1] / l) as f32, (v[2] / l) as f32]
    };
    let w = (rays.width as usize).max(1);
    let mut px = vec![MISS; rays.dirs.len()];
    // A band of image rows per task, traced as packets of neighbouring rays (tiles of
    // 4 x TILE_ROWS), then turned into records.
    px.par_chunks_mut(Scene::TILE_ROWS * w)
        .zip(rays.dirs.par_chunks(Scene::TILE_ROWS * w))
        .for_each_init(
            || (Vec::new(), Vec::new()),
            |(dirs, hits), (out, row)| {
                dirs.clear();
                dirs.extend(row.iter().map(r));
                hits.clear();
                hits.resize(dirs.len(), None);
                scene.closest_hits_image_rows(org, dirs, w, f32::INFINITY, hits);
                for ((o, dir), h) in out.iter_mut().zip(dirs.iter()).zip(hits.iter()) {
                    let Some(h) = h else {
                        continue;
                    };
                    let point = [
                        org[0] + h.t * dir[0],
                        org[1] + h.t * dir[1],
                        org[2] + h.t * dir[2],
                    ];
                    let mut n = scene.shading_normal(h.tri, h.u, h.v);
                    // V points from the surface to the viewpoint, i.e. -dir.
                    let mut gamma = -(n[0] * dir[0] + n[1] * dir[1] + n[2] * dir[2]);
                    if gamma < 0.0 {
                        n = [-n[0], -n[1], -n[2]];
                        gamma = -gamma;
                    }
                    *o = Px {
                        z: h.t,
                        point,
                        normal: n,
                        gamma: gamma.min(1.0),
                        tri: h.tri,
                        bary: [h.u, h.v],
                    };
                }
            },
        );
    let mut g = GBuffer {
        width: rays.width,
        height: rays.height,
        z: Vec::with_capacity(px.len()),
        point: Vec::with_capacity(px.len()),
        normal: Vec::with_capacity(px.len()),
        gamma: Vec::with_capacity(px.len()),
        tri: Vec::with_capacity(px.len()),
        bary: Vec::with_capacity(px.len()),
    };
    for p in px {
        g.z.push(p.z);
        g.point.push(p.point);
        g.normal.push(p.normal);
        g.gamma.push(p.gamma);
        g.tri.push(p.tri);
        g.bary.push(p.bary);
    }
    g
}
