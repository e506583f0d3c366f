//! The alternation of issue 16 item 1 at the process level: build the model (light + texture)
//! with the current poses, register every frame against it, write the refined poses into a copy
//! of the case, repeat; score every round against the phantom's truth.
//!
//! ```sh
//! cargo run --release --example register_rounds -- CASE WORK [rounds=3] [first=chroma|texture]
//!     [start=DIR] [final=yes|no] [floor=F] [sigma=S] [huber=H] [gain=yes|no] [sat=S] [coarsest=L] [finest=L]
//!     [chw=R,G,B] [kinds=GTTGTT] [blocks=4] [hp=6] [fexp=E]
//! ```
//! `start=CASE/truth` starts from the true poses (what a round does to them: its bias);
//! `kinds` gives each round's kind (G: geometry, T: texture, B: texture block by block, each of
//! `blocks` runs of frames against a model fused from the other runs alone; I: the same with
//! every `blocks`-th frame a block, so a frame's neighbours stay in its texture but the frame
//! does not; H: a geometry round whose frames are also divided by the texture's detail the colour
//! does not predict, seen from the frame's current pose, detail finer than a Gaussian of `hp`
//! pixels; `hp=0`: all of it but its frame-wide mean, as the build's shading rounds) in place
//! of `rounds` and `first`;
//! `floor`, `sigma`, `huber`, `gain`, `sat`, `coarsest`, `finest`, `chw` set the per-frame registration's options;
//! `fexp` fuses every round's model with the predicted intensity to the power E as the weight
//! (2, the build's, puts near views first; -1 far views first).
//! Each round writes `round_N/errors.csv`: per frame, the error of its own (`measured`) and of
//! the smoothed pose against the truth, in the true camera's axes (mm, degrees); and
//! `round_N/measurements.json`: per frame the start pose, its own refined pose, status, cost and
//! Gauss–Newton information (read by bench/registration_smoothing.py).
//! CASE is a phantom case with `truth/poses.json` (e.g. `bronchosim phantom --pose-noise-mm 1.5
//! --pose-noise-deg 2`). WORK receives `round_N/case` (frames hard-linked) and `round_N/model`,
//! and a final model built with the last poses and scored on the truth views
//! (`final/model/evaluation.json`). The first round registers against the geometry's shading
//! alone, each frame divided by the albedo its colour predicts (`first=chroma`, the texture fused
//! from the given poses follows their errors), or against the texture (`first=texture`).

#[path = "common/phantom_run.rs"]
mod phantom_run;

use bronchosim::image::Frame;
use bronchosim::io::poses::PoseEntry;
use bronchosim::math::Affine;
use bronchosim::model::Model;
use bronchosim::registration::chroma::ChromaAlbedo;
use bronchosim::registration::photometric::PhotometricModel;
use bronchosim::registration::photometric::RayGrid;
use bronchosim::registration::{
    pose_error_axes, refine_video, FrameRegistrar, RegistrationOptions, VideoOptions,
};
use bronchosim::volume::filter::gaussian_blur;
use bronchosim::volume::Volume;
use bronchosim::workflow::build::{build_model, BuildOptions};
use phantom_run::{
    case_copy, open_phantom, registration_model_options, score, scored_model, PhantomRun,
};
use rayon::prelude::*;
use std::path::{Path, PathBuf};
use std::time::Instant;

/// Per-frame errors (true camera axes, mm and degrees) of the frames' own and the smoothed
/// poses, as CSV.
fn write_errors(
    path: &Path,
    measured: &[Affine],
    smoothed: &[Affine],
    truth: &[Affine],
) -> anyhow::Result<()> {
    let mut csv = String::from("frame,kind,x,y,z,rx,ry,rz\n");
    for (kind, set) in [("measured", measured), ("smoothed", smoothed)] {
        for (i, (a, b)) in set.iter().zip(truth).enumerate() {
            let (t, r) = pose_error_axes(a, b);
            csv += &format!(
                "{i},{kind},{},{},{},{},{},{}\n",
                t[0], t[1], t[2], r[0], r[1], r[2]
            );
        }
    }
    std::fs::write(path, csv)?;
    Ok(())
}

/// Per frame: the pose the round started from, the frame's own refined pose, its status, cost
/// and Gauss–Newton information (camera-frame step), as JSON, for studying the smoothing.
fn write_measurements(
    path: &Path,
    start: &[Affine],
    v: &bronchosim::registration::VideoRegistration,
) -> anyhow::Result<()> {
    let rows: Vec<serde_json::Value> = v
        .frames
        .iter()
        .zip(&v.measured)
        .zip(start)
        .map(|((f, m), s)| {
            serde_json::json!({
                "start": s.iter().copied().collect::<Vec<f64>>(),
                "measured": m.iter().copied().collect::<Vec<f64>>(),
                "status": f.status.name(),
                "cost_after": f.cost_after,
                "information": f.information,
            })
        })
        .collect();
    std::fs::write(path, serde_json::to_string(&rows)?)?;
    Ok(())
}

/// A texture round block by block: the video's frames in `blocks` runs (`interleaved`: every
/// `blocks`-th frame), each registered against a model fused from the other blocks' frames
/// alone (its own errors are not in that texture). Gains are the full model's.
#[allow(clippy::too_many_arguments)]
fn refine_by_blocks(
    case_dir: &Path,
    dir: &Path,
    entries: &[PoseEntry],
    frames: &[bronchosim::image::Frame],
    gains: &[f64],
    current: &[Affine],
    blocks: usize,
    interleaved: bool,
    build_opts: &BuildOptions,
    opts: &RegistrationOptions,
) -> anyhow::Result<bronchosim::registration::VideoRegistration> {
    let n = frames.len();
    let mut slots: Vec<Option<(bronchosim::registration::FrameRegistration, Affine)>> =
        vec![None; n];
    let mut all: Option<bronchosim::registration::VideoRegistration> = None;
    for k in 0..blocks {
        let member = |i: usize| {
            if interleaved {
                i % blocks == k
            } else {
                i >= k * n / blocks && i < (k + 1) * n / blocks
            }
        };
        let mine: Vec<usize> = (0..n).filter(|&i| member(i)).collect();
        let others: Vec<PoseEntry> = entries
            .iter()
            .enumerate()
            .filter(|(i, _)| !member(*i))
            .map(|(_, e)| e.clone())
            .collect();
        let bdir = dir.join(format!("block_{k}"));
        if bdir.exists() {
            std::fs::remove_dir_all(&bdir)?;
        }
        case_copy(case_dir, &bdir.join("case"), &others)?;
        for e in mine.iter().map(|&i| &entries[i]) {
            if let bronchosim::io::poses::FrameRef::Image(i) = &e.frame {
                std::fs::remove_file(bdir.join("case/frames").join(i.file_name().unwrap()))?;
            }
        }
        build_model(&bdir.join("case"), &bdir.join("model"), build_opts)?;
        let model = Model::load(&bdir.join("model"))?;
        let reg = FrameRegistrar::new(
            model.registration_parts().expect("calibrated light"),
            RegistrationOptions {
                uniform_albedo_from_level: usize::MAX,
                ..opts.clone()
            },
        )?;
        let sub_gains: Vec<f64> = mine.iter().map(|&i| gains[i]).collect();
        let sub_poses: Vec<Affine> = mine.iter().map(|&i| current[i]).collect();
        let sub_frames: Vec<bronchosim::image::Frame> =
            mine.iter().map(|&i| frames[i].clone()).collect();
        let v = refine_video(
            &reg,
            &sub_frames,
            &sub_gains,
            None,
            &sub_poses,
            &VideoOptions {
                frame_numbers: mine.clone(),
                ..VideoOptions::default()
            },
        )?;
        for (j, &i) in mine.iter().enumerate() {
            slots[i] = Some((v.frames[j].clone(), v.measured[j]));
        }
        match &mut all {
            None => all = Some(v),
            Some(a) => {
                a.restarted += v.restarted;
                for (key, c) in v.counts {
                    *a.counts.entry(key).or_default() += c;
                }
            }
        }
    }
    let mut all = all.ok_or_else(|| anyhow::anyhow!("no blocks"))?;
    let slots: Vec<_> = slots
        .into_iter()
        .map(|s| s.expect("every frame in a block"))
        .collect();
    all.frames = slots.iter().map(|s| s.0.clone()).collect();
    all.measured = slots.iter().map(|s| s.1).collect();
    Ok(all)
}

/// `frame` divided, per pixel and channel, by the detail of the texture seen from `pose` that
/// the colour does not predict: texture / colour-predicted albedo, over its own Gaussian
/// average (`sigma` pixels). The smooth part of that ratio is where the texture absorbed the
/// shading's error; the detail is the albedo (vessels, patches) the colour misses.
fn detail_divided(
    frame: &Frame,
    model: &PhotometricModel,
    grid: &RayGrid,
    pose: &Affine,
    rel: &ChromaAlbedo,
    sigma: f64,
) -> Frame {
    let (w, h) = (frame.width as usize, frame.height as usize);
    let mut q = vec![[0.0f64; 3]; w * h];
    let mut valid = vec![0.0f64; w * h];
    for (i, ratio) in rel.texture_log_ratio(model, grid, pose) {
        q[i] = ratio;
        valid[i] = 1.0;
    }
    // Normalised convolution of the log ratio over the valid pixels: the planes q·m (R, G, B)
    // and m stacked as a volume, blurred across x and y only.
    let mut planes = Volume::filled([w, h, 4], Affine::identity(), 0.0f32);
    for (i, (qi, &m)) in q.iter().zip(&valid).enumerate() {
        for (c, v) in qi.iter().enumerate() {
            planes.data[c * w * h + i] = (v * m) as f32;
        }
        planes.data[3 * w * h + i] = m as f32;
    }
    gaussian_blur(&mut planes, [sigma, sigma, 0.0]);
    let smooth = |c: usize, i: usize| f64::from(planes.data[c * w * h + i]);
    let mut out = frame.clone();
    for (i, (qi, &m)) in q.iter().zip(&valid).enumerate() {
        if m == 0.0 || smooth(3, i) < 1e-3 {
            continue;
        }
        for (c, v) in qi.iter().enumerate() {
            let detail = v - smooth(c, i) / smooth(3, i);
            out.rgb[3 * i + c] = (f64::from(frame.rgb[3 * i + c]) / detail.exp()) as f32;
        }
    }
    out
}

fn main() -> anyhow::Result<()> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let case_dir = PathBuf::from(&args[0]);
    let work = PathBuf::from(&args[1]);
    let (mut rounds, mut first_chroma) = (3usize, true);
    let (mut relax, mut start): (f64, Option<PathBuf>) = (1.0, None);
    let mut frame_opts = RegistrationOptions {
        // Red carries the shading with the least albedo (measured: z error 0.38 -> 0.25 mm).
        uniform_channel_weights: [1.0, 0.0, 0.0],
        ..Default::default()
    };
    let mut final_model = true;
    // Kind of each round (G, H, T, B or I, see above); overrides rounds/first.
    let mut kinds: Option<Vec<char>> = None;
    let mut blocks = 4usize;
    // Gaussian sigma (px) of the smooth part an H round keeps of the texture's detail.
    let mut hp_sigma = 6.0f64;
    // Power of the predicted intensity in the round models' fusion weights (None: the build's).
    let mut fusion_exponent: Option<f32> = None;
    for kv in &args[2..] {
        match kv.split_once('=') {
            Some(("rounds", v)) => rounds = v.parse()?,
            Some(("first", v)) => first_chroma = v == "chroma",
            Some(("relax", v)) => relax = v.parse()?,
            Some(("start", v)) => start = Some(PathBuf::from(v)),
            Some(("floor", v)) => frame_opts.noise_floor = v.parse()?,
            Some(("sigma", v)) => frame_opts.relative_sigma = v.parse()?,
            Some(("huber", v)) => frame_opts.huber = v.parse()?,
            Some(("final", v)) => final_model = v == "yes",
            Some(("kinds", v)) => {
                if let Some(c) = v.chars().find(|c| !"GHTBI".contains(*c)) {
                    anyhow::bail!("kinds={v}: unknown round kind {c} (G, H, T, B or I)");
                }
                kinds = Some(v.chars().collect());
            }
            Some(("blocks", v)) => blocks = v.parse()?,
            Some(("hp", v)) => hp_sigma = v.parse()?,
            Some(("fexp", v)) => fusion_exponent = Some(v.parse()?),
            Some(("gain", v)) => frame_opts.estimate_gain = v == "yes",
            Some(("sat", v)) => frame_opts.saturation_level = v.parse()?,
            Some(("coarsest", v)) => frame_opts.coarsest_level = v.parse()?,
            Some(("finest", v)) => frame_opts.finest_level = v.parse()?,
            Some(("chw", v)) => {
                let w: Vec<f32> = v.split(',').map(|x| x.parse()).collect::<Result<_, _>>()?;
                frame_opts.uniform_channel_weights = [w[0], w[1], w[2]];
            }
            _ => anyhow::bail!("unknown argument {kv}"),
        }
    }
    let PhantomRun {
        truth,
        frames,
        mut entries,
    } = open_phantom(&case_dir, start.as_deref())?;
    let poses_of = |e: &[PoseEntry]| e.iter().map(|p| p.pose.camera_to_world).collect::<Vec<_>>();
    println!("round 0 (given): {}", score(&poses_of(&entries), &truth));
    let mut build_opts = registration_model_options();
    if let Some(e) = fusion_exponent {
        build_opts.fusion.method =
            bronchosim::texture::fusion::FusionMethod::WeightedAverage { weight_exponent: e };
    }
    if let Some(k) = &kinds {
        rounds = k.len();
    }
    for r in 1..=rounds {
        let dir = work.join(format!("round_{r}"));
        let rcase = dir.join("case");
        if rcase.exists() {
            std::fs::remove_dir_all(&rcase)?;
        }
        case_copy(&case_dir, &rcase, &entries)?;
        let t = Instant::now();
        build_model(&rcase, &dir.join("model"), &build_opts)?;
        let t_build = t.elapsed().as_secs_f64();
        let model = Model::load(&dir.join("model"))?;
        let light = model.calibrated().expect("calibrated light");
        let kind = match &kinds {
            Some(k) => k[r - 1],
            None if r == 1 && first_chroma => 'G',
            None => 'T',
        };
        let chroma = matches!(kind, 'G' | 'H');
        let opts = RegistrationOptions {
            uniform_albedo_from_level: if chroma { 0 } else { usize::MAX },
            ..frame_opts.clone()
        };
        let reg = FrameRegistrar::new(
            model.registration_parts().expect("calibrated light"),
            opts.clone(),
        )?;
        let t = Instant::now();
        let current = poses_of(&entries);
        let normalised: Vec<_>;
        let frames_used = if chroma {
            let grid = RayGrid::new(&model.manifest.camera, 2, 1);
            let every: Vec<Affine> = current.iter().step_by(4).copied().collect();
            let rel = ChromaAlbedo::fit(&reg.model, &grid, &every)?;
            normalised = if kind == 'H' {
                let full = RayGrid::new(&model.manifest.camera, 0, 1);
                frames
                    .par_iter()
                    .zip(&current)
                    .map(|(f, pose)| {
                        let level = frame_opts.saturation_level;
                        let n = rel.normalise(f, level);
                        match hp_sigma > 0.0 {
                            true => detail_divided(&n, &reg.model, &full, pose, &rel, hp_sigma),
                            // The build's shading round (registration::RoundKind::Shading).
                            false => rel.divide_texture_albedo(&n, &reg.model, &full, pose, level),
                        }
                    })
                    .collect()
            } else {
                frames
                    .iter()
                    .map(|f| rel.normalise(f, frame_opts.saturation_level))
                    .collect()
            };
            &normalised
        } else {
            &frames
        };
        let v = if matches!(kind, 'B' | 'I') {
            refine_by_blocks(
                &case_dir,
                &dir,
                &entries,
                &frames,
                &light.gains,
                &current,
                blocks,
                kind == 'I',
                &build_opts,
                &opts,
            )?
        } else {
            refine_video(
                &reg,
                frames_used,
                &light.gains,
                None,
                &current,
                &VideoOptions::default(),
            )?
        };
        let t_reg = t.elapsed().as_secs_f64();
        let smoothed: Vec<Affine> = v.frames.iter().map(|f| f.pose).collect();
        write_errors(&dir.join("errors.csv"), &v.measured, &smoothed, &truth)?;
        write_measurements(&dir.join("measurements.json"), &current, &v)?;
        // Over-relaxation of the smooth part of the corrections (experiment): the texture
        // follows the poses, so a round removes only a fraction of a smooth drift.
        let deltas: Vec<_> = v
            .frames
            .iter()
            .zip(&current)
            .map(|(f, c)| bronchosim::registration::delta_between(c, &f.pose))
            .collect();
        for (k, (e, f)) in entries.iter_mut().zip(&v.frames).enumerate() {
            e.pose.camera_to_world = f.pose;
            if !chroma && relax != 1.0 {
                let (mut t, mut w, mut ws) = (
                    bronchosim::math::Vector3::zeros(),
                    bronchosim::math::Vector3::zeros(),
                    0.0,
                );
                for (g, d) in deltas.iter().enumerate() {
                    let wt = (-0.5 * ((g as f64 - k as f64) / 8.0).powi(2)).exp();
                    t += d.translation_mm * wt;
                    w += d.rotation * wt;
                    ws += wt;
                }
                let extra = bronchosim::registration::PoseDelta {
                    translation_mm: t * ((relax - 1.0) / ws),
                    rotation: w * ((relax - 1.0) / ws),
                };
                e.pose.camera_to_world = bronchosim::registration::apply_delta(&f.pose, &extra);
            }
        }
        println!(
            "round {r} ({}; build {t_build:.1} s, registration {t_reg:.1} s, {} restarted, {:?}): {}",
            match kind {
                'H' => "geometry, colour albedo and texture detail",
                'G' => "geometry, colour albedo",
                'B' => "texture, block by block",
                'I' => "texture, interleaved blocks",
                _ => "texture",
            },
            v.restarted,
            v.counts,
            score(&poses_of(&entries), &truth)
        );
    }
    if !final_model {
        return Ok(());
    }
    println!(
        "final model: new views {:.2} dB (calibrated light)",
        scored_model(&case_dir, &work.join("final"), &entries)?
    );
    Ok(())
}
