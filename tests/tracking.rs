//! Registration without a tracker (`--poses first`, issue 16 item 5) and the registration
//! report's before/after overlays (item 3), on small phantoms (up to 60 frames, 128x128 to
//! 256x256).

use bronchosim::image::Frame;
use bronchosim::io::case::Case;
use bronchosim::io::png::write_png_srgb8;
use bronchosim::io::poses::{read_poses, write_poses, PoseEntry};
use bronchosim::math::{Affine, Vector3};
use bronchosim::model::manifest::BuildTimings;
use bronchosim::model::registration::TrackingSummary;
use bronchosim::phantom::motion_blur::MotionBlur;
use bronchosim::phantom::path::PathOptions;
use bronchosim::phantom::pose_noise::PoseNoise;
use bronchosim::phantom::{write_phantom_case, PhantomOptions};
use bronchosim::registration::{apply_delta, pose_error, PoseDelta};
use bronchosim::workflow::build::selection::select_frames;
use bronchosim::workflow::build::{register_poses, BuildOptions, BuildScene, PosesMode};
use bronchosim::workflow::register::register_command;
use std::path::Path;

#[path = "common/untracked.rs"]
mod untracked;
use untracked::{
    tracked_errors, untracked_phantom, untracked_phantom_of, untracked_phantom_paced,
    untracked_phantom_sized,
};

fn phantom(dir: &Path, noise: PoseNoise) -> Case {
    let opts = PhantomOptions {
        frames: 24,
        width: 160,
        height: 160,
        pose_noise: noise,
        ..Default::default()
    };
    write_phantom_case(dir, &opts).unwrap();
    Case::open(dir).unwrap()
}

fn poses_of(entries: &[PoseEntry]) -> Vec<Affine> {
    entries.iter().map(|p| p.pose.camera_to_world).collect()
}

/// The options of the tracking from the first pose without the registration's rounds.
fn tracking_alone() -> BuildOptions {
    BuildOptions {
        poses: PosesMode::First,
        registration_rounds: 0,
        cross_validate_every: 0,
        quiet: true,
        ..Default::default()
    }
}

/// `register CASE --out OUT --poses first --rounds 0`: the tracking alone (its options as
/// `tune` leaves them); its summary and the tracked poses.
fn track_only(
    case_dir: &Path,
    out: &Path,
    tune: impl FnOnce(&mut BuildOptions),
) -> (TrackingSummary, Vec<Affine>) {
    let mut opts = tracking_alone();
    tune(&mut opts);
    let s = register_command(case_dir, out, &opts).unwrap();
    let tracked = poses_of(&read_poses(&out.join("poses.json"), case_dir).unwrap());
    (s.registration.tracking.clone().unwrap(), tracked)
}

#[test]
fn poses_first_tracks_the_video_from_one_pose() {
    let tmp = tempfile::tempdir().unwrap();
    let case_dir = tmp.path().join("case");
    // The video without a tracker: poses.json holds the first frame's pose alone.
    let truth = untracked_phantom(&case_dir, 48);
    let refused = Case::open(&case_dir).unwrap_err().to_string();
    assert!(refused.contains("fewer poses than frames"), "{refused}");
    let opened = Case::open_untracked(&case_dir).unwrap();
    assert_eq!((opened.frame_count(), opened.poses_given), (48, 1));

    let out = tmp.path().join("reg");
    let (tracking, tracked) = track_only(&case_dir, &out, |_| {});
    assert_eq!(tracked.len(), 48);
    let (errors, within_mm, within_both) = tracked_errors(&tracked, &truth);
    println!(
        "tracked {} of 48 (first lost {:?}); within 1 mm {within_mm}, within 1 mm and 1 deg {within_both}; {:.2} s per frame; errors {:?}",
        tracking.frames_tracked, tracking.first_lost, tracking.seconds_per_frame, errors
    );
    // Measured: all 48 frames within 1 mm (median 0.35 mm), 21 also within 1 degree (1.1 deg
    // median; the registration's rounds refine them in a build); with the tracker's pyramid
    // levels those of 320-pixel frames, 7 (1.4 deg). Without each window's geometry round
    // the view direction drifted with the texture: 25 within 1 mm, the track lost at frame 32.
    assert_eq!(within_mm, 48, "{within_mm} of 48 frames within 1 mm");
    assert!(
        within_both >= 18,
        "{within_both} of 48 frames within 1 mm and 1 degree"
    );
    assert_eq!((tracking.frames_tracked, tracking.first_lost), (48, None));
    // The exact first pose agrees with the CT: refined, it fitted the frame 1.7 % better,
    // under the 10 % that would move it.
    let first = tracking.first_pose.clone().unwrap();
    println!("first pose {first:?}");
    assert!(
        !first.kept && first.cost_refined > 0.9 * first.cost_given,
        "{first:?}"
    );
    assert_eq!(errors[0], (0.0, 0.0));
    let record = std::fs::read_to_string(out.join("registration.json")).unwrap();
    assert!(record.contains("\"frames_tracked\""), "{record}");
}

#[test]
fn a_lost_track_resumes_from_the_frames_before_it_refined() {
    let tmp = tempfile::tempdir().unwrap();
    let case_dir = tmp.path().join("case");
    // The view direction swings up to 12 degrees (the built-in path's 4): the scope turns up
    // to 10 degrees between frames. The tracker's gate on a frame's turn at 10 degrees (its
    // default, 20, tracks this path to the end) refuses frames 15 and 16, and one frame
    // refused loses the track here (its default, 3, lets frame 17 through a gate widened by
    // the frames since the last accepted one). At 256x256 the tracker runs the pyramid
    // levels set for 320-pixel frames; at 128x128, counted from the frames' size, it refuses
    // none of this path at 10 degrees.
    let truth = untracked_phantom_sized(&case_dir, 80, 22, 12.0, 256);
    let (t, tracked) = track_only(&case_dir, &tmp.path().join("reg"), |o| {
        o.tracking.track.max_jump_deg = 10.0;
        o.tracking.track.lost_after = 1;
    });
    let (errors, within_mm, _) = tracked_errors(&tracked, &truth);
    println!(
        "tracked {}, lost at {:?}, resumed at {:?}; {within_mm} of 22 within 1 mm; errors {errors:?}",
        t.frames_tracked, t.first_lost, t.resumed_at
    );
    // Measured: the track is lost at frame 15; resumed there, frames 15-21 are within 0.41
    // mm and 1.6 deg, and the track is not lost again (over eight inputs one pixel apart,
    // `BRONCHOSIM_TEST_PERTURB` 0-7: within 0.39-0.45 mm and 1.55-2.15 deg, the last frame the
    // farthest). Without the resume (`TrackingOptions::resumes` 0) frames 15 and 16 stay 11
    // and 25 deg off, and every frame from 15 on is left out as lost.
    assert_eq!(t.resumed_at, [15], "{t:?}");
    assert_eq!(t.first_lost, None);
    let after = errors[15..]
        .iter()
        .filter(|e| e.0 <= 1.0 && e.1 <= 3.0)
        .count();
    assert_eq!(
        after,
        7,
        "frames 15-21 within 1 mm and 3 deg: {:?}",
        &errors[15..]
    );
    assert_eq!(
        errors[0],
        (0.0, 0.0),
        "the first frame's given pose is kept"
    );
}

#[test]
fn a_blackout_of_two_frames_is_crossed() {
    let tmp = tempfile::tempdir().unwrap();
    let case_dir = tmp.path().join("case");
    let truth = untracked_phantom(&case_dir, 22);
    // Frames 10 and 11 black: the lens against the wall, or fluid over it.
    for f in [10, 11] {
        let path = case_dir.join(format!("frames/{f:06}.png"));
        write_png_srgb8(&path, &Frame::new(128, 128)).unwrap();
    }
    let out = tmp.path().join("reg");
    let s = register_command(&case_dir, &out, &tracking_alone()).unwrap();
    let t = s.registration.tracking.clone().unwrap();
    let tracked = poses_of(&read_poses(&out.join("poses.json"), &case_dir).unwrap());
    let (errors, within_mm, _) = tracked_errors(&tracked, &truth);
    println!(
        "tracked {}, lost at {:?}; {within_mm} of 22 within 1 mm; errors {errors:?}",
        t.frames_tracked, t.first_lost
    );
    // The black frames are flagged and left out of the model, and placed between their
    // neighbours.
    for f in [10, 11] {
        let r = &s.registration.frames[f];
        assert_eq!((r.status.as_str(), r.used), ("blank", false), "{r:?}");
    }
    // Measured: frames 12-21 within 0.3 mm and 1.7 deg. With the tracker's gate on a
    // frame's move (3 mm, 20 deg) not widened by the frames since the last accepted one,
    // frame 12 was found one cartilage ring away (4.0 mm) and frames 12-21 with it.
    assert_eq!(t.first_lost, None);
    // Measured, the black frames between their neighbours: 0.36 mm / 2.9 deg and 0.29 mm /
    // 2.3 deg off; at the tracker's predictions, 0.88 mm / 3.0 deg and 2.07 mm / 9.1 deg.
    assert!(
        errors[10..12].iter().all(|e| e.0 <= 0.5 && e.1 <= 4.0),
        "black frames 10, 11: {:?}",
        &errors[10..12]
    );
    let after: Vec<_> = errors[12..].iter().filter(|e| e.0 <= 0.5).collect();
    assert_eq!(after.len(), 10, "frames 12-21 within 0.5 mm: {after:?}");
}

#[test]
fn blurred_frames_are_flagged_and_not_tracked_against() {
    // A quarter of the frames motion-blurred, the demo's pace, 128x128, the first 30 frames.
    // Registered and fused into the texture the next frames are tracked against, blurred
    // frames lead the track astray (the demo's video with a fifth blurred: its last frames
    // 6-45 deg off).
    let tmp = tempfile::tempdir().unwrap();
    let case_dir = tmp.path().join("case");
    let opts = PhantomOptions {
        frames: 80,
        width: 128,
        height: 128,
        novel_views: 1,
        motion_blur: MotionBlur {
            share: 0.25,
            ..Default::default()
        },
        ..Default::default()
    };
    let (truth, blurred) = untracked_phantom_of(&case_dir, &opts, 30);
    let out = tmp.path().join("reg");
    let s = register_command(&case_dir, &out, &tracking_alone()).unwrap();
    let t = s.registration.tracking.clone().unwrap();
    let flagged: Vec<usize> = (0..30)
        .filter(|&f| s.registration.frames[f].status == "blurred")
        .collect();
    let tracked = poses_of(&read_poses(&out.join("poses.json"), &case_dir).unwrap());
    let (errors, _, within) = tracked_errors(&tracked, &truth);
    let sharp: Vec<(f64, f64)> = (0..30)
        .filter(|f| !blurred.contains(f))
        .map(|f| errors[f])
        .collect();
    println!(
        "blurred {blurred:?}, flagged {flagged:?}; lost at {:?}; {within} of 30 within 1 mm and 1 deg; sharp frames {sharp:?}",
        t.first_lost
    );
    // Measured: all five flagged. Tracking alone (no rounds) here, 15 of 30 frames within 1 mm
    // and 1 deg, and 20 with the check off (the rounds of a build refine them; the demo's
    // video with a fifth of its frames blurred builds to 30.76 dB with the check, 29.85
    // without). A frame is judged against the recent accepted frames' median: from the fifth
    // on.
    let judged: Vec<usize> = blurred.iter().copied().filter(|&f| f >= 5).collect();
    assert_the_blurred_alone(&flagged, &blurred, &judged);
    assert!(flagged.iter().all(|&f| !s.registration.frames[f].used));
    assert_eq!(t.first_lost, None);

    // The tracker's verdict serves the tracking; a frame it flags between two kept ones is
    // refined by the rounds and left out only if the build's blur check, one model from the
    // refined poses, finds it blurred too (a bronchus's wall seen from close looks blurred to
    // the tracker's recent model). A stricter tracker here flags sharp frame 7 as well
    // (measured with `registration_rounds` 0), which the rounds keep; with the tracker's
    // verdict final it is left out.
    let mut strict = BuildOptions {
        registration_rounds: 2,
        registration_joint: false,
        ..tracking_alone()
    };
    strict.tracking.track.blurred_below = 0.9;
    strict.tracking.track.blurred_against_last_below = 0.0;
    let s = register_command(&case_dir, &tmp.path().join("rounds"), &strict).unwrap();
    let left_out: Vec<usize> = (0..30)
        .filter(|&f| !s.registration.frames[f].used)
        .collect();
    println!("strict tracker, then the rounds: left out {left_out:?}");
    assert_the_blurred_alone(&left_out, &blurred, &judged);
}

/// `found` (frames flagged or left out as blurred) holds no sharp frame and at least half of
/// the `judged` blurred ones.
fn assert_the_blurred_alone(found: &[usize], blurred: &[usize], judged: &[usize]) {
    assert!(
        found.iter().all(|f| blurred.contains(f)),
        "a sharp frame found blurred: blurred {blurred:?}, found {found:?}"
    );
    assert!(
        2 * found.len() >= judged.len(),
        "blurred {blurred:?}, found {found:?}"
    );
}

#[test]
fn sharp_frames_at_the_carina_are_not_flagged_blurred() {
    // The seed-7 phantom (no frame blurred) at 128x128, its first 60 frames: the scope reaches
    // the carina at frame 50. The model the tracker judges a frame's sharpness against is
    // fitted again every 8 frames; a fit that predicted the frames near the carina sharper
    // than the earlier fits predicted theirs put sharp frames under the recent median's share,
    // and frames 56, 57 and 58 were flagged: they kept their predicted poses, 2.3-4.5 deg off.
    // Against the frame before it a sharp frame keeps its detail, so they are not.
    let tmp = tempfile::tempdir().unwrap();
    let case_dir = tmp.path().join("case");
    let opts = PhantomOptions {
        seed: 7,
        frames: 80,
        width: 128,
        height: 128,
        novel_views: 1,
        ..Default::default()
    };
    let (truth, blurred) = untracked_phantom_of(&case_dir, &opts, 60);
    assert!(blurred.is_empty());
    let out = tmp.path().join("reg");
    let s = register_command(&case_dir, &out, &tracking_alone()).unwrap();
    let t = s.registration.tracking.clone().unwrap();
    let flagged: Vec<usize> = (0..60)
        .filter(|&f| s.registration.frames[f].status == "blurred")
        .collect();
    let tracked = poses_of(&read_poses(&out.join("poses.json"), &case_dir).unwrap());
    let (errors, _, _) = tracked_errors(&tracked, &truth);
    println!(
        "flagged {flagged:?}; lost at {:?}; frames 48-59 {:?}",
        t.first_lost,
        &errors[48..]
    );
    // Measured: none flagged, frames 48-59 within 0.58 mm and 2.2 deg (over eight inputs one
    // pixel apart, `BRONCHOSIM_TEST_PERTURB` 0-7: none flagged, within 0.41-0.64 mm and
    // 2.1-4.0 deg, the turn shared by the run). (Tracking alone at this size: frames 32-42
    // turn up to 34 deg about their view axes in the trachea and come back; the rounds of a
    // build refine them.)
    assert_eq!(flagged, Vec::<usize>::new());
    assert_eq!(t.first_lost, None);
    let past = &errors[48..];
    assert!(past.iter().all(|e| e.0 <= 1.0 && e.1 <= 6.0), "{past:?}");
}

#[test]
fn a_blackout_of_four_frames_is_crossed() {
    let tmp = tempfile::tempdir().unwrap();
    let case_dir = tmp.path().join("case");
    let truth = untracked_phantom(&case_dir, 22);
    // Frames 10-13 black: the scope moves about 7 mm unseen.
    for f in 10..14 {
        let path = case_dir.join(format!("frames/{f:06}.png"));
        write_png_srgb8(&path, &Frame::new(128, 128)).unwrap();
    }
    let run = |out: &str, tune: fn(&mut BuildOptions)| {
        let (t, tracked) = track_only(&case_dir, &tmp.path().join(out), tune);
        let (errors, within_mm, _) = tracked_errors(&tracked, &truth);
        println!(
            "{out}: tracked {}, lost at {:?}; {within_mm} of 22 within 1 mm; errors {errors:?}",
            t.frames_tracked, t.first_lost
        );
        (t, errors)
    };
    // The black frames counted as refused, and the frame after the gap tried from the
    // prediction and the last accepted pose alone.
    let (t, errors) = run("before", |o| {
        o.tracking.track.frame.blank_below = 0.0;
        o.tracking.track.relocalise_deg = 0.0;
    });
    // Measured: lost at frame 10; frames 14-21 not found again.
    assert_eq!(t.first_lost, Some(10), "{t:?}");
    assert!(errors[14..].iter().all(|e| e.0 > 1.0 || e.1 > 2.0));
    let (t, errors) = run("default", |_| {});
    // Measured: never lost; frames 14-21 within 0.28 mm and 1.1 deg (with three black frames:
    // 0.29 mm and 1.7 deg; with five, the first frame after them 6.3 deg off, the rest within
    // 2.6 deg; with six they are found 16-17 deg off). Which turn the frames after the gap
    // take is chance: over seven inputs one pixel apart (`BRONCHOSIM_TEST_PERTURB` 0-6) they
    // were always found, within 0.28-0.88 mm, but up to 1.1-5.8 deg off (median 0.7-2.4 deg).
    assert_eq!((t.first_lost, t.frames_tracked), (None, 18), "{t:?}");
    let mut turns: Vec<f64> = errors[14..].iter().map(|e| e.1).collect();
    turns.sort_by(f64::total_cmp);
    assert!(
        errors[14..].iter().all(|e| e.0 <= 1.5) && turns[turns.len() / 2] <= 3.5,
        "frames 14-21: {:?}",
        &errors[14..]
    );
}

#[test]
fn a_first_pose_a_millimetre_and_a_degree_off_is_refined_before_tracking() {
    let tmp = tempfile::tempdir().unwrap();
    let case_dir = tmp.path().join("case");
    let truth = untracked_phantom(&case_dir, 22);
    // A first pose aligned by hand: 1 mm along the camera's (1, 1, 1) and 1 deg about its
    // (1, -1, 1).
    let poses_path = case_dir.join("poses.json");
    let mut given = read_poses(&poses_path, &case_dir).unwrap();
    let r = bronchosim::registration::pose::rotation_of(&truth[0]);
    let skew = |v: [f64; 3]| r * Vector3::from(v).normalize();
    let off = PoseDelta {
        translation_mm: skew([1.0, 1.0, 1.0]),
        rotation: skew([1.0, -1.0, 1.0]) * 1f64.to_radians(),
    };
    given[0].pose.camera_to_world = apply_delta(&truth[0], &off);
    write_poses(&poses_path, &given, &case_dir).unwrap();
    let run = |refine_first: bool, out: &str| {
        track_only(&case_dir, &tmp.path().join(out), |o| {
            o.tracking.refine_first = refine_first
        })
    };
    let (trusted, trusted_poses) = run(false, "trusted");
    let (refined, refined_poses) = run(true, "refined");
    let (trusted_errors, trusted_mm, trusted_both) = tracked_errors(&trusted_poses, &truth);
    let (refined_errors, refined_mm, refined_both) = tracked_errors(&refined_poses, &truth);
    println!(
        "first pose {:?}\ntrusted: {trusted_mm} of 22 within 1 mm, {trusted_both} within 1 mm and 1 deg, {trusted_errors:?}\nrefined: {refined_mm}, {refined_both}, {refined_errors:?}",
        refined.first_pose
    );
    assert!(trusted.first_pose.is_none());
    let report =
        |out: &str| std::fs::read_to_string(tmp.path().join(out).join("report.html")).unwrap();
    assert!(report("trusted").contains("pose alone (trusted as given)"));
    assert!(report("refined").contains("pose alone (refined against the CT first, 1."));
    let first = refined.first_pose.clone().unwrap();
    assert!(
        first.kept && first.cost_refined < first.cost_given,
        "{first:?}"
    );
    let median_deg = |e: &[(f64, f64)]| {
        let mut d: Vec<f64> = e.iter().map(|e| e.1).collect();
        d.sort_by(f64::total_cmp);
        d[d.len() / 2]
    };
    let (trusted_median, refined_median) =
        (median_deg(&trusted_errors), median_deg(&refined_errors));
    println!("median deg: trusted {trusted_median:.3}, refined {refined_median:.3}");
    // Measured: trusted, 15 of 22 within 1 mm, none also within 1 deg, 9.8 deg median, the
    // last frames 36-41 deg off; refined (the first pose moved 1.49 mm / 3.49 deg), 22
    // within 1 mm, 7 also within 1 deg, 1.18 deg median, none over 2.8 deg. One frame's
    // geometry at 128x128 left the first pose itself 0.70 mm / 2.72 deg off: the frames
    // after it are tracked against the geometry's shading at the coarse levels, which
    // does not follow it.
    assert!(trusted_median > 5.0, "{trusted_median}");
    assert_eq!(refined_mm, 22);
    assert!(refined_median <= 1.5, "{refined_median}");
    assert!(refined_errors.iter().all(|e| e.1 <= 3.0));
}

#[test]
fn a_video_over_the_budget_is_tracked_densely_and_the_budget_chosen_once_tracked() {
    let tmp = tempfile::tempdir().unwrap();
    let case_dir = tmp.path().join("case");
    // Twice the demo's pace (0.85 mm between frames), as a video with more frames than the
    // build uses; the same stretch of airway as the 30 frames of the test above.
    let truth = untracked_phantom_paced(&case_dir, 160, 60, PathOptions::default().jitter_deg);
    let mut opts = tracking_alone();
    opts.selection.max_frames = 10;
    opts.tracking.tracked_per_used = 3;
    let mut scene = BuildScene::prepare(&case_dir, &opts, &mut BuildTimings::default()).unwrap();
    let mut warnings = Vec::new();
    let mut record = select_frames(&mut scene, &opts, &mut warnings)
        .unwrap()
        .unwrap();
    // Before tracking no frame has a pose to cast coverage from: 30 of the 60 are tracked,
    // evenly spaced from the first over those not judged blurred (about the demo's pace).
    println!("tracked {:?}", scene.frame_numbers);
    assert_eq!(scene.frame_count(), 30, "{:?}", record.counts);
    assert_eq!(record.frames.iter().filter(|f| !f.used).count(), 30);
    assert_eq!(scene.frame_numbers[0], 0);
    assert!(scene.frame_numbers[29] >= 55, "{:?}", scene.frame_numbers);
    let steps = scene.frame_numbers.windows(2).map(|w| w[1] - w[0]);
    assert!(steps.clone().all(|s| s <= 5), "{:?}", scene.frame_numbers);
    assert!(scene.frame_numbers[1..]
        .iter()
        .all(|&f| record.frames[f].flagged.is_none()));
    register_poses(&mut scene, &opts, Some(&mut record), &mut warnings)
        .unwrap()
        .unwrap();
    println!(
        "used {:?}, counts {:?}, cells {} of {}; warnings {warnings:?}",
        scene.frame_numbers, record.counts, record.cells_seen_used, record.cells_seen_all
    );
    // Once tracked, the budget's frames are chosen by the wall they see from their tracked
    // poses, the first kept. Measured: frames 0, 3, 17, 23, 27, 34, 49, 51, 53, 59; the 30
    // tracked frames see 5,089 wall cells, the chosen 4,453 of them (87%).
    assert_eq!(scene.frame_count(), 10, "{:?}", scene.frame_numbers);
    assert_eq!(scene.frame_numbers[0], 0);
    assert!(scene.frame_numbers[9] >= 28, "{:?}", scene.frame_numbers);
    assert_eq!(record.used, 10);
    assert!(record.frames[0].used);
    assert!(record.cells_seen_all >= 4000, "{}", record.cells_seen_all);
    assert!(
        record.cells_seen_used as f64 >= 0.75 * record.cells_seen_all as f64,
        "{} of {} cells",
        record.cells_seen_used,
        record.cells_seen_all
    );
    // Measured (tracking alone, no rounds): every chosen frame within 0.45 mm.
    let chosen_truth: Vec<Affine> = scene.frame_numbers.iter().map(|&i| truth[i]).collect();
    let (errors, within_mm, _) = tracked_errors(&scene.poses, &chosen_truth);
    println!("errors of the chosen frames (mm, deg): {errors:?}");
    assert_eq!(within_mm, 10, "{errors:?}");
}

#[test]
fn register_report_shows_frames_on_the_model_before_and_after() {
    let tmp = tempfile::tempdir().unwrap();
    let case_dir = tmp.path().join("case");
    phantom(&case_dir, PoseNoise::new(1.5, 2.0));
    let opts = BuildOptions {
        registration_rounds: 1,
        cross_validate_every: 0,
        quiet: true,
        ..Default::default()
    };
    let out = tmp.path().join("reg");
    let s = register_command(&case_dir, &out, &opts).unwrap();
    let overlays = &s.registration.overlays;
    for o in overlays {
        println!(
            "frame {} ({}): {:.2} mm; misfit given {:.4} registered {:.4}",
            o.frame, o.why, o.correction_mm, o.mismatch_given, o.mismatch_registered
        );
    }
    assert_eq!(overlays.len(), 4);
    // Measured: misfit 0.29 -> 0.21 (frame 10), 0.30 -> 0.30, 0.32 -> 0.29, 0.28 -> 0.22.
    for o in overlays {
        assert_ne!(o.given_png, o.registered_png, "frame {}", o.frame);
        assert!(
            o.mismatch_registered < o.mismatch_given,
            "frame {}: {} vs {}",
            o.frame,
            o.mismatch_registered,
            o.mismatch_given
        );
    }
    let html = std::fs::read_to_string(out.join("report.html")).unwrap();
    assert!(html.contains("Before and after"));
    assert_eq!(html.matches("data:image/png;base64,").count(), 12);
}

/// A round that converges on too few frames is discarded: the frames keep the poses it started
/// from, every frame stays in the model, and a warning says which round and why. (On a real
/// airway 3 mm / 4 deg off, ATM_224, such a round moved every frame 4 mm the wrong way.) A
/// first round is run again against the Lambertian lamp before it is given up.
#[test]
fn a_round_that_converges_on_too_few_frames_leaves_the_given_poses() {
    let tmp = tempfile::tempdir().unwrap();
    let case_dir = tmp.path().join("case");
    let case = phantom(&case_dir, PoseNoise::new(1.5, 2.0));
    let given = poses_of(&case.poses);
    let opts = BuildOptions {
        registration_rounds: 2,
        cross_validate_every: 0,
        // More than every frame: the first round fails whatever it finds.
        registration_min_converged_share: 1.01,
        // The restart from the frames' agreement has its own test (tests/scope_light.rs).
        registration_consensus_passes: 0,
        quiet: true,
        ..Default::default()
    };
    let out = tmp.path().join("reg");
    let s = register_command(&case_dir, &out, &opts).unwrap();
    let warning = s.warnings.iter().find(|w| w.contains("discarded"));
    assert!(
        warning.is_some_and(|w| w.contains("round 1 (geometry)") && w.contains("converged on")),
        "{:?}",
        s.warnings
    );
    // The round against the fitted light, and its run again against the Lambertian lamp.
    assert!(
        s.warnings.iter().any(|w| w.contains("Lambertian lamp")),
        "{:?}",
        s.warnings
    );
    assert_eq!(s.registration.rounds.len(), 2);
    assert!(s.registration.rounds.iter().all(|r| r.discarded));
    assert_eq!(s.registration.left_out, 0);
    let written = poses_of(&read_poses(&out.join("poses.json"), &case_dir).unwrap());
    for (w, g) in written.iter().zip(&given) {
        let (mm, deg) = pose_error(w, g);
        assert!(mm < 1e-6 && deg < 1e-6, "{mm} mm {deg} deg");
    }
    assert!(s
        .registration
        .frames
        .iter()
        .all(|f| f.status == "given" && f.used));
    let html = std::fs::read_to_string(out.join("report.html")).unwrap();
    assert!(html.contains("the given poses were kept"));
}
