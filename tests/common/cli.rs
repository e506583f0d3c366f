//! Running the `bronchosim` binary from integration tests.

// Each test binary uses a different subset.
#![allow(dead_code)]

use std::path::Path;
use std::process::{Command, Output};

/// Run `bronchosim ARGS` in `cwd`.
pub fn run(args: &[&str], cwd: &Path) -> Output {
    Command::new(env!("CARGO_BIN_EXE_bronchosim"))
        .args(args)
        .current_dir(cwd)
        .output()
        .unwrap()
}

/// Assert that a run succeeded, showing its output when it did not.
pub fn ok(o: &Output) {
    assert!(
        o.status.success(),
        "{}{}",
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr)
    );
}

/// Write a small phantom case (`frames` frames of `size`, e.g. "160x160") to `cwd/case`.
pub fn phantom(cwd: &Path, frames: usize, size: &str) {
    let n = frames.to_string();
    ok(&run(
        &[
            "phantom", "--out", "case", "--frames", &n, "--size", size, "--quiet",
        ],
        cwd,
    ));
}

/// The numbers of a JSON array (e.g. a `camera_to_world` matrix).
pub fn matrix(v: &serde_json::Value) -> Vec<f64> {
    v.as_array()
        .unwrap()
        .iter()
        .map(|x| x.as_f64().unwrap())
        .collect()
}
