//! Tracking a video without a tracker (`--poses first`, issue 16 item 5): only the first
//! frame's pose is known. Each next frame starts from the previous refined poses at constant
//! velocity (extrapolated from the last two accepted frames) and is registered against the
//! geometry's shading with its colour-predicted albedo, as the first round of
//! [`super::rounds`] does (no texture of the later frames exists yet).
//!
//! A frame is accepted when its registration converged, its cost lies within `cost_ratio`
//! of the accepted frames' recent costs, and it moved no further from the prediction, or from
//! the last accepted pose, than a bronchoscope moves in the frames since that pose. A frame
//! that is not accepted is flagged (its pose is the prediction) and tracking continues from
//! the last accepted poses; after `lost_after` flagged frames in a row the track is lost from
//! the first of them, and every later frame is still tried from the last accepted poses (the
//! track may be found again, but the report names the first frame lost). A frame that shows
//! nothing to register (black, or saturated) is flagged without a registration and does not
//! count towards the loss; the frame after a gap is tried from more starts (the scope may
//! have stopped, gone on, or turned while unseen).

use super::blur::{frame_energies, sharpness_against_frame, sharpness_at_pose};
use super::chroma::ChromaAlbedo;
use super::frame::RegistrationOptions;
use super::frame::{FrameObs, FrameRegistrar, FrameRegistration, FrameStatus};
use super::photometric::{ModelParts, RayGrid};
use super::pose::{delta_between, extrapolate, perturb};
use super::rounds::levels_below_reference;
use crate::camera::pose::camera_centre;
use crate::image::Frame;
use crate::math::Affine;
use crate::Result;

/// Options of [`Tracker`].
#[derive(Clone, Debug)]
pub struct TrackOptions {
    /// Per-frame registration (its uniform-albedo settings are set by the tracker).
    pub frame: RegistrationOptions,
    /// Weights of the R, G, B residuals against the geometry's shading (red: the least
    /// albedo; see [`super::rounds::RoundOptions`]).
    pub channel_weights: [f32; 3],
    /// A frame whose cost exceeds this many times the median of the last accepted frames'
    /// costs is not accepted.
    pub cost_ratio: f64,
    /// Accepted frames whose costs make that median.
    pub cost_window: usize,
    /// A frame whose refined pose is further than this (mm) per frame since the last accepted
    /// one from both its prediction and the last accepted pose is not accepted.
    pub max_jump_mm: f64,
    /// The same for the rotation (degrees). A scope turns up to 17 deg between frames 2 mm
    /// apart on the real airway trees, its constant-velocity prediction up to 13 deg off: at
    /// 10 deg the tracker refused the right pose there and lost the track (ATM_307 at frame
    /// 14, ATM_384 at 42 of 80); at 20 both are tracked to the end (BENCHMARKS.md, session 30).
    pub max_jump_deg: f64,
    /// Frames flagged in a row after which the track is lost.
    pub lost_after: usize,
    /// Register against the texture fused from the frames tracked so far (`false`: against
    /// the geometry's shading, each frame divided by the albedo its colour predicts). A
    /// round airway looks the same rolled about the view axis: without texture the roll
    /// drifts (demo phantom: 2 degrees after 1 frame, 14 after 8, 140 median).
    pub against_texture: bool,
    /// Against texture, pyramid levels at or above this one still register against the
    /// geometry's shading (red channel): the lumen's dark centre pins the view direction,
    /// which a texture fused from the tracked frames follows when they drift.
    pub geometry_from_level: usize,
    /// The frame after a gap ([`TrackState::after_gap`]) is tried from the prediction, the
    /// last accepted pose, and that pose moved on along its view axis at the last speed
    /// ([`TrackState::advanced`]); when none of them leads to an accepted pose, from all three
    /// turned this far (degrees) either way about their camera's x and y axes (0: as any
    /// other frame, from the last accepted pose only when the prediction is not accepted). Across a gap the constant-velocity rotation runs away (the demo's
    /// view 7, 14 and 28 deg off one, two and three frames into one); the scope's advance
    /// does not. A blackout of 2-5 frames at frame 30 of the demo's video lost the track
    /// without; with, the frames after it ended within 1 mm (BENCHMARKS.md, session 34).
    pub relocalise_deg: f64,
    /// Against texture, an accepted frame whose sharpness against the model's prediction from
    /// its pose ([`super::blur::sharpness_at_pose`]) is under this share of the recent accepted
    /// frames' median is not accepted but flagged `blurred`: it does not count towards the
    /// loss, and the frame after it is tried as after a gap (0: never). Registered and fused
    /// into the texture the next frames are tracked against, blurred frames led the demo's
    /// video with a fifth of its frames motion-blurred 6-45 deg off in its last frames
    /// (BENCHMARKS.md, session 36).
    pub blurred_below: f64,
    /// A frame under [`Self::blurred_below`] is flagged only when, along some direction, its
    /// own detail ([`super::blur::frame_energies`]) is also under this share of the last
    /// accepted frame's (0: the first test alone). The model the sharpness is judged against is
    /// fitted again every few frames, and the recent frames' median was judged against older
    /// fits: where a new fit predicts the frames sharper (near walls first seen from afar),
    /// sharp frames fell under it. On `phantom --seed 7` (no frame blurred) seven of frames
    /// 50-57, at the carina, were flagged (1.5-1.9 against a median of 2.76), the tracker went
    /// on from predicted poses and frames 60-79 ended 3-16 deg off in roll. Against the last
    /// accepted frame the sharp frames the first test flags there keep 0.99 of its detail, the
    /// demo's motion-blurred frames (`--motion-blur-share 0.2`) 0.18-0.46 (BENCHMARKS.md,
    /// session 46).
    pub blurred_against_last_below: f64,
    /// Accepted frames whose sharpness makes that median (at least 4 are needed to judge).
    pub sharpness_window: usize,
}

impl Default for TrackOptions {
    fn default() -> Self {
        TrackOptions {
            frame: RegistrationOptions::default(),
            channel_weights: [1.0, 0.0, 0.0],
            cost_ratio: 2.5,
            cost_window: 9,
            max_jump_mm: 3.0,
            max_jump_deg: 20.0,
            lost_after: 3,
            against_texture: true,
            geometry_from_level: 2,
            relocalise_deg: 10.0,
            blurred_below: 0.7,
            blurred_against_last_below: 0.5,
            sharpness_window: 9,
        }
    }
}

/// The track so far: one entry per frame of the video.
#[derive(Clone, Debug)]
pub struct TrackState {
    /// Camera → world pose of each frame: refined when accepted, predicted when flagged, the
    /// first frame's until tracked.
    pub poses: Vec<Affine>,
    /// Each frame's gain in the light it was tracked with (carried from the previous frame
    /// and corrected by its registration).
    pub gains: Vec<f64>,
    /// How each frame's registration ended (`None`: not tracked yet; the first frame is
    /// given).
    pub status: Vec<Option<FrameStatus>>,
    /// The frame was accepted (the first frame always is).
    pub accepted: Vec<bool>,
    /// Each frame's registration cost at its pose (NaN when not tracked).
    pub costs: Vec<f64>,
    /// Each frame's sharpness against the model's prediction from its pose (NaN when not
    /// judged).
    pub sharpness: Vec<f64>,
    /// The first frame of the first run of `lost_after` flagged frames.
    pub first_lost: Option<usize>,
    flagged_in_row: usize,
    /// Each frame's position in the video (frame number): the constant velocity is per
    /// video frame, and frames left out between tracked ones widen the step.
    times: Vec<f64>,
}

impl TrackState {
    /// The frames numbered `frame_numbers` in their video (increasing), the first with the
    /// pose `first` and gain `gain`.
    pub fn new(frame_numbers: &[usize], first: Affine, gain: f64) -> TrackState {
        let n = frame_numbers.len();
        let mut accepted = vec![false; n];
        accepted[0] = true;
        TrackState {
            poses: vec![first; n],
            gains: vec![gain; n],
            status: vec![None; n],
            accepted,
            costs: vec![f64::NAN; n],
            sharpness: vec![f64::NAN; n],
            first_lost: None,
            flagged_in_row: 0,
            times: frame_numbers.iter().map(|&f| f as f64).collect(),
        }
    }

    /// Track again from frame `f` on, the frames before it at `poses` (refined since they
    /// were tracked): the frames from `f` on are untracked again and the track not lost.
    pub fn resume_at(&mut self, f: usize, poses: &[Affine]) {
        self.poses[..f].copy_from_slice(&poses[..f]);
        let gain = self.gains[self.accepted_before(f).last().copied().unwrap_or(0)];
        for i in f..self.poses.len() {
            self.poses[i] = poses[f - 1];
            self.gains[i] = gain;
            self.status[i] = None;
            self.accepted[i] = false;
            self.costs[i] = f64::NAN;
            self.sharpness[i] = f64::NAN;
        }
        self.first_lost = None;
        self.flagged_in_row = 0;
    }

    /// The first frame not tracked yet (the video's length when every frame was).
    pub fn next_untracked(&self) -> usize {
        (1..self.poses.len())
            .find(|&i| self.status[i].is_none())
            .unwrap_or(self.poses.len())
    }

    /// The accepted frames before `f`, in order.
    pub fn accepted_before(&self, f: usize) -> Vec<usize> {
        (0..f).filter(|&i| self.accepted[i]).collect()
    }

    /// The pose of frame `f` at constant velocity from the last two accepted frames before
    /// it (centre linear, rotation along the geodesic); the last one's pose when only one is.
    pub fn predict(&self, f: usize) -> Affine {
        let ok = self.accepted_before(f);
        match ok.as_slice() {
            [] => self.poses[0],
            [a] => self.poses[*a],
            [.., a, b] => {
                let t = &self.times;
                extrapolate(&self.poses[*a], t[*a], &self.poses[*b], t[*b], t[f])
            }
        }
    }

    /// Whether frame `f` comes after a gap: a frame not accepted since the last accepted one,
    /// or more than 2.5 times as long since it as between the last two accepted frames (a
    /// dense track of a long video skips the frames judged too dark or blurred to use; frames
    /// tracked evenly spaced are at most twice as far apart as the nearest two).
    pub fn after_gap(&self, f: usize) -> bool {
        let ok = self.accepted_before(f);
        match ok.as_slice() {
            [] => false,
            [.., b] if *b + 1 < f => true,
            [.., a, b] => {
                let t = &self.times;
                t[f] - t[*b] > 2.5 * (t[*b] - t[*a])
            }
            [_] => false,
        }
    }

    /// The time from the last accepted frame before `f` to `f`, in the spacing of the last
    /// two accepted frames, and at least the frames tried since: after frames not accepted,
    /// or frames the selection left out (black ones), the scope had that much longer to move.
    pub fn steps_since_accepted(&self, f: usize) -> f64 {
        let ok = self.accepted_before(f);
        let tried = ok.last().map_or(1, |&b| f - b) as f64;
        match ok.as_slice() {
            [.., a, b] => {
                let t = &self.times;
                ((t[f] - t[*b]) / (t[*b] - t[*a])).max(tried)
            }
            _ => tried,
        }
    }

    /// The last accepted pose before `f` moved along its view axis as far as the scope
    /// moved per frame between the last two accepted frames, times the frames since: across
    /// a gap a scope goes on down the airway while its turn is unknown.
    pub fn advanced(&self, f: usize) -> Affine {
        let ok = self.accepted_before(f);
        let [.., a, b] = ok.as_slice() else {
            return self.predict(f);
        };
        let t = &self.times;
        let (ca, cb) = (
            camera_centre(&self.poses[*a]),
            camera_centre(&self.poses[*b]),
        );
        let speed = (cb - ca).norm() / (t[*b] - t[*a]);
        let ahead = speed * (t[f] - t[*b]);
        perturb(&self.poses[*b], &[0.0, 0.0, ahead, 0.0, 0.0, 0.0])
    }

    fn median_cost(&self, f: usize, window: usize) -> Option<f64> {
        self.recent_median(&self.costs, f, window, 1)
    }

    /// The median of `values` over the last `window` accepted frames before `f` where they are
    /// finite; `None` with fewer than `min` of them.
    fn recent_median(&self, values: &[f64], f: usize, window: usize, min: usize) -> Option<f64> {
        let mut c: Vec<f64> = self
            .accepted_before(f)
            .into_iter()
            .rev()
            .map(|i| values[i])
            .filter(|c| c.is_finite())
            .take(window)
            .collect();
        if c.len() < min.max(1) {
            return None;
        }
        c.sort_by(f64::total_cmp);
        Some(c[c.len() / 2])
    }
}

/// The poses of the frames `flagged` that lie between two frames not flagged, on the motion
/// between those two (centre linear, rotation along the geodesic) at their frame numbers
/// `times`. A frame the tracker could not register keeps its prediction, extrapolated from
/// the frames before it: two black frames ended 0.9 mm / 3.0 deg and 2.1 mm / 9.1 deg off,
/// between their neighbours 0.36 mm / 2.9 deg and 0.29 mm / 2.3 deg (`tests/tracking.rs`,
/// `a_blackout_of_two_frames_is_crossed`).
pub fn interpolate_flagged(poses: &mut [Affine], flagged: &[bool], times: &[usize]) {
    let kept: Vec<usize> = (0..poses.len()).filter(|&i| !flagged[i]).collect();
    for w in kept.windows(2) {
        let (a, b) = (w[0], w[1]);
        let (ta, tb) = (times[a] as f64, times[b] as f64);
        for i in a + 1..b {
            poses[i] = extrapolate(&poses[a], ta, &poses[b], tb, times[i] as f64);
        }
    }
}

/// A model to track frames against: the geometry's shading under the light, each frame
/// divided by the albedo its colour predicts.
pub struct Tracker<'a> {
    reg: FrameRegistrar<'a>,
    /// Against texture: one ray per pixel, where a frame's sharpness is judged.
    pixel_grid: Option<RayGrid>,
    /// Without texture: the colour–albedo relation the frames are divided by.
    chroma: Option<ChromaAlbedo>,
    opts: TrackOptions,
}

impl<'a> Tracker<'a> {
    /// The tracker for `parts` (light and texture fitted on frames already tracked), whose
    /// colour–albedo relation is fitted on the texture seen from `seen_from`.
    pub fn new(parts: ModelParts<'a>, seen_from: &[Affine], opts: &TrackOptions) -> Result<Self> {
        let mut frame_opts = opts.frame.clone();
        frame_opts.uniform_albedo_from_level = match opts.against_texture {
            true => opts.geometry_from_level,
            false => 0,
        };
        // The levels are set for 320-pixel frames, as the rounds' are. At the reference's
        // levels the demo phantom's path at 160x160 was lost at the carina and 54 of 80 frames
        // ended within 1 mm and 1 deg (27.29 dB); counted from the frames' size, none lost and
        // 77 (29.85 dB; BENCHMARKS.md, session 32).
        let below = levels_below_reference(parts.camera);
        frame_opts.coarsest_level = frame_opts.coarsest_level.saturating_sub(below);
        frame_opts.finest_level = frame_opts.finest_level.saturating_sub(below);
        frame_opts.uniform_albedo_from_level =
            frame_opts.uniform_albedo_from_level.saturating_sub(below);
        frame_opts.uniform_channel_weights = opts.channel_weights;
        let reg = FrameRegistrar::new(parts, frame_opts)?;
        let chroma = match opts.against_texture {
            true => None,
            false => Some(ChromaAlbedo::fit(
                &reg.model,
                &RayGrid::new(parts.camera, 2, 1),
                seen_from,
            )?),
        };
        let pixel_grid = (opts.against_texture && opts.blurred_below > 0.0)
            .then(|| RayGrid::new(parts.camera, 0, 1));
        Ok(Tracker {
            reg,
            pixel_grid,
            chroma,
            opts: opts.clone(),
        })
    }

    /// Register frame `f` alone from `from` at gain `gain`, with no prediction and no gate:
    /// the first frame's pose, given only roughly, refined before tracking starts from it.
    pub fn register_alone(
        &self,
        frames: &[Frame],
        mask: Option<&[bool]>,
        f: usize,
        from: &Affine,
        gain: f64,
    ) -> Result<FrameRegistration> {
        let frame = self.prepare(&frames[f]);
        let obs = FrameObs {
            frame: &frame,
            gain,
            mask,
        };
        self.reg.refine_frame(&obs, from)
    }

    /// The frame as registered: divided by its colour's albedo when not against texture.
    fn prepare<'f>(&self, frame: &'f Frame) -> std::borrow::Cow<'f, Frame> {
        match &self.chroma {
            Some(c) => std::borrow::Cow::Owned(c.normalise(frame, self.reg.opts.saturation_level)),
            None => std::borrow::Cow::Borrowed(frame),
        }
    }

    /// Register frame `f` from the prediction of `state` (and, when that is not accepted,
    /// from the last accepted pose, and after a gap from both turned); [`TrackState::commit`]
    /// records the result.
    pub fn try_frame(
        &self,
        frames: &[Frame],
        mask: Option<&[bool]>,
        state: &TrackState,
        f: usize,
    ) -> Result<FrameTry> {
        let o = &self.opts;
        let last = *state.accepted_before(f).last().unwrap_or(&0);
        let gain = state.gains[last];
        let predicted = state.predict(f);
        let ro = &self.reg.opts;
        if ro.shows_nothing(&frames[f], mask) {
            return Ok(FrameTry {
                accepted: false,
                status: FrameStatus::Blank,
                pose: predicted,
                gain,
                cost: f64::NAN,
                sharpness: None,
            });
        }
        let frame = self.prepare(&frames[f]);
        let obs = FrameObs {
            frame: &frame,
            gain,
            mask,
        };
        let gate = state
            .median_cost(f, o.cost_window)
            .map(|m| m * o.cost_ratio);
        let converged = |r: &FrameRegistration| {
            matches!(r.status, FrameStatus::Converged | FrameStatus::NotConverged)
                && r.cost_after.is_finite()
        };
        let still = state.poses[last];
        // The gate is per frame tried: after frames not accepted (a blackout, a turn refused)
        // the scope has had as many frames' time to move. Measured on two black frames (10
        // and 11 of 22): frame 12's pose lay 3.3 mm and 16 deg from its prediction, 4.5 mm
        // from frame 9's, and was refused at one frame's 3 mm; the start that passed found
        // it one cartilage ring away (4 mm), and the rest of the video with it. Scaled: 0.1
        // mm, and the video on track (BENCHMARKS.md, session 32).
        let steps = state.steps_since_accepted(f);
        let far = |from: &Affine, r: &FrameRegistration| {
            let jump = delta_between(from, &r.pose);
            jump.mm() > o.max_jump_mm * steps || jump.deg() > o.max_jump_deg * steps
        };
        // The prediction at constant velocity is the better start on a smooth video, but
        // where the scope jerks the last pose can be the nearer one (the demo phantom turns
        // 5 deg a frame, median, and the constant-velocity rotation is 3.5 deg off, median, up
        // to 14 deg): a frame is a jump when it is far from both.
        let jumped = |r: &FrameRegistration| far(&predicted, r) && far(&still, r);
        let accept = |r: &FrameRegistration| {
            converged(r) && gate.is_none_or(|g| r.cost_after <= g) && !jumped(r)
        };
        let better = |a: &FrameRegistration, b: &FrameRegistration| match (accept(a), accept(b)) {
            (true, false) => true,
            (x, y) => x == y && a.cost_after < b.cost_after,
        };
        let try_from = |best: &mut FrameRegistration, start: &Affine| -> Result<()> {
            let other = self.reg.refine_frame(&obs, start)?;
            if better(&other, best) {
                *best = other;
            }
            Ok(())
        };
        let mut best = self.reg.refine_frame(&obs, &predicted)?;
        if state.after_gap(f) && o.relocalise_deg > 0.0 {
            // After a gap the scope may have stopped, gone on, or turned: every start is
            // tried, and the one that fits the frame best is kept.
            let advanced = state.advanced(f);
            for start in [still, advanced] {
                try_from(&mut best, &start)?;
            }
            if !accept(&best) {
                for start in turned_starts(&[predicted, still, advanced], o.relocalise_deg) {
                    try_from(&mut best, &start)?;
                }
            }
        } else if !accept(&best) && delta_between(&predicted, &still).mm() > 0.05 {
            // At constant velocity the prediction overshoots when the scope stops.
            try_from(&mut best, &still)?;
        }
        let accepted = accept(&best);
        let sharpness = match (&self.pixel_grid, accepted) {
            (Some(grid), true) => {
                sharpness_at_pose(&self.reg.model, grid, &best.pose, &frames[f], mask, ro)
            }
            _ => None,
        };
        let reference = state.recent_median(&state.sharpness, f, o.sharpness_window, 4);
        // The frame's detail against the last accepted frame's, asked only of a frame the
        // model's prediction finds blurred.
        let against_last = || -> Option<f64> {
            let last = *state.accepted_before(f).last()?;
            let ro = &self.reg.opts;
            let now = frame_energies(&frames[f], mask, ro)?;
            sharpness_against_frame(&now, &frame_energies(&frames[last], mask, ro)?)
        };
        if let (Some(s), Some(m)) = (sharpness, reference) {
            if s < o.blurred_below * m
                && (o.blurred_against_last_below <= 0.0
                    || against_last().is_none_or(|r| r < o.blurred_against_last_below))
            {
                return Ok(FrameTry {
                    accepted: false,
                    status: FrameStatus::Blurred,
                    pose: predicted,
                    gain,
                    cost: best.cost_after,
                    sharpness,
                });
            }
        }
        let status = match best.status {
            _ if accepted => best.status,
            FrameStatus::Converged | FrameStatus::NotConverged if jumped(&best) => {
                FrameStatus::Outlier
            }
            FrameStatus::Converged | FrameStatus::NotConverged => FrameStatus::HighCost,
            s => s,
        };
        Ok(FrameTry {
            accepted,
            status,
            pose: if accepted { best.pose } else { predicted },
            gain: if accepted {
                gain * best.gain_factor
            } else {
                gain
            },
            cost: best.cost_after,
            sharpness,
        })
    }
}

/// Each of `poses` turned by `deg` either way about its camera's x and y axes.
fn turned_starts(poses: &[Affine], deg: f64) -> Vec<Affine> {
    let a = deg.to_radians();
    let turns = [[a, 0.0], [-a, 0.0], [0.0, a], [0.0, -a]];
    poses
        .iter()
        .flat_map(|p| {
            turns
                .iter()
                .map(move |[x, y]| perturb(p, &[0.0, 0.0, 0.0, *x, *y, 0.0]))
        })
        .collect()
}

/// One frame's tracking result, before [`TrackState::commit`].
#[derive(Clone, Copy, Debug)]
pub struct FrameTry {
    /// Accepted (see the module docs).
    pub accepted: bool,
    /// How it ended (`HighCost` or `Outlier` when it converged but was not accepted).
    pub status: FrameStatus,
    /// The refined pose when accepted, else the prediction.
    pub pose: Affine,
    /// Its gain.
    pub gain: f64,
    /// Its registration cost.
    pub cost: f64,
    /// Its sharpness against the model's prediction from its refined pose, when judged.
    pub sharpness: Option<f64>,
}

impl TrackState {
    /// Record frame `f`'s result; `lost_after` flagged frames in a row lose the track.
    pub fn commit(&mut self, f: usize, t: &FrameTry, lost_after: usize) {
        self.accepted[f] = t.accepted;
        self.costs[f] = t.cost;
        self.sharpness[f] = t.sharpness.filter(|_| t.accepted).unwrap_or(f64::NAN);
        self.poses[f] = t.pose;
        self.gains[f] = t.gain;
        self.status[f] = Some(t.status);
        if t.accepted {
            self.flagged_in_row = 0;
        } else if !matches!(t.status, FrameStatus::Blank | FrameStatus::Blurred) {
            self.flagged_in_row += 1;
            if self.flagged_in_row >= lost_after && self.first_lost.is_none() {
                self.first_lost = Some(f + 1 - lost_after);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::math::{Matrix3, Rotation3, Vector3};
    use crate::registration::pose::pose_from;

    fn pose_at(x: f64, turn_deg: f64) -> Affine {
        let r = Rotation3::new(Vector3::new(0.0, 0.0, turn_deg.to_radians())).into_inner();
        pose_from(&r, &Vector3::new(x, 0.0, 0.0))
    }

    #[test]
    fn across_a_gap_the_scope_goes_on_along_its_view_and_blank_frames_do_not_lose_it() {
        // Looking along world z, 2 mm a frame: accepted at frames 0 and 1, then a gap.
        let along = |z: f64| pose_from(&Matrix3::identity(), &Vector3::new(0.0, 0.0, z));
        let numbers: Vec<usize> = (0..8).collect();
        let mut state = TrackState::new(&numbers, along(0.0), 1.0);
        let try_at = |pose, accepted, blank| FrameTry {
            accepted,
            status: match blank {
                true => FrameStatus::Blank,
                false => FrameStatus::Converged,
            },
            pose,
            gain: 1.0,
            cost: 1.0,
            sharpness: None,
        };
        state.commit(1, &try_at(along(2.0), true, false), 3);
        for f in 2..6 {
            state.commit(f, &try_at(along(0.0), false, true), 3);
        }
        assert_eq!(state.first_lost, None, "blank frames are not refusals");
        assert!(!state.after_gap(2) && state.after_gap(6));
        let d = delta_between(&along(12.0), &state.advanced(6));
        assert!(d.mm() < 1e-9 && d.deg() < 1e-9, "{d:?}");
        for f in 6..8 {
            state.commit(f, &try_at(along(0.0), false, false), 2);
        }
        assert_eq!(state.first_lost, Some(6));
    }

    #[test]
    fn a_gap_in_time_between_tracked_frames_is_a_gap() {
        // Frames numbered 0, 2, 4, 10: the video's frames 5-9 were not tracked.
        let mut state = TrackState::new(&[0, 2, 4, 10], Affine::identity(), 1.0);
        state.accepted[1] = true;
        state.accepted[2] = true;
        assert!(!state.after_gap(2));
        assert!(state.after_gap(3));
        assert_eq!(state.steps_since_accepted(3), 3.0);
    }

    #[test]
    fn flagged_frames_between_kept_ones_lie_on_their_motion() {
        // Frames numbered 0, 1, 2, 4, 5: frames 1 and 2 flagged between 0 and 4, frame 5
        // flagged after the last kept one.
        let times = [0, 1, 2, 4, 5];
        let flagged = [false, true, true, false, true];
        let wild = pose_at(50.0, 90.0);
        let mut poses = [pose_at(0.0, 0.0), wild, wild, pose_at(8.0, 40.0), wild];
        interpolate_flagged(&mut poses, &flagged, &times);
        for (i, x, deg) in [(1, 2.0, 10.0), (2, 4.0, 20.0)] {
            let d = delta_between(&pose_at(x, deg), &poses[i]);
            assert!(d.mm() < 1e-9 && d.deg() < 1e-9, "frame {i}: {d:?}");
        }
        assert_eq!(poses[0], pose_at(0.0, 0.0));
        assert_eq!(poses[3], pose_at(8.0, 40.0));
        assert_eq!(poses[4], wild, "no kept frame after it: left as it was");
    }
}
