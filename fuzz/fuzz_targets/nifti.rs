//! Fuzz the NIfTI reader on raw and gzip-compressed bytes: it must return Ok or Err, never
//! panic, hang or allocate more than the input can back.
#![no_main]

use bronchosim::io::nifti::read_nifti_bytes;
use libfuzzer_sys::fuzz_target;
use std::path::Path;

fuzz_target!(|data: &[u8]| {
    let _ = read_nifti_bytes(data, false, Path::new("fuzz.nii"));
    let _ = read_nifti_bytes(data, true, Path::new("fuzz.nii.gz"));
});
