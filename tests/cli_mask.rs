//! Frames from a real scope carry a black border and burnt-in text (issue 17, item 5): with the
//! case's mask.png the model is as good as from clean frames; the pixels the mask hides enter no
//! fit, no texture and no score. The phantom makes both cases from one seed
//! (`phantom --scope-overlay`).

#[path = "common/cli.rs"]
mod cli;
use cli::{ok, phantom_with, run};
use std::path::Path;

/// Mean PSNR (dB) of the calibrated light's new views in `model/evaluation.json`.
fn calibrated_psnr(model: &Path) -> f64 {
    let text = std::fs::read_to_string(model.join("evaluation.json")).unwrap();
    let scores: serde_json::Value = serde_json::from_str(&text).unwrap();
    scores
        .as_array()
        .unwrap()
        .iter()
        .find(|m| {
            m["method"]
                .as_str()
                .unwrap()
                .starts_with("calibrated light")
        })
        .unwrap()["mean_psnr_db"]
        .as_f64()
        .unwrap()
}

/// Write a phantom case `name` (with `extra` flags) and build it against its truth views.
fn build(dir: &Path, name: &str, extra: &[&str]) -> f64 {
    let mut args = vec![
        "phantom", "--out", name, "--frames", "20", "--size", "128x128", "--quiet",
    ];
    args.extend_from_slice(extra);
    ok(&run(&args, dir));
    let model = format!("{name}_model");
    let truth = format!("{name}/truth");
    ok(&run(
        &[
            "build",
            name,
            "--out",
            &model,
            "--truth",
            &truth,
            "--cross-validate-every",
            "0",
            "--quiet",
            "--poses",
            "fixed",
        ],
        dir,
    ));
    calibrated_psnr(&dir.join(model))
}

#[test]
fn a_masked_scope_overlay_costs_under_half_a_decibel() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    let clean = build(dir, "clean", &[]);
    let masked = build(dir, "overlay", &["--scope-overlay"]);
    println!("new views: clean frames {clean:.2} dB, overlay + mask.png {masked:.2} dB");
    assert!(dir.join("overlay/mask.png").is_file());
    assert!(clean > 25.0, "clean {clean}");
    assert!(
        (clean - masked).abs() < 0.5,
        "clean {clean} vs masked {masked}"
    );
}

#[test]
fn a_mask_of_the_wrong_size_is_refused_naming_the_file() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    cli::phantom(dir, 3, "64x64");
    let small = bronchosim::image::Frame::new(32, 32);
    bronchosim::io::png::write_png_srgb8(&dir.join("case/mask.png"), &small).unwrap();
    let o = run(&["inspect", "case", "--quick"], dir);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success());
    assert!(err.contains("mask.png") && err.contains("32x32"), "{err}");
    assert_eq!(err.trim().lines().count(), 1, "{err}");
}

#[test]
fn inspect_reports_the_mask_or_a_black_border_without_one() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    phantom_with(dir, 3, "96x96", &["--scope-overlay"]);
    let o = run(&["inspect", "case"], dir);
    ok(&o);
    let text = String::from_utf8_lossy(&o.stdout);
    assert!(
        text.contains("mask.png:") && text.contains("% of each frame is image"),
        "{text}"
    );
    std::fs::remove_file(dir.join("case/mask.png")).unwrap();
    let o = run(&["inspect", "case"], dir);
    ok(&o);
    let (out, err) = (
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr),
    );
    assert!(out.contains("no mask.png"), "{out}");
    assert!(
        err.contains("black border") && err.contains("add one"),
        "{err}"
    );
}
