//! Experiment: every pose refined at once with the albedo eliminated
//! ([`bronchosim::registration::joint`]), from another run's poses, scored on the phantom's
//! truth.
//!
//! ```sh
//! cargo run --release --example joint_refine -- CASE WORK start=DIR [levels=1,0] [renders=3]
//!     [steps=4] [cell=0.25] [trust=1] [minframes=2] [gain=yes|no] [hold=yes|no]
//!     [final=yes|no]
//! ```
//! `start=DIR` reads `DIR/poses.json` (e.g. a model built with registration). WORK receives
//! `start/case` and `start/model` (built with those poses, every frame, no hold-out), and
//! `final/case` and `final/model` (built with the refined poses and scored on the truth views).

#[path = "common/case_copy.rs"]
mod case_copy;

use bronchosim::io::case::Case;
use bronchosim::io::poses::read_poses;
use bronchosim::math::Affine;
use bronchosim::model::Model;
use bronchosim::registration::joint::{refine_jointly, JointOptions, JointRole};
use bronchosim::registration::{pose_error, FrameRegistrar, RegistrationOptions};
use bronchosim::shading::ShadingKind;
use bronchosim::workflow::build::{build_model, BuildOptions, PosesMode};
use case_copy::case_copy;
use std::path::PathBuf;
use std::time::Instant;

fn score(est: &[Affine], truth: &[Affine]) -> String {
    let e: Vec<(f64, f64)> = est
        .iter()
        .zip(truth)
        .map(|(a, b)| pose_error(a, b))
        .collect();
    let mut mm: Vec<f64> = e.iter().map(|x| x.0).collect();
    let mut deg: Vec<f64> = e.iter().map(|x| x.1).collect();
    mm.sort_by(f64::total_cmp);
    deg.sort_by(f64::total_cmp);
    let within = e.iter().filter(|x| x.0 <= 1.0 && x.1 <= 1.0).count();
    format!(
        "median {:.3} mm {:.3} deg, within 1 mm & 1 deg {within}/{}",
        mm[mm.len() / 2],
        deg[deg.len() / 2],
        e.len()
    )
}

fn main() -> anyhow::Result<()> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let case_dir = PathBuf::from(&args[0]);
    let work = PathBuf::from(&args[1]);
    let mut start: Option<PathBuf> = None;
    let mut levels = vec![1usize, 0];
    let mut opts = JointOptions {
        verbose: true,
        ..Default::default()
    };
    let mut final_model = true;
    for kv in &args[2..] {
        match kv.split_once('=') {
            Some(("start", v)) => start = Some(PathBuf::from(v)),
            Some(("levels", v)) => {
                levels = v.split(',').map(|x| x.parse()).collect::<Result<_, _>>()?
            }
            Some(("renders", v)) => opts.renders = v.parse()?,
            Some(("steps", v)) => opts.steps = v.parse()?,
            Some(("cell", v)) => opts.cell_mm = v.parse()?,
            Some(("trust", v)) => opts.trust_px = v.parse()?,
            Some(("minframes", v)) => opts.min_frames = v.parse()?,
            Some(("final", v)) => final_model = v == "yes",
            Some(("gain", v)) => opts.estimate_gain = v == "yes",
            Some(("hold", v)) => opts.hold_mean_view_shift = v == "yes",
            _ => anyhow::bail!("unknown argument {kv}"),
        }
    }
    let case = Case::open(&case_dir)?;
    let truth: Vec<Affine> = read_poses(&case_dir.join("truth/poses.json"), &case_dir)?
        .iter()
        .map(|p| p.pose.camera_to_world)
        .collect();
    let frames: Vec<_> = case.frame_source()?.collect::<Result<_, _>>()?;
    let mut entries = case.poses.clone();
    let start = start.ok_or_else(|| anyhow::anyhow!("start=DIR is needed"))?;
    for (e, p) in entries
        .iter_mut()
        .zip(read_poses(&start.join("poses.json"), &start)?)
    {
        e.pose.camera_to_world = p.pose.camera_to_world;
    }
    let poses: Vec<Affine> = entries.iter().map(|p| p.pose.camera_to_world).collect();
    println!("start: {}", score(&poses, &truth));
    let mut build_opts = BuildOptions {
        cross_validate_every: 0,
        shading: Some(ShadingKind::Calibrated),
        poses: PosesMode::Fixed,
        quiet: true,
        force: true,
        ..Default::default()
    };
    build_opts.selection.max_frames = 0;
    for d in ["start/case", "final/case"] {
        if work.join(d).exists() {
            std::fs::remove_dir_all(work.join(d))?;
        }
    }
    case_copy(&case_dir, &work.join("start/case"), &entries)?;
    build_model(
        &work.join("start/case"),
        &work.join("start/model"),
        &build_opts,
    )?;
    let model = Model::load(&work.join("start/model"))?;
    let light = model.calibrated().expect("calibrated light");
    let reg = FrameRegistrar::new(
        model.registration_parts().expect("calibrated light"),
        RegistrationOptions::default(),
    )?;
    let mut current = poses;
    for &level in &levels {
        let t = Instant::now();
        let r = refine_jointly(
            &reg,
            &frames,
            &light.gains,
            None,
            &current,
            &vec![JointRole::Refined; frames.len()],
            &JointOptions {
                level,
                ..opts.clone()
            },
        )?;
        current = r.poses;
        println!(
            "level {level} ({:.1} s): {}",
            t.elapsed().as_secs_f64(),
            score(&current, &truth)
        );
    }
    if !final_model {
        return Ok(());
    }
    for (e, p) in entries.iter_mut().zip(&current) {
        e.pose.camera_to_world = *p;
    }
    case_copy(&case_dir, &work.join("final/case"), &entries)?;
    let final_opts = BuildOptions {
        truth: Some(case_dir.join("truth")),
        poses: PosesMode::Fixed,
        quiet: true,
        force: true,
        ..Default::default()
    };
    build_model(
        &work.join("final/case"),
        &work.join("final/model"),
        &final_opts,
    )?;
    let eval: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(
        work.join("final/model/evaluation.json"),
    )?)?;
    println!(
        "final model: new views {:.2} dB",
        eval[0]["mean_psnr_db"].as_f64().unwrap_or(f64::NAN)
    );
    Ok(())
}
