//! Texel-centric de-lighting (paper §2.4): every texel is projected into a frame through the
//! lens model, tested for visibility against the frame's depth buffer, sampled bilinearly and
//! divided by the frame's shading: the paper's `Psi_p(gamma, z)`, or the calibrated light
//! `g_f rho(gamma) s(theta) / z²` after subtracting its inter-reflection term, plus the
//! gathered inter-reflection `g_f k_c E_c` at the texel's pixel when fitted ([`FrameShading`]).
//!
//! A texel gives no value for a frame when it is behind the camera or outside the image, when
//! it faces away or is grazing (`gamma < min_gamma`), when any of the four pixels of its
//! bilinear footprint sees another surface (occlusion) or was excluded from the fit (no hit,
//! saturated in any channel, all channels under the noise floor), or when the shading is not positive.

// `!(x >= t)` on floats is deliberate: it also rejects NaN.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

use rayon::prelude::*;

use super::texels::{BlockSphere, TexelSet, BLOCK};
use crate::camera::Camera;
use crate::image::Frame;
use crate::image::ImageError;
use crate::math::Affine;
use crate::shading::frame_shading::FrameShading;
use crate::shading::SampleOptions;
use crate::Result;

/// One frame as the de-lighting sees it. All borrowed: a caller streaming a video keeps one
/// frame in memory at a time.
#[derive(Clone, Copy, Debug)]
pub struct Observation<'a> {
    /// The recorded frame in linear RGB (lens distortion not removed).
    pub frame: &'a Frame,
    /// The camera the frame was taken with (intrinsics and distortion).
    pub camera: &'a Camera,
    /// Camera → world (rigid, world mm).
    pub camera_to_world: &'a Affine,
    /// The frame's fitted shading model.
    pub shading: FrameShading<'a>,
    /// Euclidean distance camera → surface per pixel (mm), row-major, `+inf` where the pixel
    /// sees nothing: [`crate::raycast::GBuffer::z`] of this frame.
    pub depth: &'a [f32],
}

/// Options of the de-lighting. The pixel thresholds are those of the fit
/// ([`SampleOptions`]), so a pixel excluded from the fit gives no texture either.
#[derive(Clone, Debug, PartialEq)]
pub struct DelightOptions {
    /// Smallest cosine between the view direction and the texel normal (unitless).
    pub min_gamma: f32,
    /// Linear intensity at or above which a channel is saturated.
    pub saturation_level: f32,
    /// Linear intensity under which a channel is noise (a pixel is dark when all are).
    pub noise_floor: f32,
    /// Absolute depth tolerance of the visibility test (mm). Default 0.3.
    pub depth_tolerance_mm: f64,
    /// Depth tolerance relative to the texel's distance (unitless). Default 0.01. The test
    /// also allows the depth change across the bilinear footprint on a slanted surface.
    pub depth_tolerance_rel: f64,
    /// Observations whose predicted intensity (Psi luminance) is under this fraction of the
    /// frame's brightest prediction give no texture (unitless, 0 keeps all). Where Psi predicts
    /// little light its fit is least reliable (far, grazing) and dividing by it amplifies the
    /// error (paper: "low intensities often yielded unreliable texture values"). Default 0.05.
    pub min_relative_weight: f64,
}

impl Default for DelightOptions {
    fn default() -> Self {
        DelightOptions::from_sample_options(&SampleOptions::default())
    }
}

impl DelightOptions {
    /// The pixel thresholds of `s`, default depth tolerances.
    pub fn from_sample_options(s: &SampleOptions) -> Self {
        DelightOptions {
            min_gamma: s.min_gamma,
            saturation_level: s.saturation_level,
            noise_floor: s.noise_floor,
            depth_tolerance_mm: 0.3,
            depth_tolerance_rel: 0.01,
            min_relative_weight: 0.05,
        }
    }
}

/// One frame de-lit into the texel slots of a [`TexelSet`].
#[derive(Clone, Debug, Default)]
pub struct DelitFrame {
    /// De-lit value `pixel / Psi` per slot (relative albedo, linear); zero where not observed.
    pub value: Vec<[f32; 3]>,
    /// Psi's predicted luminance per slot (linear intensity): how well lit the observation
    /// is; 0 where the texel gives no value for this frame.
    pub weight: Vec<f32>,
}

impl DelitFrame {
    /// Slots observed in this frame.
    pub fn observed(&self) -> usize {
        self.weight.iter().filter(|&&w| w > 0.0).count()
    }
}

/// De-light one frame into every slot of `texels` (parallel over texels).
pub fn delight_frame(
    texels: &TexelSet,
    obs: &Observation,
    opts: &DelightOptions,
) -> Result<DelitFrame> {
    let ctx = FrameCtx::new(obs, opts, max_ray_angle(obs.camera))?;
    let n = texels.len();
    let mut out = DelitFrame {
        value: vec![[0.0; 3]; n],
        weight: vec![0.0; n],
    };
    out.value
        .par_chunks_mut(BLOCK)
        .zip(out.weight.par_chunks_mut(BLOCK))
        .enumerate()
        .for_each(|(b, (val, wt))| {
            if !ctx.block_visible(&texels.blocks[b]) {
                return;
            }
            let s0 = b * BLOCK;
            for k in 0..val.len() {
                if let Some((v, w)) = ctx.texel(texels.point[s0 + k], texels.normal[s0 + k]) {
                    val[k] = v;
                    wt[k] = w;
                }
            }
        });
    Ok(out)
}

/// The largest angle (radians) between the optical axis and the ray of any pixel on the image
/// border: texels beyond it are outside the image (and would fold back into it through a
/// strong distortion polynomial).
pub(crate) fn max_ray_angle(camera: &Camera) -> f64 {
    let (w, h) = (camera.width as f64 - 1.0, camera.height as f64 - 1.0);
    let steps = 64;
    let mut best = 0.0f64;
    for i in 0..=steps {
        let t = i as f64 / steps as f64;
        for (u, v) in [(t * w, 0.0), (t * w, h), (0.0, t * h), (w, t * h)] {
            let r = camera.pixel_ray(u, v);
            best = best.max(r.z.clamp(-1.0, 1.0).acos());
        }
    }
    // Half a pixel of margin beyond the border rays.
    best + 0.5 / camera.fx.min(camera.fy).max(1.0)
}

/// Per-frame constants of the de-lighting.
pub(crate) struct FrameCtx<'a> {
    rot: [[f64; 3]; 3],
    trans: [f64; 3],
    centre: [f64; 3],
    cam: Camera,
    cos_max: f64,
    max_angle: f64,
    width: usize,
    height: usize,
    rgb: &'a [f32],
    depth: &'a [f32],
    depth_max: f64,
    /// Farther than this (mm) the shading is below `min_weight` wherever the point is seen
    /// ([`FrameShading::dimmer_than_beyond`]).
    too_dim_beyond: f64,
    shading: FrameShading<'a>,
    min_gamma: f64,
    sat: f32,
    floor: f32,
    tol_abs: f64,
    tol_rel: f64,
    /// 1.5 px (a bilinear footprint's diagonal plus margin) in normalised image units.
    footprint: f64,
    tan_max: f64,
    /// Smallest accepted Psi luminance (linear intensity).
    min_weight: f64,
}

impl<'a> FrameCtx<'a> {
    /// Check the observation and precompute the frame's transform and thresholds.
    /// `max_angle` is [`max_ray_angle`] of the camera (computed once per video by callers).
    pub(crate) fn new(
        obs: &Observation<'a>,
        opts: &DelightOptions,
        max_angle: f64,
    ) -> Result<Self> {
        let bad = |message: String| {
            Err(ImageError::Inconsistent {
                stage: "de-lighting",
                message,
            }
            .into())
        };
        let (w, h) = (obs.frame.width as usize, obs.frame.height as usize);
        if obs.camera.width as usize != w || obs.camera.height as usize != h {
            return bad(format!(
                "the frame is {w}x{h} but the camera is {}x{}",
                obs.camera.width, obs.camera.height
            ));
        }
        if obs.frame.rgb.len() != 3 * w * h || obs.depth.len() != w * h {
            return bad(format!(
                "a {w}x{h} frame needs {} RGB values and {} depths, got {} and {}",
                3 * w * h,
                w * h,
                obs.frame.rgb.len(),
                obs.depth.len()
            ));
        }
        if w < 2 || h < 2 {
            return bad(format!("a {w}x{h} frame is too small to sample bilinearly"));
        }
        let m = obs.camera_to_world;
        if !m.iter().all(|x| x.is_finite()) {
            return bad("the camera pose is not finite".into());
        }
        if let Err(m) = obs.shading.validate() {
            return bad(m);
        }
        // World → camera of a rigid pose: R^T (x - t).
        let rot = [0, 1, 2].map(|i| [0, 1, 2].map(|j| m[(j, i)]));
        let centre = [m[(0, 3)], m[(1, 3)], m[(2, 3)]];
        let trans = [0, 1, 2].map(|i| -(0..3).map(|j| rot[i][j] * centre[j]).sum::<f64>());
        let (depth_min, depth_max) = obs
            .depth
            .iter()
            .filter(|z| z.is_finite() && **z > 0.0)
            .fold((f32::INFINITY, 0.0f32), |(lo, hi), &z| {
                (lo.min(z), hi.max(z))
            });
        let depth_max = depth_max as f64;
        let min_gamma = (opts.min_gamma as f64).clamp(1e-3, 1.0);
        let min_weight = opts.min_relative_weight.max(0.0)
            * obs
                .shading
                .peak_luminance(min_gamma, depth_min as f64, depth_max);
        let too_dim_beyond = obs.shading.dimmer_than_beyond(min_weight);
        Ok(FrameCtx {
            rot,
            trans,
            centre,
            cam: *obs.camera,
            cos_max: max_angle.cos(),
            max_angle,
            width: w,
            height: h,
            rgb: &obs.frame.rgb,
            depth: obs.depth,
            depth_max,
            too_dim_beyond,
            shading: obs.shading,
            min_gamma,
            sat: opts.saturation_level,
            floor: opts.noise_floor,
            tol_abs: opts.depth_tolerance_mm.max(0.0),
            tol_rel: opts.depth_tolerance_rel.max(0.0),
            footprint: 1.5 / obs.camera.fx.min(obs.camera.fy),
            tan_max: (1.0 - min_gamma * min_gamma).sqrt() / min_gamma,
            min_weight,
        })
    }

    #[inline]
    fn to_camera(&self, p: [f64; 3]) -> [f64; 3] {
        let r = &self.rot;
        [0, 1, 2].map(|i| r[i][0] * p[0] + r[i][1] * p[1] + r[i][2] * p[2] + self.trans[i])
    }

    /// Largest depth tolerance the texel test can allow at distance `d` (mm).
    #[inline]
    fn max_tolerance(&self, d: f64) -> f64 {
        self.tol_abs.max(self.tol_rel * d) + self.footprint * d * self.tan_max
    }

    /// False only when no texel of the block can pass [`FrameCtx::texel`]: behind the camera,
    /// outside the view cone, or farther than anything the frame sees.
    #[inline]
    pub(crate) fn block_visible(&self, b: &BlockSphere) -> bool {
        let pc = self.to_camera(b.centre.map(f64::from));
        let r = b.radius as f64;
        let dist = (pc[0] * pc[0] + pc[1] * pc[1] + pc[2] * pc[2]).sqrt();
        if dist <= r {
            return true;
        }
        if pc[2] + r <= 0.0 {
            return false;
        }
        if dist - r - self.max_tolerance(dist + r) > self.depth_max
            || dist - r > self.too_dim_beyond
        {
            return false;
        }
        let angle = (pc[2] / dist).clamp(-1.0, 1.0).acos();
        angle - (r / dist).asin() <= self.max_angle
    }

    /// De-light one texel: `((pixel - offset) / scale, luminance of scale)` of the frame's
    /// [`FrameShading`], or `None` when this frame gives
    /// no value for it (see the module documentation).
    #[inline]
    pub(crate) fn texel(&self, p: [f32; 3], n: [f32; 3]) -> Option<([f32; 3], f32)> {
        let pw = p.map(f64::from);
        let pc = self.to_camera(pw);
        if !(pc[2] > 0.0) {
            return None;
        }
        let d = (pc[0] * pc[0] + pc[1] * pc[1] + pc[2] * pc[2]).sqrt();
        if pc[2] < self.cos_max * d || d > self.too_dim_beyond {
            return None;
        }
        let v = [0, 1, 2].map(|k| self.centre[k] - pw[k]);
        let gamma = (v[0] * n[0] as f64 + v[1] * n[1] as f64 + v[2] * n[2] as f64) / d;
        if !(gamma >= self.min_gamma) {
            return None;
        }
        let gamma = gamma.min(1.0);
        // Lens model (OpenCV), as Camera::project.
        let c = &self.cam;
        let (x, y) = (pc[0] / pc[2], pc[1] / pc[2]);
        let r2 = x * x + y * y;
        let radial = 1.0 + r2 * (c.k1 + r2 * (c.k2 + r2 * c.k3));
        let xd = x * radial + 2.0 * c.p1 * x * y + c.p2 * (r2 + 2.0 * x * x);
        let yd = y * radial + c.p1 * (r2 + 2.0 * y * y) + 2.0 * c.p2 * x * y;
        let u = c.fx * xd + c.cx;
        let vv = c.fy * yd + c.cy;
        let (wm, hm) = ((self.width - 1) as f64, (self.height - 1) as f64);
        if !(u >= 0.0 && u <= wm && vv >= 0.0 && vv <= hm) {
            return None;
        }
        // u, vv >= 0: truncation is floor, without a libm call.
        let x0 = (u as usize).min(self.width - 2);
        let y0 = (vv as usize).min(self.height - 2);
        let (fx, fy) = ((u - x0 as f64) as f32, (vv - y0 as f64) as f32);
        let i00 = y0 * self.width + x0;
        let idx = [i00, i00 + 1, i00 + self.width, i00 + self.width + 1];
        // Visibility: every pixel of the footprint must see this surface at this depth, within
        // the tolerance plus the depth change across the footprint on a slanted surface.
        let slope = (1.0 - gamma * gamma).sqrt() / gamma;
        let tol = self.tol_abs.max(self.tol_rel * d) + self.footprint * d * slope;
        for &i in &idx {
            let z = self.depth[i] as f64;
            if !((z - d).abs() <= tol) {
                return None;
            }
        }
        let mut px = [[0.0f32; 3]; 4];
        for (k, &i) in idx.iter().enumerate() {
            let q = [self.rgb[3 * i], self.rgb[3 * i + 1], self.rgb[3 * i + 2]];
            if !(q[0] < self.sat && q[1] < self.sat && q[2] < self.sat) {
                return None;
            }
            if q[0] < self.floor && q[1] < self.floor && q[2] < self.floor {
                return None;
            }
            px[k] = q;
        }
        let mut shade = self.shading.shade(gamma, d, pc[2] / d);
        let extra = self.shading.indirect_scale(
            (u + 0.5) / self.width as f64,
            (vv + 0.5) / self.height as f64,
        );
        for (s, e) in shade.scale.iter_mut().zip(extra) {
            *s += e;
        }
        let psi = shade.scale;
        if !psi.iter().all(|&s| s > 1e-9 && s.is_finite()) {
            return None;
        }
        let weight = shade.luminance();
        if !(weight >= self.min_weight) {
            return None;
        }
        let mut value = [0.0f32; 3];
        for ch in 0..3 {
            let top = px[0][ch] + fx * (px[1][ch] - px[0][ch]);
            let bottom = px[2][ch] + fx * (px[3][ch] - px[2][ch]);
            value[ch] = (((top + fy * (bottom - top)) as f64 - shade.offset[ch]) / psi[ch]) as f32;
        }
        Some((value, weight as f32))
    }
}
