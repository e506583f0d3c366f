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
    phantom_with(cwd, frames, size, &[]);
}

/// The same with more `phantom` arguments (e.g. `--pose-noise-mm 1.5`).
pub fn phantom_with(cwd: &Path, frames: usize, size: &str, more: &[&str]) {
    let n = frames.to_string();
    let mut args = vec![
        "phantom", "--out", "case", "--frames", &n, "--size", size, "--quiet",
    ];
    args.extend_from_slice(more);
    ok(&run(&args, cwd));
}

/// The numbers of a JSON array (e.g. a `camera_to_world` matrix).
pub fn matrix(v: &serde_json::Value) -> Vec<f64> {
    v.as_array()
        .unwrap()
        .iter()
        .map(|x| x.as_f64().unwrap())
        .collect()
}
