//! What the registration stage of a build did (model.json `registration`, issue 16): every
//! frame's correction and status, and the rounds of the alternation.

use crate::io::poses::PoseEntry;
use crate::math::Affine;
use crate::registration::accuracy::PoseAccuracy;
use serde::{Deserialize, Serialize};

/// One frame's registration, as model.json and poses.json record it.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct FramePoseResult {
    /// Index of the frame in the case's poses.json.
    pub frame: usize,
    /// Distance between the given and the refined camera centre (mm).
    pub correction_mm: f64,
    /// Rotation between the given and the refined camera (degrees).
    pub correction_deg: f64,
    /// How its last round ended (`converged`, `not_converged`, `outlier`, ...), or why it
    /// was not registered or not used: `blank` (it shows next to nothing), `blurred` (far less
    /// sharp than the model predicts it; its pose is the first rounds', or between its
    /// neighbours' when the tracker found it), `track_lost`.
    pub status: String,
    /// The model was built with this frame (flagged frames are left out).
    pub used: bool,
}

/// One round of the alternation.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct RoundSummary {
    /// What the frames were registered against (`geometry` or `texture`).
    pub against: String,
    /// Median over frames of how far this round moved a pose (mm, degrees).
    pub median_step_mm: f64,
    /// See `median_step_mm`.
    pub median_step_deg: f64,
    /// Frames per status at the end of the round.
    pub counts: std::collections::BTreeMap<String, usize>,
    /// Frames moved as part of a run registered away from its neighbours: a run one airway
    /// ring off, registered again in a round (`registration::blocks`), or a run the joint
    /// stage's search moved along its views (`registration::joint_shift`).
    #[serde(default)]
    pub realigned: usize,
    /// Wall time of the round (s): light, texture and registration.
    pub seconds: f64,
    /// The round converged on too few frames and its poses were discarded.
    #[serde(default)]
    pub discarded: bool,
}

/// What the registration stage did.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct PoseRegistration {
    /// Every frame of the case, in video order.
    pub frames: Vec<FramePoseResult>,
    /// The rounds run.
    pub rounds: Vec<RoundSummary>,
    /// The stage after the rounds that refines every frame they kept at once, the albedo
    /// eliminated (`registration::joint`); `None` when it did not run.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub joint: Option<RoundSummary>,
    /// Frames left out of the model.
    pub left_out: usize,
    /// The poses the model was built with: `refined`, or `given` unless the refined poses
    /// predict held-out frames more than `registration_keep_margin_db` (1 dB) better.
    pub kept: String,
    /// The calibrated light's mean PSNR on held-out frames with the given poses (dB; `None`
    /// without cross-validation).
    pub held_out_psnr_given_db: Option<f64>,
    /// The same with the refined poses.
    pub held_out_psnr_refined_db: Option<f64>,
    /// With `--poses first`: how tracking from the first frame's pose went (the "given"
    /// poses above are then the tracked ones).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub tracking: Option<TrackingSummary>,
    /// The model whose calibrated light (the same bronchoscope's) the first round and the
    /// tracking from the first pose registered against, with this video's gains
    /// (`--scope-light`); `None`: lights fitted at the given or tracked poses.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub scope_light: Option<String>,
    /// The first round was run again against a Lambertian lamp with a uniform beam and this
    /// video's gains ([`crate::shading::calibrated::lambert_lamp`]): against the light fitted
    /// at the given poses it converged on too few frames.
    #[serde(default)]
    pub lambert_lamp: bool,
    /// The first round was run again from the given poses corrected as each frame's
    /// neighbours agreed (the median of their corrections,
    /// [`crate::registration::consensus::consensus_poses`]): from the given poses it converged
    /// on too few frames.
    #[serde(default)]
    pub consensus_start: bool,
    /// Every frame's sharpness against the model after the first rounds, when it could be
    /// judged (frames found blurred were left out and the rounds run again without them).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub blur_check: Option<crate::model::blur_check::BlurCheck>,
    /// Before/after overlays of a few frames, for the reports (not written to model.json).
    #[serde(skip)]
    pub overlays: Vec<PoseOverlay>,
    /// The poses as given (camera → world, every frame of the case).
    #[serde(skip)]
    pub given: Vec<Affine>,
    /// The pose of every frame of the case as the model is built with it (the refined one, or
    /// the given one when `kept` says so), with its image or video index.
    #[serde(skip)]
    pub poses: Vec<PoseEntry>,
    /// What the rounds refined every frame's pose to, kept or not.
    #[serde(skip)]
    pub refined: Vec<PoseEntry>,
}

impl PoseRegistration {
    /// How many rounds ran, how many of them were discarded, and whether all frames were
    /// refined at once after them: "9 rounds (1 discarded) and all frames at once".
    pub fn rounds_text(&self) -> String {
        let discarded = self.rounds.iter().filter(|r| r.discarded).count();
        let rounds = match discarded {
            0 => format!("{} rounds", self.rounds.len()),
            d => format!("{} rounds ({d} discarded)", self.rounds.len()),
        };
        match self.joint {
            Some(_) => format!("{rounds} and all frames at once"),
            None => rounds,
        }
    }

    /// Which poses the model is built with and why, as a sentence: the refined ones, or the
    /// given ones when the refined ones do not predict held-out frames enough better (every
    /// frame's correction is then zero). Empty without a held-out score of both.
    pub fn kept_text(&self) -> String {
        let (Some(given), Some(refined)) =
            (self.held_out_psnr_given_db, self.held_out_psnr_refined_db)
        else {
            return String::new();
        };
        let start = self.started_from();
        if self.kept_given() {
            format!(
                "The {start} poses were kept, so every correction is zero: with the refined \
                 poses held-out frames are predicted at {refined:.2} dB, with the {start} ones \
                 at {given:.2} dB, and the refined poses replace them only when they predict \
                 held-out frames better by a margin (1 dB unless the build is told otherwise)."
            )
        } else {
            format!(
                "The refined poses are used: with them held-out frames are predicted at \
                 {refined:.2} dB, with the {start} ones at {given:.2} dB."
            )
        }
    }

    /// The model is built with the poses the rounds started from, not the refined ones.
    pub fn kept_given(&self) -> bool {
        self.kept == "given"
    }

    /// What the rounds started from, in words: the "given" poses of the record are the
    /// tracked ones when the video was tracked from its first pose.
    pub fn started_from(&self) -> &'static str {
        match self.tracking {
            Some(_) => "tracked",
            None => "given",
        }
    }

    /// What the first round (and the tracking) registered against, as a sentence.
    pub fn first_light_text(&self) -> String {
        let what = match (self.tracking.is_some(), self.rounds.is_empty()) {
            (true, false) => "The tracking from the first pose and the first round",
            (true, true) => "The tracking from the first pose",
            (false, _) => "The first round",
        };
        const AGREED: &str = "it was run again from the given poses corrected as each \
                              frame's neighbours agreed (the median of their corrections)";
        let sentence = match (&self.scope_light, self.lambert_lamp, self.consensus_start) {
            (Some(source), _, false) => format!(
                "{what} registered against the calibrated light of {source} (the same \
                 bronchoscope), with this video's gains."
            ),
            (Some(source), _, true) => format!(
                "{what} registered against the calibrated light of {source} (the same \
                 bronchoscope), with this video's gains. From the given poses it converged \
                 on too few frames, and {AGREED}."
            ),
            (None, true, false) => format!(
                "{what} registered against a Lambertian lamp with a uniform beam and this \
                 video's gains: against the light fitted at the poses it started from it \
                 converged on too few frames."
            ),
            (None, true, true) => format!(
                "{what} converged on too few frames against the light fitted at the given \
                 poses and against a Lambertian lamp; {AGREED}, against a light fitted there."
            ),
            (None, false, true) => format!(
                "{what} converged on too few frames against the light fitted at the given \
                 poses; {AGREED}, against a light fitted there."
            ),
            (None, false, false) => {
                format!("{what} registered against a light fitted at the poses it started from.")
            }
        };
        match self.rounds.iter().all(|r| r.discarded) && !self.rounds.is_empty() {
            true => format!(
                "{sentence} It converged on too few frames there too, and the given poses \
                 were kept."
            ),
            false => sentence,
        }
    }
}

/// How tracking the video from its first frame's pose went (`--poses first`).
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct TrackingSummary {
    /// Frames accepted by the tracker (the first, given, included).
    pub frames_tracked: usize,
    /// Frames tried: the video's, or those evenly spaced in it that were tracked when it
    /// has more frames than the build's budget (model.json `frame_selection`).
    pub frames: usize,
    /// The first frame (its number in the video, poses.json order) of the first run of
    /// flagged frames after which the track was lost (`None`: never lost).
    pub first_lost: Option<usize>,
    /// The frames (numbers in the video) tracking resumed at after it was lost there, each
    /// time from the frames before refined by the registration's rounds.
    #[serde(default)]
    pub resumed_at: Vec<usize>,
    /// Fits of the light and texture the frames were tracked against.
    pub light_fits: usize,
    /// Wall time of the tracking (s).
    pub seconds: f64,
    /// The same per tracked frame (s).
    pub seconds_per_frame: f64,
    /// The first frame's pose refined against the CT before tracking (`None`: trusted as
    /// given, `--trust-first-pose`).
    #[serde(default)]
    pub first_pose: Option<FirstPoseRefinement>,
}

/// The first frame's given pose registered against the CT's geometry before tracking starts
/// from it (`--poses first`).
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct FirstPoseRefinement {
    /// How its registration ended (`converged`, `too_few_points`, ...).
    pub status: String,
    /// The refined pose was kept (it converged and lowered the cost by the share the build
    /// asks for); else tracking started from the given pose.
    pub kept: bool,
    /// The move from the given pose (mm; 0 when not kept).
    pub correction_mm: f64,
    /// The same (degrees).
    pub correction_deg: f64,
    /// Mean robust cost against the geometry's shading at the given pose.
    pub cost_given: f64,
    /// The same at the refined pose.
    pub cost_refined: f64,
}

impl TrackingSummary {
    /// What became of the first frame's given pose, in words (reports and the command's
    /// summary).
    pub fn first_pose_words(&self) -> String {
        match &self.first_pose {
            None => "trusted as given".to_string(),
            Some(f) if f.kept => format!(
                "refined against the CT first, {:.2} mm / {:.2} deg from the given pose",
                f.correction_mm, f.correction_deg
            ),
            Some(f) if f.cost_refined.is_finite() && f.cost_given > 0.0 => format!(
                "used as given: refined against the CT it fitted the frame {:.0} % better",
                100.0 * (1.0 - f.cost_refined / f.cost_given)
            ),
            Some(f) => format!(
                "used as given: it could not be refined against the CT ({})",
                f.status
            ),
        }
    }
}

/// One frame shown on the model at its given and at its registered pose (the reports'
/// before/after overlays; `workflow::registration_overlays`).
#[derive(Clone, Debug)]
pub struct PoseOverlay {
    /// Index of the frame in the case's poses.json.
    pub frame: usize,
    /// Why it was chosen (e.g. "large correction").
    pub why: String,
    /// Its correction (mm).
    pub correction_mm: f64,
    /// Its correction (degrees).
    pub correction_deg: f64,
    /// The frame (PNG bytes, reduced).
    pub frame_png: Vec<u8>,
    /// Checkerboard of the frame and the model at the given pose (PNG bytes).
    pub given_png: Vec<u8>,
    /// The same at the registered pose.
    pub registered_png: Vec<u8>,
    /// Mean absolute difference of frame and model at the given pose over the frame's mean.
    pub mismatch_given: f64,
    /// The same at the registered pose.
    pub mismatch_registered: f64,
}

/// The poses against the case's true poses (model.json `pose_truth`, registration.json
/// `pose_truth`), when the truth folder given to `build --truth` / `register --truth` holds a
/// poses.json naming the case's frames.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct PoseTruth {
    /// The poses as given (tracked, with `--poses first`).
    pub given: PoseAccuracy,
    /// What the registration refined them to, kept or not (absent with `--poses fixed`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub refined: Option<PoseAccuracy>,
    /// The poses the model was built with.
    pub used: PoseAccuracy,
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A registration record with held-out scores, as model.json holds it.
    fn record(kept: &str, tracking: bool) -> PoseRegistration {
        let mut v = serde_json::json!({
            "frames": [], "rounds": [], "left_out": 0, "kept": kept,
            "held_out_psnr_given_db": 30.004, "held_out_psnr_refined_db": 30.456,
        });
        if tracking {
            v["tracking"] = serde_json::json!({
                "frames_tracked": 10, "frames": 10, "first_lost": null, "light_fits": 2,
                "seconds": 1.0, "seconds_per_frame": 0.1,
            });
        }
        serde_json::from_value(v).unwrap()
    }

    #[test]
    fn kept_text_names_the_poses_used_and_both_scores() {
        let given = record("given", false).kept_text();
        assert!(given.starts_with("The given poses were kept"), "{given}");
        assert!(
            given.contains("30.46 dB, with the given ones at 30.00 dB"),
            "{given}"
        );
        let tracked = record("given", true).kept_text();
        assert!(
            tracked.starts_with("The tracked poses were kept"),
            "{tracked}"
        );
        assert!(
            tracked.contains("with the tracked ones at 30.00 dB"),
            "{tracked}"
        );
        let refined = record("refined", false).kept_text();
        assert!(
            refined.starts_with("The refined poses are used"),
            "{refined}"
        );
        // Without a held-out score of both there is nothing to say.
        let mut none = record("refined", false);
        none.held_out_psnr_given_db = None;
        assert_eq!(none.kept_text(), "");
    }
}
