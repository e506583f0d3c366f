//! Experiment: every pose refined at once with the albedo eliminated
//! ([`bronchosim::registration::joint`]), from another run's poses, scored on the phantom's
//! truth.
//!
//! ```sh
//! cargo run --release --example joint_refine -- CASE WORK start=DIR [levels=1,0] [renders=3]
//!     [steps=4] [cell=0.25] [trust=1] [minframes=2] [gain=yes|no] [hold=yes|no]
//!     [final=yes|no] [search=yes|no] [run=6] [gainmin=0.005] [jitter=yes|no]
//!     [light=MODEL] [costs=yes|no] [mesh=truth|ctn|offset:D] [pattern=RUN,MM,DEG,PASSES]
//! ```
//! `start=DIR` reads `DIR/poses.json` (e.g. a model built with registration). WORK receives
//! `start/case` and `start/model` (built with those poses, every frame, no hold-out), and
//! `final/case` and `final/model` (built with the refined poses and scored on the truth views).
//! `light=MODEL` takes the light and gains of a model built before (every frame kept) instead
//! of building `start/model`, so that several pose sets are compared under one light;
//! `steps=0 renders=1 final=no` then prints the reduced cost at the start poses alone, and
//! `costs=yes` each frame's.
//! `mesh=truth` registers against the phantom's true surface (truth/lumen.ply) instead of the
//! model's mesh, `mesh=ctn` against the model's mesh with the true surface's normals (each
//! vertex takes its nearest true vertex's), `mesh=offset:D` against the model's mesh moved D mm
//! along its normals: how much of where the stage ends is the mesh's. The final model is built
//! with the CT's mesh either way.
//! `pattern=RUN,MM,DEG,PASSES` then searches without derivatives: every run of RUN consecutive
//! frames is moved together by MM along each camera axis and by DEG about each, both ways, and
//! a move is kept when the reduced cost rendered afresh (on the last level) falls; PASSES
//! sweeps over the runs.

#[path = "common/phantom_run.rs"]
mod phantom_run;

use bronchosim::io::mesh_export::read_ply;
use bronchosim::math::Affine;
use bronchosim::model::Model;
use bronchosim::raycast::Scene;
use bronchosim::registration::joint::{refine_jointly, JointOptions, JointRole};
use bronchosim::registration::joint_shift::ShiftSearch;
use bronchosim::registration::{FrameRegistrar, RegistrationOptions};
use bronchosim::workflow::build::build_model;
use phantom_run::{
    case_copy, open_phantom, registration_model_options, score, scored_model, PhantomRun,
};
use std::path::PathBuf;
use std::time::Instant;

/// The surface the frames are registered against (`mesh=`).
enum MeshChoice {
    /// The model's (the CT's) mesh.
    Model,
    /// The phantom's true surface.
    Truth,
    /// The model's mesh with the true surface's normals.
    TrueNormals,
    /// The model's mesh moved this far (mm) along its normals.
    Offset(f32),
}

fn main() -> anyhow::Result<()> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let case_dir = PathBuf::from(&args[0]);
    let work = PathBuf::from(&args[1]);
    let mut start: Option<PathBuf> = None;
    let mut light_from: Option<PathBuf> = None;
    let mut frame_costs = false;
    let mut mesh = MeshChoice::Model;
    let mut levels = vec![1usize, 0];
    let mut opts = JointOptions::default();
    let mut final_model = true;
    let mut search: Option<ShiftSearch> = None;
    let mut reg_opts = RegistrationOptions::default();
    let mut pattern: Option<(usize, f64, f64, usize)> = None;
    for kv in &args[2..] {
        match kv.split_once('=') {
            Some(("start", v)) => start = Some(PathBuf::from(v)),
            Some(("light", v)) => light_from = Some(PathBuf::from(v)),
            Some(("costs", v)) => frame_costs = v == "yes",
            Some(("mesh", v)) => {
                mesh = match v {
                    "model" => MeshChoice::Model,
                    "truth" => MeshChoice::Truth,
                    "ctn" => MeshChoice::TrueNormals,
                    _ => match v.strip_prefix("offset:") {
                        Some(d) => MeshChoice::Offset(d.parse()?),
                        None => anyhow::bail!("mesh={v}: model, truth, ctn or offset:D"),
                    },
                }
            }
            Some(("levels", v)) => {
                levels = v.split(',').map(|x| x.parse()).collect::<Result<_, _>>()?
            }
            Some(("renders", v)) => opts.renders = v.parse()?,
            Some(("steps", v)) => opts.steps = v.parse()?,
            Some(("cell", v)) => opts.cell_mm = v.parse()?,
            Some(("trust", v)) => opts.trust_px = v.parse()?,
            Some(("minframes", v)) => opts.min_frames = v.parse()?,
            Some(("final", v)) => final_model = v == "yes",
            Some(("jitter", v)) => reg_opts.ray_jitter = v == "yes",
            Some(("gain", v)) => opts.estimate_gain = v == "yes",
            Some(("hold", v)) => opts.hold_mean_view_shift = v == "yes",
            Some(("search", v)) => search = (v == "yes").then(ShiftSearch::default),
            Some(("pattern", v)) => {
                let p: Vec<&str> = v.split(',').collect();
                pattern = Some((p[0].parse()?, p[1].parse()?, p[2].parse()?, p[3].parse()?));
            }
            Some(("run", v)) => {
                if let Some(s) = search.as_mut() {
                    s.run_frames = v.parse()?
                }
            }
            Some(("gainmin", v)) => {
                if let Some(s) = search.as_mut() {
                    s.min_gain = v.parse()?
                }
            }
            _ => anyhow::bail!("unknown argument {kv}"),
        }
    }
    let start = start.ok_or_else(|| anyhow::anyhow!("start=DIR is needed"))?;
    let PhantomRun {
        truth,
        frames,
        mut entries,
    } = open_phantom(&case_dir, Some(&start))?;
    let poses: Vec<Affine> = entries.iter().map(|p| p.pose.camera_to_world).collect();
    println!("start: {}", score(&poses, &truth));
    let build_opts = registration_model_options();
    if work.join("start/case").exists() {
        std::fs::remove_dir_all(work.join("start/case"))?;
    }
    let model = match &light_from {
        Some(dir) => Model::load(dir)?,
        None => {
            case_copy(&case_dir, &work.join("start/case"), &entries)?;
            build_model(
                &work.join("start/case"),
                &work.join("start/model"),
                &build_opts,
            )?;
            Model::load(&work.join("start/model"))?
        }
    };
    let light = model.calibrated().expect("calibrated light");
    let (scene, tri_uv) = match mesh {
        MeshChoice::Model => (None, None),
        MeshChoice::Truth => {
            let s = Scene::new(&read_ply(&case_dir.join("truth/lumen.ply"))?)?;
            let uv = vec![[[0.0f32; 2]; 3]; s.triangle_count()];
            (Some(s), Some(uv))
        }
        MeshChoice::TrueNormals => (
            Some(normals_from_truth(
                &model,
                &case_dir.join("truth/lumen.ply"),
            )?),
            None,
        ),
        MeshChoice::Offset(d) => {
            let mut moved = model.mesh.clone();
            let normals = moved.vertex_normals();
            for (p, n) in moved.positions.iter_mut().zip(&normals) {
                *p += n * d;
            }
            (Some(Scene::new(&moved)?), None)
        }
    };
    let mut parts = model.registration_parts().expect("calibrated light");
    if let Some(s) = &scene {
        parts.scene = s;
    }
    if let Some(uv) = &tri_uv {
        // The true surface has no atlas: registered against its shading, the albedo
        // eliminated as always in this stage.
        parts.tri_uv = uv;
        parts.texture = None;
    }
    let reg = FrameRegistrar::new(parts, reg_opts)?;
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
                shift_search: search.take(),
                ..opts.clone()
            },
        )?;
        for s in &r.shifted {
            println!(
                "level {level}: frames {:?} moved {:+.2} mm along their views, cost {:.4} -> {:.4}",
                s.frames, s.shift_mm, s.cost_before, s.cost_after
            );
        }
        for (render, (before, after)) in r.costs.iter().enumerate() {
            println!("level {level} render {render}: mean cost {before:.4} -> {after:.4}");
        }
        if frame_costs {
            for (i, c) in r.frame_costs.iter().enumerate() {
                println!("frame_cost {i} {:.5}", c.unwrap_or(f64::NAN));
            }
        }
        current = r.poses;
        println!(
            "level {level} ({:.1} s): {}",
            t.elapsed().as_secs_f64(),
            score(&current, &truth)
        );
    }
    if let Some((run, t_mm, r_deg, passes)) = pattern {
        let eval = |poses: &[Affine]| -> anyhow::Result<f64> {
            let r = refine_jointly(
                &reg,
                &frames,
                &light.gains,
                None,
                poses,
                &vec![JointRole::Refined; frames.len()],
                &JointOptions {
                    level: *levels.last().unwrap_or(&0),
                    renders: 1,
                    steps: 0,
                    shift_search: None,
                    ..opts.clone()
                },
            )?;
            Ok(r.costs[0].0)
        };
        let t = Instant::now();
        let mut best = eval(&current)?;
        println!(
            "pattern: start cost {best:.5} ({:.1} s an evaluation)",
            t.elapsed().as_secs_f64()
        );
        let n = current.len();
        for pass in 0..passes {
            let mut moves = 0;
            for start in (0..n).step_by(run) {
                for axis in 0..6 {
                    let step = if axis < 3 { t_mm } else { r_deg.to_radians() };
                    for sign in [1.0, -1.0] {
                        let mut cand = current.clone();
                        let mut xi = [0.0; 6];
                        xi[axis] = sign * step;
                        for p in cand.iter_mut().skip(start).take(run) {
                            *p = bronchosim::registration::pose::perturb(p, &xi);
                        }
                        let c = eval(&cand)?;
                        if c < best {
                            best = c;
                            current = cand;
                            moves += 1;
                            break;
                        }
                    }
                }
            }
            println!(
                "pattern pass {pass}: {moves} moves, cost {best:.5}: {}",
                score(&current, &truth)
            );
        }
    }
    if !final_model {
        return Ok(());
    }
    for (e, p) in entries.iter_mut().zip(&current) {
        e.pose.camera_to_world = *p;
    }
    println!(
        "final model: new views {:.2} dB",
        scored_model(&case_dir, &work.join("final"), &entries)?
    );
    Ok(())
}

/// The model's mesh with each vertex normal replaced by the normal of the nearest vertex of
/// the true surface: the CT mesh's positions, the truth's normals.
fn normals_from_truth(model: &Model, true_ply: &std::path::Path) -> anyhow::Result<Scene> {
    let truth = Scene::new(&read_ply(true_ply)?)?;
    let mut scene = Scene::new(&model.mesh)?;
    let cell = 0.3f32;
    let key = |p: &[f32; 3]| {
        (
            (p[0] / cell).floor() as i32,
            (p[1] / cell).floor() as i32,
            (p[2] / cell).floor() as i32,
        )
    };
    let mut grid: std::collections::HashMap<(i32, i32, i32), Vec<u32>> = Default::default();
    for (i, p) in truth.positions.iter().enumerate() {
        grid.entry(key(p)).or_default().push(i as u32);
    }
    let mut far = 0;
    for (v, p) in scene.positions.iter().enumerate() {
        let (kx, ky, kz) = key(p);
        let mut best = (f32::MAX, u32::MAX);
        for r in [1, 3] {
            for dx in -r..=r {
                for dy in -r..=r {
                    for dz in -r..=r {
                        if let Some(list) = grid.get(&(kx + dx, ky + dy, kz + dz)) {
                            for &i in list {
                                let q = truth.positions[i as usize];
                                let d = (0..3).map(|a| (q[a] - p[a]).powi(2)).sum::<f32>();
                                if d < best.0 {
                                    best = (d, i);
                                }
                            }
                        }
                    }
                }
            }
            if best.1 != u32::MAX {
                break;
            }
        }
        if best.1 == u32::MAX {
            far += 1;
            continue;
        }
        let n = truth.normals[best.1 as usize];
        let own = scene.normals[v];
        // The true surface's normals may face the other way (its winding).
        let s = if (0..3).map(|a| n[a] * own[a]).sum::<f32>() < 0.0 {
            -1.0
        } else {
            1.0
        };
        scene.normals[v] = n.map(|c| s * c);
    }
    println!("normals from the truth: {far} vertices without a true vertex within 1 mm");
    Ok(scene)
}
