//! The whole video: every frame refined from its given pose, then the video's continuity as a
//! prior. A tracker's error is a smooth drift plus jitter, so a frame that did not converge
//! (its cost well above the video's) is started again from its given pose corrected as its
//! converged neighbours were, and from its neighbours' refined poses (the bronchoscope moves
//! smoothly); passes repeat until no frame changes. A frame whose correction departs from its
//! neighbours' by more than a tracker could (e.g. a given pose off by 10 mm) is flagged an
//! outlier. Nothing is kept silently: every frame ends with a status, and they are counted.

use super::blocks::{realign_blocks, BlockOptions};
use super::frame::{FrameObs, FrameRegistrar, FrameRegistration, FrameStatus};
use super::pose::{apply_delta, delta_between, extrapolate, rotation_of, PoseDelta};
use super::prior::{smooth_corrections, DriftPrior};
use crate::image::Frame;
use crate::math::Affine;
use crate::{Error, Result};
use rayon::prelude::*;
use std::collections::BTreeMap;

/// Options of [`refine_video`].
#[derive(Clone, Debug)]
pub struct VideoOptions {
    /// A frame whose cost after refinement exceeds this many times the median over the
    /// video's converged frames did not converge (measured on the phantom: converged frames
    /// lie within 2x the median, failed ones beyond 5x).
    pub cost_ratio: f64,
    /// Most passes of restarting the frames that did not converge.
    pub max_passes: usize,
    /// A frame whose correction differs from the one interpolated from its neighbours by more
    /// than this (mm) is an outlier (a tracker's error changes by a few tenths of a mm
    /// between frames).
    pub outlier_mm: f64,
    /// The same for the rotation (degrees).
    pub outlier_deg: f64,
    /// Smooth the corrections with this model of the tracker's error (`None`: every frame
    /// keeps its own measurement; see [`super::prior`]).
    pub smooth: Option<DriftPrior>,
    /// The frames' positions in the video (increasing; empty: consecutive), for the prior:
    /// after a frame selection, kept frames far apart are allowed more drift between them.
    pub frame_numbers: Vec<usize>,
    /// Ticked once per frame refined (restarts lengthen it).
    pub progress: Option<indicatif::ProgressBar>,
    /// Runs of frames whose corrections jump where they meet the neighbouring runs are
    /// registered again from their neighbours' corrections (see [`super::blocks`]). `None`
    /// (the default): never; a video registered straight from a tracker's poses has no run to
    /// trust yet.
    pub blocks: Option<BlockOptions>,
    /// Frames whose given pose is exact (the trusted first frame of a video registered
    /// without a tracker): kept there, and the drift pinned at them.
    pub anchored: Vec<usize>,
    /// The poses the video came with, whose error is a tracker's smooth drift: the runs of
    /// `blocks` are judged by their corrections from these too, not only from the poses this
    /// registration starts at, which after an earlier round are not smooth in their error (a
    /// run that round put a ring away starts there, and its own corrections join). Empty: from
    /// the start poses alone.
    pub tracker_poses: Vec<Affine>,
}

impl Default for VideoOptions {
    fn default() -> Self {
        VideoOptions {
            cost_ratio: 2.5,
            max_passes: 4,
            outlier_mm: 3.0,
            outlier_deg: 5.0,
            smooth: Some(DriftPrior::default()),
            frame_numbers: Vec::new(),
            progress: None,
            blocks: None,
            anchored: Vec::new(),
            tracker_poses: Vec::new(),
        }
    }
}

/// How the video's registration went.
#[derive(Clone, Debug)]
pub struct VideoRegistration {
    /// Every frame's result, in video order (the pose is the one to use).
    pub frames: Vec<FrameRegistration>,
    /// Passes of restarts run.
    pub passes: usize,
    /// Frames per final status.
    pub counts: BTreeMap<String, usize>,
    /// Frames that needed a restart from their neighbours.
    pub restarted: usize,
    /// Frames registered again as part of a run whose corrections jumped at its ends, and
    /// moved to join their neighbours (see [`super::blocks`]).
    pub realigned: usize,
    /// Each frame's own refined pose, before the smoothing.
    pub measured: Vec<Affine>,
    /// Registration noise the smoother estimated per camera axis (x, y, z mm; rotations about
    /// x, y, z degrees); zeros without smoothing.
    pub noise: [f64; 6],
}

/// A frame's result is usable: it converged to a cost like the video's.
fn good(r: &FrameRegistration, gate: f64) -> bool {
    matches!(r.status, FrameStatus::Converged | FrameStatus::NotConverged)
        && r.cost_after.is_finite()
        && r.cost_after <= gate
}

fn median(mut v: Vec<f64>) -> Option<f64> {
    if v.is_empty() {
        return None;
    }
    let mid = v.len() / 2;
    Some(*v.select_nth_unstable_by(mid, |a, b| a.total_cmp(b)).1)
}

/// The nearest good frames before and after `f`.
fn neighbours(ok: &[bool], f: usize) -> (Option<usize>, Option<usize>) {
    (
        (0..f).rev().find(|&i| ok[i]),
        (f + 1..ok.len()).find(|&i| ok[i]),
    )
}

/// Linear interpolation of the corrections of frames `a` and `b` at frame `f` (the nearer
/// one alone when only one exists).
fn interpolate_delta(
    d: &[PoseDelta],
    f: usize,
    a: Option<usize>,
    b: Option<usize>,
) -> Option<PoseDelta> {
    match (a, b) {
        (Some(a), Some(b)) => {
            let t = (f - a) as f64 / (b - a) as f64;
            Some(PoseDelta {
                translation_mm: d[a].translation_mm * (1.0 - t) + d[b].translation_mm * t,
                rotation: d[a].rotation * (1.0 - t) + d[b].rotation * t,
            })
        }
        (Some(i), None) | (None, Some(i)) => Some(d[i]),
        (None, None) => None,
    }
}

/// The pose at frame `f` interpolated between the poses of frames `a` and `b` (centre linear,
/// rotation along the geodesic); extrapolated at constant velocity beyond the video's
/// good frames when two exist on one side.
fn interpolate_pose(p: &[Affine], ok: &[bool], f: usize) -> Option<Affine> {
    let (a, b) = neighbours(ok, f);
    let (a, b) = match (a, b) {
        (Some(a), Some(b)) => (a, b),
        (Some(a), None) => ((0..a).rev().find(|&i| ok[i])?, a),
        (None, Some(b)) => (b, (b + 1..ok.len()).find(|&i| ok[i])?),
        (None, None) => return None,
    };
    Some(extrapolate(&p[a], a as f64, &p[b], b as f64, f as f64))
}

/// Mark the frames that did not converge (`ok[f]` false) as high-cost and those whose
/// correction departs from their neighbours' by more than a tracker's error can as outliers.
fn flag_failures(
    res: &mut [FrameRegistration],
    ok: &[bool],
    deltas: &[PoseDelta],
    poses: &[Affine],
    opts: &VideoOptions,
) {
    for f in 0..res.len() {
        if !ok[f] {
            if matches!(
                res[f].status,
                FrameStatus::Converged | FrameStatus::NotConverged
            ) {
                res[f].status = FrameStatus::HighCost;
            }
            continue;
        }
        let mut others = ok.to_vec();
        others[f] = false;
        let (a, b) = neighbours(&others, f);
        if let Some(expect) = interpolate_delta(deltas, f, a, b) {
            let d = delta_between(&apply_delta(&poses[f], &expect), &res[f].pose);
            if d.mm() > opts.outlier_mm || d.deg() > opts.outlier_deg {
                res[f].status = FrameStatus::Outlier;
            }
        }
    }
}

/// Refine every frame of a video (`frames[f]` with gain `gains[f]`, optional pixel `mask`)
/// starting from the given `poses` (camera → world); see the module docs.
pub fn refine_video(
    reg: &FrameRegistrar,
    frames: &[Frame],
    gains: &[f64],
    mask: Option<&[bool]>,
    poses: &[Affine],
    opts: &VideoOptions,
) -> Result<VideoRegistration> {
    let n = frames.len();
    if gains.len() != n || poses.len() != n {
        return Err(Error::Other(format!(
            "registration: {n} frames, {} gains and {} poses (need one of each per frame)",
            gains.len(),
            poses.len()
        )));
    }
    let run = |f: usize, start: &Affine| -> Result<FrameRegistration> {
        let obs = FrameObs {
            frame: &frames[f],
            gain: gains[f],
            mask,
        };
        let mut r = reg.refine_frame(&obs, start)?;
        // Corrections are always relative to the given pose.
        r.correction = delta_between(&poses[f], &r.pose);
        if let Some(p) = &opts.progress {
            p.inc(1);
        }
        Ok(r)
    };
    let mut res: Vec<FrameRegistration> = (0..n)
        .into_par_iter()
        .map(|f| run(f, &poses[f]))
        .collect::<Result<_>>()?;
    let gate = |res: &[FrameRegistration]| {
        let costs = res
            .iter()
            .filter(|r| matches!(r.status, FrameStatus::Converged | FrameStatus::NotConverged))
            .map(|r| r.cost_after)
            .filter(|c| c.is_finite())
            .collect();
        median(costs).map_or(0.0, |m| m * opts.cost_ratio)
    };
    // Frames registered again from other starts (restarts, realigned runs), in parallel.
    let run_jobs = |jobs: &[(usize, Affine)]| -> Result<Vec<FrameRegistration>> {
        if let Some(p) = &opts.progress {
            p.inc_length(jobs.len() as u64);
        }
        jobs.par_iter().map(|(f, s)| run(*f, s)).collect()
    };
    let mut tried: Vec<Vec<Affine>> = vec![Vec::new(); n];
    let mut restarted = vec![false; n];
    let mut passes = 0;
    for _ in 0..opts.max_passes {
        let g = gate(&res);
        let ok: Vec<bool> = res.iter().map(|r| good(r, g)).collect();
        let deltas: Vec<PoseDelta> = res.iter().map(|r| r.correction).collect();
        let refined: Vec<Affine> = res.iter().map(|r| r.pose).collect();
        // Starts for each frame that did not converge, not tried before.
        let mut jobs: Vec<(usize, Affine)> = Vec::new();
        for f in (0..n).filter(|&f| !ok[f]) {
            let (a, b) = neighbours(&ok, f);
            let starts = [
                interpolate_delta(&deltas, f, a, b).map(|d| apply_delta(&poses[f], &d)),
                interpolate_pose(&refined, &ok, f),
            ];
            for s in starts.into_iter().flatten() {
                let seen = tried[f].iter().any(|t| {
                    let d = delta_between(t, &s);
                    d.mm() < 0.05 && d.deg() < 0.05
                });
                if !seen {
                    tried[f].push(s);
                    jobs.push((f, s));
                }
            }
        }
        if jobs.is_empty() {
            break;
        }
        passes += 1;
        let out = run_jobs(&jobs)?;
        for ((f, _), r) in jobs.into_iter().zip(out) {
            let better = good(&r, g) && (!good(&res[f], g) || r.cost_after < res[f].cost_after)
                || (!good(&res[f], g) && r.cost_after < res[f].cost_after);
            if better {
                res[f] = r;
                restarted[f] = true;
            }
        }
    }
    let mut realigned = 0;
    if let Some(block_opts) = &opts.blocks {
        let g = gate(&res);
        let ok: Vec<bool> = res.iter().map(|r| good(r, g)).collect();
        // Judged in this round's own corrections, then in those from the tracker's poses (see
        // `blocks`).
        let mut replaced = Vec::new();
        for judged_from in [poses, &opts.tracker_poses[..]] {
            if judged_from.len() != n {
                continue;
            }
            replaced.extend(realign_blocks(
                &mut res,
                poses,
                judged_from,
                &ok,
                &opts.frame_numbers,
                block_opts,
                run_jobs,
                |r| good(r, g),
            )?);
        }
        replaced.sort_unstable();
        replaced.dedup();
        realigned = replaced.len();
        for f in replaced {
            restarted[f] = true;
        }
    }
    for &f in opts.anchored.iter().filter(|&&f| f < n) {
        res[f].pose = poses[f];
        res[f].correction = PoseDelta::default();
    }
    // Flags: frames that never converged, and frames whose correction departs from their
    // neighbours'.
    let g = gate(&res);
    let ok: Vec<bool> = res.iter().map(|r| good(r, g)).collect();
    let deltas: Vec<PoseDelta> = res.iter().map(|r| r.correction).collect();
    flag_failures(&mut res, &ok, &deltas, poses, opts);
    let mut anchored = vec![false; n];
    for &f in opts.anchored.iter().filter(|&&f| f < n) {
        anchored[f] = true;
        res[f].status = FrameStatus::Converged;
    }
    let measured: Vec<Affine> = res.iter().map(|r| r.pose).collect();
    let noise = match &opts.smooth {
        Some(prior) => smooth(
            &mut res,
            &ok,
            &anchored,
            &deltas,
            poses,
            &opts.frame_numbers,
            prior,
        ),
        None => [0.0; 6],
    };
    let mut counts = BTreeMap::new();
    for r in &res {
        *counts.entry(r.status.name().to_string()).or_insert(0) += 1;
    }
    Ok(VideoRegistration {
        restarted: restarted.iter().filter(|&&r| r).count(),
        realigned,
        frames: res,
        passes,
        counts,
        measured,
        noise,
    })
}

/// Replace each frame's correction by the smoothed one (see [`super::prior`]); frames not `ok`
/// or flagged as outliers take the drift alone. Returns the registration noise per axis.
fn smooth(
    res: &mut [FrameRegistration],
    ok: &[bool],
    anchored: &[bool],
    deltas: &[PoseDelta],
    poses: &[Affine],
    frame_numbers: &[usize],
    prior: &DriftPrior,
) -> [f64; 6] {
    let usable: Vec<bool> = (0..res.len())
        .map(|f| anchored[f] || ok[f] && res[f].status != FrameStatus::Outlier)
        .collect();
    let rot: Vec<_> = res.iter().map(|r| rotation_of(&r.pose)).collect();
    let information: Vec<_> = res.iter().map(|r| r.information).collect();
    let s = smooth_corrections(
        deltas,
        &rot,
        &information,
        &usable,
        anchored,
        frame_numbers,
        prior,
    );
    for (f, d) in s.corrections.iter().enumerate() {
        res[f].pose = apply_delta(&poses[f], d);
        res[f].correction = *d;
    }
    s.noise
}
