//! Every frame's pose refined at once with the albedo eliminated
//! (`registration::joint`, the build's stage after its rounds) on a small phantom (24 frames,
//! 160x160): an error that changes smoothly along the video shrinks, with no texture, the
//! cost falling at every render; true poses stay where they are; a frame marked skipped is
//! not moved, and an anchor is held. What the stage gains on the demo's denser 320-pixel
//! video after the rounds is measured in BENCHMARKS.md (session 38).

use bronchosim::io::case::Case;
use bronchosim::math::Affine;
use bronchosim::model::Model;
use bronchosim::phantom::{write_phantom_case, PhantomOptions};
use bronchosim::registration::joint::{refine_jointly, JointOptions, JointRole};
use bronchosim::registration::pose::perturb;
use bronchosim::registration::{FrameRegistrar, RegistrationOptions};
use std::path::Path;

#[path = "common/registration_model.rs"]
mod registration_model;
use registration_model::{build, case_with_poses, errors};

/// A model of the case at `case` with `poses` (fixed), as the registration tests build it.
fn build_with(case: &Path, poses: &[Affine], dir: &Path) -> Model {
    let entries = Case::open(case).unwrap().poses;
    case_with_poses(case, &dir.join("case"), &entries, poses);
    build(&dir.join("case"), &dir.join("model"))
}

#[test]
fn a_smooth_error_shrinks_and_true_poses_stay() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    let case_dir = dir.join("phantom");
    write_phantom_case(
        &case_dir,
        &PhantomOptions {
            frames: 24,
            width: 160,
            height: 160,
            ..Default::default()
        },
    )
    .unwrap();
    let case = Case::open(&case_dir).unwrap();
    let truth: Vec<Affine> = case.poses.iter().map(|p| p.pose.camera_to_world).collect();
    let frames: Vec<_> = case.frame_source().unwrap().map(|f| f.unwrap()).collect();
    let n = frames.len();
    // An error that turns and shifts the camera smoothly along the video (zero on average:
    // what the whole video shares no video can see), in each camera's own axes.
    let drifted: Vec<Affine> = truth
        .iter()
        .enumerate()
        .map(|(f, p)| {
            let t = f as f64 / (n - 1) as f64 - 0.5;
            let a = 1.2f64.to_radians() * t;
            perturb(p, &[0.4 * t, -0.3 * t, 0.0, a, -0.8 * a, 0.0])
        })
        .collect();
    let (mm0, deg0, _) = errors(&drifted, &truth);
    assert!(mm0 > 0.1 && deg0 > 0.35, "{mm0} mm {deg0} deg");

    // The model's geometry and light (the texture is not used).
    let model = build_with(&case_dir, &drifted, &dir.join("drifted"));
    let parts = model.registration_parts().unwrap();
    let gains = parts.light.gains.clone();

    // All frames at once, the albedo eliminated: the same model's geometry and light only.
    let reg = FrameRegistrar::new(
        bronchosim::registration::ModelParts {
            texture: None,
            ..parts
        },
        RegistrationOptions {
            coarsest_level: 0,
            ..Default::default()
        },
    )
    .unwrap();
    let refined = refine_jointly(
        &reg,
        &frames,
        &gains,
        None,
        &drifted,
        &vec![JointRole::Refined; n],
        &JointOptions {
            level: 0,
            ..Default::default()
        },
    )
    .unwrap();
    let (mm, deg, _) = errors(&refined.poses, &truth);
    println!(
        "drift {mm0:.3} mm {deg0:.3} deg; all at once {mm:.3} mm {deg:.3} deg; costs {:?}",
        refined.costs
    );
    assert!(deg < 0.75 * deg0 && mm < 0.95 * mm0, "{mm} mm {deg} deg");
    for (before, after) in &refined.costs {
        assert!(after < before, "{:?}", refined.costs);
    }

    // True poses in: they stay, a skipped frame is not moved and an anchor is held.
    let mut roles = vec![JointRole::Refined; n];
    roles[0] = JointRole::Anchor;
    roles[5] = JointRole::Skipped;
    let mut start = truth.clone();
    start[5] = drifted[0];
    let kept = refine_jointly(
        &reg,
        &frames,
        &gains,
        None,
        &start,
        &roles,
        &JointOptions {
            level: 0,
            ..Default::default()
        },
    )
    .unwrap();
    assert_eq!(kept.poses[0], truth[0]);
    assert_eq!(kept.poses[5], drifted[0]);
    let others: Vec<usize> = (1..n).filter(|&f| f != 5).collect();
    let pick = |p: &[Affine]| others.iter().map(|&f| p[f]).collect::<Vec<_>>();
    let (mm, deg, _) = errors(&pick(&kept.poses), &pick(&truth));
    println!("true poses moved {mm:.4} mm {deg:.4} deg");
    // The bound for true poses is 0.1 mm; the rotation moves about as the rounds' do.
    assert!(mm < 0.1 && deg < 0.3, "{mm} mm {deg} deg");
}
