//! OpenCV FileStorage camera files (YAML and XML, OpenCV 3/4 `%YAML:1.0` and OpenCV 5):
//! camera_matrix, distortion_coefficients, image_width, image_height.

use super::camera_file::{image_size, one_line, OPENCV_EXTRA};
use crate::camera::Camera;
use crate::{Error, Result};
use serde_json::{Map, Value};
use std::path::Path;

/// A matrix of an OpenCV FileStorage file (`!!opencv-matrix` or `!!opencv-nd-matrix`).
struct FsMatrix {
    /// Rows and columns (an nd-matrix of one dimension n is n x 1).
    shape: (usize, usize),
    data: Vec<f64>,
}

/// The fields of an OpenCV camera file, before checking.
struct FsCamera {
    width: Option<f64>,
    height: Option<f64>,
    k: Option<FsMatrix>,
    d: Option<FsMatrix>,
}

/// Element count implied by `dt` (e.g. "d", "f", "3d": channels × count); one channel only.
fn check_dt(path: &Path, field: &str, dt: &str) -> Result<()> {
    let dt = dt.trim();
    let digits: String = dt.chars().take_while(|c| c.is_ascii_digit()).collect();
    let kind = &dt[digits.len()..];
    if !matches!(kind, "u" | "c" | "w" | "s" | "i" | "f" | "d" | "h") {
        return Err(Error::invalid(
            path,
            format!("{field}: unknown element type dt \"{dt}\""),
        ));
    }
    if !digits.is_empty() && digits != "1" {
        return Err(Error::unsupported(
            path,
            format!("{field}: dt \"{dt}\" has {digits} channels, expected 1"),
        ));
    }
    Ok(())
}

fn make_matrix(
    path: &Path,
    field: &str,
    dims: Vec<usize>,
    dt: &str,
    data: Vec<f64>,
) -> Result<FsMatrix> {
    check_dt(path, field, dt)?;
    let shape = match dims.as_slice() {
        [n] => (*n, 1),
        [r, c] => (*r, *c),
        _ => {
            return Err(Error::invalid(
                path,
                format!("{field}: expected a 1-D or 2-D matrix, got sizes {dims:?}"),
            ))
        }
    };
    if shape.0 * shape.1 != data.len() {
        return Err(Error::invalid(
            path,
            format!(
                "{field}: {} x {} matrix has {} data values",
                shape.0,
                shape.1,
                data.len()
            ),
        ));
    }
    Ok(FsMatrix { shape, data })
}

/// Turn the FileStorage fields into a Camera: K must be [[fx 0 cx] [0 fy cy] [0 0 1]].
fn fs_to_camera(path: &Path, fs: FsCamera) -> Result<Camera> {
    let width = fs
        .width
        .ok_or_else(|| Error::invalid(path, "missing field image_width"))?;
    let height = fs
        .height
        .ok_or_else(|| Error::invalid(path, "missing field image_height"))?;
    let k =
        fs.k.ok_or_else(|| Error::invalid(path, "missing field camera_matrix"))?;
    let d =
        fs.d.ok_or_else(|| Error::invalid(path, "missing field distortion_coefficients"))?;
    if k.shape != (3, 3) {
        return Err(Error::invalid(
            path,
            format!(
                "camera_matrix must be 3 x 3, got {} x {}",
                k.shape.0, k.shape.1
            ),
        ));
    }
    let m = &k.data;
    if m[1] != 0.0 {
        return Err(Error::unsupported(
            path,
            format!("camera_matrix: skew K[0][1] = {} must be 0", m[1]),
        ));
    }
    if m[3] != 0.0 || m[6] != 0.0 || m[7] != 0.0 || m[8] != 1.0 {
        return Err(Error::invalid(
            path,
            format!("camera_matrix: bottom-left must be 0 and K[2][2] = 1, got rows [{}, {}, {}] [{}, {}, {}]", m[3], m[4], m[5], m[6], m[7], m[8]),
        ));
    }
    let n = d.data.len();
    if !(d.shape.0 == 1 || d.shape.1 == 1) || ![4, 5, 8, 12, 14].contains(&n) {
        return Err(Error::invalid(
            path,
            format!("distortion_coefficients: expected a vector of 4, 5, 8, 12 or 14 values, got {} x {}", d.shape.0, d.shape.1),
        ));
    }
    if let Some((i, v)) = d.data.iter().enumerate().skip(5).find(|(_, v)| **v != 0.0) {
        return Err(Error::unsupported(
            path,
            format!(
                "distortion_coefficients: {} = {v} is non-zero; only k1 k2 p1 p2 k3 are supported (no rational, thin-prism or tilt terms)",
                OPENCV_EXTRA[i - 5]
            ),
        ));
    }
    let coef = |i: usize| d.data.get(i).copied().unwrap_or(0.0);
    Ok(Camera {
        width: image_size(path, "image_width", width)?,
        height: image_size(path, "image_height", height)?,
        fx: m[0],
        fy: m[4],
        cx: m[2],
        cy: m[5],
        k1: coef(0),
        k2: coef(1),
        p1: coef(2),
        p2: coef(3),
        k3: coef(4),
    })
}

/// OpenCV YAML is not plain YAML: OpenCV 3/4 write a `%YAML:1.0` directive (invalid syntax)
/// and all versions tag matrices `!!opencv-matrix`; drop both, then parse the rest.
pub(super) fn parse_yaml(path: &Path, text: &str) -> Result<Camera> {
    let cleaned: String = text
        .lines()
        .filter(|l| !l.trim_start().starts_with("%YAML"))
        .map(|l| {
            l.replace("!!opencv-nd-matrix", "")
                .replace("!!opencv-matrix", "")
        })
        .collect::<Vec<_>>()
        .join("\n");
    // Non-finite numbers arrive as ".nan" / ".inf" strings (the JSON value model cannot hold
    // them) so that validate can name the field; no source snippet, to keep errors one line.
    let mut options = serde_saphyr::Options::default();
    options.non_finite_float_policy = serde_saphyr::NonFiniteFloatPolicy::AsString;
    options.with_snippet = false;
    let value: Value = serde_saphyr::from_str_with_options(&cleaned, options)
        .map_err(|e| Error::invalid(path, format!("not valid OpenCV YAML: {}", one_line(e))))?;
    let Value::Object(map) = value else {
        return Err(Error::invalid(
            path,
            "expected a YAML mapping with camera_matrix and distortion_coefficients",
        ));
    };
    let scalar = |key: &str| -> Result<Option<f64>> {
        match map.get(key) {
            None => Ok(None),
            Some(v) => yaml_number(v)
                .map(Some)
                .ok_or_else(|| Error::invalid(path, format!("{key} must be a number, got {v}"))),
        }
    };
    let matrix = |key: &str| -> Result<Option<FsMatrix>> {
        let Some(v) = map.get(key) else {
            return Ok(None);
        };
        let m = v
            .as_object()
            .ok_or_else(|| Error::invalid(path, format!("{key} must be an !!opencv-matrix")))?;
        yaml_matrix(path, key, m).map(Some)
    };
    let fs = FsCamera {
        width: scalar("image_width")?,
        height: scalar("image_height")?,
        k: matrix("camera_matrix")?,
        d: matrix("distortion_coefficients")?,
    };
    fs_to_camera(path, fs)
}

fn yaml_matrix(path: &Path, key: &str, m: &Map<String, Value>) -> Result<FsMatrix> {
    let count = |name: &str| -> Result<usize> {
        let v = m
            .get(name)
            .ok_or_else(|| Error::invalid(path, format!("{key}: missing {name}")))?;
        v.as_u64().map(|n| n as usize).ok_or_else(|| {
            Error::invalid(
                path,
                format!("{key}: {name} must be a whole number, got {v}"),
            )
        })
    };
    let dims = if m.contains_key("sizes") {
        let sizes = m["sizes"]
            .as_array()
            .ok_or_else(|| Error::invalid(path, format!("{key}: sizes must be a list")))?;
        sizes
            .iter()
            .map(|v| {
                v.as_u64().map(|n| n as usize).ok_or_else(|| {
                    Error::invalid(path, format!("{key}: sizes must be whole numbers, got {v}"))
                })
            })
            .collect::<Result<Vec<_>>>()?
    } else {
        vec![count("rows")?, count("cols")?]
    };
    let dt = m
        .get("dt")
        .and_then(|v| v.as_str())
        .ok_or_else(|| Error::invalid(path, format!("{key}: missing dt")))?;
    let data = m
        .get("data")
        .and_then(|v| v.as_array())
        .ok_or_else(|| Error::invalid(path, format!("{key}: missing data list")))?
        .iter()
        .map(|v| {
            yaml_number(v).ok_or_else(|| {
                Error::invalid(path, format!("{key}: data value {v} is not a number"))
            })
        })
        .collect::<Result<Vec<_>>>()?;
    make_matrix(path, key, dims, dt, data)
}

/// A YAML number; `.nan` / `.inf` arrive as strings when the JSON value model cannot hold them.
fn yaml_number(v: &Value) -> Option<f64> {
    v.as_f64()
        .or_else(|| match v.as_str()?.to_ascii_lowercase().as_str() {
            ".nan" => Some(f64::NAN),
            ".inf" | "+.inf" => Some(f64::INFINITY),
            "-.inf" => Some(f64::NEG_INFINITY),
            _ => None,
        })
}

pub(super) fn parse_xml(path: &Path, text: &str) -> Result<Camera> {
    let doc = roxmltree::Document::parse(text)
        .map_err(|e| Error::invalid(path, format!("not valid XML: {}", one_line(e))))?;
    let root = doc.root_element();
    if root.tag_name().name() != "opencv_storage" {
        return Err(Error::invalid(
            path,
            format!(
                "root element is <{}>, expected <opencv_storage>",
                root.tag_name().name()
            ),
        ));
    }
    let numbers = |field: &str, s: &str| -> Result<Vec<f64>> {
        s.split_whitespace()
            .map(|t| {
                parse_xml_number(t).ok_or_else(|| {
                    Error::invalid(path, format!("{field}: \"{t}\" is not a number"))
                })
            })
            .collect()
    };
    let scalar = |key: &str| -> Result<Option<f64>> {
        let Some(n) = child(root, key) else {
            return Ok(None);
        };
        match numbers(key, n.text().unwrap_or(""))?.as_slice() {
            [v] => Ok(Some(*v)),
            _ => Err(Error::invalid(path, format!("{key} must be one number"))),
        }
    };
    let matrix = |key: &str| -> Result<Option<FsMatrix>> {
        let Some(n) = child(root, key) else {
            return Ok(None);
        };
        let text_of = |name: &str| {
            child(n, name)
                .map(|c| c.text().unwrap_or("").to_string())
                .ok_or_else(|| Error::invalid(path, format!("{key}: missing <{name}>")))
        };
        let as_counts = |name: &str, s: &str| -> Result<Vec<usize>> {
            s.split_whitespace()
                .map(|t| {
                    t.parse::<usize>().map_err(|_| {
                        Error::invalid(path, format!("{key}: {name} \"{t}\" is not a whole number"))
                    })
                })
                .collect()
        };
        let dims = if child(n, "sizes").is_some() {
            as_counts("sizes", &text_of("sizes")?)?
        } else {
            let mut d = as_counts("rows", &text_of("rows")?)?;
            d.extend(as_counts("cols", &text_of("cols")?)?);
            d
        };
        let data = numbers(key, &text_of("data")?)?;
        make_matrix(path, key, dims, &text_of("dt")?, data).map(Some)
    };
    let fs = FsCamera {
        width: scalar("image_width")?,
        height: scalar("image_height")?,
        k: matrix("camera_matrix")?,
        d: matrix("distortion_coefficients")?,
    };
    fs_to_camera(path, fs)
}

/// The first child element of `node` named `name`.
fn child<'a, 'input>(
    node: roxmltree::Node<'a, 'input>,
    name: &str,
) -> Option<roxmltree::Node<'a, 'input>> {
    node.children()
        .find(|c| c.is_element() && c.tag_name().name() == name)
}

/// OpenCV writes `.Nan`, `.Inf`, `-.Inf` in XML as in YAML; Rust's parser handles the rest
/// (including the trailing-dot form "500.").
fn parse_xml_number(t: &str) -> Option<f64> {
    match t.to_ascii_lowercase().as_str() {
        ".nan" => Some(f64::NAN),
        ".inf" | "+.inf" => Some(f64::INFINITY),
        "-.inf" => Some(f64::NEG_INFINITY),
        s => s.parse().ok(),
    }
}
