//! Camera files: camera.json (CASE_FORMAT.md) and OpenCV FileStorage YAML / XML
//! (camera_matrix, distortion_coefficients, image_width, image_height).
//!
//! OpenCV's distortion vector may have 4, 5, 8, 12 or 14 coefficients
//! (k1 k2 p1 p2 [k3 [k4 k5 k6 [s1 s2 s3 s4 [tau_x tau_y]]]]); bronchosim's model uses
//! k1 k2 p1 p2 k3, so any non-zero further coefficient is rejected as unsupported rather than
//! silently dropped.

use super::camera_opencv::{parse_xml, parse_yaml};
use crate::camera::Camera;
use crate::{Error, Result};
use serde_json::Value;
use std::path::{Path, PathBuf};

/// The camera file names looked for in a case folder, in this order.
pub const CAMERA_FILE_NAMES: [&str; 4] = ["camera.json", "camera.yml", "camera.yaml", "camera.xml"];

/// Keys of camera.json; missing distortion keys mean 0.
const JSON_REQUIRED: [&str; 6] = ["width", "height", "fx", "fy", "cx", "cy"];
const JSON_DISTORTION: [&str; 5] = ["k1", "k2", "p1", "p2", "k3"];
/// Names of OpenCV's distortion coefficients after k1 k2 p1 p2 k3.
pub(super) const OPENCV_EXTRA: [&str; 9] =
    ["k4", "k5", "k6", "s1", "s2", "s3", "s4", "tau_x", "tau_y"];

/// The syntax of a camera file.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum CameraFormat {
    /// camera.json (CASE_FORMAT.md).
    Json,
    /// OpenCV FileStorage YAML.
    Yaml,
    /// OpenCV FileStorage XML.
    Xml,
}

impl CameraFormat {
    /// The format named by `path`'s extension: `.json`, `.yml` / `.yaml` or `.xml` (any case).
    pub fn from_path(path: &Path) -> Result<Self> {
        let ext = path
            .extension()
            .and_then(|e| e.to_str())
            .map(|e| e.to_ascii_lowercase())
            .unwrap_or_default();
        match ext.as_str() {
            "json" => Ok(Self::Json),
            "yml" | "yaml" => Ok(Self::Yaml),
            "xml" => Ok(Self::Xml),
            _ => Err(Error::unsupported(
                path,
                "camera file extension must be .json, .yml, .yaml or .xml",
            )),
        }
    }
}

/// Read a camera file, chosen by extension: `.json` (CASE_FORMAT.md), `.yml` / `.yaml` / `.xml`
/// (OpenCV FileStorage). The camera is validated ([`Camera::validate`]); every error names the
/// file and the field.
pub fn read_camera(path: &Path) -> Result<Camera> {
    let format = CameraFormat::from_path(path)?;
    let text = std::fs::read_to_string(path).map_err(|e| Error::io(path, e))?;
    parse_camera_str(&text, format, path)
}

/// Parse and validate the text of a camera file in `format`, as [`read_camera`] does, without
/// touching the disk; `path_for_errors` only names the source in error messages.
pub fn parse_camera_str(
    text: &str,
    format: CameraFormat,
    path_for_errors: &Path,
) -> Result<Camera> {
    let path = path_for_errors;
    let camera = match format {
        CameraFormat::Json => parse_json(path, text),
        CameraFormat::Yaml => parse_yaml(path, text),
        CameraFormat::Xml => parse_xml(path, text),
    }?;
    camera.validate().map_err(|m| {
        // OpenCV files spell the image size image_width / image_height.
        let opencv =
            format != CameraFormat::Json && (m.starts_with("width") || m.starts_with("height"));
        Error::invalid(path, if opencv { format!("image_{m}") } else { m })
    })?;
    Ok(camera)
}

/// Find the one camera file of a case folder: camera.json, camera.yml, camera.yaml or
/// camera.xml. An error when there is none, or more than one (which would be ambiguous).
pub fn find_camera(case_dir: &Path) -> Result<PathBuf> {
    let found: Vec<PathBuf> = CAMERA_FILE_NAMES
        .iter()
        .map(|n| case_dir.join(n))
        .filter(|p| p.is_file())
        .collect();
    match found.len() {
        0 => Err(Error::missing(
            case_dir,
            "camera.json, camera.yml, camera.yaml or camera.xml",
        )),
        1 => Ok(found.into_iter().next().expect("one element")),
        _ => {
            let names: Vec<String> = found
                .iter()
                .filter_map(|p| p.file_name().map(|n| n.to_string_lossy().into_owned()))
                .collect();
            Err(Error::invalid(
                case_dir,
                format!(
                    "more than one camera file ({}); keep exactly one",
                    names.join(", ")
                ),
            ))
        }
    }
}

/// Write `camera` as camera.json (CASE_FORMAT.md), all eleven keys, pretty-printed.
pub fn write_camera_json(path: &Path, camera: &Camera) -> Result<()> {
    let text =
        serde_json::to_string_pretty(camera).map_err(|e| Error::invalid(path, e.to_string()))?;
    std::fs::write(path, text + "\n").map_err(|e| Error::io(path, e))
}

/// One line of a parser's message (some render multi-line snippets).
pub(super) fn one_line(msg: impl std::fmt::Display) -> String {
    msg.to_string()
        .split_whitespace()
        .collect::<Vec<_>>()
        .join(" ")
}

fn parse_json(path: &Path, text: &str) -> Result<Camera> {
    let value: Value = serde_json::from_str(text)
        .map_err(|e| Error::invalid(path, format!("not valid JSON: {}", one_line(e))))?;
    let Value::Object(map) = value else {
        return Err(Error::invalid(
            path,
            "expected a JSON object with width, height, fx, fy, cx, cy",
        ));
    };
    // Unknown keys are rejected: a misspelt distortion key would otherwise silently mean 0.
    if let Some(k) = map
        .keys()
        .find(|k| !JSON_REQUIRED.contains(&k.as_str()) && !JSON_DISTORTION.contains(&k.as_str()))
    {
        return Err(Error::invalid(
            path,
            format!("unknown field \"{k}\" (expected width, height, fx, fy, cx, cy, k1, k2, p1, p2, k3)"),
        ));
    }
    let num = |key: &str, required: bool| -> Result<f64> {
        match map.get(key) {
            None if required => Err(Error::invalid(path, format!("missing field \"{key}\""))),
            None => Ok(0.0),
            Some(v) => v.as_f64().ok_or_else(|| {
                Error::invalid(path, format!("field \"{key}\" must be a number, got {v}"))
            }),
        }
    };
    Ok(Camera {
        width: image_size(path, "width", num("width", true)?)?,
        height: image_size(path, "height", num("height", true)?)?,
        fx: num("fx", true)?,
        fy: num("fy", true)?,
        cx: num("cx", true)?,
        cy: num("cy", true)?,
        k1: num("k1", false)?,
        k2: num("k2", false)?,
        p1: num("p1", false)?,
        p2: num("p2", false)?,
        k3: num("k3", false)?,
    })
}

/// An image size in pixels: a whole number in 1..=u32::MAX (0 is caught by validate with
/// the same wording as for other sources).
pub(super) fn image_size(path: &Path, field: &str, v: f64) -> Result<u32> {
    if v.fract() != 0.0 || !(0.0..=u32::MAX as f64).contains(&v) {
        return Err(Error::invalid(
            path,
            format!("{field} must be a whole positive number of pixels, got {v}"),
        ));
    }
    Ok(v as u32)
}
