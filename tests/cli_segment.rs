//! `bronchosim segment` end to end on the coarse phantom CT: outputs written, readable, on the
//! CT's grid, the summary right against the truth; no clobbering without --force.

use bronchosim::io::mesh_export::read_ply;
use bronchosim::io::nifti::{read_nifti, write_nifti};
use bronchosim::phantom::{make_ct_phantom, CtPhantomOptions};
use std::process::Command;

fn segment(args: &[&std::ffi::OsStr]) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_bronchosim"))
        .arg("segment")
        .args(args)
        .output()
        .unwrap()
}

#[test]
fn segment_writes_mask_mesh_and_summary() {
    let ph = make_ct_phantom(&CtPhantomOptions::coarse()).unwrap();
    let tmp = tempfile::tempdir().unwrap();
    let ct_path = tmp.path().join("ct.nii.gz");
    write_nifti(&ct_path, &ph.ct.map(|v| v.round() as i16)).unwrap();
    let out = tmp.path().join("seg");
    let o = segment(&[ct_path.as_os_str(), "--out".as_ref(), out.as_os_str()]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let text = String::from_utf8_lossy(&o.stdout);
    assert!(
        text.contains("seed") && text.contains("ml") && text.contains("triangles"),
        "{text}"
    );

    // The mask is on the CT's grid, with the CT's affine.
    let mask = read_nifti(&out.join("segmentation.nii.gz")).unwrap();
    assert_eq!(mask.dims, ph.ct.dims);
    assert!((mask.affine - ph.ct.affine).abs().max() < 1e-5);
    let voxels = mask.data.iter().filter(|&&v| v > 0.5).count();
    let sp = ph.ct.spacing();
    let ml = voxels as f64 * sp[0] * sp[1] * sp[2] / 1000.0;

    let summary: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("summary.json")).unwrap()).unwrap();
    let volume = summary["volume_ml"].as_f64().unwrap();
    assert!(
        (volume - ml).abs() < 1e-6 * ml,
        "summary {volume} ml, mask {ml} ml"
    );
    assert!(
        (volume / ph.truth_volume_ml - 1.0).abs() < 0.05,
        "volume {volume:.2} ml vs truth {:.2} ml",
        ph.truth_volume_ml
    );
    assert_eq!(summary["seed_automatic"], true);
    assert!(summary["branches"].as_u64().unwrap() >= 7);
    assert!(summary["thresholds"].as_array().unwrap().len() >= 2);

    // The mesh files agree with each other and with the summary.
    let mesh = read_ply(&out.join("lumen.ply")).unwrap();
    assert_eq!(
        mesh.triangles.len() as u64,
        summary["triangles"].as_u64().unwrap()
    );
    let area = summary["surface_area_mm2"].as_f64().unwrap();
    assert!((mesh.area() - area).abs() < 1e-6 * area);
    let obj = std::fs::read_to_string(out.join("lumen.obj")).unwrap();
    assert_eq!(
        obj.lines().filter(|l| l.starts_with("f ")).count(),
        mesh.triangles.len()
    );
    let glb = std::fs::read(out.join("lumen.glb")).unwrap();
    assert_eq!(&glb[0..4], b"glTF");

    // No clobbering without --force; --force replaces.
    let again = segment(&[ct_path.as_os_str(), "--out".as_ref(), out.as_os_str()]);
    assert!(!again.status.success());
    let err = String::from_utf8_lossy(&again.stderr);
    assert!(
        err.contains("already exists") && err.contains("--force"),
        "{err}"
    );
    let forced = segment(&[
        ct_path.as_os_str(),
        "--out".as_ref(),
        out.as_os_str(),
        "--force".as_ref(),
        "--seed".as_ref(),
        format!(
            "{},{},{}",
            summary["seed_mm"][0].as_f64().unwrap(),
            summary["seed_mm"][1].as_f64().unwrap(),
            summary["seed_mm"][2].as_f64().unwrap()
        )
        .as_ref(),
    ]);
    assert!(
        forced.status.success(),
        "{}",
        String::from_utf8_lossy(&forced.stderr)
    );
    let s2: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("summary.json")).unwrap()).unwrap();
    assert_eq!(s2["seed_automatic"], false);
    assert_eq!(s2["volume_ml"], summary["volume_ml"]);
}

#[test]
fn segment_bad_input() {
    let tmp = tempfile::tempdir().unwrap();
    let o = segment(&[tmp.path().join("missing.nii.gz").as_os_str()]);
    assert!(!o.status.success());
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        err.contains("missing.nii.gz") && err.contains("not found"),
        "{err}"
    );
    assert!(!err.contains("panicked"));
    let o = segment(&["x.nii.gz".as_ref(), "--seed".as_ref(), "1,2".as_ref()]);
    assert!(!o.status.success());
    assert!(String::from_utf8_lossy(&o.stderr).contains("X,Y,Z"));
}

/// A float CT with a 10x10x10 block of NaN (issue 17): `segment` ends in seconds, says how many
/// voxels were not finite and that they count as tissue, and writes the same tree otherwise.
#[test]
fn segment_counts_nan_voxels_as_tissue() {
    let ph = make_ct_phantom(&CtPhantomOptions::coarse()).unwrap();
    let mut ct = ph.ct.clone();
    // In the lung, beside the airway: the tree must not change.
    let c = ph.tree.carina();
    let at = ct
        .voxel_at_world(bronchosim::math::Point3::new(c.x + 40.0, c.y, c.z - 10.0))
        .unwrap();
    for k in at[2] - 5..at[2] + 5 {
        for j in at[1] - 5..at[1] + 5 {
            for i in at[0] - 5..at[0] + 5 {
                assert_eq!(ph.truth_mask.get(i, j, k), 0);
                ct.set(i, j, k, f32::NAN);
            }
        }
    }
    let tmp = tempfile::tempdir().unwrap();
    let clean_path = tmp.path().join("clean.nii.gz");
    write_nifti(&clean_path, &ph.ct).unwrap();
    let nan_path = tmp.path().join("nan.nii.gz");
    write_nifti(&nan_path, &ct).unwrap();
    let summary = |out: &std::path::Path| -> serde_json::Value {
        serde_json::from_str(&std::fs::read_to_string(out.join("summary.json")).unwrap()).unwrap()
    };
    let (clean_out, nan_out) = (tmp.path().join("clean"), tmp.path().join("nan"));
    let o = segment(&[
        clean_path.as_os_str(),
        "--out".as_ref(),
        clean_out.as_os_str(),
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let t = std::time::Instant::now();
    let o = segment(&[nan_path.as_os_str(), "--out".as_ref(), nan_out.as_os_str()]);
    let seconds = t.elapsed().as_secs_f64();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert!(seconds < 30.0, "segment took {seconds:.1} s");
    let text = String::from_utf8_lossy(&o.stdout);
    let note = text.lines().find(|l| l.starts_with("note")).unwrap_or("");
    assert!(
        note.contains("nan.nii.gz")
            && note.contains("1000 voxels are NaN")
            && note.contains("tissue"),
        "{text}"
    );
    let (a, b) = (summary(&clean_out), summary(&nan_out));
    assert_eq!(b["non_finite_voxels"], 1000);
    assert_eq!(a["non_finite_voxels"], 0);
    for key in ["volume_ml", "threshold_hu", "seed_voxel", "branches"] {
        assert_eq!(a[key], b[key], "{key}");
    }
}
