//! `bronchosim inspect` on a bare CT (a NIfTI file or a DICOM folder): the CT summary alone,
//! with non-finite voxels counted and located (issue 17: a NaN block went unmentioned).

use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::{Duration, Instant};

use bronchosim::io::nifti::write_nifti;
use bronchosim::volume::Volume;
use serde_json::{json, Value};

fn data(p: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/data")
        .join(p)
}

/// Run inspect; (success, stdout, stderr, wall time).
fn inspect(input: &Path, extra: &[&str]) -> (bool, String, String, Duration) {
    let t = Instant::now();
    let o = Command::new(env!("CARGO_BIN_EXE_bronchosim"))
        .arg("inspect")
        .arg(input)
        .args(extra)
        .output()
        .unwrap();
    (
        o.status.success(),
        String::from_utf8_lossy(&o.stdout).into_owned(),
        String::from_utf8_lossy(&o.stderr).into_owned(),
        t.elapsed(),
    )
}

/// A float32 CT of 64 x 56 x 48 voxels (0.7 x 0.7 x 1.5 mm, origin (-20, 10, 100)) with a
/// 10 x 10 x 10 block of NaN at i 20..29, j 30..39, k 5..14.
fn nan_ct(path: &Path) {
    let mut aff = nalgebra::Matrix4::identity();
    aff[(0, 0)] = 0.75;
    aff[(1, 1)] = 0.75;
    aff[(2, 2)] = 1.5;
    aff[(0, 3)] = -20.0;
    aff[(1, 3)] = 10.0;
    aff[(2, 3)] = 100.0;
    let mut vol = Volume::filled([64, 56, 48], aff, 40.0f32);
    vol.set(3, 4, 5, -1000.0);
    for k in 5..15 {
        for j in 30..40 {
            for i in 20..30 {
                vol.set(i, j, k, f32::NAN);
            }
        }
    }
    write_nifti(path, &vol).unwrap();
}

#[test]
fn nan_block_is_counted_and_located_in_seconds() {
    let tmp = tempfile::tempdir().unwrap();
    let ct = tmp.path().join("nan.nii.gz");
    nan_ct(&ct);
    let (ok, out, err, took) = inspect(&ct, &["--json"]);
    assert!(ok, "{err}");
    assert!(took < Duration::from_secs(10), "took {took:?}");
    let r: Value = serde_json::from_str(&out).unwrap();
    assert_eq!(r["kind"], "ct");
    assert!(r.get("camera").is_none() && r.get("video").is_none());
    let nf = &r["ct"]["non_finite"];
    assert_eq!(nf["count"], 1000);
    assert_eq!(nf["nan"], 1000);
    assert_eq!(nf["pos_inf"], 0);
    assert_eq!(nf["index_bounds"], json!([[20, 30, 5], [29, 39, 14]]));
    // Centres of voxels 20 and 29 along x: -20 + 0.75 i.
    assert_eq!(
        nf["world_bounds_mm"],
        json!([[-5.0, 32.5, 107.5], [1.75, 39.25, 121.0]])
    );
    // The HU statistics are over the finite voxels only.
    assert_eq!(r["ct"]["hu_range"], json!([-1000.0, 40.0]));
    assert!(
        err.contains("1000 of 172032 voxels are not finite"),
        "{err}"
    );

    let (ok, text, _, _) = inspect(&ct, &[]);
    assert!(ok);
    assert!(
        text.contains("non-finite voxels: 1000 (NaN 1000, +inf 0, -inf 0) in voxels i 20..29, j 30..39, k 5..14"),
        "{text}"
    );
    assert!(
        text.contains("OK, with warnings") && !text.contains("case "),
        "{text}"
    );
}

#[test]
fn finite_ct_reports_none() {
    let (ok, text, err, _) = inspect(&data("nifti/int16_flipped_sform.nii.gz"), &[]);
    assert!(ok, "{err}");
    assert!(text.contains("non-finite voxels: none"), "{text}");
    assert!(text.trim_end().ends_with("OK"), "{text}");
}

/// A scan as downloaded: a folder holding one NIfTI file with its licence and read-me is that
/// CT (it was read as a DICOM series and refused); several NIfTI files are named as the problem.
#[test]
fn folder_with_one_nifti_is_inspected_as_that_ct() {
    let file = data("nifti/int16_flipped_sform.nii.gz");
    let (ok, out, err, _) = inspect(&file, &["--json"]);
    assert!(ok, "{err}");
    let direct: Value = serde_json::from_str(&out).unwrap();
    let tmp = tempfile::tempdir().unwrap();
    std::fs::copy(&file, tmp.path().join("scan.nii.gz")).unwrap();
    std::fs::write(tmp.path().join("README.md"), "# a chest CT").unwrap();
    std::fs::write(tmp.path().join("LICENSE"), "CC BY 4.0").unwrap();
    let (ok, out, err, _) = inspect(tmp.path(), &["--json"]);
    assert!(ok, "{err}");
    let r: Value = serde_json::from_str(&out).unwrap();
    assert_eq!(r["kind"], "ct");
    assert_eq!(r["ct"]["format"], "nifti");
    assert!(
        r["case"].as_str().unwrap().ends_with("scan.nii.gz"),
        "{}",
        r["case"]
    );
    for key in ["dims", "spacing_mm", "hu_range"] {
        assert_eq!(r["ct"][key], direct["ct"][key], "{key}");
    }
    std::fs::copy(&file, tmp.path().join("other.nii")).unwrap();
    let (ok, _, err, _) = inspect(tmp.path(), &[]);
    assert!(!ok);
    assert_eq!(err.lines().count(), 1, "{err}");
    assert!(err.contains("holds 2 NIfTI files"), "{err}");
}

#[test]
fn dicom_folder_is_inspected_as_a_ct() {
    let (ok, out, err, _) = inspect(&data("dicom_real/j2k_lossless"), &["--json"]);
    assert!(ok, "{err}");
    let r: Value = serde_json::from_str(&out).unwrap();
    assert_eq!(r["kind"], "ct");
    assert_eq!(r["ct"]["format"], "dicom");
    assert_eq!(r["ct"]["dims"], json!([512, 512, 5]));
    assert_eq!(r["ct"]["dicom"]["slices"], 5);
    assert_eq!(r["ct"]["dicom"]["slice_step_mm"], 2.0);
    assert_eq!(
        r["ct"]["dicom"]["transfer_syntax"],
        "1.2.840.10008.1.2.4.90 (JPEG 2000 Image Compression (Lossless Only))"
    );
    // Same extremes as the reference decoders (tests/data/dicom_real_reference.json).
    assert_eq!(r["ct"]["hu_range"], json!([-1024.0, 1450.0]));
    // A series copied with its licence and notes: they are left out, and the summary says so.
    let tmp = tempfile::tempdir().unwrap();
    for e in std::fs::read_dir(data("dicom_real/j2k_sign_mismatch")).unwrap() {
        let p = e.unwrap().path();
        std::fs::copy(&p, tmp.path().join(p.file_name().unwrap())).unwrap();
    }
    std::fs::write(tmp.path().join("notes.txt"), "not a slice").unwrap();
    std::fs::write(tmp.path().join("LICENSE"), "CC BY 4.0").unwrap();
    let (ok, out, err, _) = inspect(tmp.path(), &[]);
    assert!(ok, "{err}");
    assert!(out.contains("3 slices"), "{out}");
    assert!(
        err.contains("left out 2 file(s) that are not DICOM slices: LICENSE, notes.txt"),
        "{err}"
    );
    // Any other file without the DICOM marker is a bad series, named as such.
    std::fs::write(tmp.path().join("slice_x"), "not a slice").unwrap();
    let (ok, _, err, _) = inspect(tmp.path(), &[]);
    assert!(!ok);
    assert_eq!(err.lines().count(), 1, "{err}");
    assert!(
        err.contains("slice_x") && err.contains("not a DICOM file"),
        "{err}"
    );
}

#[test]
fn a_reader_that_stops_early_is_not_an_error() {
    // `bronchosim inspect CT | head`: the pipe is closed before the summary is written.
    let mut child = Command::new(env!("CARGO_BIN_EXE_bronchosim"))
        .arg("inspect")
        .arg(data("nifti/int16_flipped_sform.nii.gz"))
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    drop(child.stdout.take());
    let o = child.wait_with_output().unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success(), "{err}");
    assert!(!err.contains("panicked"), "{err}");
}
