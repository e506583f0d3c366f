//! One frame's pose against the model: coarse to fine over the frame's pyramid, at each level
//! Levenberg–Marquardt on the robust photometric error of [`super::align`], re-rendering the
//! model's surface points whenever the pose has moved (visibility changes).

use super::level::{pose_information, State};
use super::photometric::{ModelParts, PhotometricModel, RayGrid};
use super::pose::{delta_between, PoseDelta};
use super::pyramid::{ObservedPyramid, PyramidOptions};
use crate::image::Frame;
use crate::math::Affine;
use crate::render::MipTexture;
use crate::Result;

/// Options of [`FrameRegistrar`]. Steps per frame: build the pyramid of the frame divided by
/// its gain; from `coarsest_level` to `finest_level`, render the model's surface points from
/// the current pose (`fine_stride` pixels apart at level 0, half that per level), take a
/// damped Gauss–Newton step inside the trust region, render again from the new pose and keep
/// it when the cost fell (Levenberg–Marquardt on the rendered cost, at most `max_renders`
/// renders per level); then compare the cost at the first and last pose on the finest grid.
#[derive(Clone, Debug)]
pub struct RegistrationOptions {
    /// The coarsest pyramid level used (level L has 2^L times fewer pixels per side).
    pub coarsest_level: usize,
    /// The finest level used (0 = full resolution).
    pub finest_level: usize,
    /// Pixel step of the model's points at level 0 (1 = every pixel; 0 = about 80 points
    /// across), halved per level down to 1.
    pub fine_stride: usize,
    /// Levels at or above this one use a uniform albedo (the geometry's shading alone),
    /// e.g. while the texture was fused from poorly registered frames. `usize::MAX`: never.
    pub uniform_albedo_from_level: usize,
    /// Weights of the R, G, B residuals on the uniform-albedo levels: blood darkens green and
    /// blue far more than red, so red carries the geometry's shading with the least albedo.
    pub uniform_channel_weights: [f32; 3],
    /// Most renders of the model per level.
    pub max_renders: usize,
    /// Steps between renders. 0 (default): one step per render, kept only when the new render
    /// lowers the cost. N > 0: up to N Levenberg–Marquardt steps on the model's points held
    /// fixed between renders (cheaper per step, but measured on the demo phantom far from the
    /// optimum they head where moving points leave the comparison: 70 of 80 frames converged
    /// from 1.5 mm / 2 degrees against 75 with one step per render).
    pub max_inner: usize,
    /// Largest motion between two renders, in pixels of the level (a trust region: the
    /// points held fixed between renders are only valid near the pose they were rendered
    /// from); it doubles after a successful render and halves after a failed one.
    pub trust_px: f64,
    /// Huber threshold of the normalised residual.
    pub huber: f64,
    /// Expected relative error of the model's prediction (light and texture error).
    pub relative_sigma: f64,
    /// Noise floor of the frames (linear intensity at the frame's own gain): added to the
    /// expected error, and observed pixels darker than it in every channel are not used.
    pub noise_floor: f32,
    /// A frame's channel at or above this is saturated; such pixels are not used.
    pub saturation_level: f32,
    /// A frame with fewer than this share of its pixels (inside the mask) neither under the
    /// noise floor nor saturated shows nothing to register (the lens against the wall, fluid
    /// over it, the light off): [`RegistrationOptions::shows_nothing`]. Such frames are
    /// flagged [`FrameStatus::Blank`] without a registration. Tried, three black frames lost
    /// a track wherever they fell (BENCHMARKS.md, session 32), and one stopped a build from a
    /// tracker's poses at the light's first fit (session 34).
    pub blank_below: f64,
    /// Surface points seen more obliquely than this (cos of the angle) are not used.
    pub min_gamma: f32,
    /// Weight of the model's image gradient in the Jacobian at levels against the texture
    /// (0: the frame's, 1: the model's, 0.5: both averaged); see
    /// [`super::align::LevelProblem::grad_blend`].
    pub grad_blend: f32,
    /// The same at levels against the geometry's shading (from `uniform_albedo_from_level`).
    pub geometry_grad_blend: f32,
    /// Fit a per-frame gain correction with the pose (the light's gains were fitted with the
    /// unrefined poses).
    pub estimate_gain: bool,
    /// Fewest usable points for a level to count.
    pub min_points: usize,
    /// A step whose translation is under this (mm) and whose rotation is under a hundredth of
    /// it (radians) ends a level's iterations; doubled per level.
    pub step_tolerance: f64,
    /// A level ends when failed renders have shrunk the trust region below this fraction of
    /// its starting size.
    pub min_radius: f64,
    /// After a failed render the trust region becomes half the step that failed (the usual
    /// trust-region rule) instead of half the region: a step well inside the region is
    /// otherwise tried again almost unchanged (only the damping grows), a render each time.
    pub shrink_to_failed_step: bool,
    /// Render the model's points off the pixel centres by a fixed sub-pixel offset per ray.
    /// Points rendered at pixel centres read one pixel each; once a step moves the pose they
    /// read a bilinear mix of four, whose noise is lower, so a cost summed over points held
    /// between renders falls for any small move and rises again at the next render (demo
    /// phantom, true poses, joint stage at level 0: 0.695 -> 0.640 held, 0.690 rendered;
    /// with the offsets 0.587 -> 0.580 held, 0.584 rendered). With the offsets the points sit
    /// between pixels at every pose. The model's image gradient
    /// ([`super::align::LevelProblem::set_model_gradient`]) assumes the grid's even spacing,
    /// so this is for solves that read the frame's gradient only (the joint stage).
    pub ray_jitter: bool,
}

impl Default for RegistrationOptions {
    fn default() -> Self {
        RegistrationOptions {
            coarsest_level: 3,
            finest_level: 0,
            fine_stride: 0,
            uniform_albedo_from_level: usize::MAX,
            uniform_channel_weights: [1.0; 3],
            max_renders: 30,
            max_inner: 0,
            trust_px: 1.5,
            huber: 2.0,
            relative_sigma: 0.05,
            noise_floor: 0.004,
            saturation_level: 0.999,
            blank_below: 0.05,
            min_gamma: 0.1,
            // Against the texture, the frame's own gradient: the exact Jacobian of the
            // residual the steps between renders minimise. With the model's, texture rounds
            // grow an error the frames share instead of shrinking it (demo phantom, every pose
            // turned 0.4 deg in pitch, texture rounds alone: 0.52 deg after three, 0.86 after
            // six; with the frame's 0.19 and 0.24), so where they end depends on when they
            // stop. From 1.5 mm / 2 deg drift new views went 29.71 -> 30.64 dB (BENCHMARKS.md).
            grad_blend: 0.0,
            // Against the geometry the model's: the frames divided by their colour's albedo
            // are noisy (1.5 mm / 2 deg: 30.64 dB with the model's gradient in the geometry
            // rounds, 29.87 dB with both averaged there).
            geometry_grad_blend: 1.0,
            estimate_gain: true,
            min_points: 100,
            step_tolerance: 2e-3,
            min_radius: 1.0 / 32.0,
            shrink_to_failed_step: false,
            ray_jitter: false,
        }
    }
}

impl RegistrationOptions {
    /// Whether `frame` shows nothing to register: under [`RegistrationOptions::blank_below`]
    /// of its pixels (inside `mask`) have a brightest channel at or above the noise floor and
    /// none saturated.
    pub fn shows_nothing(&self, frame: &Frame, mask: Option<&[bool]>) -> bool {
        let (mut inside, mut usable) = (0usize, 0usize);
        for (i, px) in frame.rgb.chunks_exact(3).enumerate() {
            if mask.is_some_and(|m| !m[i]) {
                continue;
            }
            inside += 1;
            usable += usize::from(self.comparable(px));
        }
        (usable as f64) < self.blank_below * inside.max(1) as f64
    }

    /// Whether a pixel's RGB can be compared with the model: its brightest channel at or
    /// above the noise floor, and none saturated.
    pub fn comparable(&self, px: &[f32]) -> bool {
        let brightest = px.iter().fold(0.0f32, |a, &v| a.max(v));
        brightest >= self.noise_floor && brightest < self.saturation_level
    }
}

/// A frame to register: linear RGB, its gain in the model's light, an optional mask of the
/// pixels that may be used.
#[derive(Clone, Copy)]
pub struct FrameObs<'a> {
    /// The frame (linear RGB).
    pub frame: &'a Frame,
    /// Its gain g_f in the calibrated light (unitless).
    pub gain: f64,
    /// One flag per pixel, row-major; `None` uses every pixel.
    pub mask: Option<&'a [bool]>,
}

/// How a frame's registration ended.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum FrameStatus {
    /// The steps became smaller than the tolerance at the finest level.
    Converged,
    /// The finest level ran out of renders or steps while still moving.
    NotConverged,
    /// Too few pixels could be compared with the model (pose outside the airway, or the
    /// frame mostly saturated or dark): the initial pose is kept.
    TooFewPoints,
    /// The camera was found outside the lumen: the initial pose is kept.
    OutsideLumen,
    /// The cost stayed far above the video's (see [`super::video`]): not converged.
    HighCost,
    /// The correction departs from its neighbours' far more than a tracker's error can
    /// (see [`super::video`]): the given pose was wrong.
    Outlier,
    /// The frame shows next to nothing, dark or saturated
    /// ([`RegistrationOptions::shows_nothing`]): not registered, and left out.
    Blank,
    /// The frame is far less sharp than the model predicts it from its pose (motion blur,
    /// defocus; [`super::blur`]): left out.
    Blurred,
}

impl FrameStatus {
    /// The status as written in files and reports.
    pub fn name(&self) -> &'static str {
        match self {
            FrameStatus::Converged => "converged",
            FrameStatus::NotConverged => "not_converged",
            FrameStatus::TooFewPoints => "too_few_points",
            FrameStatus::OutsideLumen => "outside_lumen",
            FrameStatus::HighCost => "high_cost",
            FrameStatus::Outlier => "outlier",
            FrameStatus::Blank => "blank",
            FrameStatus::Blurred => "blurred",
        }
    }
}

/// The result for one frame.
#[derive(Clone, Debug)]
pub struct FrameRegistration {
    /// The refined camera → world pose (the initial one when the frame failed).
    pub pose: Affine,
    /// The correction from the initial pose (world mm and radians).
    pub correction: PoseDelta,
    /// Gain correction found (multiplies the frame's gain; 1 when not estimated).
    pub gain_factor: f64,
    /// Mean robust cost per residual on the finest grid at the initial pose.
    pub cost_before: f64,
    /// The same at the refined pose.
    pub cost_after: f64,
    /// Points used on the finest grid at the refined pose.
    pub points: usize,
    /// Levenberg–Marquardt steps taken over all levels.
    pub iterations: usize,
    /// How it ended.
    pub status: FrameStatus,
    /// Gauss–Newton information of the six pose parameters (camera-frame step of
    /// [`super::pose::perturb`], gain eliminated) on the finest grid.
    pub information: [[f64; 6]; 6],
}

/// A model with the ray grids of every pyramid level, ready to register frames.
pub struct FrameRegistrar<'a> {
    /// The model.
    pub model: PhotometricModel<'a>,
    /// A copy of the model without texture (for the uniform-albedo levels).
    pub(crate) uniform: PhotometricModel<'a>,
    pub(crate) grids: Vec<RayGrid>,
    /// The options.
    pub opts: RegistrationOptions,
}

impl<'a> FrameRegistrar<'a> {
    /// Prepare `parts` for registration with `opts`.
    pub fn new(parts: ModelParts<'a>, opts: RegistrationOptions) -> Result<FrameRegistrar<'a>> {
        let model = PhotometricModel::new(parts)?;
        let uniform = PhotometricModel::new(ModelParts {
            texture: None::<&MipTexture>,
            ..parts
        })?;
        // About 80 points across at level 0 (measured on the 320-pixel demo: stride 4 against 2
        // halves the time, median error 0.012 -> 0.016 mm against a model of the true poses).
        let fine_stride = match opts.fine_stride {
            0 => (parts.camera.width as usize / 80).max(1),
            s => s,
        };
        let grids = (0..=opts.coarsest_level)
            .map(|l| {
                RayGrid::with_jitter(parts.camera, l, (fine_stride >> l).max(1), opts.ray_jitter)
            })
            .collect();
        Ok(FrameRegistrar {
            model,
            uniform,
            grids,
            opts,
        })
    }

    pub(crate) fn model_at(&self, level: usize) -> &PhotometricModel<'a> {
        if level >= self.opts.uniform_albedo_from_level {
            &self.uniform
        } else {
            &self.model
        }
    }

    /// The image pyramid of `obs` down to the coarsest level used.
    pub(crate) fn pyramid(&self, obs: &FrameObs) -> Result<ObservedPyramid> {
        ObservedPyramid::new(
            obs.frame,
            self.model.parts.camera,
            obs.gain,
            obs.mask,
            &PyramidOptions {
                levels: self.opts.coarsest_level,
                saturation_level: self.opts.saturation_level,
            },
        )
    }

    /// The mean robust cost per residual of `obs` at `pose` on `level`'s grid (gain
    /// correction 1); `None` when the model cannot be compared with the frame there.
    pub fn cost_at(&self, obs: &FrameObs, pose: &Affine, level: usize) -> Result<Option<f64>> {
        let pyr = self.pyramid(obs)?;
        let floor = f64::from(self.opts.noise_floor) / obs.gain;
        let level = level.min(pyr.levels.len() - 1);
        Ok(self
            .snapshot(&pyr, level, pose, 0.0, floor)
            .ok()
            .map(|s| s.mean_cost))
    }

    /// Refine the pose of `obs` starting from `initial` (camera → world).
    pub fn refine_frame(&self, obs: &FrameObs, initial: &Affine) -> Result<FrameRegistration> {
        let o = &self.opts;
        let pyr = self.pyramid(obs)?;
        let floor = f64::from(o.noise_floor) / obs.gain;
        let finest = o.finest_level.min(pyr.levels.len() - 1);
        let coarsest = o.coarsest_level.min(pyr.levels.len() - 1);
        let mut state = State {
            pose: *initial,
            log_k: 0.0,
            iterations: 0,
            converged: false,
        };
        let before = self.snapshot(&pyr, finest, initial, 0.0, floor);
        let mut fail = before.as_ref().err().copied();
        // The finest level ends with the model rendered at the pose it returns.
        let mut last = None;
        if fail.is_none() {
            for level in (finest..=coarsest).rev() {
                match self.refine_level(&pyr, level, &mut state, floor) {
                    Ok(snapshot) => last = Some(snapshot),
                    Err(status) => {
                        fail = Some(status);
                        break;
                    }
                }
            }
        }
        let (pose, log_k, after) = match (fail, &last) {
            (None, Some(a)) => (state.pose, state.log_k, Ok(a)),
            _ => (*initial, 0.0, before.as_ref()),
        };
        let status = fail.or(after.err().copied()).unwrap_or(if state.converged {
            FrameStatus::Converged
        } else {
            FrameStatus::NotConverged
        });
        let (cost_after, points, information) = match after {
            Ok(a) => (a.mean_cost, a.lin.used, pose_information(&a.lin.h)),
            Err(_) => (f64::NAN, 0, [[0.0; 6]; 6]),
        };
        Ok(FrameRegistration {
            pose,
            correction: delta_between(initial, &pose),
            gain_factor: log_k.exp(),
            cost_before: before.as_ref().map_or(f64::NAN, |b| b.mean_cost),
            cost_after,
            points,
            iterations: state.iterations,
            status,
            information,
        })
    }
}
