//! Pose registration against the model (issue 16) on a small phantom (24 frames, 160x160):
//! tracker-like errors are recovered against a model of the true poses, true poses stay put,
//! a frame whose given pose is 10 mm off is flagged, and the first round against a model fused
//! from the erroneous poses (geometry and colour-predicted albedo) reduces the error; `build
//! --poses refine` registers a tracker's poses, leaves a wrong one out and records both, and
//! repeats a geometry round that leaves many frames outliers (3 mm / 4 degree poses); texture
//! rounds shrink an error every frame shares (their Jacobian from the frame's gradient); a run
//! of frames that falls one cartilage ring away from its neighbours is brought back by the
//! tracker's continuity; a frame turned half a turn registers to the turned pose (no error
//! fixed to the pixel grid); a black frame is left out by `register` and by a build without a
//! frame selection; motion-blurred frames are left out against the model's prediction.

use bronchosim::camera::Pose;
use bronchosim::image::Frame;
use bronchosim::io::case::Case;
use bronchosim::io::poses::{read_poses, write_poses, PoseEntry};
use bronchosim::math::{Affine, Vector3};
use bronchosim::model::{Model, ModelManifest};
use bronchosim::phantom::motion_blur::MotionBlur;
use bronchosim::phantom::pose_noise::PoseNoise;
use bronchosim::phantom::{write_phantom_case, PhantomOptions};
use bronchosim::registration::accuracy::PoseAccuracy;
use bronchosim::registration::blocks::BlockOptions;
use bronchosim::registration::pose::perturb;
use bronchosim::registration::prior::MeasurementNoise;
use bronchosim::registration::{
    apply_delta, pose_error, register_round, FrameObs, FrameRegistrar, FrameStatus, PoseDelta,
    RegistrationOptions, RoundKind, RoundOptions, VideoOptions, VideoRegistration,
};
use bronchosim::shading::ShadingKind;
use bronchosim::workflow::build::{build_model, BuildOptions, PosesMode};
use bronchosim::workflow::register::register_command;
use bronchosim::workflow::summary::build_text;
use std::path::Path;

#[path = "common/registration_model.rs"]
mod registration_model;
#[path = "common/untracked.rs"]
mod untracked;
use registration_model::{build, case_with_poses, errors};
use untracked::phantom_cut_to;

/// The phantom case's true poses (truth/poses.json).
fn true_poses(case_dir: &Path) -> Vec<Affine> {
    read_poses(&case_dir.join("truth/poses.json"), case_dir)
        .unwrap()
        .iter()
        .map(|p| p.pose.camera_to_world)
        .collect()
}

fn register(
    model: &Model,
    frames: &[Frame],
    poses: &[Affine],
    kind: RoundKind,
) -> VideoRegistration {
    register_with(model, frames, poses, kind, &RoundOptions::default())
}

fn register_with(
    model: &Model,
    frames: &[Frame],
    poses: &[Affine],
    kind: RoundKind,
    opts: &RoundOptions,
) -> VideoRegistration {
    let parts = model.registration_parts().unwrap();
    register_round(parts, frames, &parts.light.gains, None, poses, kind, opts).unwrap()
}

/// `build` with two registration rounds and no cross-validation (the refined poses are kept),
/// scored against `truth` when given.
fn build_refined(case: &Path, out: &Path, truth: Option<&Path>) -> ModelManifest {
    let opts = BuildOptions {
        cross_validate_every: 0,
        shading: Some(ShadingKind::Calibrated),
        poses: PosesMode::Refine,
        registration_rounds: 2,
        truth: truth.map(Path::to_path_buf),
        quiet: true,
        ..Default::default()
    };
    build_model(case, out, &opts).unwrap()
}

/// A 24-frame 160x160 phantom in `dir`/case whose poses carry a tracker's error (1.5 mm / 2
/// degrees RMS), and the case opened.
fn tracker_phantom(dir: &Path) -> (std::path::PathBuf, Case) {
    phantom_with_pose_noise(dir, PoseNoise::new(1.5, 2.0))
}

/// A 24-frame 160x160 phantom in `dir`/case whose poses carry `noise`, and the case opened.
fn phantom_with_pose_noise(dir: &Path, noise: PoseNoise) -> (std::path::PathBuf, Case) {
    let case_dir = dir.join("case");
    let opts = PhantomOptions {
        frames: 24,
        width: 160,
        height: 160,
        pose_noise: noise,
        ..Default::default()
    };
    write_phantom_case(&case_dir, &opts).unwrap();
    untracked::perturb_frame0(&case_dir);
    let case = Case::open(&case_dir).unwrap();
    (case_dir, case)
}

#[test]
fn tracker_errors_are_recovered_true_poses_kept_and_a_wrong_pose_flagged() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    let (case_dir, case) = tracker_phantom(dir);
    let given: Vec<Affine> = case.poses.iter().map(|p| p.pose.camera_to_world).collect();
    let truth = true_poses(&case_dir);
    let frames: Vec<Frame> = case.frame_source().unwrap().map(|f| f.unwrap()).collect();
    let (mm0, deg0, _) = errors(&given, &truth);
    assert!(
        mm0 > 1.0 && deg0 > 1.2,
        "the phantom's error: {mm0} mm {deg0} deg"
    );

    // Against the model of the true poses: the registration itself.
    case_with_poses(&case_dir, &dir.join("true_case"), &case.poses, &truth);
    let model = build(&dir.join("true_case"), &dir.join("true_model"));
    let v = register(&model, &frames, &given, RoundKind::Texture);
    let refined: Vec<Affine> = v.frames.iter().map(|f| f.pose).collect();
    let (mm, deg, within) = errors(&refined, &truth);
    println!("tracker poses {mm0:.3} mm {deg0:.3} deg -> {mm:.3} mm {deg:.3} deg, {within}/24 within 1 mm and 1 deg; {:?}", v.counts);
    assert!(mm < 0.3 && deg < 0.3, "{mm} mm {deg} deg");
    assert_eq!(within, 24);

    // True poses in: they move less than 0.1 mm (median).
    let v = register(&model, &frames, &truth, RoundKind::Texture);
    let kept: Vec<Affine> = v.frames.iter().map(|f| f.pose).collect();
    let (mm, deg, _) = errors(&kept, &truth);
    println!("true poses moved {mm:.4} mm {deg:.4} deg");
    assert!(mm < 0.1 && deg < 0.2, "{mm} mm {deg} deg");

    // One given pose 10 mm off (sideways, out of the airway): flagged, and its neighbours
    // unharmed.
    let mut wrong = given.clone();
    let side = wrong[12].fixed_view::<3, 1>(0, 0).into_owned();
    wrong[12] = apply_delta(
        &wrong[12],
        &PoseDelta {
            translation_mm: side * 10.0,
            rotation: Vector3::zeros(),
        },
    );
    let v = register(&model, &frames, &wrong, RoundKind::Texture);
    let st = v.frames[12].status;
    println!("frame 12 off by 10 mm: {st:?}; {:?}", v.counts);
    assert!(
        !matches!(st, FrameStatus::Converged | FrameStatus::NotConverged),
        "a 10 mm error went unflagged ({st:?})"
    );
    assert_eq!(v.counts.values().sum::<usize>(), 24);
    let others: Vec<Affine> = v.frames.iter().map(|f| f.pose).collect();
    let (mm, _, _) = errors(&others, &truth);
    assert!(mm < 0.1, "{mm} mm");

    // The first round against a model fused from the tracker's poses: the geometry and the
    // colour-predicted albedo halve the error.
    let model = build(&case_dir, &dir.join("model"));
    let v = register(&model, &frames, &given, RoundKind::Geometry);
    let first: Vec<Affine> = v.frames.iter().map(|f| f.pose).collect();
    let (mm, deg, _) = errors(&first, &truth);
    println!("first round against the tracker's model: {mm0:.3} mm {deg0:.3} deg -> {mm:.3} mm {deg:.3} deg");
    assert!(mm < 0.5 * mm0, "{mm} mm");
    assert!(deg < deg0, "{deg} deg");
    // Smoothed with one registration noise per camera axis instead of each frame's own
    // information, the round's rotation is worse.
    let per_axis = RoundOptions {
        geometry_noise: MeasurementNoise::PerAxis,
        ..RoundOptions::default()
    };
    let v = register_with(&model, &frames, &given, RoundKind::Geometry, &per_axis);
    let first: Vec<Affine> = v.frames.iter().map(|f| f.pose).collect();
    let (mm_axis, deg_axis, _) = errors(&first, &truth);
    println!("the same smoothed per axis: {mm_axis:.3} mm {deg_axis:.3} deg");
    // Measured: 0.41 mm / 1.29 deg against 0.39 mm / 2.02 deg.
    assert!(
        deg < 0.8 * deg_axis && mm < 1.15 * mm_axis,
        "each frame's information {mm:.3} mm {deg:.3} deg, per axis {mm_axis:.3} mm {deg_axis:.3} deg"
    );
}

#[test]
fn build_refines_tracker_poses_and_leaves_a_wrong_one_out() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    let (case_dir, case) = tracker_phantom(dir);
    let truth = true_poses(&case_dir);
    // Frame 12's given pose 10 mm off along its own x axis.
    let mut given: Vec<Affine> = case.poses.iter().map(|p| p.pose.camera_to_world).collect();
    let side = given[12].fixed_view::<3, 1>(0, 0).into_owned();
    given[12] = apply_delta(
        &given[12],
        &PoseDelta {
            translation_mm: side * 10.0,
            rotation: Vector3::zeros(),
        },
    );
    let noisy = dir.join("noisy");
    case_with_poses(&case_dir, &noisy, &case.poses, &given);
    let (mm0, deg0, _) = errors(&given, &truth);

    // A truth folder with the true poses alone (no reference views to render).
    let truth_dir = dir.join("true_poses");
    std::fs::create_dir(&truth_dir).unwrap();
    std::fs::copy(
        case_dir.join("truth/poses.json"),
        truth_dir.join("poses.json"),
    )
    .unwrap();
    let out = dir.join("model");
    let m = build_refined(&noisy, &out, Some(&truth_dir));
    let reg = m
        .registration
        .as_ref()
        .expect("model.json records the registration");
    // The model's poses.json: every frame, refined, readable as a case's poses.
    let written = read_poses(&out.join("poses.json"), &noisy).unwrap();
    assert_eq!(written.len(), 24);
    let refined: Vec<Affine> = written.iter().map(|p| p.pose.camera_to_world).collect();
    let used: Vec<usize> = (0..24).filter(|&i| reg.frames[i].used).collect();
    let pick = |v: &[Affine]| used.iter().map(|&i| v[i]).collect::<Vec<_>>();
    let (mm, deg, within) = errors(&pick(&refined), &pick(&truth));
    println!(
        "build --poses refine: {mm0:.3} mm {deg0:.3} deg -> {mm:.3} mm {deg:.3} deg over {} used frames, {within} within 1 mm and 1 deg; left out {}; rounds (against, discarded) {:?}; joint stage {:?}",
        used.len(),
        reg.left_out,
        reg.rounds
            .iter()
            .map(|r| (&r.against, r.discarded))
            .collect::<Vec<_>>(),
        reg.joint
    );
    assert_eq!(reg.frames.len(), 24);
    // Two rounds kept (a first round run again against the Lambertian lamp leaves its
    // discarded run in the list).
    assert_eq!(reg.rounds.iter().filter(|r| !r.discarded).count(), 2);
    // After the rounds, the frames they ran on refined at once (those they flagged not, but
    // for a frame flagged for its cost alone, which is taken back if it now fits).
    let joint = reg.joint.as_ref().expect("the joint stage ran");
    let last = reg.rounds.last().unwrap();
    let total = |c: &std::collections::BTreeMap<String, usize>| c.values().sum::<usize>();
    assert_eq!(total(&joint.counts), total(&last.counts));
    let fitting = |c: &std::collections::BTreeMap<String, usize>| {
        c.get("converged").copied().unwrap_or(0) + c.get("not_converged").copied().unwrap_or(0)
    };
    assert!(
        fitting(&joint.counts) >= fitting(&last.counts),
        "{joint:?} {last:?}"
    );
    assert!(
        joint.median_step_mm > 0.0 && joint.median_step_mm < 1.0,
        "{joint:?}"
    );
    assert!(!reg.frames[12].used, "frame 12: {:?}", reg.frames[12]);
    assert_eq!(reg.left_out, reg.frames.iter().filter(|f| !f.used).count());
    assert_eq!(m.counts.frames, 24 - reg.left_out);

    // The camera centres are found; the rotation is not yet on this small, low-resolution
    // case (1.73 -> 2.1 degrees measured; the 80-frame 320x320 demo: 1.80 -> 0.79 degrees,
    // BENCHMARKS.md "Registration"), so only the translation is asserted. How far the two
    // rounds get here is largely chance: over six inputs one pixel apart
    // (`BRONCHOSIM_TEST_PERTURB` 0-5) 1.33 mm went to 0.26-0.72 mm over the 15-20 frames
    // used (4-9 left out), the joint stage's median step 0.19-0.78 mm (BENCHMARKS.md, session
    // 51); the registration against a fixed model (the test above) moves by 0.001 mm.
    assert!(mm < 0.7 * mm0, "{mm} mm");
    let text = std::fs::read_to_string(out.join("poses.json")).unwrap();
    assert_eq!(text.matches("\"status\"").count(), 24);

    // With the truth's poses, model.json scores the given and the refined poses against them
    // (the same frames' errors as computed here: the median of 24 lies between the 12th and
    // 13th error).
    let pt = m.pose_truth.as_ref().expect("model.json pose_truth");
    let (given_acc, used_acc) = (&pt.given, &pt.used);
    assert_eq!((given_acc.frames, used_acc.frames), (24, 24));
    let mut e: Vec<f64> = given
        .iter()
        .zip(&truth)
        .map(|(g, t)| pose_error(g, t).0)
        .collect();
    e.sort_by(f64::total_cmp);
    assert!(
        (given_acc.median_mm - 0.5 * (e[11] + e[12])).abs() < 1e-9,
        "{given_acc:?}"
    );
    assert!(used_acc.median_mm < 0.7 * given_acc.median_mm, "{pt:?}");
    assert!(pt.refined.is_some());
    let html = std::fs::read_to_string(out.join("report.html")).unwrap();
    assert!(html.contains("Poses against the truth"));
}

#[test]
fn build_keeps_exact_poses_when_refining_does_not_predict_held_out_frames_better() {
    let tmp = tempfile::tempdir().unwrap();
    let case_dir = tmp.path().join("case");
    let opts = PhantomOptions {
        frames: 24,
        width: 160,
        height: 160,
        ..Default::default()
    };
    write_phantom_case(&case_dir, &opts).unwrap();
    let out = tmp.path().join("model");
    let build_opts = BuildOptions {
        cross_validate_every: 4,
        poses: PosesMode::Refine,
        registration_rounds: 2,
        quiet: true,
        ..Default::default()
    };
    let m = build_model(&case_dir, &out, &build_opts).unwrap();
    let reg = m.registration.as_ref().unwrap();
    let (given, refined) = (
        reg.held_out_psnr_given_db.unwrap(),
        reg.held_out_psnr_refined_db.unwrap(),
    );
    println!(
        "exact poses: held-out frames {given:.2} dB as given, {refined:.2} dB refined; kept {}",
        reg.kept
    );
    assert!(given > refined, "{given} vs {refined} dB");
    assert_eq!(reg.kept, "given");
    assert_eq!(reg.left_out, 0);
    let case = Case::open(&case_dir).unwrap();
    let written = read_poses(&out.join("poses.json"), &case_dir).unwrap();
    for (w, g) in written.iter().zip(&case.poses) {
        assert_eq!(w.pose.camera_to_world, g.pose.camera_to_world);
    }

    // `register` says the same, and writes what the rounds found beside it.
    let reg_dir = tmp.path().join("reg");
    let r = register_command(&case_dir, &reg_dir, &build_opts).unwrap();
    assert_eq!(r.registration.kept, "given");
    let written = read_poses(&reg_dir.join("poses.json"), &case_dir).unwrap();
    let refined = read_poses(&reg_dir.join("refined_poses.json"), &case_dir).unwrap();
    let mut moved = 0;
    for ((w, r), g) in written.iter().zip(&refined).zip(&case.poses) {
        assert_eq!(w.pose.camera_to_world, g.pose.camera_to_world);
        moved += usize::from(r.pose.camera_to_world != g.pose.camera_to_world);
    }
    assert!(moved > 12, "the rounds moved {moved} of 24 poses");
    // Both reports say the corrections are zero because the given poses were kept, with the
    // two held-out scores, and the register report where the refined poses are.
    for (report, reg) in [
        (out.join("report.html"), reg),
        (reg_dir.join("report.html"), &r.registration),
    ] {
        let scores = format!(
            "{:.2} dB, with the given ones at {:.2} dB",
            reg.held_out_psnr_refined_db.unwrap(),
            reg.held_out_psnr_given_db.unwrap()
        );
        let html = std::fs::read_to_string(&report).unwrap();
        assert!(
            html.contains("The given poses were kept") && html.contains(&scores),
            "{}: {scores}",
            report.display()
        );
    }
    let html = std::fs::read_to_string(reg_dir.join("report.html")).unwrap();
    assert!(html.contains("refined_poses.json"));
    let text = bronchosim::workflow::summary::register_text(&reg_dir, &r);
    assert!(text.contains("the given poses were kept"), "{text}");
}

/// A 12-frame 128x128 phantom in `case_dir` whose poses carry 1 mm / 1 degree of error.
fn small_tracker_phantom(case_dir: &Path) {
    let opts = PhantomOptions {
        frames: 12,
        width: 128,
        height: 128,
        pose_noise: PoseNoise::new(1.0, 1.0),
        ..Default::default()
    };
    write_phantom_case(case_dir, &opts).unwrap();
}

#[test]
fn register_command_writes_poses_and_a_report_and_refuses_bad_input() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    small_tracker_phantom(&dir.join("case"));
    let bin = env!("CARGO_BIN_EXE_bronchosim");
    let run = |args: &[&str]| {
        std::process::Command::new(bin)
            .args(args)
            .current_dir(dir)
            .output()
            .unwrap()
    };
    let out = run(&[
        "register",
        "case",
        "--out",
        "reg",
        "--rounds",
        "1",
        "--truth",
        "case/truth",
    ]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(
        text.contains("poses registered in 1 rounds and all frames at once"),
        "{text}"
    );
    let poses = read_poses(&dir.join("reg/poses.json"), &dir.join("case")).unwrap();
    assert_eq!(poses.len(), 12);
    let record: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("reg/registration.json")).unwrap())
            .unwrap();
    assert_eq!(
        record["registration"]["frames"].as_array().unwrap().len(),
        12
    );
    // What the round found is written whichever poses the held-out check keeps: it moved the
    // tracker-like given poses.
    let given = Case::open(&dir.join("case")).unwrap().poses;
    let refined = read_poses(&dir.join("reg/refined_poses.json"), &dir.join("case")).unwrap();
    assert_eq!(refined.len(), 12);
    let moved = refined
        .iter()
        .zip(&given)
        .filter(|(r, g)| pose_error(&r.pose.camera_to_world, &g.pose.camera_to_world).0 > 0.05)
        .count();
    println!(
        "{moved} of 12 poses moved by the round; kept {}",
        record["registration"]["kept"]
    );
    assert!(moved > 6, "{moved} of 12 poses moved by the round");
    // Scored against the truth's poses: the given ones are about 1 mm off, the refined ones
    // closer.
    let truth_record = &record["pose_truth"];
    let given_mm = truth_record["given"]["median_mm"].as_f64().unwrap();
    let refined_mm = truth_record["refined"]["median_mm"].as_f64().unwrap();
    println!("against the truth: given {given_mm:.3} mm, refined {refined_mm:.3} mm");
    assert_eq!(truth_record["given"]["frames"], 12);
    assert!(given_mm > 0.5 && refined_mm < given_mm, "{truth_record}");
    assert!(text.contains("poses against the truth"), "{text}");
    let html = std::fs::read_to_string(dir.join("reg/report.html")).unwrap();
    assert!(html.contains("<svg") && html.contains("camera centre moved (mm)"));

    // An existing result is kept without --force; a folder that is no case is named.
    let again = run(&["--quiet", "register", "case", "--out", "reg"]);
    assert!(!again.status.success());
    assert!(String::from_utf8_lossy(&again.stderr).contains("--force"));
    let bad = run(&["--quiet", "register", "nowhere", "--out", "reg2"]);
    assert!(!bad.status.success());
    let err = String::from_utf8_lossy(&bad.stderr);
    assert!(err.contains("nowhere") && err.lines().count() == 1, "{err}");
    assert!(!dir.join("reg2").exists());
    // A truth folder that is not there is named before any work.
    let bad = run(&[
        "--quiet", "register", "case", "--out", "reg3", "--truth", "no_truth",
    ]);
    assert!(!bad.status.success());
    let err = String::from_utf8_lossy(&bad.stderr);
    assert!(
        err.contains("no_truth") && err.lines().count() == 1,
        "{err}"
    );
    assert!(!dir.join("reg3").exists());
    // So is a scope light that is not a model's.
    let bad = run(&[
        "--quiet",
        "register",
        "case",
        "--out",
        "reg4",
        "--scope-light",
        "case",
    ]);
    assert!(!bad.status.success());
    let err = String::from_utf8_lossy(&bad.stderr);
    assert!(
        err.contains("case/shading.json")
            && err.contains("scope light")
            && err.lines().count() == 1,
        "{err}"
    );
    assert!(!dir.join("reg4").exists());
}

#[test]
fn a_black_frame_is_left_out_by_register_and_by_a_build_without_a_selection() {
    // A tracker's poses, and frame 5 black (the lens against the wall). `register` runs no
    // frame selection, nor does `build --max-frames 0`: both stopped at the light's first fit
    // ("too few pixels obey the shading model") before the registration flagged such frames.
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    let case_dir = dir.join("case");
    small_tracker_phantom(&case_dir);
    let black = case_dir.join("frames/000005.png");
    bronchosim::io::png::write_png_srgb8(&black, &Frame::new(128, 128)).unwrap();
    let build_opts = BuildOptions {
        cross_validate_every: 0,
        shading: Some(ShadingKind::Calibrated),
        registration_rounds: 1,
        quiet: true,
        ..Default::default()
    };

    let s = register_command(&case_dir, &dir.join("reg"), &build_opts).unwrap();
    let frames = &s.registration.frames;
    let statuses: Vec<&str> = frames.iter().map(|f| f.status.as_str()).collect();
    println!("register: {statuses:?}; {:?}", s.warnings);
    assert_eq!(
        (frames[5].status.as_str(), frames[5].used),
        ("blank", false)
    );
    assert_eq!(frames.iter().filter(|f| f.used).count(), 11, "{frames:?}");
    assert_eq!(s.registration.left_out, 1);
    assert!(
        s.warnings
            .iter()
            .any(|w| w.contains("show next to nothing")),
        "{:?}",
        s.warnings
    );
    // poses.json keeps one entry per frame of the video, the black one at its given pose.
    let poses = read_poses(&dir.join("reg/poses.json"), &case_dir).unwrap();
    assert_eq!(poses.len(), 12);
    let given = Case::open(&case_dir).unwrap().poses;
    let (mm, deg) = pose_error(
        &poses[5].pose.camera_to_world,
        &given[5].pose.camera_to_world,
    );
    assert!(mm < 1e-6 && deg < 1e-6, "{mm} mm {deg} deg");

    let no_selection = BuildOptions {
        selection: bronchosim::selection::SelectionOptions {
            max_frames: 0,
            ..Default::default()
        },
        ..build_opts
    };
    let m = build_model(&case_dir, &dir.join("model"), &no_selection).unwrap();
    let reg = m.registration.as_ref().unwrap();
    assert!(m.frame_selection.is_none());
    assert_eq!((reg.frames[5].status.as_str(), reg.left_out), ("blank", 1));
    assert_eq!(
        m.fit_quality.len(),
        11,
        "the model is built from the other frames"
    );
    assert!(m.fit_quality.iter().all(|f| f.frame != 5));
}

#[test]
fn build_leaves_out_the_frames_blurred_against_the_model() {
    // A quarter of the frames motion-blurred, with a tracker's error: the first 30 frames of
    // an 80-frame video (the demo's pace), 128x128. The video is within the frame budget,
    // where the selection uses every frame: a frame's sharpness against its neighbours' also
    // follows what it sees. The model's prediction from the frame's pose sees the same wall.
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    let case_dir = dir.join("case");
    let opts = PhantomOptions {
        frames: 80,
        width: 128,
        height: 128,
        novel_views: 1,
        pose_noise: PoseNoise::new(1.5, 2.0),
        motion_blur: MotionBlur {
            share: 0.25,
            ..Default::default()
        },
        ..Default::default()
    };
    let kept = 30;
    let (case, blurred) = phantom_cut_to(&case_dir, &opts, kept);
    let m = build_refined(&case_dir, &dir.join("model"), None);
    let reg = m.registration.as_ref().unwrap();
    let flagged: Vec<usize> = reg
        .frames
        .iter()
        .filter(|f| f.status == "blurred")
        .map(|f| f.frame)
        .collect();
    println!(
        "blurred {blurred:?}, flagged {flagged:?}; rounds {:?}",
        reg.rounds
            .iter()
            .map(|r| (&r.against, r.discarded, &r.counts))
            .collect::<Vec<_>>()
    );
    // Measured: blurred 8, 13, 24, 28, 29, flagged all but 29; the sharp frames' sharpness
    // against the model 0.90-1.36 of the median, the blurred ones' 0.46-0.74. On 24 frames
    // over the whole path (three times the pace) the sharp ones' spread 0.61-1.90 and the
    // last frame was flagged.
    assert!(
        flagged.iter().all(|f| blurred.contains(f)),
        "a sharp frame flagged: blurred {blurred:?}, flagged {flagged:?}"
    );
    assert!(
        2 * flagged.len() >= blurred.len(),
        "blurred {blurred:?}, flagged {flagged:?}"
    );
    assert!(reg.frames.iter().all(|f| f.status != "blurred" || !f.used));
    assert!(m.fit_quality.iter().all(|f| !flagged.contains(&f.frame)));

    // The same video with its true poses, trusted as given (`--poses fixed`): no registration
    // runs, and the check runs at the given poses.
    let truth = true_poses(&case_dir);
    let exact: Vec<PoseEntry> = case.poses[..kept]
        .iter()
        .zip(&truth)
        .map(|(e, p)| PoseEntry {
            frame: e.frame.clone(),
            pose: Pose::new(*p),
        })
        .collect();
    write_poses(&case_dir.join("poses.json"), &exact, &case_dir).unwrap();
    let opts = BuildOptions {
        cross_validate_every: 0,
        shading: Some(ShadingKind::Calibrated),
        poses: PosesMode::Fixed,
        quiet: true,
        ..Default::default()
    };
    let m = build_model(&case_dir, &dir.join("fixed"), &opts).unwrap();
    assert!(m.registration.is_none());
    let check = m.blur_check.as_ref().expect("model.json records the check");
    let flagged = check.blurred_frames();
    let sharpest_blurred = check
        .frames
        .iter()
        .filter(|f| blurred.contains(&f.frame))
        .filter_map(|f| f.relative_sharpness)
        .fold(0.0, f64::max);
    let least_sharp = check
        .frames
        .iter()
        .filter(|f| !blurred.contains(&f.frame))
        .filter_map(|f| f.relative_sharpness)
        .fold(f64::INFINITY, f64::min);
    println!(
        "fixed poses: flagged {flagged:?}; sharpness of the blurred up to {sharpest_blurred:.2}, of the sharp from {least_sharp:.2}"
    );
    // Measured: 8, 13, 24 and 28 flagged, the mildest blur (29, the last frame) at 0.76 of
    // the median; the sharp frames from 0.90.
    assert!(
        flagged.iter().all(|f| blurred.contains(f)) && flagged.len() + 1 >= blurred.len(),
        "blurred {blurred:?}, flagged {flagged:?}"
    );
    assert!(
        least_sharp > 0.8,
        "a sharp frame at {least_sharp:.2} of the median"
    );
    assert!(m.fit_quality.iter().all(|f| !flagged.contains(&f.frame)));
    assert!(m.warnings.iter().any(|w| w.contains("less sharp")));
    let said = format!("{} of {kept} left out ({flagged:?})", flagged.len());
    let summary = build_text(&dir.join("fixed"), &m);
    assert!(summary.contains(&said), "{summary}");
    let html = std::fs::read_to_string(dir.join("fixed/report.html")).unwrap();
    assert!(
        html.contains("<h2>Blurred frames</h2>") && html.contains(&format!("frames {flagged:?}"))
    );
}

#[test]
fn build_repeats_a_geometry_round_that_leaves_many_outliers() {
    // Tracker poses 3 mm / 4 degrees off: the first geometry round leaves many frames outliers,
    // and a texture fused after it follows their errors.
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    let (case_dir, case) = phantom_with_pose_noise(dir, PoseNoise::new(3.0, 4.0));
    let truth = true_poses(&case_dir);
    let given: Vec<Affine> = case.poses.iter().map(|p| p.pose.camera_to_world).collect();
    let (mm0, deg0, _) = errors(&given, &truth);
    let out = dir.join("model");
    let m = build_refined(&case_dir, &out, None);
    let reg = m.registration.expect("model.json records the registration");
    let refined: Vec<Affine> = read_poses(&out.join("poses.json"), &case_dir)
        .unwrap()
        .iter()
        .map(|p| p.pose.camera_to_world)
        .collect();
    let kinds: Vec<&str> = reg.rounds.iter().map(|r| r.against.as_str()).collect();
    let outliers = reg.rounds[0].counts.get("outlier").copied().unwrap_or(0);
    let (mm, deg, within) = errors(&refined, &truth);
    println!(
        "3 mm / 4 deg: {mm0:.3} mm {deg0:.3} deg; first round {outliers} outliers; {kinds:?} -> {mm:.3} mm {deg:.3} deg, {within} within"
    );
    assert!(
        4 * outliers > 24,
        "{outliers} outliers after the first round"
    );
    assert_eq!(kinds, ["geometry", "geometry"]);
    // Measured from 2.64 mm / 3.41 deg: 0.94 mm / 2.40 deg; without the repeat (geometry, then
    // texture: `registration_geometry_repeat_share` 1) 1.57 mm / 2.82 deg, which fails this.
    assert!(mm < 0.5 * mm0 && deg < 0.75 * deg0, "{mm} mm {deg} deg");
}

/// Mean rotation error about the camera's own x axis (pitch, degrees) of `poses` against
/// `truth`.
fn mean_pitch_deg(poses: &[Affine], truth: &[Affine]) -> f64 {
    PoseAccuracy::of(poses, truth).unwrap().mean_deg[0]
}

/// The tracker phantom with every pose turned 0.4 deg about its camera's x axis, and the model
/// fused at those poses.
struct PitchedPhantom {
    case_dir: std::path::PathBuf,
    entries: Vec<PoseEntry>,
    truth: Vec<Affine>,
    frames: Vec<Frame>,
    pitched: Vec<Affine>,
    model: Model,
}

fn pitched_phantom(dir: &Path) -> PitchedPhantom {
    let (case_dir, case) = tracker_phantom(dir);
    let truth = true_poses(&case_dir);
    let frames: Vec<Frame> = case.frame_source().unwrap().map(|f| f.unwrap()).collect();
    let turn = [0.0, 0.0, 0.0, 0.4f64.to_radians(), 0.0, 0.0];
    let pitched: Vec<Affine> = truth.iter().map(|t| perturb(t, &turn)).collect();
    case_with_poses(&case_dir, &dir.join("pitched"), &case.poses, &pitched);
    let model = build(&dir.join("pitched"), &dir.join("pitched_model"));
    PitchedPhantom {
        case_dir,
        entries: case.poses.clone(),
        truth,
        frames,
        pitched,
        model,
    }
}

#[test]
fn texture_rounds_shrink_an_error_every_frame_shares() {
    // Every pose turned 0.4 deg about its camera's x axis and the model fused at those poses:
    // the texture follows the frames, and only how the shift differs between frames that see
    // a wall from different distances says which way to turn them back.
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    let PitchedPhantom {
        case_dir,
        entries,
        truth,
        frames,
        pitched,
        model: first,
    } = pitched_phantom(dir);
    let start = mean_pitch_deg(&pitched, &truth);
    // Rounds as the build runs them: the model fused at the poses, then every frame
    // registered against it.
    let rounds = |grad_blend: f32, label: &str| {
        let opts = RoundOptions {
            frame: RegistrationOptions {
                grad_blend,
                ..RegistrationOptions::default()
            },
            ..RoundOptions::default()
        };
        let mut poses = pitched.clone();
        let mut pitch = Vec::new();
        for r in 0..2 {
            let fused_here;
            let model = match r {
                0 => &first,
                _ => {
                    let case = dir.join(format!("{label}_case_{r}"));
                    case_with_poses(&case_dir, &case, &entries, &poses);
                    fused_here = build(&case, &dir.join(format!("{label}_model_{r}")));
                    &fused_here
                }
            };
            let v = register_with(model, &frames, &poses, RoundKind::Texture, &opts);
            poses = v.frames.iter().map(|f| f.pose).collect();
            pitch.push(mean_pitch_deg(&poses, &truth));
        }
        pitch
    };
    let frame_gradient = rounds(RegistrationOptions::default().grad_blend, "frame");
    let model_gradient = rounds(1.0, "model");
    println!(
        "shared pitch {start:.3} deg, after each round: {frame_gradient:.3?} deg (frame's gradient), {model_gradient:.3?} deg (model's)"
    );
    // Measured: 0.400 -> 0.307, 0.246 deg with the frame's gradient, 0.329, 0.284 deg with the
    // model's (a third round: 0.207 against 0.256 deg).
    let (f, m) = (frame_gradient[1], model_gradient[1]);
    assert!(f < 0.8 * start, "{f} deg");
    assert!(f < m, "{f} vs {m} deg");
}

#[test]
fn a_shading_round_turns_back_an_error_every_frame_shares() {
    // Every pose turned 0.4 deg about its camera's x axis and the model fused there. A geometry
    // round pulls the poses toward its own bias (the albedo a frame's colour does not
    // predict); a shading round holds the texture's albedo in the image, so the shading alone
    // moves the poses, and it turns the shared pitch back.
    let tmp = tempfile::tempdir().unwrap();
    let PitchedPhantom {
        truth,
        frames,
        pitched,
        model,
        ..
    } = pitched_phantom(tmp.path());
    let pitch_after = |kind: RoundKind| {
        let v = register(&model, &frames, &pitched, kind);
        let poses: Vec<Affine> = v.frames.iter().map(|f| f.pose).collect();
        mean_pitch_deg(&poses, &truth)
    };
    let (shading, geometry) = (
        pitch_after(RoundKind::Shading),
        pitch_after(RoundKind::Geometry),
    );
    println!("shared pitch 0.400 deg, after a shading round {shading:.3} deg, after a geometry round {geometry:.3} deg");
    // Measured: 0.115 deg after the shading round, 0.191 deg after the geometry round.
    assert!(shading.abs() < 0.2, "{shading} deg");
    assert!(
        shading.abs() < geometry.abs(),
        "{shading} vs {geometry} deg"
    );
}

#[test]
fn a_run_of_frames_one_ring_away_is_realigned_with_its_neighbours() {
    // The first frames' poses start 2.4 mm behind along their view, past half a
    // cartilage-ring period (4 mm), the tracker's drift fading to nothing by frame 12:
    // registered against the geometry, frames in the trachea that start past half a period
    // fall to the ring behind, the others come back to the truth. The corrections jump where
    // the two runs meet, and the tracker's continuity brings the trachea's run back.
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    let (case_dir, case) = tracker_phantom(dir);
    let truth = true_poses(&case_dir);
    let frames: Vec<Frame> = case.frame_source().unwrap().map(|f| f.unwrap()).collect();
    case_with_poses(&case_dir, &dir.join("true_case"), &case.poses, &truth);
    let model = build(&dir.join("true_case"), &dir.join("true_model"));
    let behind = |f: usize| -2.4 * (12.0 - f.max(5) as f64).max(0.0) / 7.0;
    let start: Vec<Affine> = truth
        .iter()
        .enumerate()
        .map(|(f, t)| perturb(t, &[0.0, 0.0, behind(f), 0.0, 0.0, 0.0]))
        .collect();
    let alone = register(&model, &frames, &start, RoundKind::Geometry);
    let error = |v: &VideoRegistration, f: usize| pose_error(&v.frames[f].pose, &truth[f]).0;
    let aliased: Vec<usize> = (0..truth.len())
        .filter(|&f| error(&alone, f) > 3.0)
        .collect();
    let with_blocks = RoundOptions {
        video: VideoOptions {
            blocks: Some(BlockOptions::default()),
            ..VideoOptions::default()
        },
        ..RoundOptions::default()
    };
    let realigned = register_with(&model, &frames, &start, RoundKind::Geometry, &with_blocks);
    let before: Vec<f64> = aliased.iter().map(|&f| error(&alone, f)).collect();
    let after: Vec<f64> = aliased.iter().map(|&f| error(&realigned, f)).collect();
    let (_, _, within_alone) = errors(
        &alone.frames.iter().map(|f| f.pose).collect::<Vec<_>>(),
        &truth,
    );
    let (_, _, within) = errors(
        &realigned.frames.iter().map(|f| f.pose).collect::<Vec<_>>(),
        &truth,
    );
    println!(
        "frames {aliased:?} at the ring behind: {before:.2?} mm left alone, {after:.2?} mm realigned ({} frames moved); within 1 mm and 1 deg {within_alone} -> {within} of 24",
        realigned.realigned
    );
    assert!(
        aliased.len() >= 2,
        "no run fell to the ring behind: {aliased:?}"
    );
    assert!(after.iter().all(|&e| e < 1.0), "{after:?}");
    assert!(within > within_alone, "{within_alone} -> {within}");
}

/// `frame` turned half a turn about its centre (pixel (x, y) to (w-1-x, h-1-y)).
fn half_turned(frame: &Frame) -> Frame {
    let rgb = frame.rgb.chunks_exact(3).rev().flatten().copied().collect();
    Frame { rgb, ..*frame }
}

#[test]
fn a_frame_turned_half_a_turn_registers_to_the_turned_pose() {
    // A frame rotated 180 degrees about its centre is what the camera turned half a turn about
    // its optical axis sees. Registered from the turned true pose, its errors must be the
    // unturned frame's with x and y negated. An error that does not turn with the image is
    // fixed to the pixel grid: a half-pixel slip in the pyramid, the ray grid or the camera's
    // levels (the levels' principal point at `cx / 2^l`: 0.51 deg of yaw). The errors that
    // do turn are the scene's (the geometry's shading against a frame with its own albedo:
    // tenths of a degree) and cancel.
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    let (case_dir, case) = phantom_with_pose_noise(dir, PoseNoise::new(0.0, 0.0));
    let truth = true_poses(&case_dir);
    let frames: Vec<Frame> = case.frame_source().unwrap().map(|f| f.unwrap()).collect();
    let camera = &case.camera;
    assert_eq!(
        (2.0 * camera.cx + 1.0, 2.0 * camera.cy + 1.0),
        (camera.width as f64, camera.height as f64),
        "the turn needs the principal point at the image's centre"
    );
    let model = build(&case_dir, &dir.join("model"));
    let parts = model.registration_parts().unwrap();
    let turn = Affine::from_diagonal(&nalgebra::Vector4::new(-1.0, -1.0, 1.0, 1.0));
    let levels = [
        (
            "geometry (red, levels 4..1)",
            RegistrationOptions {
                uniform_albedo_from_level: 0,
                uniform_channel_weights: [1.0, 0.0, 0.0],
                finest_level: 1,
                ..RegistrationOptions::default()
            },
        ),
        (
            "texture (levels 4..1)",
            RegistrationOptions {
                finest_level: 1,
                ..RegistrationOptions::default()
            },
        ),
    ];
    for (name, opts) in levels {
        let reg = FrameRegistrar::new(parts, opts).unwrap();
        let (mut found, mut found_turned, mut truth_used, mut truth_turned) =
            (Vec::new(), Vec::new(), Vec::new(), Vec::new());
        for i in (0..frames.len()).step_by(2) {
            let gain = parts.light.gains[i];
            let plain = FrameObs {
                frame: &frames[i],
                gain,
                mask: None,
            };
            let turned_frame = half_turned(&frames[i]);
            let turned = FrameObs {
                frame: &turned_frame,
                gain,
                mask: None,
            };
            let turned_truth = truth[i] * turn;
            found.push(reg.refine_frame(&plain, &truth[i]).unwrap().pose);
            found_turned.push(reg.refine_frame(&turned, &turned_truth).unwrap().pose);
            truth_used.push(truth[i]);
            truth_turned.push(turned_truth);
        }
        let a = PoseAccuracy::of(&found, &truth_used).unwrap();
        let b = PoseAccuracy::of(&found_turned, &truth_turned).unwrap();
        // x and y of the camera (pitch, yaw, sideways shifts): what turns with the scene
        // changes sign, what is fixed to the image does not.
        let pairs = [
            (a.mean_deg[0], b.mean_deg[0]),
            (a.mean_deg[1], b.mean_deg[1]),
            (a.mean_mm[0], b.mean_mm[0]),
            (a.mean_mm[1], b.mean_mm[1]),
        ];
        let scene = pairs.map(|(p, q)| 0.5 * (p - q));
        let fixed = pairs.map(|(p, q)| 0.5 * (p + q));
        println!(
            "{name}: turning with the scene pitch {:.4} yaw {:.4} deg, x {:.4} y {:.4} mm; fixed to the image {:.5} {:.5} deg, {:.5} {:.5} mm",
            scene[0], scene[1], scene[2], scene[3], fixed[0], fixed[1], fixed[2], fixed[3]
        );
        // Measured: geometry 0.00000 deg fixed against -0.05 / -0.42 deg turning; texture
        // 0.0003 / -0.0012 deg against 0.016 / -0.015 deg.
        assert!(
            fixed[0].abs() < 0.005 && fixed[1].abs() < 0.005,
            "{name}: {fixed:?}"
        );
        assert!(
            fixed[2].abs() < 0.002 && fixed[3].abs() < 0.002,
            "{name}: {fixed:?}"
        );
    }
}
