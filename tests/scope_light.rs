//! Registering a video against the calibrated light of a model built from another video of the
//! same bronchoscope (`--scope-light`, issue 16): the first round's light no longer follows the
//! given poses' errors.

use bronchosim::io::poses::read_poses;
use bronchosim::io::scope_light::read_scope_light;
use bronchosim::math::Affine;
use bronchosim::phantom::pose_noise::PoseNoise;
use bronchosim::phantom::{write_phantom_case, PhantomOptions};
use bronchosim::registration::pose_error;
use bronchosim::workflow::build::{build_model, BuildOptions, PosesMode};
use bronchosim::workflow::register::register_command;
use std::path::Path;

fn phantom(dir: &Path, seed: u64, noise: PoseNoise) {
    let opts = PhantomOptions {
        frames: 24,
        width: 160,
        height: 160,
        seed,
        pose_noise: noise,
        ..Default::default()
    };
    write_phantom_case(dir, &opts).unwrap();
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

fn poses(file: &Path, case: &Path) -> Vec<Affine> {
    read_poses(file, case)
        .unwrap()
        .iter()
        .map(|p| p.pose.camera_to_world)
        .collect()
}

/// Median centre and rotation errors of `file`'s poses against the case's true ones.
fn errors(file: &Path, case: &Path) -> (f64, f64) {
    let truth = poses(&case.join("truth/poses.json"), case);
    let e: Vec<(f64, f64)> = poses(file, case)
        .iter()
        .zip(&truth)
        .map(|(p, t)| pose_error(p, t))
        .collect();
    (
        median(e.iter().map(|x| x.0).collect()),
        median(e.iter().map(|x| x.1).collect()),
    )
}

#[test]
fn a_scope_light_from_another_video_registers_the_first_round() {
    let tmp = tempfile::tempdir().unwrap();
    // The scope's light, calibrated on one video (another seed: another path and mucosa).
    let scope_case = tmp.path().join("scope_case");
    phantom(&scope_case, 3, PoseNoise::new(0.0, 0.0));
    let scope_model = tmp.path().join("scope_model");
    let fixed = BuildOptions {
        poses: PosesMode::Fixed,
        cross_validate_every: 0,
        quiet: true,
        ..Default::default()
    };
    build_model(&scope_case, &scope_model, &fixed).unwrap();
    // A second video with tracker poses 3 mm / 4 deg off.
    let case = tmp.path().join("case");
    phantom(&case, 1, PoseNoise::new(3.0, 4.0));
    let given = errors(&case.join("poses.json"), &case);
    let scope = read_scope_light(&scope_model).unwrap();
    let mut results = Vec::new();
    for (name, scope_light) in [("fitted", None), ("scope", Some(scope))] {
        let opts = BuildOptions {
            registration_rounds: 1,
            cross_validate_every: 0,
            scope_light,
            quiet: true,
            ..Default::default()
        };
        let out = tmp.path().join(name);
        let s = register_command(&case, &out, &opts).unwrap();
        let e = errors(&out.join("refined_poses.json"), &case);
        let first = &s.registration.rounds[0].counts;
        println!(
            "{name}: given {:.3} mm {:.3} deg -> {:.3} mm {:.3} deg; first round {first:?}",
            given.0, given.1, e.0, e.1
        );
        results.push((s, e));
    }
    let converged = |i: usize| {
        let counts = &results[i].0.registration.rounds[0].counts;
        counts.get("converged").copied().unwrap_or(0)
    };
    // Measured from 2.64 mm / 3.41 deg median: against the light fitted at the given poses the
    // round converged on 6 of 24 frames (2.26 mm / 3.31 deg after it), against the scope's on
    // 16 (0.85 mm / 2.34 deg).
    assert!(converged(1) >= 12 && converged(1) > converged(0) + 4);
    let (s, e) = &results[1];
    assert!(e.0 < 1.0 && e.0 < 0.5 * results[0].1 .0, "{e:?}");
    assert!(s
        .registration
        .scope_light
        .as_deref()
        .is_some_and(|p| p.ends_with("shading.json")));
    let html = std::fs::read_to_string(tmp.path().join("scope/report.html")).unwrap();
    assert!(html.contains("the same bronchoscope"));
    assert!(e.1 < given.1);
}
