//! The per-frame geometry buffer: what each pixel of a camera sees of the lumen.

use super::scene::{Hit, Scene};
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

/// A depth plane's [`GBuffer::mask_out`]: pixels where `image` is false see nothing.
pub fn mask_out_depth(z: &mut [f32], image: &[bool]) {
    for (z, _) in z.iter_mut().zip(image).filter(|(_, &m)| !m) {
        *z = MISS.z;
    }
}

/// One pixel's values in every plane ([`MISS`]: a pixel without a hit).
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

/// A camera pose's rays in world coordinates: the origin, and each camera-space direction
/// rotated (in f64, then normalised) as every cast of this module turns them.
struct WorldRays<'a> {
    org: [f32; 3],
    m: &'a Affine,
}

impl<'a> WorldRays<'a> {
    fn new(camera_to_world: &'a Affine) -> WorldRays<'a> {
        let m = camera_to_world;
        WorldRays {
            org: [m[(0, 3)] as f32, m[(1, 3)] as f32, m[(2, 3)] as f32],
            m,
        }
    }

    #[inline]
    fn dir(&self, d: &[f32; 3]) -> [f32; 3] {
        let m = self.m;
        let v = [0, 1, 2]
            .map(|i| m[(i, 0)] * d[0] as f64 + m[(i, 1)] * d[1] as f64 + m[(i, 2)] * d[2] as f64);
        let l = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
        [(v[0] / l) as f32, (v[1] / l) as f32, (v[2] / l) as f32]
    }

    /// The closest hits of a band of image rows (`row` camera-space directions, `width` per
    /// row) as packets of neighbouring rays; `dirs` receives the world directions.
    fn trace_band(
        &self,
        scene: &Scene,
        row: &[[f32; 3]],
        width: usize,
        dirs: &mut Vec<[f32; 3]>,
        hits: &mut Vec<Option<Hit>>,
    ) {
        dirs.clear();
        dirs.extend(row.iter().map(|d| self.dir(d)));
        hits.clear();
        hits.resize(dirs.len(), None);
        scene.closest_hits_image_rows(self.org, dirs, width, f32::INFINITY, hits);
    }
}

/// One band of image rows of each plane of a [`GBuffer`] being filled.
struct Band<'a> {
    z: &'a mut [f32],
    point: &'a mut [[f32; 3]],
    normal: &'a mut [[f32; 3]],
    gamma: &'a mut [f32],
    tri: &'a mut [u32],
    bary: &'a mut [[f32; 2]],
}

/// Ray cast one frame with precomputed pixel rays (parallel over bands of image rows, traced
/// in packets of neighbouring rays by [`Scene::closest_hits_image_rows`]; each band writes its
/// rows of every plane).
pub fn cast_frame_with(scene: &Scene, rays: &RayTable, camera_to_world: &Affine) -> GBuffer {
    let world = WorldRays::new(camera_to_world);
    let org = world.org;
    let w = (rays.width as usize).max(1);
    let n = rays.dirs.len();
    let mut g = GBuffer {
        width: rays.width,
        height: rays.height,
        z: vec![MISS.z; n],
        point: vec![MISS.point; n],
        normal: vec![MISS.normal; n],
        gamma: vec![MISS.gamma; n],
        tri: vec![MISS.tri; n],
        bary: vec![MISS.bary; n],
    };
    let rows = Scene::TILE_ROWS * w;
    let bands: Vec<Band> =
        g.z.chunks_mut(rows)
            .zip(g.point.chunks_mut(rows))
            .zip(g.normal.chunks_mut(rows))
            .zip(g.gamma.chunks_mut(rows))
            .zip(g.tri.chunks_mut(rows))
            .zip(g.bary.chunks_mut(rows))
            .map(|(((((z, point), normal), gamma), tri), bary)| Band {
                z,
                point,
                normal,
                gamma,
                tri,
                bary,
            })
            .collect();
    bands
        .into_par_iter()
        .zip(rays.dirs.par_chunks(rows))
        .for_each_init(
            || (Vec::new(), Vec::new()),
            |(dirs, hits), (out, row)| {
                world.trace_band(scene, row, w, dirs, hits);
                for (k, (dir, h)) in dirs.iter().zip(hits.iter()).enumerate() {
                    let Some(h) = h else {
                        continue;
                    };
                    let mut n = scene.shading_normal(h.tri, h.u, h.v);
                    // V points from the surface to the viewpoint, i.e. -dir.
                    let mut gamma = -(n[0] * dir[0] + n[1] * dir[1] + n[2] * dir[2]);
                    if gamma < 0.0 {
                        n = [-n[0], -n[1], -n[2]];
                        gamma = -gamma;
                    }
                    out.z[k] = h.t;
                    out.point[k] = [
                        org[0] + h.t * dir[0],
                        org[1] + h.t * dir[1],
                        org[2] + h.t * dir[2],
                    ];
                    out.normal[k] = n;
                    out.gamma[k] = gamma.min(1.0);
                    out.tri[k] = h.tri;
                    out.bary[k] = [h.u, h.v];
                }
            },
        );
    g
}

/// The distance plane of [`cast_frame_with`] alone (the same rays and hits, so the same
/// values): what a visibility test needs, without a full G-buffer's normals and points.
pub fn cast_depth_with(scene: &Scene, rays: &RayTable, camera_to_world: &Affine) -> Vec<f32> {
    let world = WorldRays::new(camera_to_world);
    let w = (rays.width as usize).max(1);
    let rows = Scene::TILE_ROWS * w;
    let mut z = vec![MISS.z; rays.dirs.len()];
    z.par_chunks_mut(rows)
        .zip(rays.dirs.par_chunks(rows))
        .for_each_init(
            || (Vec::new(), Vec::new()),
            |(dirs, hits), (out, row)| {
                world.trace_band(scene, row, w, dirs, hits);
                for (o, h) in out.iter_mut().zip(hits.iter()) {
                    if let Some(h) = h {
                        *o = h.t;
                    }
                }
            },
        );
    z
}
