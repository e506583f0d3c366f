//! The poses against the case's true poses (issue 16 item 4): when the truth folder given to
//! `build --truth` or `register --truth` has a poses.json (the phantom's `truth/` does), the
//! given, refined and used poses of the frames it names are scored against it.

use super::scene::BuildScene;
use crate::io::poses::{read_poses, FrameRef, PoseEntry};
use crate::math::Affine;
use crate::model::registration::{PoseRegistration, PoseTruth};
use crate::registration::accuracy::PoseAccuracy;
use crate::{Error, Result};
use std::path::Path;

/// Check a truth folder before any work is done: it must hold the true poses (poses.json), or,
/// when `views_will_do`, reference views (views.json) instead.
pub fn check_truth_dir(truth_dir: Option<&Path>, views_will_do: bool) -> Result<()> {
    let Some(dir) = truth_dir else {
        return Ok(());
    };
    if !dir.is_dir() {
        return Err(Error::missing(dir, "the truth folder"));
    }
    let (poses, views) = (dir.join("poses.json"), dir.join("views.json"));
    match (poses.exists(), views.exists() && views_will_do) {
        (false, false) if views_will_do => Err(Error::missing(
            views,
            "the reference views (or poses.json, the true poses)",
        )),
        (false, false) => Err(Error::missing(poses, "the true poses")),
        _ => Ok(()),
    }
}

/// The poses of `registration` (or, without one, the scene's case as given) against
/// `truth_dir/poses.json`, its images resolved in the case folder. `None` without a truth
/// folder, when it has no poses.json, or (with a warning) when it names none of the frames.
pub fn poses_against_truth(
    registration: Option<&PoseRegistration>,
    scene: &BuildScene,
    truth_dir: Option<&Path>,
    warnings: &mut Vec<String>,
) -> Result<Option<PoseTruth>> {
    let Some(truth_dir) = truth_dir else {
        return Ok(None);
    };
    let (given, case_dir) = (scene.case.poses.as_slice(), &scene.case.dir);
    let path = truth_dir.join("poses.json");
    if !path.exists() {
        return Ok(None);
    }
    let truth = read_poses(&path, case_dir)?;
    let pose_of = |frame: &FrameRef| {
        truth
            .iter()
            .find(|t| &t.frame == frame)
            .map(|t| t.pose.camera_to_world)
    };
    let poses = |entries: &[PoseEntry]| -> Vec<Affine> {
        entries.iter().map(|e| e.pose.camera_to_world).collect()
    };
    // Every frame of the case (the registration's entries, or the case's as given), with its
    // given pose, what the rounds refined it to and the pose the model uses.
    let used_entries = registration.map_or(given, |reg| reg.poses.as_slice());
    let frames: Vec<&FrameRef> = used_entries.iter().map(|e| &e.frame).collect();
    let used = poses(used_entries);
    let refined = registration.map(|reg| poses(&reg.refined));
    let given = registration.map_or_else(|| poses(given), |reg| reg.given.clone());
    // The frames the truth names, with their true poses.
    let matched: Vec<(usize, Affine)> = frames
        .iter()
        .enumerate()
        .filter_map(|(i, f)| pose_of(f).map(|t| (i, t)))
        .collect();
    // Each list's poses of the matched frames, scored against their true poses.
    let score = |all: &[Affine]| -> Option<PoseAccuracy> {
        let (est, truth): (Vec<Affine>, Vec<Affine>) = matched
            .iter()
            .filter_map(|&(i, t)| all.get(i).map(|p| (*p, t)))
            .unzip();
        PoseAccuracy::of(&est, &truth)
    };
    let (Some(given), Some(used)) = (score(&given), score(&used)) else {
        warnings.push(format!(
            "{}: names none of the case's frames; the poses are not scored against it",
            path.display()
        ));
        return Ok(None);
    };
    Ok(Some(PoseTruth {
        given,
        refined: refined.and_then(|r| score(&r)),
        used,
    }))
}
