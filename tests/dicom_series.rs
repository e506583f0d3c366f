//! DICOM series reader against SimpleITK (values from scripts/reference/make_dicom_series.py):
//! world positions of chosen voxels within 1e-4 mm, HU exact; RLE equal to raw; every bad
//! series fails with a message naming the folder or file and the problem.

use std::path::{Path, PathBuf};

use bronchosim::io::dicom::{
    read_dicom_series, read_dicom_series_from_memory, read_dicom_series_with_info,
};
use bronchosim::math::{Point3, Vector3};
use serde_json::Value;

fn data(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/data/dicom")
        .join(name)
}

fn reference(series: &str) -> Value {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/dicom_reference.json");
    let text = std::fs::read_to_string(&path).unwrap();
    let all: Value = serde_json::from_str(&text).unwrap();
    all["series"][series].clone()
}

fn f(v: &Value) -> f64 {
    v.as_f64().unwrap()
}

/// Compare a series with SimpleITK: dims, affine (all columns, or only i, j and origin), every
/// chosen voxel's world point and HU, and the HU sum/min/max over the whole volume.
fn check_against_simpleitk(series: &str, compare_k_axis: bool) {
    let (vol, info) = read_dicom_series_with_info(&data(series)).unwrap();
    let r = reference(series);
    let dims: Vec<usize> = r["dims"]
        .as_array()
        .unwrap()
        .iter()
        .map(|v| v.as_u64().unwrap() as usize)
        .collect();
    assert_eq!(vol.dims.to_vec(), dims, "{series}: dims");
    assert_eq!(info.files.len(), dims[2]);
    for row in 0..3 {
        for col in 0..4 {
            if col == 2 && !compare_k_axis {
                continue;
            }
            let want = f(&r["affine_ras"][row][col]);
            let got = vol.affine[(row, col)];
            assert!(
                (got - want).abs() < 1e-4,
                "{series}: affine[{row}][{col}] = {got}, SimpleITK {want}"
            );
        }
    }
    let voxels = r["voxels"].as_array().unwrap();
    assert!(voxels.len() >= 30);
    for v in voxels {
        let ras = Point3::new(f(&v["ras"][0]), f(&v["ras"][1]), f(&v["ras"][2]));
        let p = vol.world_to_index(ras);
        let ijk = [p.x.round(), p.y.round(), p.z.round()];
        let back = vol.index_to_world(Point3::new(ijk[0], ijk[1], ijk[2]));
        assert!(
            (back - ras).norm() < 1e-4,
            "{series}: SimpleITK voxel at {ras} maps to index {p}, off the grid by {}",
            (back - ras).norm()
        );
        let hu = vol.get(ijk[0] as usize, ijk[1] as usize, ijk[2] as usize);
        assert_eq!(hu as f64, f(&v["hu"]), "{series}: HU at {ras}");
    }
    let sum: f64 = vol.data.iter().map(|&v| v as f64).sum();
    assert_eq!(sum, f(&r["hu_sum"]), "{series}: HU sum");
    let min = vol.data.iter().cloned().fold(f32::INFINITY, f32::min);
    let max = vol.data.iter().cloned().fold(f32::NEG_INFINITY, f32::max);
    assert_eq!(
        (min as f64, max as f64),
        (f(&r["hu_min"]), f(&r["hu_max"])),
        "{series}: HU range"
    );
}

#[test]
fn axial_series_matches_simpleitk() {
    check_against_simpleitk("axial", true);
    let (vol, info) = read_dicom_series_with_info(&data("axial")).unwrap();
    // Sorted by position, not by file name or InstanceNumber (both scrambled by the script).
    assert!((info.slice_step_mm - 2.5).abs() < 1e-9);
    assert_eq!(vol.orientation(), "LPS");
    assert_eq!(info.transfer_syntax_uid, "1.2.840.10008.1.2.1");
    let names: Vec<_> = info
        .files
        .iter()
        .map(|p| p.file_name().unwrap().to_owned())
        .collect();
    let mut sorted = names.clone();
    sorted.sort();
    assert_ne!(names, sorted, "test data must not be sorted by name");
}

#[test]
fn oblique_feet_first_series_matches_simpleitk() {
    check_against_simpleitk("oblique", true);
    let (vol, info) = read_dicom_series_with_info(&data("oblique")).unwrap();
    assert!((info.slice_step_mm - 1.25).abs() < 1e-5);
    let sp = vol.spacing();
    assert!(
        (sp[0] - 0.65).abs() < 1e-6 && (sp[1] - 0.8).abs() < 1e-6 && (sp[2] - 1.25).abs() < 1e-5,
        "{sp:?}"
    );
    // The k axis is the slice normal r × c (no gantry tilt): right-handed in LPS and, since
    // diag(-1, -1, 1) has determinant 1, in RAS too.
    let m = vol.affine.fixed_view::<3, 3>(0, 0);
    assert!(m.determinant() > 0.0);
    let k = Vector3::new(vol.affine[(0, 2)], vol.affine[(1, 2)], vol.affine[(2, 2)]);
    let ci = Vector3::new(vol.affine[(0, 0)], vol.affine[(1, 0)], vol.affine[(2, 0)]);
    assert!(k.dot(&ci).abs() < 1e-6);
}

#[test]
fn rle_series_equals_raw_series() {
    check_against_simpleitk("axial_rle", true);
    let (raw, _) = read_dicom_series_with_info(&data("axial")).unwrap();
    let (rle, info) = read_dicom_series_with_info(&data("axial_rle")).unwrap();
    assert_eq!(info.transfer_syntax_uid, "1.2.840.10008.1.2.5");
    assert_eq!(info.transfer_syntax_name, "RLE Lossless");
    assert_eq!(raw, rle);
}

#[test]
fn single_slice_uses_slice_thickness() {
    // SimpleITK puts 1 mm on the k axis of a single slice; we use SliceThickness (2.5 mm).
    check_against_simpleitk("single_slice", false);
    let vol = read_dicom_series(&data("single_slice")).unwrap();
    assert_eq!(vol.dims, [24, 20, 1]);
    assert!((vol.affine[(2, 2)] - 2.5).abs() < 1e-12);
    assert!(vol.affine[(0, 2)].abs() < 1e-12 && vol.affine[(1, 2)].abs() < 1e-12);
}

#[test]
fn memory_reader_equals_folder_reader() {
    let files: Vec<(PathBuf, Vec<u8>)> = std::fs::read_dir(data("oblique"))
        .unwrap()
        .map(|e| {
            let p = e.unwrap().path();
            let b = std::fs::read(&p).unwrap();
            (p, b)
        })
        .collect();
    let (mem, _) = read_dicom_series_from_memory(&files).unwrap();
    assert_eq!(mem, read_dicom_series(&data("oblique")).unwrap());
    // Truncated copies fail cleanly instead of panicking.
    for cut in [0, 100, 131, 300, 700, files[0].1.len() - 10] {
        let mut t = files.clone();
        t[0].1.truncate(cut);
        let err = read_dicom_series_from_memory(&t).unwrap_err().to_string();
        assert!(
            err.contains(&*files[0].0.to_string_lossy()),
            "cut {cut}: {err}"
        );
    }
}

/// Read `series`, expect an error containing every string in `want`.
fn expect_error(series: &str, want: &[&str]) -> String {
    let err = read_dicom_series(&data(series))
        .expect_err(series)
        .to_string();
    assert!(!err.contains('\n'), "{series}: multi-line error {err}");
    for w in want {
        assert!(err.contains(w), "{series}: error '{err}' lacks '{w}'");
    }
    err
}

#[test]
fn missing_folder_is_an_error() {
    expect_error(
        "no_such_series",
        &["no_such_series", "not found", "DICOM series folder"],
    );
}

#[test]
fn jpeg2000_fails_naming_the_syntax() {
    expect_error(
        "jpeg2000",
        &[
            "jpeg2000/j",
            "1.2.840.10008.1.2.4.90",
            "JPEG 2000 Image Compression (Lossless Only)",
            "unsupported",
        ],
    );
}

#[test]
fn unknown_transfer_syntax_fails_naming_the_uid() {
    expect_error(
        "unknown_syntax",
        &[
            "unknown_syntax/u0.dcm",
            "1.2.826.0.1.3680043.8.498.999.1",
            "not a standard transfer syntax",
        ],
    );
}

#[test]
fn mixed_series_fails() {
    expect_error(
        "mixed_series",
        &[
            "mixed_series",
            "mixes series",
            "1.2.826.0.1.3680043.8.498.10.6",
            "1.2.826.0.1.3680043.8.498.10.7",
        ],
    );
}

#[test]
fn mixed_size_fails() {
    expect_error(
        "mixed_size",
        &["mixed_size", "differ in size", "odd.dcm", "24x16", "24x20"],
    );
}

#[test]
fn localizer_fails() {
    expect_error(
        "localizer",
        &["localizer/scout.dcm", "2-D localizer", "LOCALIZER"],
    );
}

#[test]
fn missing_slice_fails() {
    expect_error(
        "missing_slice",
        &[
            "missing_slice",
            "missing slice",
            "gap of 5.0000 mm",
            "2.5000 mm",
        ],
    );
}

#[test]
fn nonuniform_spacing_fails() {
    expect_error(
        "nonuniform",
        &["nonuniform", "non-uniform slice spacing", "2.8000 mm", "1%"],
    );
}

#[test]
fn duplicate_position_fails() {
    expect_error(
        "duplicate",
        &["duplicate", "two slices at the same position"],
    );
}

#[test]
fn huge_header_fails_before_allocating() {
    expect_error(
        "huge_header",
        &[
            "huge_header/h0.dcm",
            "60000x60000",
            "7200000000 bytes",
            "more than a",
        ],
    );
}

#[test]
fn non_dicom_file_fails() {
    expect_error("not_dicom", &["not_dicom/notes.txt", "not a DICOM file"]);
}
