//! Frame selection (issue 21) on a phantom whose blurred frames are known (truth.json
//! `motion_blur.frames`): under a budget below the frame count no blurred frame is chosen,
//! the chosen frames see most of the wall every frame sees, and `--max-frames 0` builds the
//! same model as a budget above the frame count on a case without blur.

#[path = "common/cli.rs"]
mod cli;
use cli::{ok, phantom, phantom_with, run};

use bronchosim::model::manifest::BuildTimings;
use bronchosim::phantom::{write_phantom_case, PhantomOptions};
use bronchosim::selection::Reason;
use bronchosim::workflow::build::selection::select_frames;
use bronchosim::workflow::build::{BuildOptions, BuildScene};

#[test]
fn blurred_frames_are_not_chosen_and_the_chosen_cover_the_wall() {
    let tmp = tempfile::tempdir().unwrap();
    let case = tmp.path().join("case");
    let mut po = PhantomOptions {
        frames: 100,
        width: 128,
        height: 128,
        seed: 3,
        ..Default::default()
    };
    // A fast turn: a smear of 6% of the width (7.7 px), as bronchoscope videos show.
    po.motion_blur.share = 0.2;
    po.motion_blur.length_share = 0.06;
    write_phantom_case(&case, &po).unwrap();
    let truth: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(case.join("truth/truth.json")).unwrap())
            .unwrap();
    let blurred: Vec<usize> = truth["motion_blur"]["frames"]
        .as_array()
        .unwrap()
        .iter()
        .map(|v| v.as_u64().unwrap() as usize)
        .collect();
    assert_eq!(blurred.len(), 20);

    let mut opts = BuildOptions {
        quiet: true,
        ..Default::default()
    };
    opts.selection.max_frames = 30;
    let mut timings = BuildTimings::default();
    let mut scene = BuildScene::prepare(&case, &opts, &mut timings).unwrap();
    let mut warnings = Vec::new();
    let sel = select_frames(&mut scene, &opts, &mut warnings)
        .unwrap()
        .unwrap();
    let used: Vec<usize> = sel
        .frames
        .iter()
        .filter(|f| f.used)
        .map(|f| f.frame)
        .collect();
    println!("used {used:?}, counts {:?}", sel.counts);
    assert!(used.len() <= 30 && used.len() >= 10, "{used:?}");
    assert_eq!(scene.frame_count(), used.len());
    // Sharp frames see the whole wall the blurred ones see: none of them is chosen.
    for &b in &blurred {
        assert!(
            !sel.frames[b].used,
            "blurred frame {b} chosen: {:?}",
            sel.frames[b]
        );
    }
    // Nearly all are recognised as blurred. With 100 small frames along the whole tree,
    // neighbours differ in content too: some sharp frames fall below 0.75 of their neighbours'
    // median (8 here, printed below); at 300 frames of 320x320 none does.
    let flagged: Vec<usize> = sel
        .frames
        .iter()
        .filter(|f| f.reason == Reason::Blurred)
        .map(|f| f.frame)
        .collect();
    for f in sel
        .frames
        .iter()
        .filter(|f| f.reason == Reason::Blurred && !blurred.contains(&f.frame))
    {
        println!(
            "sharp frame {} judged blurred: relative sharpness {:.2}",
            f.frame, f.relative_sharpness
        );
    }
    // Measured: 19 of the 20 recognised (frame 98, near the end, is not: its neighbours are
    // all on one side), 8 sharp ones flagged.
    let found = blurred.iter().filter(|b| flagged.contains(b)).count();
    assert!(found >= 19, "{flagged:?} vs {blurred:?}");
    assert!(flagged.len() - found <= 8, "{flagged:?} vs {blurred:?}");
    // The 30 chosen frames see most wall cells any of the 100 sees (measured: 7772 of 8513).
    let share = sel.cells_seen_used as f64 / sel.cells_seen_all as f64;
    println!(
        "cells seen: {} of {} ({share:.3})",
        sel.cells_seen_used, sel.cells_seen_all
    );
    assert!(share > 0.9, "{share}");
}

#[test]
fn max_frames_zero_builds_the_same_model_as_a_budget_above_the_frames() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    phantom(dir, 8, "96x96");
    let build = |out: &str, max: &str| {
        ok(&run(
            &[
                "build",
                "case",
                "--out",
                out,
                "--quiet",
                "--poses",
                "fixed",
                "--cross-validate-every",
                "0",
                "--max-frames",
                max,
            ],
            dir,
        ))
    };
    build("all", "0");
    build("budget", "50");
    let read = |m: &str, f: &str| std::fs::read(dir.join(m).join(f)).unwrap();
    assert_eq!(read("all", "albedo.png"), read("budget", "albedo.png"));
    // shading.json to the last digits: the fit's parallel sums may round differently from run
    // to run (seen in debug builds, 1 ulp), with or without a selection.
    let shading = |m: &str| -> serde_json::Value {
        serde_json::from_slice(&read(m, "shading.json")).unwrap()
    };
    assert_close(&shading("all"), &shading("budget"), "shading.json");
    let json =
        |m: &str| -> serde_json::Value { serde_json::from_slice(&read(m, "model.json")).unwrap() };
    let (all, budget) = (json("all"), json("budget"));
    assert!(all.get("frame_selection").is_none());
    let sel = &budget["frame_selection"];
    assert_eq!(sel["used"], 8);
    assert_eq!(sel["counts"]["chosen"], 8);
    assert_eq!(budget["counts"]["frames"], 8);
}

#[test]
fn a_tracked_video_over_the_budget_is_registered_and_reported_on_its_chosen_frames() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    phantom_with(
        dir,
        48,
        "96x96",
        &["--pose-noise-mm", "1.5", "--pose-noise-deg", "2"],
    );
    ok(&run(
        &[
            "build",
            "case",
            "--out",
            "m",
            "--quiet",
            "--max-frames",
            "16",
            "--cross-validate-every",
            "0",
        ],
        dir,
    ));
    let model: serde_json::Value =
        serde_json::from_slice(&std::fs::read(dir.join("m/model.json")).unwrap()).unwrap();
    let used: Vec<u64> = model["frame_selection"]["frames"]
        .as_array()
        .unwrap()
        .iter()
        .filter(|f| f["used"] == true)
        .map(|f| f["frame"].as_u64().unwrap())
        .collect();
    assert_eq!(used.len(), 16);
    let registered: Vec<u64> = model["registration"]["frames"]
        .as_array()
        .unwrap()
        .iter()
        .map(|f| f["frame"].as_u64().unwrap())
        .collect();
    assert_eq!(registered, used);
    // The report's before/after overlays name frames of the video the build used. (They were
    // looked up by their number in the video among the chosen frames: a build whose largest
    // correction was on a frame numbered past the budget panicked.)
    let report = std::fs::read_to_string(dir.join("m/report.html")).unwrap();
    let shown: Vec<u64> = report
        .split("<tr><td>")
        .skip(1)
        .filter(|row| row.contains(" correction: "))
        .map(|row| row.split(' ').next().unwrap().parse().unwrap())
        .collect();
    println!("used {used:?}, overlays of {shown:?}");
    assert!(shown.len() >= 3, "{shown:?}");
    assert!(shown.iter().all(|f| used.contains(f)), "{shown:?}");
}

/// `a` and `b` have the same structure and numbers within 1e-9 (relative).
fn assert_close(a: &serde_json::Value, b: &serde_json::Value, at: &str) {
    use serde_json::Value;
    match (a, b) {
        (Value::Number(x), Value::Number(y)) => {
            let (x, y) = (x.as_f64().unwrap(), y.as_f64().unwrap());
            assert!(
                (x - y).abs() <= 1e-9 * x.abs().max(y.abs()).max(1e-300),
                "{at}: {x} vs {y}"
            );
        }
        (Value::Array(x), Value::Array(y)) => {
            assert_eq!(x.len(), y.len(), "{at}");
            for (i, (u, v)) in x.iter().zip(y).enumerate() {
                assert_close(u, v, &format!("{at}[{i}]"));
            }
        }
        (Value::Object(x), Value::Object(y)) => {
            assert_eq!(x.len(), y.len(), "{at}");
            for (k, u) in x {
                assert_close(u, &y[k], &format!("{at}.{k}"));
            }
        }
        _ => assert_eq!(a, b, "{at}"),
    }
}
