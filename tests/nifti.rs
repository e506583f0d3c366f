//! NIfTI reader against nibabel (tests/data/nifti_reference.json, scripts/reference/nifti_nibabel.py),
//! the writer by round trip, and bad inputs.

use bronchosim::io::nifti::{read_nifti, read_nifti_with_info, write_nifti, AffineSource};
use bronchosim::math::{Affine, Point3};
use bronchosim::volume::Volume;
use std::io::{Read, Write};
use std::path::{Path, PathBuf};

fn data(p: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/data")
        .join(p)
}

#[test]
fn geometry_and_values_agree_with_nibabel() {
    let text = std::fs::read_to_string(data("nifti_reference.json")).unwrap();
    let reference: serde_json::Value = serde_json::from_str(&text).unwrap();
    let cases = reference["cases"].as_array().unwrap();
    assert_eq!(cases.len(), 9);
    for case in cases {
        let file = case["file"].as_str().unwrap();
        let (vol, info) = read_nifti_with_info(&data(&format!("nifti/{file}"))).unwrap();
        let dims: Vec<usize> = case["dims"]
            .as_array()
            .unwrap()
            .iter()
            .map(|v| v.as_u64().unwrap() as usize)
            .collect();
        assert_eq!(vol.dims.to_vec(), dims, "{file}");
        for v in case["voxels"].as_array().unwrap() {
            let ijk: Vec<f64> = v["ijk"]
                .as_array()
                .unwrap()
                .iter()
                .map(|x| x.as_f64().unwrap())
                .collect();
            let world: Vec<f64> = v["world"]
                .as_array()
                .unwrap()
                .iter()
                .map(|x| x.as_f64().unwrap())
                .collect();
            let p = vol.index_to_world(Point3::new(ijk[0], ijk[1], ijk[2]));
            let err = (p - Point3::new(world[0], world[1], world[2])).norm();
            assert!(
                err < 1e-4,
                "{file}: voxel {ijk:?} at {p} but nibabel says {world:?} ({err} mm)"
            );
            // And back: world → index.
            let back = vol.world_to_index(p);
            assert!((back - Point3::new(ijk[0], ijk[1], ijk[2])).norm() < 1e-6);
            let expect = v["value"].as_f64().unwrap();
            let got = vol.get(ijk[0] as usize, ijk[1] as usize, ijk[2] as usize) as f64;
            assert!(
                (got - expect).abs() <= 1e-5 * expect.abs().max(1.0),
                "{file}: value {got} != {expect}"
            );
        }
        let mean = vol.data.iter().map(|&v| v as f64).sum::<f64>() / vol.len() as f64;
        let expect = case["mean"].as_f64().unwrap();
        assert!(
            (mean - expect).abs() <= 1e-4 * expect.abs().max(1.0),
            "{file}: mean {mean} != {expect}"
        );
        let expected_source = if file.starts_with("pixdim") {
            AffineSource::Pixdim
        } else if file.contains("qform") {
            AffineSource::Qform
        } else {
            AffineSource::Sform
        };
        assert_eq!(info.affine_source, expected_source, "{file}");
        assert_eq!(
            info.warnings.is_empty(),
            expected_source != AffineSource::Pixdim,
            "{file}"
        );
    }
}

#[test]
fn orientation_codes_of_reference_files() {
    let v = read_nifti(&data("nifti/int16_flipped_sform.nii.gz")).unwrap();
    assert_eq!(v.orientation(), "LPS");
    let s = v.spacing();
    assert!((s[0] - 0.7).abs() < 1e-6 && (s[2] - 1.25).abs() < 1e-6);
}

fn oblique_affine() -> Affine {
    let r = nalgebra::Rotation3::from_euler_angles(0.2, -0.1, 0.4);
    let mut a = Affine::identity();
    let lin =
        r.matrix() * nalgebra::Matrix3::from_diagonal(&nalgebra::Vector3::new(0.6, 0.8, -1.5));
    a.fixed_view_mut::<3, 3>(0, 0).copy_from(&lin);
    a[(0, 3)] = -30.0;
    a[(1, 3)] = 44.0;
    a[(2, 3)] = 12.5;
    a
}

#[test]
fn write_then_read_round_trips_u8_i16_f32() {
    let dir = tempfile::tempdir().unwrap();
    let a = oblique_affine();
    let dims = [9, 8, 7];
    let n = dims[0] * dims[1] * dims[2];
    let mask = Volume::from_data(dims, a, (0..n).map(|i| (i % 3 == 0) as u8).collect()).unwrap();
    let hu = Volume::from_data(dims, a, (0..n).map(|i| (i as i16) * 7 - 1000).collect()).unwrap();
    let f = Volume::from_data(dims, a, (0..n).map(|i| (i as f32).sin() * 900.0).collect()).unwrap();
    for (name, expect) in [
        ("m.nii.gz", mask.map(|v| v as f32)),
        ("h.nii", hu.map(|v| v as f32)),
        ("f.nii.gz", f.clone()),
    ] {
        let p = dir.path().join(name);
        match name {
            "m.nii.gz" => write_nifti(&p, &mask).unwrap(),
            "h.nii" => write_nifti(&p, &hu).unwrap(),
            _ => write_nifti(&p, &f).unwrap(),
        }
        let back = read_nifti(&p).unwrap();
        assert_eq!(back.dims, dims);
        assert_eq!(back.data, expect.data, "{name}");
        assert!(
            (back.affine - a).abs().max() < 1e-5,
            "{name}: {}",
            back.affine
        );
    }
    // No temporary files left behind by the atomic writer.
    let names: Vec<_> = std::fs::read_dir(dir.path())
        .unwrap()
        .map(|e| e.unwrap().file_name())
        .collect();
    assert_eq!(names.len(), 3, "{names:?}");
}

/// The uncompressed bytes of a reference file, for corrupting.
fn raw_bytes(name: &str) -> Vec<u8> {
    let gz = std::fs::read(data(&format!("nifti/{name}"))).unwrap();
    let mut out = Vec::new();
    flate2::read::GzDecoder::new(&gz[..])
        .read_to_end(&mut out)
        .unwrap();
    out
}

fn gz(bytes: &[u8]) -> Vec<u8> {
    let mut e = flate2::write::GzEncoder::new(Vec::new(), flate2::Compression::fast());
    e.write_all(bytes).unwrap();
    e.finish().unwrap()
}

fn expect_error(name: &str, bytes: &[u8], needle: &str) {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join(name);
    std::fs::write(&p, bytes).unwrap();
    let err = read_nifti(&p).unwrap_err().to_string();
    assert!(err.contains(name), "error does not name the file: {err}");
    assert!(err.contains(needle), "expected '{needle}' in: {err}");
}

#[test]
fn bad_inputs_get_clear_errors() {
    let raw = raw_bytes("int16_flipped_sform.nii.gz");
    let gzb = gz(&raw);
    // Missing file.
    let err = read_nifti(Path::new("/nonexistent/ct.nii.gz"))
        .unwrap_err()
        .to_string();
    assert!(
        err.contains("/nonexistent/ct.nii.gz") && err.contains("not found"),
        "{err}"
    );
    // Truncated gzip (cut in the middle of the voxel data).
    expect_error("trunc.nii.gz", &gzb[..gzb.len() * 2 / 3], "");
    // Truncated uncompressed file.
    expect_error("trunc.nii", &raw[..raw.len() - 10], "truncated");
    // Not gzip at all although .gz.
    expect_error(
        "garbage.nii.gz",
        b"this is not a gzip stream at all, just text",
        "",
    );
    // Corrupt deflate stream.
    let mut bad = gzb.clone();
    for b in bad[20..40].iter_mut() {
        *b ^= 0x5a;
    }
    expect_error("corrupt.nii.gz", &bad, "");
    // Wrong header size / magic.
    expect_error("short.nii", &raw[..100], "truncated");
    let mut magic = raw.clone();
    magic[344..348].copy_from_slice(b"abcd");
    expect_error("magic.nii", &magic, "magic");
    // 2-D image: dims 7x6x1.
    let mut two_d = raw.clone();
    two_d[46..48].copy_from_slice(&1i16.to_le_bytes());
    expect_error("twod.nii", &two_d, "2-D");
    // 4-D series: dim[0] = 4, dim[4] = 3.
    let mut four_d = raw.clone();
    four_d[40..42].copy_from_slice(&4i16.to_le_bytes());
    four_d[48..50].copy_from_slice(&3i16.to_le_bytes());
    expect_error("fourd.nii", &four_d, "4-D");
    // Unsupported datatype: complex64.
    let mut cplx = raw.clone();
    cplx[70..72].copy_from_slice(&32i16.to_le_bytes());
    expect_error("complex.nii", &cplx, "complex64");
    // Header promising far more voxels than the file holds: refused before allocating
    // (32767^3 int16 voxels would need 70 TB).
    let mut huge = raw.clone();
    for a in 0..3 {
        huge[42 + 2 * a..44 + 2 * a].copy_from_slice(&32767i16.to_le_bytes());
    }
    expect_error("huge.nii.gz", &gz(&huge), "header promises");
    expect_error("huge.nii", &huge, "header promises");
    // Negative (i.e. invalid) dimension.
    let mut neg = raw.clone();
    neg[42..44].copy_from_slice(&(-5i16).to_le_bytes());
    expect_error("neg.nii", &neg, "dimensions");
}

/// Writes a file for the nibabel cross-check in scripts/reference/nifti_nibabel.py (run with
/// `BRONCHOSIM_WRITE_NIFTI=path cargo test --test nifti written_file_for_nibabel`).
#[test]
fn written_file_for_nibabel() {
    let Ok(path) = std::env::var("BRONCHOSIM_WRITE_NIFTI") else {
        return;
    };
    let vol = Volume::from_data(
        [4, 3, 2],
        oblique_affine(),
        (0..24).map(|i| i as i16 * 10 - 100).collect(),
    )
    .unwrap();
    write_nifti(Path::new(&path), &vol).unwrap();
}
