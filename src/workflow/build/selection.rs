//! The frame selection stage (issue 21): right after the scene is prepared and before the
//! registration, score every frame in one streaming pass, ray cast each from its pose on a
//! coarse grid for the wall it sees, and keep the frames [`crate::selection`] chooses under
//! `--max-frames`. Every later stage (registration included) sees the kept frames only.

use std::time::Instant;

use rayon::prelude::*;

use super::options::{BuildOptions, PosesMode};
use super::scene::BuildScene;
use crate::camera::Camera;
use crate::image::Frame;
use crate::io::case::FramesLocation;
use crate::io::png::read_png;
use crate::io::poses::FrameRef;
use crate::model::selection::{FrameSelection, SelectedFrame};
use crate::raycast::{cast_frame_with, RayTable};
use crate::selection::{
    choose_frames, frames_to_track, judge_frames, needs_coverage, score_frame, CoverState,
    CoverageGrid, Decision, FrameCoverage, FrameStats, Judgement, Reason, WallHit,
};
use crate::workflow::progress::Progress;
use crate::{Error, Result};

/// Choose the frames of `scene` (unless `opts.selection.max_frames` is 0) and drop the others
/// from it. `None` when no selection ran. Without a tracker (`--poses first`) a video over
/// the budget has no poses to cast coverage from yet: the frames to track are chosen here
/// ([`frames_to_track`]) and the budget's among them once tracked ([`choose_tracked`]).
pub fn select_frames(
    scene: &mut BuildScene,
    opts: &BuildOptions,
    warnings: &mut Vec<String>,
) -> Result<Option<FrameSelection>> {
    let sel = &opts.selection;
    if sel.max_frames == 0 {
        return Ok(None);
    }
    let t = Instant::now();
    let stats = score_all(scene, opts)?;
    let judged = judge_frames(&stats, &sel.judge);
    let t_score = t.elapsed().as_secs_f64();

    if opts.poses == PosesMode::First && needs_coverage(&judged, sel.max_frames) {
        let t = Instant::now();
        let most = sel
            .max_frames
            .saturating_mul(opts.tracking.tracked_per_used);
        let decisions = frames_to_track(&judged, most);
        let keep = chosen(&decisions);
        scene.keep_frames(&keep, opts.depth_cache_bytes);
        let seconds = [t_score, 0.0, t.elapsed().as_secs_f64()];
        return Ok(Some(record(
            sel.max_frames,
            &stats,
            &judged,
            &decisions,
            true,
            seconds,
        )));
    }

    let t = Instant::now();
    let atlas = &scene.atlas;
    let grid = CoverageGrid::new(atlas.width, atlas.height, atlas.texel_mm, sel.cell_mm);
    let (coverage, ray_grid) = if needs_coverage(&judged, sel.max_frames) {
        let all: Vec<usize> = (0..scene.frame_count()).collect();
        let (c, g) = cast_coverage(scene, &all, &grid, opts);
        (c, Some(g))
    } else {
        (Vec::new(), None)
    };
    let t_cast = t.elapsed().as_secs_f64();

    let t = Instant::now();
    let mut decisions = choose_frames(&judged, &coverage, grid.cells(), sel);
    if opts.poses == PosesMode::First && !decisions.is_empty() {
        // Without a tracker the first frame's pose is the only one given: tracking starts
        // from that frame, whatever it shows (a blank one fails there, naming it).
        decisions[0].reason = Reason::Chosen;
    }
    let keep = chosen(&decisions);
    if keep.is_empty() {
        warnings.push(
            "frame selection: no frame sees the airway wall usably; every frame is kept".into(),
        );
    } else if keep.len() < scene.frame_count() {
        scene.keep_frames(&keep, opts.depth_cache_bytes);
    }
    let seconds = [t_score, t_cast, t.elapsed().as_secs_f64()];
    let mut out = record(
        sel.max_frames,
        &stats,
        &judged,
        &decisions,
        !keep.is_empty(),
        seconds,
    );
    out.coverage_grid = ray_grid;
    (out.cells_seen_used, out.cells_seen_all) = cells_seen(&coverage, &keep, grid.cells());
    Ok(Some(out))
}

/// After the frames of `scene` were tracked from the first pose (`--poses first`, the frames
/// [`select_frames`] chose to track): choose among those the tracker accepted (`accepted`,
/// one per frame of the scene) the frames the budget allows, by the wall they see from their
/// tracked poses, as with a tracker's poses. The first frame of the video stays (its pose is
/// the one given, and anchors the registration). Updates `record`; returns the frames of the
/// scene to keep: the chosen, and those the tracker did not accept (the registration reports
/// them and leaves them out).
pub fn choose_tracked(
    scene: &BuildScene,
    record: &mut FrameSelection,
    accepted: &[bool],
    opts: &BuildOptions,
) -> Vec<usize> {
    let sel = &opts.selection;
    let n = scene.frame_count();
    let candidates: Vec<usize> = (0..n).filter(|&i| accepted[i]).collect();
    if sel.max_frames == 0 || candidates.len() <= sel.max_frames {
        return (0..n).collect();
    }
    let t = Instant::now();
    let atlas = &scene.atlas;
    let grid = CoverageGrid::new(atlas.width, atlas.height, atlas.texel_mm, sel.cell_mm);
    let (coverage, ray_grid) = cast_coverage(scene, &candidates, &grid, opts);
    let t_cast = t.elapsed().as_secs_f64();

    let t = Instant::now();
    let entry = |i: usize| &record.frames[scene.frame_numbers[i]];
    let judged: Vec<Judgement> = candidates
        .iter()
        .map(|&i| Judgement {
            relative_sharpness: entry(i).relative_sharpness,
            score: entry(i).score,
            failure: entry(i).flagged.as_deref().and_then(Reason::failure_named),
        })
        .collect();
    let decisions = choose_frames(&judged, &coverage, grid.cells(), sel);
    let mut keep: Vec<usize> = (0..n).filter(|&i| !accepted[i]).collect();
    // Positions in `candidates` of the frames used.
    let mut used = Vec::new();
    for (k, (&i, d)) in candidates.iter().zip(&decisions).enumerate() {
        let first = scene.frame_numbers[i] == 0;
        let reason = match first {
            true => Reason::Chosen,
            false => d.reason,
        };
        if reason == Reason::Chosen {
            keep.push(i);
            used.push(k);
        }
        let e = &mut record.frames[scene.frame_numbers[i]];
        (e.reason, e.used, e.coverage_gain) = (reason, reason == Reason::Chosen, d.gain);
    }
    keep.sort_unstable();
    (record.cells_seen_used, record.cells_seen_all) = cells_seen(&coverage, &used, grid.cells());
    record.coverage_grid = Some(ray_grid);
    record.used = record.frames.iter().filter(|f| f.used).count();
    record.counts = reason_counts(&record.frames);
    record.seconds[1] += t_cast;
    record.seconds[2] += t.elapsed().as_secs_f64();
    keep
}

/// The frames decided `Chosen`.
fn chosen(decisions: &[Decision]) -> Vec<usize> {
    (0..decisions.len())
        .filter(|&i| decisions[i].reason == Reason::Chosen)
        .collect()
}

/// Wall cells seen by the frames `used` (indices into `coverage`), and by all of them.
fn cells_seen(coverage: &[FrameCoverage], used: &[usize], cells: usize) -> (usize, usize) {
    if coverage.is_empty() {
        return (0, 0);
    }
    let seen = |frames: &mut dyn Iterator<Item = usize>| {
        let mut st = CoverState::new(cells, 1);
        frames.for_each(|i| st.add(&coverage[i], 1.0));
        st.seen_cells()
    };
    (
        seen(&mut used.iter().copied()),
        seen(&mut (0..coverage.len())),
    )
}

/// Frames per reason, by the reasons' names (every reason, zero counts too).
fn reason_counts(frames: &[SelectedFrame]) -> std::collections::BTreeMap<String, usize> {
    Reason::ALL
        .iter()
        .map(|r| {
            (
                r.name().to_string(),
                frames.iter().filter(|f| f.reason == *r).count(),
            )
        })
        .collect()
}

/// The selection's record of every frame of the video (`any_chosen` false: none was, and
/// every frame is used); no coverage yet.
fn record(
    budget: usize,
    stats: &[FrameStats],
    judged: &[Judgement],
    decisions: &[Decision],
    any_chosen: bool,
    seconds: [f64; 3],
) -> FrameSelection {
    let frames: Vec<SelectedFrame> = (0..decisions.len())
        .map(|i| SelectedFrame {
            frame: i,
            used: !any_chosen || decisions[i].reason == Reason::Chosen,
            reason: decisions[i].reason,
            flagged: judged[i]
                .failure
                .map(|f| Reason::of_failure(f).name().to_string()),
            sharpness: stats[i].sharpness,
            relative_sharpness: judged[i].relative_sharpness,
            saturated_share: stats[i].saturated_share,
            dark_share: stats[i].dark_share,
            score: judged[i].score,
            coverage_gain: decisions[i].gain,
        })
        .collect();
    FrameSelection {
        budget,
        used: frames.iter().filter(|f| f.used).count(),
        counts: reason_counts(&frames),
        coverage_grid: None,
        cells_seen_used: 0,
        cells_seen_all: 0,
        seconds,
        frames,
    }
}

/// Score every frame in one pass: PNG files decoded in parallel (one frame per thread in
/// memory), a video decoded as one stream.
fn score_all(scene: &BuildScene, opts: &BuildOptions) -> Result<Vec<FrameStats>> {
    let case = &scene.case;
    let mask = case.mask.as_ref().map(|m| m.image.as_slice());
    let n = case.frame_count();
    let progress = Progress::new("scoring frames", n as u64, opts.quiet);
    let score = |f: &Frame| {
        progress.inc();
        score_frame(f, mask, &opts.selection.score)
    };
    let stats = match &case.frames {
        FramesLocation::Png { .. } => case
            .poses
            .par_iter()
            .map(|p| match &p.frame {
                FrameRef::Image(path) => {
                    let f = read_png(path)?;
                    check_size(&f, &case.camera, path)?;
                    Ok(score(&f))
                }
                FrameRef::VideoIndex(_) => Err(Error::invalid(
                    &case.poses_path,
                    "refers to video frames but the case has PNG frames",
                )),
            })
            .collect::<Result<Vec<_>>>()?,
        FramesLocation::Video { .. } => case
            .frame_source()?
            .map(|f| f.map(|f| score(&f)))
            .collect::<Result<Vec<_>>>()?,
    };
    progress.finish();
    Ok(stats)
}

fn check_size(f: &Frame, camera: &Camera, path: &std::path::Path) -> Result<()> {
    if (f.width, f.height) != (camera.width, camera.height) {
        return Err(Error::invalid(
            path,
            format!(
                "frame size {}x{} differs from the camera's {}x{}",
                f.width, f.height, camera.width, camera.height
            ),
        ));
    }
    Ok(())
}

/// The pyramid level whose camera has at most `max_rays` pixels.
fn coverage_level(camera: &Camera, max_rays: usize) -> usize {
    let mut level = 0;
    while ((camera.width >> level) as usize) * ((camera.height >> level) as usize) > max_rays
        && (camera.width >> (level + 1)) >= 8
        && (camera.height >> (level + 1)) >= 8
    {
        level += 1;
    }
    level
}

/// The coverage of the frames `frames` (indices into the scene), each ray cast from its pose
/// through the reduced camera (the case's image mask sampled at each reduced pixel's centre);
/// returns the ray grid's size too.
fn cast_coverage(
    scene: &BuildScene,
    frames: &[usize],
    grid: &CoverageGrid,
    opts: &BuildOptions,
) -> (Vec<FrameCoverage>, [u32; 2]) {
    let camera = &scene.case.camera;
    let level = coverage_level(camera, opts.selection.max_rays);
    let small = camera.at_level(level);
    let rays = RayTable::new(&small);
    let s = 1usize << level;
    let mask: Option<Vec<bool>> = scene.case.mask.as_ref().map(|m| {
        let (w, h) = (small.width as usize, small.height as usize);
        (0..w * h)
            .map(|i| {
                let (x, y) = ((i % w) * s + s / 2, (i / w) * s + s / 2);
                m.image[y.min(camera.height as usize - 1) * camera.width as usize
                    + x.min(camera.width as usize - 1)]
            })
            .collect()
    });
    let progress = Progress::new("frame coverage", frames.len() as u64, opts.quiet);
    let coverage = frames
        .par_iter()
        .map(|&i| {
            let mut g = cast_frame_with(&scene.scene, &rays, &scene.poses[i]);
            if let Some(m) = &mask {
                g.mask_out(m);
            }
            let hits = (0..g.tri.len()).filter(|&k| g.hit(k)).map(|k| {
                let uv = scene.tri_uv[g.tri[k] as usize];
                let [u, v] = g.bary[k];
                let w0 = 1.0 - u - v;
                WallHit {
                    uv: [
                        w0 * uv[0][0] + u * uv[1][0] + v * uv[2][0],
                        w0 * uv[0][1] + u * uv[1][1] + v * uv[2][1],
                    ],
                    z: g.z[k],
                    gamma: g.gamma[k],
                }
            });
            let c = FrameCoverage::from_hits(hits, grid, camera.fx, scene.atlas.texel_mm);
            progress.inc();
            c
        })
        .collect();
    progress.finish();
    (coverage, [small.width, small.height])
}
