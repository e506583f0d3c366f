//! DICOM series made from real Siemens CT slices: JPEG 2000 (.4.90 lossless, .4.91 lossy), HTJ2K
//! (.4.201, .4.203) and deflate (.1.99), against independent decoders (values from
//! scripts/reference/make_real_dicom_series.py): every HU value equal to pydicom's (one CRC-32
//! per slice), the affine and chosen voxels' world points within 1e-4 mm of SimpleITK's;
//! damaged codestreams fail naming the file.

mod common {
    // Only next_u64 is needed here; the uniform and normal draws serve the shading tests.
    #[allow(dead_code)]
    pub mod rng;
}

use std::path::{Path, PathBuf};

use bronchosim::io::dicom::{read_dicom_series_from_memory, read_dicom_series_with_info};
use bronchosim::math::Point3;
use bronchosim::volume::Volume;
use serde_json::Value;

fn series_dir(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/data/dicom_real")
        .join(name)
}

fn reference(name: &str) -> Value {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/dicom_real_reference.json");
    let all: Value = serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap();
    all["series"][name].clone()
}

fn f(v: &Value) -> f64 {
    v.as_f64().unwrap()
}

/// CRC-32 of slice `k`'s HU values as little-endian int32 (each must be an integer).
fn slice_crc(vol: &Volume<f32>, k: usize) -> u32 {
    let n = vol.dims[0] * vol.dims[1];
    let mut crc = flate2::Crc::new();
    for &v in &vol.data[k * n..(k + 1) * n] {
        assert_eq!(v, v.round(), "HU {v} is not an integer");
        crc.update(&(v as i32).to_le_bytes());
    }
    crc.sum()
}

/// Dims, affine (1e-4 mm), every HU value (per-slice CRC), sum/min/max and chosen voxels'
/// world points and HU against the reference of `name`.
fn check(name: &str, vol: &Volume<f32>) {
    let r = reference(name);
    let dims: Vec<usize> = r["dims"]
        .as_array()
        .unwrap()
        .iter()
        .map(|v| v.as_u64().unwrap() as usize)
        .collect();
    assert_eq!(vol.dims.to_vec(), dims, "{name}: dims");
    for row in 0..3 {
        for col in 0..4 {
            let (got, want) = (vol.affine[(row, col)], f(&r["affine_ras"][row][col]));
            assert!(
                (got - want).abs() < 1e-4,
                "{name}: affine[{row}][{col}] = {got}, SimpleITK {want}"
            );
        }
    }
    let crcs: Vec<u32> = (0..vol.dims[2]).map(|k| slice_crc(vol, k)).collect();
    let want: Vec<u32> = r["slice_crc32_hu_i32le"]
        .as_array()
        .unwrap()
        .iter()
        .map(|v| v.as_u64().unwrap() as u32)
        .collect();
    assert_eq!(crcs, want, "{name}: HU of some slice differ from pydicom's");
    let sum: f64 = vol.data.iter().map(|&v| v as f64).sum();
    let min = vol.data.iter().copied().fold(f32::INFINITY, f32::min);
    let max = vol.data.iter().copied().fold(f32::NEG_INFINITY, f32::max);
    assert_eq!(
        (sum, min as f64, max as f64),
        (f(&r["hu_sum"]), f(&r["hu_min"]), f(&r["hu_max"])),
        "{name}: HU sum, min, max"
    );
    let voxels = r["voxels"].as_array().unwrap();
    assert!(voxels.len() >= 40);
    for v in voxels {
        let ijk: Vec<usize> = (0..3)
            .map(|a| v["ijk"][a].as_u64().unwrap() as usize)
            .collect();
        let ras = Point3::new(f(&v["ras"][0]), f(&v["ras"][1]), f(&v["ras"][2]));
        let p = vol.index_to_world(Point3::new(ijk[0] as f64, ijk[1] as f64, ijk[2] as f64));
        assert!(
            (p - ras).norm() < 1e-4,
            "{name}: voxel {ijk:?} at {p}, SimpleITK {ras}"
        );
        assert_eq!(
            vol.get(ijk[0], ijk[1], ijk[2]) as f64,
            f(&v["hu"]),
            "{name}: HU at {ijk:?}"
        );
    }
}

#[test]
fn real_lossless_series_equals_reference_decoders() {
    let (vol, info) = read_dicom_series_with_info(&series_dir("j2k_lossless")).unwrap();
    check("j2k_lossless", &vol);
    assert_eq!(info.transfer_syntax_uid, "1.2.840.10008.1.2.4.90");
    assert_eq!(
        info.transfer_syntax_name,
        "JPEG 2000 Image Compression (Lossless Only)"
    );
    // Real positions step 2 mm (SliceThickness says 3 mm): the step comes from the positions.
    assert!(
        (info.slice_step_mm - 2.0).abs() < 1e-9,
        "{}",
        info.slice_step_mm
    );
    assert_eq!(vol.orientation(), "LPS");
}

#[test]
fn lossy_series_equals_reference_decoder() {
    let (vol, info) = read_dicom_series_with_info(&series_dir("j2k_lossy")).unwrap();
    assert_eq!(info.transfer_syntax_uid, "1.2.840.10008.1.2.4.91");
    check("j2k_lossy", &vol);
    // Lossy really lost something: it differs from the lossless original, by a few HU.
    let (orig, _) = read_dicom_series_with_info(&series_dir("j2k_lossless")).unwrap();
    let diff: Vec<f32> = vol
        .data
        .iter()
        .zip(&orig.data)
        .map(|(a, b)| (a - b).abs())
        .collect();
    let max = diff.iter().copied().fold(0.0, f32::max);
    let rms = (diff.iter().map(|d| (d * d) as f64).sum::<f64>() / diff.len() as f64).sqrt();
    let want = &reference("j2k_lossy")["error_vs_lossless_hu"];
    assert_eq!(max as f64, f(&want["max_abs"]));
    assert!((rms - f(&want["rms"])).abs() < 1e-6, "{rms}");
}

#[test]
fn gdcm_encoded_series_equals_reference_decoders() {
    // Small signed slices encoded by GDCM (an encoder independent of OpenJPEG's), made by
    // scripts/reference/make_dicom_series.py.
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/dicom/jpeg2000");
    let (vol, _) = read_dicom_series_with_info(&dir).unwrap();
    check("gdcm_small", &vol);
}

#[test]
fn htj2k_series_equal_reference_decoders() {
    // Encoded by OpenJPH, decoded for reference by OpenJPEG (pydicom) and GDCM (SimpleITK).
    for (name, uid) in [
        ("htj2k_lossless", "1.2.840.10008.1.2.4.201"),
        ("htj2k_lossy", "1.2.840.10008.1.2.4.203"),
    ] {
        let (vol, info) = read_dicom_series_with_info(&series_dir(name)).unwrap();
        assert_eq!(info.transfer_syntax_uid, uid);
        check(name, &vol);
    }
}

#[test]
fn deflated_series_equals_reference_decoders() {
    let (vol, info) = read_dicom_series_with_info(&series_dir("deflated")).unwrap();
    assert_eq!(info.transfer_syntax_uid, "1.2.840.10008.1.2.1.99");
    check("deflated", &vol);
    // Same crops as the lossless HTJ2K series: same voxels.
    let (ht, _) = read_dicom_series_with_info(&series_dir("htj2k_lossless")).unwrap();
    assert_eq!(vol, ht);
}

#[test]
fn corrupt_deflate_stream_fails_fast() {
    // Found by cargo-fuzz from the deflated seed: the deflate stream breaks after an element
    // header declaring 3 GB. The pre-scan used to count 0 inflated bytes (flate2's reader drops a
    // whole read's output on error) while the parser, reading in small pieces, got the header and
    // zero-filled 3 GB (7.8 s); now the scan sees every byte inflated before the error.
    let path = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/data/dicom_fuzz/deflated_corrupt_stream.dcm");
    let t = std::time::Instant::now();
    let err = read_one("deflated.dcm", std::fs::read(path).unwrap()).unwrap_err();
    assert!(t.elapsed().as_secs_f64() < 1.0, "{:?}", t.elapsed());
    assert!(
        err.contains("deflated.dcm")
            && err.contains("(6434,31FE)")
            && err.contains("inflated data set"),
        "{err}"
    );
}

#[test]
fn stray_delimiter_with_a_length_fails_fast() {
    // Found by cargo-fuzz from tests/data/dicom/jpeg2000/j0.dcm: PixelData's tag damaged, so a
    // sequence delimiter declaring 3.2 GB stands at the top level; dicom-parser zero-filled it
    // (4.1 s, 3.2 GB) while the pre-scan skipped delimiters without looking at their length.
    let path = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/data/dicom_fuzz/stray_delimiter_length.dcm");
    let t = std::time::Instant::now();
    let err = read_one("stray.dcm", std::fs::read(path).unwrap()).unwrap_err();
    assert!(t.elapsed().as_secs_f64() < 1.0, "{:?}", t.elapsed());
    assert!(
        err.contains("stray.dcm")
            && err.contains("(FFFE,E0DD)")
            && err.contains("3271557120 bytes instead of 0"),
        "{err}"
    );
}

#[test]
fn unsigned_codestream_with_signed_header_is_sign_extended() {
    let (vol, _) = read_dicom_series_with_info(&series_dir("j2k_sign_mismatch")).unwrap();
    check("j2k_sign_mismatch", &vol);
    assert!(
        vol.data.iter().any(|&v| v < -1000.0),
        "air must stay negative"
    );
}

/// The slices of `name` as in-memory files, sorted by name.
fn slices(name: &str) -> Vec<(PathBuf, Vec<u8>)> {
    let mut files: Vec<PathBuf> = std::fs::read_dir(series_dir(name))
        .unwrap()
        .map(|e| e.unwrap().path())
        .collect();
    files.sort();
    files
        .into_iter()
        .map(|p| {
            let b = std::fs::read(&p).unwrap();
            (p, b)
        })
        .collect()
}

/// Byte offset of the codestream (SOC + SIZ markers) in a slice file.
fn codestream_at(bytes: &[u8]) -> usize {
    bytes
        .windows(4)
        .position(|w| w == [0xFF, 0x4F, 0xFF, 0x51])
        .expect("a JPEG 2000 codestream")
}

/// Rewrite the last pixel-data fragment to its first `keep` bytes, fixing the item length.
fn truncate_fragment(bytes: &[u8], keep: usize) -> Vec<u8> {
    let cs = codestream_at(bytes);
    let len_at = cs - 4; // item tag (FFFE,E000) then a u32 length, then the fragment
    assert_eq!(bytes[len_at - 4..len_at], [0xFE, 0xFF, 0x00, 0xE0]);
    let mut out = bytes[..len_at].to_vec();
    out.extend_from_slice(&(keep as u32).to_le_bytes());
    out.extend_from_slice(&bytes[cs..cs + keep]);
    out.extend_from_slice(&[0xFE, 0xFF, 0xDD, 0xE0, 0, 0, 0, 0]); // sequence delimiter
    out
}

fn read_one(name: &str, bytes: Vec<u8>) -> Result<Volume<f32>, String> {
    read_dicom_series_from_memory(&[(PathBuf::from(name), bytes)])
        .map(|(v, _)| v)
        .map_err(|e| e.to_string())
}

#[test]
fn damaged_codestreams_fail_naming_the_file() {
    let good = slices("j2k_sign_mismatch").swap_remove(0).1;
    let cs = codestream_at(&good);
    // SIZ says 48 columns (Xsiz), the header 40.
    let mut wide = good.clone();
    wide[cs + 8..cs + 12].copy_from_slice(&48u32.to_be_bytes());
    let err = read_one("wide.dcm", wide).unwrap_err();
    assert!(
        err.contains("wide.dcm")
            && err.contains("codestream is 48x32")
            && err.contains("Columns x Rows = 40x32"),
        "{err}"
    );
    // Two components.
    let mut two = good.clone();
    two[cs + 40..cs + 42].copy_from_slice(&2u16.to_be_bytes());
    let err = read_one("two.dcm", two).unwrap_err();
    assert!(err.contains("two.dcm") && err.contains("SIZ"), "{err}");
    // Not a codestream at all.
    let mut junk = good.clone();
    junk[cs..cs + 4].copy_from_slice(b"JUNK");
    let err = read_one("junk.dcm", junk).unwrap_err();
    assert!(
        err.contains("junk.dcm") && err.contains("does not start with a JPEG 2000 codestream"),
        "{err}"
    );
    // Truncated codestreams: header only, half the data. Strict decoding refuses both
    // rather than returning a partly blank slice.
    let len = good.len() - cs - 8;
    for keep in [30, 60, len / 2] {
        let err = read_one("cut.dcm", truncate_fragment(&good, keep)).unwrap_err();
        assert!(
            err.contains("cut.dcm") && err.contains("JPEG 2000"),
            "{keep}: {err}"
        );
    }
    // The untouched slice still reads (the helpers above did not break the file layout).
    assert!(read_one("good.dcm", truncate_fragment(&good, len)).is_ok());
}

#[test]
fn corrupted_codestream_bytes_never_panic() {
    // Seeded byte corruption inside the codestream: Ok (JPEG 2000 has few checks) or an error
    // naming the file, never a panic or a wrong-sized volume.
    let files = slices("j2k_sign_mismatch");
    let mut rng = common::rng::Rng::new(17);
    let mut next = move || rng.next_u64();
    let (mut ok, mut err) = (0, 0);
    for _ in 0..300 {
        let (name, bytes) = &files[(next() % files.len() as u64) as usize];
        let mut bytes = bytes.clone();
        let cs = codestream_at(&bytes);
        for _ in 0..1 + next() % 3 {
            // Half of the hits in the main header (the first ~80 bytes), where sizes live.
            let span = if next() % 2 == 0 {
                80
            } else {
                bytes.len() - cs
            };
            let at = cs + (next() % span as u64) as usize;
            bytes[at] = next() as u8;
        }
        match read_dicom_series_from_memory(&[(name.clone(), bytes)]) {
            Ok((v, _)) => {
                assert_eq!(v.dims, [40, 32, 1]);
                ok += 1;
            }
            Err(e) => {
                assert!(e.to_string().contains(&*name.to_string_lossy()), "{e}");
                err += 1;
            }
        }
    }
    assert!(ok > 0 && err > 0, "{ok} ok, {err} err");
}
