//! Two baselines the paper's new views are scored against (issue 7), on the same pixels and
//! with the same per-channel gain fit ([`super::evaluate`]):
//!
//! (a) [`reproject_nearest_frame`]: the nearest training frame projected onto the geometry,
//!     with no de-lighting (what a plain projective-texturing simulator would show);
//! (b) [`flat_albedo_view`]: a uniform albedo under `cos(gamma) / z²` shading (a point light at
//!     the lens, no texture).

use rayon::prelude::*;

use crate::camera::pose::rigid_inverse;
use crate::camera::Camera;
use crate::image::Frame;
use crate::image::ImageError;
use crate::math::{transform_point, Affine, Point3};
use crate::raycast::{cast_frame, cast_frame_with, GBuffer, RayTable, Scene};
use crate::shading::paper::ViewpointIndex;
use crate::{Error, Result};

/// One training frame: the image as recorded (linear RGB, lens distortion kept) and its pose.
#[derive(Clone, Copy, Debug)]
pub struct TrainingView<'a> {
    /// The frame in linear light, as the training camera recorded it.
    pub frame: &'a Frame,
    /// Camera → world of the frame (world mm).
    pub camera_to_world: &'a Affine,
    /// Which of its pixels are image (the case's mask.png); `None`: all of them.
    pub image_mask: Option<&'a [bool]>,
}

/// Relative depth tolerance of the visibility test (a point is visible in the training frame
/// when its distance to the training camera is at most the frame's depth there, plus this
/// fraction, plus [`VISIBILITY_MM`]): the point is not on the pixel-centre ray, so the depths
/// of neighbouring pixels differ slightly on oblique walls.
pub const VISIBILITY_REL: f32 = 0.02;
/// Absolute depth tolerance of the visibility test (mm).
pub const VISIBILITY_MM: f32 = 0.1;

/// Baseline (a): for every pixel of the new view that sees the mesh, project its surface point
/// into the training frame with the nearest camera centre, keep it when that frame sees the
/// point (depth test against the frame's own ray cast), and sample the frame bilinearly.
/// The mask marks the pixels that got a value.
pub fn reproject_nearest_frame(
    scene: &Scene,
    camera: &Camera,
    camera_to_world: &Affine,
    training_camera: &Camera,
    training: &[TrainingView],
) -> Result<(Frame, Vec<bool>)> {
    let poses: Vec<Affine> = training.iter().map(|t| *t.camera_to_world).collect();
    let index = ViewpointIndex::from_poses(&poses);
    let Some(near) = index.nearest(camera_to_world) else {
        return Err(Error::BadOptions {
            stage: "baseline (a)",
            message: "no training frames to reproject".into(),
        });
    };
    let tv = training[near];
    if tv.frame.width != training_camera.width || tv.frame.height != training_camera.height {
        return Err(ImageError::SizeMismatch {
            stage: "baseline (a)",
            what: format!("training frame {near}"),
            got: [tv.frame.width, tv.frame.height],
            expected: [training_camera.width, training_camera.height],
        }
        .into());
    }
    let view = cast_frame(scene, camera, camera_to_world);
    let train = cast_frame_with(scene, &RayTable::new(training_camera), tv.camera_to_world);
    let to_cam = rigid_inverse(tv.camera_to_world);
    let tc = [
        tv.camera_to_world[(0, 3)] as f32,
        tv.camera_to_world[(1, 3)] as f32,
        tv.camera_to_world[(2, 3)] as f32,
    ];
    let px: Vec<Option<[f32; 3]>> = (0..view.tri.len())
        .into_par_iter()
        .with_min_len(512)
        .map(|i| {
            if !view.hit(i) {
                return None;
            }
            let p = view.point[i];
            let q = transform_point(&to_cam, &Point3::new(p[0] as f64, p[1] as f64, p[2] as f64));
            let uv = training_camera.project(&q)?;
            let dist =
                ((p[0] - tc[0]).powi(2) + (p[1] - tc[1]).powi(2) + (p[2] - tc[2]).powi(2)).sqrt();
            if !visible(&train, uv.x, uv.y, dist) || !is_image(&tv, uv.x, uv.y) {
                return None;
            }
            tv.frame.bilinear(uv.x, uv.y)
        })
        .collect();
    let mut frame = Frame::new(camera.width, camera.height);
    let mut mask = vec![false; px.len()];
    for (i, v) in px.into_iter().enumerate() {
        if let Some(c) = v {
            frame.rgb[3 * i..3 * i + 3].copy_from_slice(&c);
            mask[i] = true;
        }
    }
    Ok((frame, mask))
}

/// True when (`u`, `v`) is within a pixel of a `w` x `h` image (false for NaN): beyond it no
/// pixel is read, and far-off projections would overflow the integer pixel arithmetic.
fn near_image(u: f64, v: f64, w: i64, h: i64) -> bool {
    u >= -1.0 && v >= -1.0 && u <= w as f64 && v <= h as f64
}

/// True when the (up to four) pixels around (`u`, `v`) that bilinear sampling reads are image.
fn is_image(tv: &TrainingView, u: f64, v: f64) -> bool {
    let Some(mask) = tv.image_mask else {
        return true;
    };
    let (w, h) = (tv.frame.width as i64, tv.frame.height as i64);
    if !near_image(u, v, w, h) {
        return false;
    }
    let (x0, y0) = (u.floor() as i64, v.floor() as i64);
    [(x0, y0), (x0 + 1, y0), (x0, y0 + 1), (x0 + 1, y0 + 1)]
        .into_iter()
        .filter(|&(x, y)| x >= 0 && y >= 0 && x < w && y < h)
        .all(|(x, y)| mask[(y * w + x) as usize])
}

/// True when a point at distance `dist` (mm) from the training camera, projecting to pixel
/// (`u`, `v`), is not hidden: no more than the tolerances behind the farthest surface the
/// (up to four) surrounding pixel-centre rays hit.
fn visible(g: &GBuffer, u: f64, v: f64, dist: f32) -> bool {
    let (w, h) = (g.width as i64, g.height as i64);
    if !near_image(u, v, w, h) {
        return false;
    }
    let (x0, y0) = (u.floor() as i64, v.floor() as i64);
    let mut zmax = f32::NEG_INFINITY;
    for (x, y) in [(x0, y0), (x0 + 1, y0), (x0, y0 + 1), (x0 + 1, y0 + 1)] {
        if x < 0 || y < 0 || x >= w || y >= h {
            continue;
        }
        let i = (y * w + x) as usize;
        if g.hit(i) {
            zmax = zmax.max(g.z[i]);
        }
    }
    zmax.is_finite() && dist <= zmax * (1.0 + VISIBILITY_REL) + VISIBILITY_MM
}

/// Baseline (b): albedo 1 under a point light at the lens, `cos(gamma) / z²` (z in mm), the
/// same value in R, G and B; one gain per channel is fitted at evaluation.
pub fn flat_albedo_view(
    scene: &Scene,
    camera: &Camera,
    camera_to_world: &Affine,
) -> (Frame, Vec<bool>) {
    let g = cast_frame(scene, camera, camera_to_world);
    let mut frame = Frame::new(camera.width, camera.height);
    let mut mask = vec![false; g.tri.len()];
    for (i, m) in mask.iter_mut().enumerate() {
        if g.hit(i) {
            let v = g.gamma[i] / (g.z[i] * g.z[i]);
            frame.rgb[3 * i..3 * i + 3].copy_from_slice(&[v; 3]);
            *m = true;
        }
    }
    (frame, mask)
}
