//! `bronchosim convert` end to end: the real JPEG 2000 series becomes a NIfTI whose values equal
//! nibabel's reading of SimpleITK's NIfTI of the same series (one CRC-32 per slice) and whose
//! sform and qform both give SimpleITK's affine within 1e-4 mm (values from
//! scripts/reference/make_real_dicom_series.py); existing outputs are never clobbered without --force;
//! bad inputs fail with one line naming the file and leave nothing behind.

use std::io::Read;
use std::path::{Path, PathBuf};
use std::process::Command;

use bronchosim::io::nifti::{read_nifti_with_info, write_nifti, AffineSource};
use bronchosim::volume::Volume;
use serde_json::Value;

fn data(p: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/data")
        .join(p)
}

struct Outcome {
    ok: bool,
    stdout: String,
    stderr: String,
}

fn convert(input: &Path, out: &Path, extra: &[&str]) -> Outcome {
    let o = Command::new(env!("CARGO_BIN_EXE_bronchosim"))
        .arg("convert")
        .arg(input)
        .arg("--out")
        .arg(out)
        .args(extra)
        .output()
        .unwrap();
    Outcome {
        ok: o.status.success(),
        stdout: String::from_utf8_lossy(&o.stdout).into_owned(),
        stderr: String::from_utf8_lossy(&o.stderr).into_owned(),
    }
}

/// Exactly one line on stderr, an error naming `file` and saying `needle`.
fn assert_one_line_error(o: &Outcome, file: &str, needle: &str) {
    assert!(!o.ok, "expected failure, got:\n{}", o.stdout);
    assert_eq!(o.stderr.lines().count(), 1, "one line:\n{}", o.stderr);
    assert!(
        o.stderr.starts_with("error:") && o.stderr.contains(file) && o.stderr.contains(needle),
        "error should name {file} and say '{needle}': {}",
        o.stderr
    );
}

fn reference() -> Value {
    let text = std::fs::read_to_string(data("dicom_real_reference.json")).unwrap();
    let all: Value = serde_json::from_str(&text).unwrap();
    all["series"]["j2k_lossless"]["nibabel_from_simpleitk_nifti"].clone()
}

fn assert_affine(vol: &Volume<f32>, want: &Value, what: &str) {
    for r in 0..4 {
        for c in 0..4 {
            let (got, w) = (vol.affine[(r, c)], want[r][c].as_f64().unwrap());
            assert!(
                (got - w).abs() < 1e-4,
                "{what}: affine[{r}][{c}] {got}, nibabel {w}"
            );
        }
    }
}

#[test]
fn real_jpeg2000_series_converts_to_what_nibabel_reads_from_simpleitk() {
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("sub/ct.nii.gz");
    let o = convert(&data("dicom_real/j2k_lossless"), &out, &[]);
    assert!(o.ok, "{}", o.stderr);
    assert!(
        o.stdout.contains("int16") && o.stdout.contains("512 x 512 x 5"),
        "{}",
        o.stdout
    );
    let (vol, info) = read_nifti_with_info(&out).unwrap();
    assert_eq!(info.datatype, "int16");
    assert_eq!(info.affine_source, AffineSource::Sform);
    let r = reference();
    assert_affine(&vol, &r["affine"], "sform");
    let n = vol.dims[0] * vol.dims[1];
    let crcs: Vec<u64> = (0..vol.dims[2])
        .map(|k| {
            let mut crc = flate2::Crc::new();
            for &v in &vol.data[k * n..(k + 1) * n] {
                crc.update(&(v as i32).to_le_bytes());
            }
            crc.sum() as u64
        })
        .collect();
    let want: Vec<u64> = r["slice_crc32_hu_i32le"]
        .as_array()
        .unwrap()
        .iter()
        .map(|v| v.as_u64().unwrap())
        .collect();
    assert_eq!(crcs, want, "HU differ from nibabel's");

    // Tools that read the qform (sform_code 0 here) must see the same affine.
    let mut raw = Vec::new();
    flate2::read::GzDecoder::new(std::fs::File::open(&out).unwrap())
        .read_to_end(&mut raw)
        .unwrap();
    raw[254..256].copy_from_slice(&0i16.to_le_bytes());
    let qform_only = tmp.path().join("qform.nii");
    std::fs::write(&qform_only, &raw).unwrap();
    let (q, qi) = read_nifti_with_info(&qform_only).unwrap();
    assert_eq!(qi.affine_source, AffineSource::Qform);
    assert_affine(&q, &r["affine"], "qform");
}

#[test]
fn existing_output_is_kept_without_force() {
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("ct.nii.gz");
    std::fs::write(&out, b"precious").unwrap();
    let input = data("dicom_real/j2k_sign_mismatch");
    let o = convert(&input, &out, &[]);
    assert_one_line_error(&o, "ct.nii.gz", "--force");
    assert_eq!(std::fs::read(&out).unwrap(), b"precious");
    let o = convert(&input, &out, &["--force"]);
    assert!(o.ok, "{}", o.stderr);
    assert_eq!(read_nifti_with_info(&out).unwrap().0.dims, [40, 32, 3]);
}

#[test]
fn bad_inputs_fail_in_one_line_and_leave_nothing() {
    let tmp = tempfile::tempdir().unwrap();
    // Not a NIfTI name.
    let o = convert(&data("dicom/axial"), &tmp.path().join("ct.png"), &[]);
    assert_one_line_error(&o, "ct.png", ".nii.gz");
    // A damaged JPEG 2000 slice: the codestream's SIZ disagrees with the header's Columns.
    let series = tmp.path().join("series");
    std::fs::create_dir(&series).unwrap();
    for e in std::fs::read_dir(data("dicom_real/j2k_sign_mismatch")).unwrap() {
        let p = e.unwrap().path();
        std::fs::copy(&p, series.join(p.file_name().unwrap())).unwrap();
    }
    let victim = std::fs::read_dir(&series).unwrap().next().unwrap().unwrap();
    let mut bytes = std::fs::read(victim.path()).unwrap();
    let cs = bytes
        .windows(4)
        .position(|w| w == [0xFF, 0x4F, 0xFF, 0x51])
        .unwrap();
    bytes[cs + 8..cs + 12].copy_from_slice(&48u32.to_be_bytes());
    std::fs::write(victim.path(), &bytes).unwrap();
    let out = tmp.path().join("out/ct.nii.gz");
    let o = convert(&series, &out, &[]);
    let name = victim.file_name().to_string_lossy().into_owned();
    assert_one_line_error(&o, &name, "Columns x Rows");
    assert!(!out.exists());
    // A missing input.
    let o = convert(&tmp.path().join("nope"), &out, &[]);
    assert_one_line_error(&o, "nope", "not found");
    assert!(!out.exists());
}

#[test]
fn float_nifti_with_nan_stays_float_and_warns() {
    let tmp = tempfile::tempdir().unwrap();
    let mut aff = nalgebra::Matrix4::identity();
    aff[(0, 0)] = 0.75; // exact in the header's f32
    aff[(2, 3)] = -40.0;
    let mut data = vec![-1000.0f32; 16 * 12 * 10];
    data[5] = 12.5;
    data[100] = f32::NAN;
    let vol = Volume::from_data([16, 12, 10], aff, data).unwrap();
    let input = tmp.path().join("in.nii.gz");
    write_nifti(&input, &vol).unwrap();
    let out = tmp.path().join("out.nii");
    let o = convert(&input, &out, &[]);
    assert!(o.ok, "{}", o.stderr);
    assert!(
        o.stderr.contains("1 of 1920 voxels are not finite"),
        "{}",
        o.stderr
    );
    let (back, info) = read_nifti_with_info(&out).unwrap();
    assert_eq!(info.datatype, "float32");
    assert_eq!(back.affine, vol.affine);
    assert!(back.data[100].is_nan() && back.data[5] == 12.5);
    assert_eq!(
        back.data.iter().filter(|v| v.is_nan()).count(),
        1,
        "one NaN in, one out"
    );
}
