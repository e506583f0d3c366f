//! Fuzz the poses.json parser: Ok or Err, never a panic or a hang. Image paths are resolved
//! inside an empty temporary case folder, so path checks (escaping the folder) run too.
#![no_main]

use bronchosim::io::poses::{parse_poses_str, validate_pose};
use libfuzzer_sys::fuzz_target;
use std::path::Path;
use std::sync::OnceLock;

fn case_dir() -> &'static Path {
    static DIR: OnceLock<tempfile::TempDir> = OnceLock::new();
    DIR.get_or_init(|| tempfile::tempdir().expect("temp dir"))
        .path()
}

fuzz_target!(|data: &[u8]| {
    let Ok(text) = std::str::from_utf8(data) else {
        return;
    };
    if let Ok(poses) = parse_poses_str(text, case_dir(), Path::new("poses.json")) {
        // Every accepted pose is a rigid transform.
        assert!(!poses.is_empty());
        for p in &poses {
            assert!(validate_pose(&p.camera_to_world).is_ok());
        }
    }
});
