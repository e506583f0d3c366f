//! A case whose poses.json gives fewer poses than it has frames (a video without a tracker,
//! registered with `--poses first`): every frame of frames/ (file-name order) or of the video
//! (decode order) becomes a frame of the case, and the first of them must have a pose.
//!
//! Frames without a pose start at the first frame's pose: a starting value the tracker
//! replaces ([`crate::registration::track`]), never a pose the model is built with.

use std::path::{Path, PathBuf};

use crate::io::case::VIDEO_EXTENSIONS;
use crate::io::poses::{FrameRef, PoseEntry};
use crate::io::video::VideoReader;
use crate::{Error, Result};

/// Every frame of the case in `dir` with a pose: the one `poses` (read from `poses_path`)
/// gives, else the first frame's. Returns the entries and how many poses were given; `None`
/// when `poses` already covers every frame (the case is read as usual).
pub fn complete_poses(
    dir: &Path,
    poses_path: &Path,
    poses: &[PoseEntry],
) -> Result<Option<(Vec<PoseEntry>, usize)>> {
    let frames = all_frames(dir, poses_path, poses)?;
    if frames.len() <= poses.len() {
        return Ok(None);
    }
    let first = &poses[0];
    if first.frame != frames[0] {
        return Err(Error::invalid(
            poses_path,
            format!(
                "{} poses for {} frames: the first pose must be the first frame's ({}), not {}",
                poses.len(),
                frames.len(),
                describe(&frames[0]),
                describe(&first.frame)
            ),
        ));
    }
    if let Some(p) = poses.iter().find(|p| !frames.contains(&p.frame)) {
        return Err(Error::invalid(
            poses_path,
            format!("{} is not a frame of the case", describe(&p.frame)),
        ));
    }
    let entries = frames
        .into_iter()
        .map(|frame| {
            let pose = poses
                .iter()
                .find(|p| p.frame == frame)
                .map_or(first.pose, |p| p.pose);
            PoseEntry { frame, pose }
        })
        .collect();
    Ok(Some((entries, poses.len())))
}

fn describe(f: &FrameRef) -> String {
    match f {
        FrameRef::Image(p) => p.display().to_string(),
        FrameRef::VideoIndex(i) => format!("video frame {i}"),
    }
}

/// Every frame of the case: the PNG files of frames/ sorted by name, or each decoded frame
/// of the video when the poses use `"frame"` indices.
fn all_frames(dir: &Path, poses_path: &Path, poses: &[PoseEntry]) -> Result<Vec<FrameRef>> {
    if poses
        .iter()
        .any(|p| matches!(p.frame, FrameRef::VideoIndex(_)))
    {
        let video = VIDEO_EXTENSIONS
            .iter()
            .map(|e| dir.join(format!("video.{e}")))
            .find(|p| p.is_file())
            .ok_or_else(|| {
                Error::missing(
                    dir.join("video.mp4"),
                    format!(
                        "{} refers to video frames but there is no video file",
                        poses_path.display()
                    ),
                )
            })?;
        let count = VideoReader::open(&video)?.frame_count();
        return Ok((0..count).map(FrameRef::VideoIndex).collect());
    }
    let frames_dir = dir.join("frames");
    if !frames_dir.is_dir() {
        return Ok(Vec::new());
    }
    let mut files: Vec<PathBuf> = std::fs::read_dir(&frames_dir)
        .map_err(|e| Error::io(&frames_dir, e))?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.extension().is_some_and(|x| x.eq_ignore_ascii_case("png")))
        .collect();
    files.sort();
    // Compare with the poses' paths as the reader resolved them (inside the case folder).
    let canonical = |p: &Path| p.canonicalize().unwrap_or_else(|_| p.to_path_buf());
    Ok(files
        .into_iter()
        .map(|f| {
            let c = canonical(&f);
            poses
                .iter()
                .find_map(|p| match &p.frame {
                    FrameRef::Image(q) if canonical(q) == c => Some(p.frame.clone()),
                    _ => None,
                })
                .unwrap_or(FrameRef::Image(f))
        })
        .collect())
}
