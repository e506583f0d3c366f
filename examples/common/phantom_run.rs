//! A phantom case opened with its truth and, optionally, another run's poses; and copies of
//! it with other poses: for the examples that build models from another run's poses.

use bronchosim::image::Frame;
use bronchosim::io::case::Case;
use bronchosim::io::poses::{read_poses, write_poses, FrameRef, PoseEntry};
use bronchosim::math::Affine;
use bronchosim::registration::{pose_error, pose_error_axes};
use bronchosim::shading::ShadingKind;
use bronchosim::workflow::build::{BuildOptions, PosesMode};
use std::path::Path;

/// The build of a model frames are registered against: the poses as given, calibrated light,
/// no hold-out, and every frame (each frame registered needs its gain: no frame selection,
/// however long the video).
pub fn registration_model_options() -> BuildOptions {
    let mut opts = BuildOptions {
        cross_validate_every: 0,
        shading: Some(ShadingKind::Calibrated),
        poses: PosesMode::Fixed,
        quiet: true,
        force: true,
        ..Default::default()
    };
    opts.selection.max_frames = 0;
    opts
}

/// A phantom case's true poses, frames, and its pose entries with the poses of
/// `start/poses.json` when given (e.g. a model built with registration, or a round's case).
pub struct PhantomRun {
    pub truth: Vec<Affine>,
    pub frames: Vec<Frame>,
    pub entries: Vec<PoseEntry>,
}

/// Open the phantom case at `case_dir` (see [`PhantomRun`]).
pub fn open_phantom(case_dir: &Path, start: Option<&Path>) -> anyhow::Result<PhantomRun> {
    let case = Case::open(case_dir)?;
    let truth: Vec<Affine> = read_poses(&case_dir.join("truth/poses.json"), case_dir)?
        .iter()
        .map(|p| p.pose.camera_to_world)
        .collect();
    let frames: Vec<Frame> = case.frame_source()?.collect::<Result<_, _>>()?;
    let mut entries = case.poses.clone();
    if let Some(s) = start {
        for (e, p) in entries
            .iter_mut()
            .zip(read_poses(&s.join("poses.json"), s)?)
        {
            e.pose.camera_to_world = p.pose.camera_to_world;
        }
    }
    Ok(PhantomRun {
        truth,
        frames,
        entries,
    })
}

/// A copy of the case at `to` with its own poses.json (everything else hard-linked).
pub fn case_copy(from: &Path, to: &Path, poses: &[PoseEntry]) -> anyhow::Result<()> {
    std::fs::create_dir_all(to.join("frames"))?;
    for e in std::fs::read_dir(from)? {
        let p = e?.path();
        let name = p.file_name().unwrap();
        if name == "poses.json" || name == "truth" {
            continue;
        }
        if p.is_dir() {
            for f in std::fs::read_dir(&p)? {
                let f = f?.path();
                std::fs::hard_link(&f, to.join(name).join(f.file_name().unwrap()))?;
            }
        } else {
            std::fs::hard_link(&p, to.join(name))?;
        }
    }
    let entries: Vec<PoseEntry> = poses
        .iter()
        .map(|p| PoseEntry {
            frame: match &p.frame {
                FrameRef::Image(i) => FrameRef::Image(to.join(i.strip_prefix(from).unwrap_or(i))),
                other => other.clone(),
            },
            pose: p.pose,
        })
        .collect();
    write_poses(&to.join("poses.json"), &entries, to)?;
    Ok(())
}

/// A model built at `dir/model` from a copy of the case at `dir/case` with `entries`' poses,
/// scored on the case's truth views: their mean PSNR (dB, model.json `evaluation`).
pub fn scored_model(case_dir: &Path, dir: &Path, entries: &[PoseEntry]) -> anyhow::Result<f64> {
    if dir.join("case").exists() {
        std::fs::remove_dir_all(dir.join("case"))?;
    }
    case_copy(case_dir, &dir.join("case"), entries)?;
    let opts = BuildOptions {
        truth: Some(case_dir.join("truth")),
        poses: PosesMode::Fixed,
        quiet: true,
        force: true,
        ..Default::default()
    };
    bronchosim::workflow::build::build_model(&dir.join("case"), &dir.join("model"), &opts)?;
    let eval: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("model/evaluation.json"))?)?;
    Ok(eval[0]["mean_psnr_db"].as_f64().unwrap_or(f64::NAN))
}

fn quantile(v: &[f64], q: f64) -> f64 {
    let mut s = v.to_vec();
    s.sort_by(|a, b| a.total_cmp(b));
    s[((s.len() - 1) as f64 * q).round() as usize]
}

/// One line of pose-error statistics.
pub fn score(est: &[Affine], truth: &[Affine]) -> String {
    let e: Vec<(f64, f64)> = est
        .iter()
        .zip(truth)
        .map(|(a, b)| pose_error(a, b))
        .collect();
    let mm: Vec<f64> = e.iter().map(|x| x.0).collect();
    let deg: Vec<f64> = e.iter().map(|x| x.1).collect();
    let within = e.iter().filter(|x| x.0 <= 1.0 && x.1 <= 1.0).count();
    let mut ax = [0.0f64; 6];
    for (a, b) in est.iter().zip(truth) {
        let (t, r) = pose_error_axes(a, b);
        for k in 0..3 {
            ax[k] += t[k] * t[k];
            ax[3 + k] += r[k] * r[k];
        }
    }
    let ax = ax.map(|v| (v / est.len() as f64).sqrt());
    format!(
        "median {:.3} mm {:.3} deg | p95 {:.3} mm {:.3} deg | within 1 mm & 1 deg {}/{} | RMS x {:.3} y {:.3} z {:.3} mm, pitch {:.3} yaw {:.3} roll {:.3} deg",
        quantile(&mm, 0.5),
        quantile(&deg, 0.5),
        quantile(&mm, 0.95),
        quantile(&deg, 0.95),
        within,
        est.len(),
        ax[0], ax[1], ax[2], ax[3], ax[4], ax[5]
    )
}
