//! `bronchosim inspect` end to end: the sample case passes with the right summary, and every
//! bad input of issue 2 gets a one-line error naming the file, a non-zero exit, and no panic.

use std::path::{Path, PathBuf};
use std::process::Command;

fn data(p: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/data")
        .join(p)
}

/// Copy a folder recursively.
fn copy_dir(from: &Path, to: &Path) {
    std::fs::create_dir_all(to).unwrap();
    for e in std::fs::read_dir(from).unwrap() {
        let e = e.unwrap();
        let dest = to.join(e.file_name());
        if e.file_type().unwrap().is_dir() {
            copy_dir(&e.path(), &dest);
        } else {
            std::fs::copy(e.path(), dest).unwrap();
        }
    }
}

/// A fresh copy of the sample case in a temporary folder.
fn sample_case() -> (tempfile::TempDir, PathBuf) {
    let tmp = tempfile::tempdir().unwrap();
    let case = tmp.path().join("case");
    copy_dir(&data("case_small"), &case);
    (tmp, case)
}

struct Outcome {
    ok: bool,
    stdout: String,
    stderr: String,
}

fn inspect(case: &Path, extra: &[&str]) -> Outcome {
    let out = Command::new(env!("CARGO_BIN_EXE_bronchosim"))
        .arg("inspect")
        .arg(case)
        .args(extra)
        .output()
        .unwrap();
    Outcome {
        ok: out.status.success(),
        stdout: String::from_utf8_lossy(&out.stdout).into_owned(),
        stderr: String::from_utf8_lossy(&out.stderr).into_owned(),
    }
}

/// Inspect must fail with one error line that mentions `file` and `needle`.
fn assert_fails(case: &Path, file: &str, needle: &str) {
    let o = inspect(case, &[]);
    assert!(
        !o.ok,
        "expected failure for {file}, got success:\n{}",
        o.stdout
    );
    assert!(
        !o.stderr.contains("panicked"),
        "panic instead of an error:\n{}",
        o.stderr
    );
    let errors: Vec<&str> = o
        .stderr
        .lines()
        .filter(|l| l.starts_with("error:"))
        .collect();
    assert_eq!(errors.len(), 1, "one error line expected:\n{}", o.stderr);
    assert_eq!(
        o.stderr.lines().count(),
        1,
        "the error is one line:\n{}",
        o.stderr
    );
    assert!(
        errors[0].contains(file),
        "error does not name {file}: {}",
        errors[0]
    );
    assert!(
        errors[0].to_lowercase().contains(&needle.to_lowercase()),
        "error does not say '{needle}': {}",
        errors[0]
    );
}

fn poses_json(case: &Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(case.join("poses.json")).unwrap()).unwrap()
}

fn write_poses(case: &Path, v: &serde_json::Value) {
    std::fs::write(
        case.join("poses.json"),
        serde_json::to_string_pretty(v).unwrap(),
    )
    .unwrap();
}

#[test]
fn sample_case_summary() {
    let (_tmp, case) = sample_case();
    let o = inspect(&case, &["--json"]);
    assert!(o.ok, "{}", o.stderr);
    let r: serde_json::Value = serde_json::from_str(&o.stdout).unwrap();
    assert_eq!(r["ct"]["dims"], serde_json::json!([48, 48, 40]));
    assert_eq!(r["ct"]["orientation"], "LPS");
    let sp = r["ct"]["spacing_mm"].as_array().unwrap();
    assert!((sp[2].as_f64().unwrap() - 1.5).abs() < 1e-6);
    assert_eq!(r["video"]["frames"], 6);
    assert_eq!(r["video"]["poses"], 6);
    // Centres step 4 mm in z and 0.3 mm in x: 5 * sqrt(16 + 0.09) mm.
    let len = r["video"]["path_length_mm"].as_f64().unwrap();
    assert!((len - 5.0 * (16.09f64).sqrt()).abs() < 1e-9, "{len}");
    // All six centres are on the tube axis, in air.
    assert_eq!(r["video"]["centres_in_air"], 6);
    let fov = r["camera"]["fov_deg"].as_array().unwrap();
    let h = fov[0].as_f64().unwrap();
    assert!(
        h > 2.0 * (32.0f64 / 40.0).atan().to_degrees(),
        "barrel distortion widens the fov: {h}"
    );
    // Text output names the essentials.
    let t = inspect(&case, &[]);
    assert!(t.ok);
    assert!(
        t.stdout.contains("48 x 48 x 40")
            && t.stdout.contains("LPS")
            && t.stdout.contains("in air")
    );
}

#[test]
fn centres_outside_the_airway_are_flagged() {
    let (_tmp, case) = sample_case();
    let mut p = poses_json(&case);
    // Move the first camera into the body wall (x = 21 mm: soft tissue in the sample CT).
    p["frames"][0]["camera_to_world"][3] = serde_json::json!(21.0);
    write_poses(&case, &p);
    let o = inspect(&case, &["--json"]);
    assert!(o.ok, "{}", o.stderr);
    let r: serde_json::Value = serde_json::from_str(&o.stdout).unwrap();
    assert_eq!(r["video"]["centres_in_air"], 5);
    assert!(o.stderr.contains("registration"), "{}", o.stderr);
}

#[test]
fn missing_parts() {
    let (tmp, case) = sample_case();
    assert_fails(&tmp.path().join("nope"), "nope", "not found");
    std::fs::remove_file(case.join("camera.json")).unwrap();
    assert_fails(&case, "case", "camera");
    let (_t2, case) = sample_case();
    std::fs::remove_file(case.join("poses.json")).unwrap();
    assert_fails(&case, "poses.json", "not found");
    let (_t3, case) = sample_case();
    std::fs::remove_file(case.join("ct.nii.gz")).unwrap();
    assert_fails(&case, "case", "no CT");
    let (_t4, case) = sample_case();
    std::fs::remove_file(case.join("frames/000003.png")).unwrap();
    assert_fails(&case, "000003.png", "not found");
}

#[test]
fn bad_ct_files() {
    let (_t, case) = sample_case();
    let gz = std::fs::read(case.join("ct.nii.gz")).unwrap();
    std::fs::write(case.join("ct.nii.gz"), &gz[..gz.len() / 2]).unwrap();
    assert_fails(&case, "ct.nii.gz", "");
    // 4-D NIfTI from the reference set, copied over the CT.
    let mut raw = Vec::new();
    use std::io::Read;
    flate2::read::GzDecoder::new(
        &std::fs::read(data("nifti/int16_flipped_sform.nii.gz")).unwrap()[..],
    )
    .read_to_end(&mut raw)
    .unwrap();
    let (_t2, case) = sample_case();
    std::fs::remove_file(case.join("ct.nii.gz")).unwrap();
    let mut four = raw.clone();
    four[40..42].copy_from_slice(&4i16.to_le_bytes());
    four[48..50].copy_from_slice(&2i16.to_le_bytes());
    std::fs::write(case.join("ct.nii"), &four).unwrap();
    assert_fails(&case, "ct.nii", "4-D");
    let mut dtype = raw.clone();
    dtype[70..72].copy_from_slice(&128i16.to_le_bytes());
    std::fs::write(case.join("ct.nii"), &dtype).unwrap();
    assert_fails(&case, "ct.nii", "rgb24");
    let mut huge = raw.clone();
    huge[42..44].copy_from_slice(&30000i16.to_le_bytes());
    huge[44..46].copy_from_slice(&30000i16.to_le_bytes());
    std::fs::write(case.join("ct.nii"), &huge).unwrap();
    assert_fails(&case, "ct.nii", "header promises");
}

#[test]
fn bad_dicom_series() {
    for (series, needle) in [
        ("mixed_series", "series"),
        ("missing_slice", "missing"),
        ("huge_header", ""),
        ("unknown_syntax", "not a standard transfer syntax"),
    ] {
        let (_t, case) = sample_case();
        std::fs::remove_file(case.join("ct.nii.gz")).unwrap();
        copy_dir(&data(&format!("dicom/{series}")), &case.join("ct"));
        assert_fails(&case, "ct", needle);
    }
    // A good series reads (its centres are not in this CT's air, which is only a warning).
    let (_t, case) = sample_case();
    std::fs::remove_file(case.join("ct.nii.gz")).unwrap();
    copy_dir(&data("dicom/oblique"), &case.join("ct"));
    let o = inspect(&case, &["--json"]);
    assert!(o.ok, "{}", o.stderr);
    let r: serde_json::Value = serde_json::from_str(&o.stdout).unwrap();
    assert_eq!(r["ct"]["format"], "dicom");
}

#[test]
fn bad_camera_files() {
    let (_t, case) = sample_case();
    let cam: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(case.join("camera.json")).unwrap()).unwrap();
    let mut no_fx = cam.clone();
    no_fx.as_object_mut().unwrap().remove("fx");
    std::fs::write(case.join("camera.json"), no_fx.to_string()).unwrap();
    assert_fails(&case, "camera.json", "fx");
    for bad in [0.0, -40.0] {
        let mut c = cam.clone();
        c["fy"] = serde_json::json!(bad);
        std::fs::write(case.join("camera.json"), c.to_string()).unwrap();
        assert_fails(&case, "camera.json", "fy");
    }
    // Frames of a different size than the camera's.
    let mut wide = cam.clone();
    wide["width"] = serde_json::json!(80);
    std::fs::write(case.join("camera.json"), wide.to_string()).unwrap();
    assert_fails(&case, "000000.png", "size");
}

#[test]
fn bad_poses() {
    let (_t, case) = sample_case();
    let good = poses_json(&case);
    std::fs::write(case.join("poses.json"), "{ \"frames\": [ {\"image\": ").unwrap();
    assert_fails(&case, "poses.json", "");
    // A non-finite number: 1e999 does not fit an f64, and JSON has no NaN, so "NaN" comes as a string.
    let text = serde_json::to_string(&good).unwrap();
    let inf = text.replacen("0.3", "1e999", 1);
    std::fs::write(case.join("poses.json"), inf).unwrap();
    assert_fails(&case, "poses.json", "out of range");
    let nan = text.replacen("0.3", "\"NaN\"", 1);
    std::fs::write(case.join("poses.json"), nan).unwrap();
    assert_fails(&case, "poses.json", "");
    // A rotation that is not orthonormal; the error names the frame.
    let mut skew = good.clone();
    skew["frames"][2]["camera_to_world"][0] = serde_json::json!(1.2);
    write_poses(&case, &skew);
    assert_fails(&case, "poses.json", "2");
    // Fewer poses than frames, and more.
    let mut fewer = good.clone();
    fewer["frames"].as_array_mut().unwrap().pop();
    write_poses(&case, &fewer);
    assert_fails(&case, "poses.json", "fewer poses");
    let mut more = good.clone();
    let extra = {
        let mut e = more["frames"][0].clone();
        e["image"] = serde_json::json!("frames/000006.png");
        e
    };
    std::fs::copy(case.join("frames/000000.png"), case.join("extra.png")).unwrap();
    more["frames"].as_array_mut().unwrap().push(extra);
    write_poses(&case, &more);
    assert_fails(&case, "000006.png", "not found");
    // Image paths that leave the case folder.
    for path in ["/etc/passwd", "../outside.png", "frames/../../outside.png"] {
        let mut p = good.clone();
        p["frames"][1]["image"] = serde_json::json!(path);
        write_poses(&case, &p);
        assert_fails(&case, "poses.json", "");
    }
}

#[test]
fn bad_frames() {
    let (_t, case) = sample_case();
    std::fs::write(
        case.join("frames/000004.png"),
        b"\x89PNG\r\n\x1a\nthis is not a png",
    )
    .unwrap();
    assert_fails(&case, "000004.png", "PNG");
}

#[test]
fn video_cases() {
    if Command::new("ffmpeg").arg("-version").output().is_err() {
        panic!("ffmpeg is required (Debian package ffmpeg; .ci/install-deps installs it)");
    }
    let (_t, case) = sample_case();
    // Encode the six PNG frames losslessly into video.mkv, and point the poses at it.
    let st = Command::new("ffmpeg")
        .args(["-v", "error", "-y", "-framerate", "10", "-i"])
        .arg(case.join("frames/%06d.png"))
        .args(["-c:v", "ffv1"])
        .arg(case.join("video.mkv"))
        .status()
        .unwrap();
    assert!(st.success());
    std::fs::remove_dir_all(case.join("frames")).unwrap();
    let mut p = poses_json(&case);
    for (i, f) in p["frames"].as_array_mut().unwrap().iter_mut().enumerate() {
        let o = f.as_object_mut().unwrap();
        o.remove("image");
        o.insert("frame".into(), serde_json::json!(i));
    }
    write_poses(&case, &p);
    let o = inspect(&case, &["--json"]);
    assert!(o.ok, "{}", o.stderr);
    let r: serde_json::Value = serde_json::from_str(&o.stdout).unwrap();
    assert_eq!(r["video"]["kind"], "video");
    assert_eq!(r["video"]["frames"], 6);
    // A video that cannot be decoded.
    std::fs::write(
        case.join("video.mkv"),
        b"\x1aE\xdf\xa3 definitely not a matroska stream",
    )
    .unwrap();
    assert_fails(&case, "video.mkv", "");
}
