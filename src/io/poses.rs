//! poses.json (and views.json, the same schema): the camera→world pose of each frame.
//!
//! Schema (CASE_FORMAT.md): `{ "frames": [ { "image": "frames/000000.png" | "frame": 0,
//! "camera_to_world": [16 numbers, row-major] } ] }`. Each matrix is validated: finite numbers,
//! last row `0 0 0 1`, a rotation block that is orthonormal with determinant +1.

use std::path::{Path, PathBuf};

use serde_json::Value;

use crate::camera::pose::{validate_pose, Pose};
use crate::io::paths::{relative_slash_path, resolve_case_relative};
use crate::math::Affine;
use crate::{Error, Result};

/// Which image a pose belongs to.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum FrameRef {
    /// A PNG file, resolved against the case folder and checked to lie inside it.
    Image(PathBuf),
    /// A 0-based decoded-frame index into the case's video.
    VideoIndex(usize),
}

/// One entry of poses.json: a frame and the camera→world transform (mm) of the camera that
/// took it. Camera axes follow OpenCV: +x right, +y down, +z the viewing direction.
#[derive(Clone, Debug, PartialEq)]
pub struct PoseEntry {
    /// The frame this pose belongs to.
    pub frame: FrameRef,
    /// Camera coordinates (mm) → world coordinates (mm, RAS+); a rigid transform.
    pub pose: Pose,
}

/// Read and validate poses.json at `path`; `"image"` paths are resolved inside `case_dir`.
///
/// Rules beyond the per-matrix checks: the `frames` list is not empty; every entry has exactly
/// one of `"image"` (a relative path) and `"frame"` (a non-negative integer); all entries use
/// the same one; video frame indices strictly increase (frames are decoded in one pass).
pub fn read_poses(path: &Path, case_dir: &Path) -> Result<Vec<PoseEntry>> {
    let text = std::fs::read_to_string(path).map_err(|e| Error::io(path, e))?;
    parse_poses_str(&text, case_dir, path)
}

/// Parse and validate the text of a poses.json, as [`read_poses`] does, without reading it from
/// disk; `"image"` paths are still resolved inside `case_dir`, and `path_for_errors` only names
/// the source in error messages.
pub fn parse_poses_str(
    text: &str,
    case_dir: &Path,
    path_for_errors: &Path,
) -> Result<Vec<PoseEntry>> {
    let path = path_for_errors;
    // serde_json refuses numbers that overflow f64 (1e400) with "number out of range".
    let root: Value = serde_json::from_str(text)
        .map_err(|e| Error::invalid(path, format!("not valid JSON: {e}")))?;
    let frames = root
        .as_object()
        .ok_or_else(|| Error::invalid(path, "expected a JSON object with a \"frames\" list"))?
        .get("frames")
        .ok_or_else(|| Error::invalid(path, "missing the \"frames\" list"))?
        .as_array()
        .ok_or_else(|| Error::invalid(path, "\"frames\" is not a list"))?;
    if frames.is_empty() {
        return Err(Error::invalid(path, "\"frames\" is empty"));
    }
    let mut out: Vec<PoseEntry> = Vec::with_capacity(frames.len());
    for (i, entry) in frames.iter().enumerate() {
        let pose = parse_entry(entry, i, path, case_dir)?;
        if let Some(prev) = out.last() {
            match (&prev.frame, &pose.frame) {
                (FrameRef::Image(_), FrameRef::VideoIndex(_))
                | (FrameRef::VideoIndex(_), FrameRef::Image(_)) => {
                    return Err(Error::invalid(
                        path,
                        format!("frame {i}: mixes \"image\" and \"frame\" entries; use one kind"),
                    ));
                }
                (FrameRef::VideoIndex(a), FrameRef::VideoIndex(b)) if b <= a => {
                    return Err(Error::invalid(
                        path,
                        format!("frame {i}: video index {b} does not follow {a}; indices must strictly increase"),
                    ));
                }
                _ => {}
            }
        }
        out.push(pose);
    }
    Ok(out)
}

/// Describe entry `i` for messages: its index and, when readable, its image or frame.
fn entry_label(entry: &Value, i: usize) -> String {
    match (
        entry.get("image").and_then(Value::as_str),
        entry.get("frame"),
    ) {
        (Some(img), _) => format!("frame {i} ({img})"),
        (None, Some(f)) => format!("frame {i} (video frame {f})"),
        _ => format!("frame {i}"),
    }
}

fn parse_entry(entry: &Value, i: usize, path: &Path, case_dir: &Path) -> Result<PoseEntry> {
    let label = entry_label(entry, i);
    let bad = |msg: String| Error::invalid(path, format!("{label}: {msg}"));
    let obj = entry
        .as_object()
        .ok_or_else(|| bad("expected an object".into()))?;
    let frame = match (obj.get("image"), obj.get("frame")) {
        (Some(_), Some(_)) => return Err(bad("has both \"image\" and \"frame\"; give one".into())),
        (None, None) => {
            return Err(bad(
                "needs \"image\" (a PNG path) or \"frame\" (a video index)".into(),
            ))
        }
        (Some(image), None) => {
            let rel = image
                .as_str()
                .ok_or_else(|| bad(format!("\"image\" is not a string ({image})")))?;
            let resolved = resolve_case_relative(case_dir, rel, path)
                .map_err(|e| bad(strip_path_prefix(&e.to_string(), path)))?;
            FrameRef::Image(resolved)
        }
        (None, Some(index)) => {
            let n = index
                .as_u64()
                .and_then(|n| usize::try_from(n).ok())
                .ok_or_else(|| {
                    bad(format!(
                        "\"frame\" must be a non-negative integer, not {index}"
                    ))
                })?;
            FrameRef::VideoIndex(n)
        }
    };
    let values = obj
        .get("camera_to_world")
        .ok_or_else(|| bad("missing \"camera_to_world\"".into()))?
        .as_array()
        .ok_or_else(|| bad("\"camera_to_world\" is not a list of 16 numbers".into()))?;
    if values.len() != 16 {
        return Err(bad(format!(
            "\"camera_to_world\" has {} numbers, expected 16 (a row-major 4x4 matrix)",
            values.len()
        )));
    }
    let mut m = Affine::zeros();
    for (k, v) in values.iter().enumerate() {
        let x = v
            .as_f64()
            .ok_or_else(|| bad(format!("camera_to_world[{k}] is not a number ({v})")))?;
        if !x.is_finite() {
            return Err(bad(format!("camera_to_world[{k}] is not finite ({x})")));
        }
        m[(k / 4, k % 4)] = x;
    }
    validate_pose(&m).map_err(|msg| bad(format!("camera_to_world: {msg}")))?;
    Ok(PoseEntry {
        frame,
        pose: Pose::new(m),
    })
}

/// Drop a leading "`path`: " from a nested error message so the file is named once.
fn strip_path_prefix(message: &str, path: &Path) -> String {
    let prefix = format!("{}: ", path.display());
    message.strip_prefix(&prefix).unwrap_or(message).to_string()
}

/// Write `poses` as poses.json (or views.json) at `path`, one entry per line, numbers in
/// shortest round-trip form. Image paths are written relative to `base_dir` with `/`.
/// Each pose is validated first so a file this writes is always readable by [`read_poses`].
pub fn write_poses(path: &Path, poses: &[PoseEntry], base_dir: &Path) -> Result<()> {
    write_poses_annotated(path, poses, base_dir, &[])
}

/// [`write_poses`] with more keys per entry: `notes[i]` (when given) is appended to entry `i`
/// (e.g. a registration's correction and status); readers of poses.json ignore unknown keys.
pub fn write_poses_annotated(
    path: &Path,
    poses: &[PoseEntry],
    base_dir: &Path,
    notes: &[serde_json::Map<String, Value>],
) -> Result<()> {
    if poses.is_empty() {
        return Err(Error::invalid(path, "no poses to write"));
    }
    let mut text = String::from("{ \"frames\": [\n");
    for (i, pose) in poses.iter().enumerate() {
        pose.pose
            .validate()
            .map_err(|msg| Error::invalid(path, format!("frame {i}: {msg}")))?;
        let frame = match &pose.frame {
            FrameRef::Image(p) => {
                let rel = relative_slash_path(base_dir, p, path)?;
                format!("\"image\": {}", serde_json::Value::String(rel))
            }
            FrameRef::VideoIndex(n) => format!("\"frame\": {n}"),
        };
        let m = &pose.pose.camera_to_world;
        let numbers: Vec<String> = (0..16)
            .map(|k| serde_json::Value::from(m[(k / 4, k % 4)]).to_string())
            .collect();
        let sep = if i + 1 < poses.len() { "," } else { "" };
        let extra: String = notes
            .get(i)
            .into_iter()
            .flatten()
            .map(|(k, v)| format!(", {}: {v}", Value::String(k.clone())))
            .collect();
        text.push_str(&format!(
            "  {{ {frame}, \"camera_to_world\": [{}]{extra} }}{sep}\n",
            numbers.join(", ")
        ));
    }
    text.push_str("] }\n");
    std::fs::write(path, text).map_err(|e| Error::io(path, e))
}
