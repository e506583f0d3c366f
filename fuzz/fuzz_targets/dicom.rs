//! Fuzz the DICOM series reader on 1–3 in-memory slice files, so that both the per-file
//! header/pixel parsing and the multi-slice checks (same series, same grid, sorting, spacing)
//! run: it must return Ok or Err, never panic, hang or allocate more than the input can back.
//!
//! Input layout (see fuzz/seeds/dicom and `split` below): byte 0 picks the number of files
//! (1 + byte % 3); every file but the last is preceded by its length as u16 little endian; the
//! last file takes the remaining bytes.
#![no_main]

use bronchosim::io::dicom::read_dicom_series_from_memory;
use libfuzzer_sys::fuzz_target;
use std::path::PathBuf;

fn split(data: &[u8]) -> Vec<(PathBuf, Vec<u8>)> {
    let Some((&first, mut rest)) = data.split_first() else {
        return Vec::new();
    };
    let n = 1 + first as usize % 3;
    let mut files = Vec::with_capacity(n);
    for i in 0..n {
        let bytes = if i + 1 == n || rest.len() < 2 {
            std::mem::take(&mut rest)
        } else {
            let len = (u16::from_le_bytes([rest[0], rest[1]]) as usize).min(rest.len() - 2);
            let (file, tail) = rest[2..].split_at(len);
            rest = tail;
            file
        };
        files.push((PathBuf::from(format!("fuzz/slice{i}.dcm")), bytes.to_vec()));
    }
    files
}

fuzz_target!(|data: &[u8]| {
    let files = split(data);
    if !files.is_empty() {
        let _ = read_dicom_series_from_memory(&files);
    }
});
