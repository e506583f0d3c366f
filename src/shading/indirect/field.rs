//! The gathered light of one view on a coarse grid of its pixels, interpolated in between.
//!
//! The once-reflected light varies slowly over the image (it averages the wall a whole
//! hemisphere sees), so it is gathered at the centres of blocks of pixels and interpolated
//! bilinearly. The grid lives in normalised image coordinates, so a field gathered at the
//! working resolution serves the full-resolution frames of the same view too.

use rayon::prelude::*;

use super::gather::{gather_one, GatherOptions, LensLight, SurfaceAlbedo};
use crate::camera::Camera;
use crate::math::Affine;
use crate::raycast::Scene;
use crate::shading::calibrated::CalibratedModel;

/// The gathered light of one view: per channel, camera units at the reference gain.
#[derive(Debug, Clone, PartialEq)]
pub struct IndirectField {
    /// Grid nodes across the image.
    pub nx: usize,
    /// Grid nodes down the image.
    pub ny: usize,
    /// Node values, row-major (holes filled from their neighbours).
    pub values: Vec<[f32; 3]>,
}

impl IndirectField {
    /// The light at normalised image coordinates (`x / width`, `y / height` of a pixel's
    /// continuous position, pixel centres at `(i + 0.5) / width`), bilinear between nodes and
    /// held constant beyond the outer node centres.
    pub fn at(&self, u: f64, v: f64) -> [f32; 3] {
        let fx = (u * self.nx as f64 - 0.5).clamp(0.0, (self.nx - 1) as f64);
        let fy = (v * self.ny as f64 - 0.5).clamp(0.0, (self.ny - 1) as f64);
        let (x0, y0) = (fx.floor() as usize, fy.floor() as usize);
        let (x1, y1) = ((x0 + 1).min(self.nx - 1), (y0 + 1).min(self.ny - 1));
        let (ax, ay) = ((fx - x0 as f64) as f32, (fy - y0 as f64) as f32);
        let g = |x: usize, y: usize| self.values[y * self.nx + x];
        let (a, b, c, d) = (g(x0, y0), g(x1, y0), g(x0, y1), g(x1, y1));
        std::array::from_fn(|k| {
            let top = a[k] + ax * (b[k] - a[k]);
            let bottom = c[k] + ax * (d[k] - c[k]);
            top + ay * (bottom - top)
        })
    }

    /// [`Self::at`] at the centre of pixel `index` (row-major) of a `width` x `height` image.
    pub fn at_pixel(&self, index: usize, width: usize, height: usize) -> [f32; 3] {
        let (x, y) = (index % width.max(1), index / width.max(1));
        self.at(
            (x as f64 + 0.5) / width.max(1) as f64,
            (y as f64 + 0.5) / height.max(1) as f64,
        )
    }
}

/// Gather the light of the view of `camera` at `camera_to_world` (its own light at the lens,
/// `model`'s rho and s) on a grid of `nodes_across` nodes across the image (rows in proportion),
/// with the wall's `albedo`. `view_id` seeds the rays (the same view gets the same rays).
#[allow(clippy::too_many_arguments)]
pub fn gather_view(
    scene: &Scene,
    camera: &Camera,
    camera_to_world: &Affine,
    model: &CalibratedModel,
    albedo: &dyn SurfaceAlbedo,
    nodes_across: usize,
    view_id: u64,
    opts: &GatherOptions,
) -> IndirectField {
    let ray = |px: f64, py: f64| {
        let r = camera.pixel_ray(px, py);
        [r.x, r.y, r.z]
    };
    let view = ViewGrid {
        width: camera.width,
        height: camera.height,
        nodes_across,
        ray: &ray,
    };
    gather_grid(scene, &view, camera_to_world, model, albedo, view_id, opts)
}

/// A view's image and grid: its size (pixels), nodes across it, and the unit ray (camera
/// coordinates) through a continuous pixel position (pixel centres at integers).
pub struct ViewGrid<'a> {
    /// Image width (pixels).
    pub width: u32,
    /// Image height (pixels).
    pub height: u32,
    /// Grid nodes across the image.
    pub nodes_across: usize,
    /// The ray through pixel position (x, y).
    pub ray: &'a (dyn Fn(f64, f64) -> [f64; 3] + Sync),
}

/// [`gather_view`] for any view whose rays `view` gives.
pub fn gather_grid(
    scene: &Scene,
    view: &ViewGrid,
    camera_to_world: &Affine,
    model: &CalibratedModel,
    albedo: &dyn SurfaceAlbedo,
    view_id: u64,
    opts: &GatherOptions,
) -> IndirectField {
    let (w, h) = (f64::from(view.width), f64::from(view.height));
    let nx = view.nodes_across.max(1);
    let ny = ((nx as f64 * h / w).round() as usize).max(1);
    let m = camera_to_world;
    let centre = [m[(0, 3)], m[(1, 3)], m[(2, 3)]];
    let rot = |d: [f64; 3]| -> [f64; 3] {
        std::array::from_fn(|i| m[(i, 0)] * d[0] + m[(i, 1)] * d[1] + m[(i, 2)] * d[2])
    };
    let light = LensLight {
        model,
        centre,
        axis: rot([0.0, 0.0, 1.0]),
    };
    let org = centre.map(|v| v as f32);
    let raw: Vec<Option<[f32; 3]>> = (0..nx * ny)
        .into_par_iter()
        .with_min_len(4)
        .map(|k| {
            let (i, j) = (k % nx, k / nx);
            let px = (i as f64 + 0.5) / nx as f64 * w - 0.5;
            let py = (j as f64 + 0.5) / ny as f64 * h - 0.5;
            let d = rot((view.ray)(px, py)).map(|v| v as f32);
            let hit = scene.closest_hit(org, d, f32::INFINITY)?;
            let p = [0, 1, 2].map(|q| org[q] + hit.t * d[q]);
            let n = scene.shading_normal(hit.tri, hit.u, hit.v);
            let id = view_id.wrapping_mul(1 << 20).wrapping_add(k as u64);
            Some(gather_one(scene, &light, albedo, p, n, id, opts))
        })
        .collect();
    IndirectField {
        nx,
        ny,
        values: fill_holes(&raw, nx, ny),
    }
}

/// Nodes without a hit take the mean of their gathered 8-neighbours, ring by ring; zeros when
/// no node hit anything.
fn fill_holes(raw: &[Option<[f32; 3]>], nx: usize, ny: usize) -> Vec<[f32; 3]> {
    let mut cur: Vec<Option<[f32; 3]>> = raw.to_vec();
    for _ in 0..nx + ny {
        if cur.iter().all(Option::is_some) {
            break;
        }
        let prev = cur.clone();
        let mut changed = false;
        for y in 0..ny {
            for x in 0..nx {
                if prev[y * nx + x].is_some() {
                    continue;
                }
                let (mut s, mut c) = ([0f32; 3], 0u32);
                for (dx, dy) in (-1i64..=1).flat_map(|a| (-1i64..=1).map(move |b| (a, b))) {
                    let (xx, yy) = (x as i64 + dx, y as i64 + dy);
                    if xx < 0 || yy < 0 || xx >= nx as i64 || yy >= ny as i64 {
                        continue;
                    }
                    if let Some(v) = prev[yy as usize * nx + xx as usize] {
                        for k in 0..3 {
                            s[k] += v[k];
                        }
                        c += 1;
                    }
                }
                if c > 0 {
                    cur[y * nx + x] = Some(s.map(|v| v / c as f32));
                    changed = true;
                }
            }
        }
        if !changed {
            break;
        }
    }
    cur.into_iter().map(|v| v.unwrap_or([0.0; 3])).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn field_interpolates_between_node_centres_and_fills_holes() {
        // 2 x 1 nodes: 1 at the left, 3 at the right; a hole in a 3 x 1 grid takes the mean.
        let f = IndirectField {
            nx: 2,
            ny: 1,
            values: vec![[1.0; 3], [3.0; 3]],
        };
        assert_eq!(f.at(0.25, 0.5)[0], 1.0);
        assert_eq!(f.at(0.75, 0.5)[1], 3.0);
        assert!((f.at(0.5, 0.5)[2] - 2.0).abs() < 1e-6);
        assert_eq!(f.at(0.0, 0.0)[0], 1.0);
        // Pixel 3 of an 8-wide row sits at u = 3.5 / 8, 3/8 of the way from the left node
        // centre (u = 1/4) to the right one (u = 3/4).
        assert!((f.at_pixel(3, 8, 1)[0] - 1.75).abs() < 1e-6);
        let filled = fill_holes(&[Some([2.0; 3]), None, Some([4.0; 3])], 3, 1);
        assert_eq!(filled[1], [3.0; 3]);
        assert_eq!(fill_holes(&[None, None], 2, 1), vec![[0.0; 3]; 2]);
    }
}
