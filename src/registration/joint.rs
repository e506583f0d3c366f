//! Every frame's pose refined at once with the albedo eliminated (variable projection, the
//! structure of photometric bundle adjustment). The surface is cut into small cells; each
//! cell's albedo (per channel) is an unknown shared by every frame that sees it, and for given
//! poses its best value is a weighted mean of the frames' de-lit observations. The reduced
//! cost (the frames' disagreement about each cell) is minimised over all poses together by
//! Levenberg–Marquardt on the Schur complement: a step moves the frames and, implicitly, the
//! albedo with them, so an error that neighbouring frames share and that a texture fused from
//! them follows is not frozen in place as it is when texture and poses alternate.

use super::align::{huber, PointRow};
use super::frame::{FrameObs, FrameRegistrar};
use super::joint_shift::{search_run_shifts, RunShift, ShiftSearch};
use super::level::Snapshot;
use super::pose::{perturb, rotation_of};
use super::pyramid::ObservedPyramid;
use crate::camera::pose::camera_centre;
use crate::image::Frame;
use crate::math::Affine;
use crate::Result;
use nalgebra::{DMatrix, DVector};
use rayon::prelude::*;
use std::collections::HashMap;

/// Options of [`refine_jointly`].
#[derive(Clone, Debug)]
pub struct JointOptions {
    /// Pyramid level (counted as the registrar's levels are).
    pub level: usize,
    /// Renders of the model (the points are re-cast from the poses reached).
    pub renders: usize,
    /// Levenberg–Marquardt steps on the points of one render.
    pub steps: usize,
    /// Edge of the surface cells that share an albedo (mm).
    pub cell_mm: f64,
    /// A cell is an unknown only when this many frames see it.
    pub min_frames: usize,
    /// Largest image motion of one frame in one step (level pixels).
    pub trust_px: f64,
    /// Reweightings of the cells' albedo (Huber).
    pub reweightings: usize,
    /// Each frame's gain is an unknown too.
    pub estimate_gain: bool,
    /// The mean over the frames of the shift along each camera's view axis stays where it
    /// started (see [`HOLD_STIFFNESS`]).
    pub hold_mean_view_shift: bool,
    /// Before the first render's steps, runs of frames are tried at a few shifts along their
    /// views ([`super::joint_shift`]); `None`: not.
    pub shift_search: Option<ShiftSearch>,
    /// Ticked once per render.
    pub progress: Option<indicatif::ProgressBar>,
}

impl Default for JointOptions {
    fn default() -> Self {
        JointOptions {
            level: 1,
            renders: 3,
            steps: 4,
            // Small enough that a cell's albedo barely varies inside it, large enough that
            // several frames see each: from the rounds' poses of the demo phantom with a
            // 1.5 mm / 2 deg tracker, new views 31.23 / 31.56 / 32.01 / 31.91 dB with cells of
            // 0.1 / 0.15 / 0.25 / 0.4 mm (nothing held; BENCHMARKS.md, session 38).
            cell_mm: 0.25,
            min_frames: 2,
            trust_px: 1.0,
            reweightings: 2,
            estimate_gain: true,
            hold_mean_view_shift: true,
            shift_search: None,
            progress: None,
        }
    }
}

/// What [`refine_jointly`] reached.
#[derive(Clone, Debug)]
pub struct JointResult {
    /// Every frame's pose.
    pub poses: Vec<Affine>,
    /// Mean robust cost per residual before and after each render's steps; the renders end
    /// early after one that took no step (the next would repeat it).
    pub costs: Vec<(f64, f64)>,
    /// The runs [`JointOptions::shift_search`] moved.
    pub shifted: Vec<RunShift>,
    /// Each frame's mean robust cost per residual at the end, against the albedo all frames
    /// agree on (`None`: not rendered).
    pub frame_costs: Vec<Option<f64>>,
}

/// How much stiffer than the data the hold on the mean shift along the view is. Moving every
/// camera along its view is nearly invisible to an albedo that moves with them, and the
/// reduced cost drifts there: from the demo phantom's true poses every camera went back
/// 0.04-0.08 mm and new views fell 33.37 -> 32.05 dB; with the mean held, 33.12 dB. The rounds
/// against the CT's shading, where the light's fall-off with distance places the camera,
/// set that mean.
const HOLD_STIFFNESS: f64 = 100.0;

/// Damping values tried per step (each four times the last) before the step is given up and
/// the render ends. A try costs a pass over every row, and at convergence the damping used to
/// climb from 1e-7 to 1e6, 22 tries, in every render: with 4 renders per level the stage took
/// 26.5 s of the demo build, 21-23 s with 6 tries (3 mm / 4 deg: new views 31.56 and 31.59
/// dB; BENCHMARKS.md, session 40).
const STEP_TRIES: usize = 6;

/// The shift along each camera's view axis from `start` to `poses`, summed over `frames`.
fn view_shift_sum(start: &[Affine], poses: &[Affine], frames: &[usize]) -> f64 {
    frames
        .iter()
        .map(|&f| {
            let d = camera_centre(&poses[f]) - camera_centre(&start[f]);
            (rotation_of(&start[f]).transpose() * d).z
        })
        .sum()
}

/// Number of pose and gain parameters per frame.
const P: usize = 7;

/// One pair of frames' block of the normal equations.
type Block = [[f64; P]; P];

/// One frame's residual rows at some pose, the unknown (cell x 3 + channel) of each, and its
/// slot: the unknown's rank among the frame's unknowns (those of the cells its render's points
/// fall in), so that sums per unknown need no hash map and run in increasing unknown order.
struct Rows {
    rows: Vec<PointRow>,
    unknown: Vec<u32>,
    slot: Vec<u32>,
    /// How many unknowns the frame's render reaches (slots run below it).
    slots: usize,
}

/// The albedo cells of one render's points, per frame and point.
struct CellNumbers {
    /// The cell's number (`u32::MAX`: a cell fewer than `min_frames` frames see).
    cell: Vec<Vec<u32>>,
    /// The cell's rank among the frame's cells in increasing number (`u32::MAX`: none).
    rank: Vec<Vec<u32>>,
    /// Per frame, the cells its points fall in, in increasing number.
    frame_cells: Vec<Vec<u32>>,
    /// Albedo unknowns (three channels a cell).
    unknowns: usize,
}

/// Cell key of a world point.
pub(super) fn cell_key(x: &crate::math::Vector3<f64>, edge: f64) -> u64 {
    let q = |v: f64| ((v / edge).floor() as i64 + (1 << 20)) as u64 & 0x1f_ffff;
    q(x.x) | q(x.y) << 21 | q(x.z) << 42
}

/// The rows of every frame with a render, at `poses` / `log_k`, their unknowns and slots from
/// `cells`.
fn rows_at(
    snaps: &[Option<Snapshot>],
    cells: &CellNumbers,
    poses: &[Affine],
    log_k: &[f64],
) -> Vec<Option<Rows>> {
    snaps
        .par_iter()
        .enumerate()
        .map(|(f, s)| {
            let s = s.as_ref()?;
            let rows = s.prob.point_rows(&poses[f], log_k[f]);
            let of = |numbers: &[u32], r: &PointRow| match numbers[r.point as usize] {
                u32::MAX => u32::MAX,
                c => c * 3 + u32::from(r.channel),
            };
            let unknown = rows.iter().map(|r| of(&cells.cell[f], r)).collect();
            let slot = rows.iter().map(|r| of(&cells.rank[f], r)).collect();
            Some(Rows {
                rows,
                unknown,
                slot,
                slots: 3 * cells.frame_cells[f].len(),
            })
        })
        .collect()
}

/// The model's points for frame pyramid `pyr` rendered at `pose` (gain `log_k`, noise
/// floor `floor`) at `level`, or the pyramid's coarsest level when it has fewer; `None` for a
/// frame without a pyramid (skipped) or a render that fails.
pub(super) fn render_frame<'p>(
    reg: &'p FrameRegistrar,
    pyr: &'p Option<ObservedPyramid>,
    floor: f64,
    level: usize,
    pose: &Affine,
    log_k: f64,
) -> Option<Snapshot<'p>> {
    let pyr = pyr.as_ref()?;
    let level = level.min(pyr.levels.len() - 1);
    reg.snapshot(pyr, level, pose, log_k, floor).ok()
}

/// The albedo cells of the points `snaps` render.
fn number_cells(snaps: &[Option<Snapshot>], opts: &JointOptions) -> CellNumbers {
    // Cells (numbered in the order the frames' points first meet them, so that the
    // sums run in the same order on every run), and how many frames see each.
    let mut cells: HashMap<u64, u32> = HashMap::new();
    let mut seeing: Vec<(usize, u32)> = Vec::new();
    let keys: Vec<Vec<u64>> = snaps
        .iter()
        .map(|s| {
            s.as_ref().map_or(Vec::new(), |s| {
                s.prob
                    .points
                    .iter()
                    .map(|q| cell_key(&q.x, opts.cell_mm))
                    .collect()
            })
        })
        .collect();
    let point_cell: Vec<Vec<u32>> = keys
        .iter()
        .enumerate()
        .map(|(f, ks)| {
            ks.iter()
                .map(|&key| {
                    let id = *cells.entry(key).or_insert_with(|| {
                        seeing.push((usize::MAX, 0));
                        seeing.len() as u32 - 1
                    });
                    let c = &mut seeing[id as usize];
                    if c.0 != f {
                        *c = (f, c.1 + 1);
                    }
                    id
                })
                .collect()
        })
        .collect();
    let mut index = vec![u32::MAX; seeing.len()];
    let mut kept = 0u32;
    for (i, &(_, frames_seeing)) in seeing.iter().enumerate() {
        if frames_seeing as usize >= opts.min_frames {
            index[i] = kept;
            kept += 1;
        }
    }
    let cell: Vec<Vec<u32>> = point_cell
        .iter()
        .map(|ids| ids.iter().map(|&id| index[id as usize]).collect())
        .collect();
    let (rank, frame_cells) = cell
        .par_iter()
        .map(|numbers| {
            let mut own: Vec<u32> = numbers.iter().copied().filter(|&c| c != u32::MAX).collect();
            own.sort_unstable();
            own.dedup();
            let rank = numbers
                .iter()
                .map(|c| own.binary_search(c).map_or(u32::MAX, |r| r as u32))
                .collect();
            (rank, own)
        })
        .unzip();
    CellNumbers {
        cell,
        rank,
        frame_cells,
        unknowns: 3 * kept as usize,
    }
}

impl CellNumbers {
    /// Per frame, the unknown of each slot.
    fn slot_unknowns(&self) -> Vec<Vec<u32>> {
        self.frame_cells
            .iter()
            .map(|cells| {
                cells
                    .iter()
                    .flat_map(|&c| (0..3).map(move |ch| 3 * c + ch))
                    .collect()
            })
            .collect()
    }
}

/// Which frames' renders see each albedo unknown: for unknown `u`, (frame, slot) at
/// `seen[start[u]..start[u + 1]]`, in frame order, and where each frame's slot is there. Sums
/// per unknown over its frames run in that order: every run adds the same numbers in the same
/// order, however the frames are shared among threads.
struct Sightings {
    start: Vec<usize>,
    seen: Vec<(u32, u32)>,
    /// Per frame and slot, its index in `seen`.
    place: Vec<Vec<usize>>,
}

impl Sightings {
    /// From each frame's unknown of each slot.
    fn new(slot_unknowns: &[Vec<u32>], unknowns: usize) -> Self {
        let mut start = vec![0usize; unknowns + 1];
        for &u in slot_unknowns.iter().flatten() {
            start[u as usize + 1] += 1;
        }
        for u in 0..unknowns {
            start[u + 1] += start[u];
        }
        let mut seen = vec![(0u32, 0u32); start[unknowns]];
        let mut next = start.clone();
        let place = slot_unknowns
            .iter()
            .enumerate()
            .map(|(f, slots)| {
                slots
                    .iter()
                    .enumerate()
                    .map(|(slot, &u)| {
                        let at = next[u as usize];
                        seen[at] = (f as u32, slot as u32);
                        next[u as usize] += 1;
                        at
                    })
                    .collect()
            })
            .collect();
        Sightings { start, seen, place }
    }

    fn unknowns(&self) -> usize {
        self.start.len() - 1
    }

    /// The frames (and their slots) that see unknown `u`.
    fn of(&self, u: usize) -> &[(u32, u32)] {
        &self.seen[self.start[u]..self.start[u + 1]]
    }

    /// The frames (and their slots) that see unknown `u` from frame `f` (seeing it in `slot`)
    /// on.
    fn from(&self, u: usize, f: usize, slot: usize) -> &[(u32, u32)] {
        &self.seen[self.place[f][slot]..self.start[u + 1]]
    }
}

/// The albedo of every unknown that best explains `rows` (Huber-reweighted means): each
/// frame's sums per slot, then per unknown over the frames that see it.
fn solve_albedo(rows: &[Option<Rows>], seen: &Sightings, k: f64, reweightings: usize) -> Vec<f64> {
    let mut a = vec![f64::NAN; seen.unknowns()];
    for pass in 0..=reweightings {
        let sums: Vec<Vec<(f64, f64)>> = rows
            .par_iter()
            .map(|r| {
                let Some(r) = r else { return Vec::new() };
                let mut s = vec![(0.0, 0.0); r.slots];
                for ((row, &u), &slot) in r.rows.iter().zip(&r.unknown).zip(&r.slot) {
                    if u == u32::MAX {
                        continue;
                    }
                    let (pa, y) = (f64::from(row.per_albedo), row.residual(0.0));
                    let w = match pass {
                        0 => 1.0,
                        _ => huber(y - a[u as usize] * pa, k).1,
                    };
                    let s = &mut s[slot as usize];
                    s.0 += w * pa * y;
                    s.1 += w * pa * pa;
                }
                s
            })
            .collect();
        a = (0..seen.unknowns())
            .into_par_iter()
            .map(|u| {
                let (mut num, mut den) = (0.0, 0.0);
                for &(f, slot) in seen.of(u) {
                    let (n, d) = sums[f as usize][slot as usize];
                    num += n;
                    den += d;
                }
                if den > 0.0 {
                    num / den
                } else {
                    f64::NAN
                }
            })
            .collect();
    }
    a
}

/// Total robust cost of `rows` with albedo `a`, each frame's rows missing against `expected`
/// charged the Huber threshold's cost; and the number of rows counted.
fn total_cost(rows: &[Option<Rows>], a: &[f64], k: f64, expected: &[usize]) -> (f64, usize) {
    let penalty = 0.5 * k * k;
    let frames: Vec<(f64, usize)> = rows
        .par_iter()
        .zip(expected)
        .map(|(r, &want)| {
            let Some(r) = r else { return (0.0, 0) };
            let (cost, here) = frame_cost(r, a, k);
            (
                cost + want.saturating_sub(here) as f64 * penalty,
                here.max(want),
            )
        })
        .collect();
    frames
        .iter()
        .fold((0.0, 0), |(c, n), &(fc, fn_)| (c + fc, n + fn_))
}

/// Rows per frame counted by [`total_cost`] (those with an albedo).
fn counted(rows: &[Option<Rows>], a: &[f64]) -> Vec<usize> {
    rows.iter()
        .map(|r| {
            r.as_ref().map_or(0, |r| {
                r.unknown
                    .iter()
                    .filter(|&&u| u != u32::MAX && a[u as usize].is_finite())
                    .count()
            })
        })
        .collect()
}

/// Each frame's mean robust cost over its rows with an albedo (`None`: no such row).
fn per_frame_costs(rows: &[Option<Rows>], a: &[f64], k: f64) -> Vec<Option<f64>> {
    rows.iter()
        .map(|r| {
            let (cost, count) = frame_cost(r.as_ref()?, a, k);
            (count > 0).then(|| cost / count as f64)
        })
        .collect()
}

/// One frame's robust cost over its rows with an albedo, and their number.
fn frame_cost(r: &Rows, a: &[f64], k: f64) -> (f64, usize) {
    let (mut cost, mut count) = (0.0, 0);
    for (row, &u) in r.rows.iter().zip(&r.unknown) {
        if u != u32::MAX && a[u as usize].is_finite() {
            cost += huber(row.residual(a[u as usize]), k).0;
            count += 1;
        }
    }
    (cost, count)
}

/// The normal equations of all frames' parameters with the albedo eliminated (Schur
/// complement): matrix and gradient.
fn reduced_system(
    rows: &[Option<Rows>],
    a: &[f64],
    k: f64,
    seen: &Sightings,
) -> (DMatrix<f64>, DVector<f64>) {
    let unknowns = seen.unknowns();
    let n = rows.len();
    /// One frame's sums over its rows.
    struct FrameSums {
        h: [[f64; P]; P],
        g: [f64; P],
        /// Per slot: the coupling `sum w J (-per_albedo)`, `sum w per_albedo^2` and
        /// `sum w (-per_albedo) e`.
        coupling: Vec<([f64; P], f64, f64)>,
        /// Per slot, its unknown (`u32::MAX`: no row counted).
        unknown: Vec<u32>,
    }
    let sums: Vec<Option<FrameSums>> = rows
        .par_iter()
        .map(|r| {
            let r = r.as_ref()?;
            let mut s = FrameSums {
                h: [[0.0; P]; P],
                g: [0.0; P],
                coupling: vec![([0.0; P], 0.0, 0.0); r.slots],
                unknown: vec![u32::MAX; r.slots],
            };
            for ((row, &u), &slot) in r.rows.iter().zip(&r.unknown).zip(&r.slot) {
                if u == u32::MAX || !a[u as usize].is_finite() {
                    continue;
                }
                let al = a[u as usize];
                let pa = f64::from(row.per_albedo);
                let e = row.residual(al);
                let w = huber(e, k).1;
                let j = row.jacobian(al);
                for (i, &ji) in j.iter().enumerate() {
                    for (h, &jl) in s.h[i][i..].iter_mut().zip(&j[i..]) {
                        *h += w * ji * jl;
                    }
                    s.g[i] += w * ji * e;
                }
                let c = &mut s.coupling[slot as usize];
                for (ci, &ji) in c.0.iter_mut().zip(&j) {
                    *ci -= w * ji * pa;
                }
                c.1 += w * pa * pa;
                c.2 -= w * pa * e;
                s.unknown[slot as usize] = u;
            }
            Some(s)
        })
        .collect();
    // Per unknown, its sums over the frames that have rows of it.
    let mut haa = vec![0.0; unknowns];
    let mut ga = vec![0.0; unknowns];
    for s in sums.iter().flatten() {
        for (&u, &(_, hu, gu)) in s.unknown.iter().zip(&s.coupling) {
            if u != u32::MAX {
                haa[u as usize] += hu;
                ga[u as usize] += gu;
            }
        }
    }
    // Each cell couples every pair of frames that see it. Frame f's row of blocks, (f, g) for
    // g >= f, and its gradient are summed by one task, over its unknowns in increasing order
    // as a loop over all unknowns would; the lower block triangle is mirrored after.
    let block_rows: Vec<(Vec<Block>, [f64; P])> = sums
        .par_iter()
        .enumerate()
        .map(|(f, s)| {
            let mut blocks: Vec<Block> = vec![[[0.0; P]; P]; n - f];
            let Some(s) = s else {
                return (blocks, [0.0; P]);
            };
            blocks[0] = std::array::from_fn(|i| std::array::from_fn(|l| s.h[i.min(l)][i.max(l)]));
            let mut grad = s.g;
            for (slot, &u) in s.unknown.iter().enumerate() {
                let u = u as usize;
                if u == u32::MAX as usize || haa[u] <= 0.0 {
                    continue;
                }
                let inv = 1.0 / haa[u];
                let cf = &s.coupling[slot].0;
                for i in 0..P {
                    grad[i] -= cf[i] * ga[u] * inv;
                }
                for &(fg, sg) in seen.from(u, f, slot) {
                    let Some(other) = &sums[fg as usize] else {
                        continue;
                    };
                    if other.unknown[sg as usize] == u32::MAX {
                        continue;
                    }
                    let cg = &other.coupling[sg as usize].0;
                    let block = &mut blocks[fg as usize - f];
                    for i in 0..P {
                        for l in 0..P {
                            block[i][l] -= cf[i] * cg[l] * inv;
                        }
                    }
                }
            }
            (blocks, grad)
        })
        .collect();
    let mut h = DMatrix::zeros(P * n, P * n);
    let mut g = DVector::zeros(P * n);
    for (f, (blocks, grad)) in block_rows.iter().enumerate() {
        for i in 0..P {
            g[P * f + i] = grad[i];
        }
        for (d, block) in blocks.iter().enumerate() {
            let fg = f + d;
            for i in 0..P {
                for l in 0..P {
                    h[(P * f + i, P * fg + l)] = block[i][l];
                    h[(P * fg + l, P * f + i)] = block[i][l];
                }
            }
        }
    }
    (h, g)
}

/// Which frames take part in [`refine_jointly`], and how.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum JointRole {
    /// Its pose is refined.
    Refined,
    /// Its pose is exact: it is kept there, and its pixels still place the albedo.
    Anchor,
    /// Not used (a flagged frame).
    Skipped,
}

/// Refine the poses of `frames` (gains `gains`, optional pixel `mask`) from `poses` together
/// against the model's geometry and light, the albedo eliminated (see the module docs), each
/// frame as its `roles` entry says.
pub fn refine_jointly(
    reg: &FrameRegistrar,
    frames: &[Frame],
    gains: &[f64],
    mask: Option<&[bool]>,
    poses: &[Affine],
    roles: &[JointRole],
    opts: &JointOptions,
) -> Result<JointResult> {
    let n = frames.len();
    if gains.len() != n || poses.len() != n || roles.len() != n {
        return Err(crate::Error::Other(format!(
            "joint registration: {n} frames, {} gains, {} poses and {} roles (need one of each per frame)",
            gains.len(),
            poses.len(),
            roles.len()
        )));
    }
    let pyramids: Vec<Option<ObservedPyramid>> = frames
        .par_iter()
        .zip(gains)
        .zip(roles)
        .map(|((frame, &gain), role)| match role {
            JointRole::Skipped => Ok(None),
            _ => reg.pyramid(&FrameObs { frame, gain, mask }).map(Some),
        })
        .collect::<Result<_>>()?;
    let floors: Vec<f64> = gains
        .iter()
        .map(|g| f64::from(reg.opts.noise_floor) / g)
        .collect();
    let k = reg.opts.huber;
    let px = reg.model.parts.camera.fx / f64::from(1u32 << opts.level);
    let mut poses = poses.to_vec();
    let mut log_k = vec![0.0; n];
    let mut costs = Vec::new();
    let mut shifted = Vec::new();
    let mut frame_costs = vec![None; n];
    // Where the hold on the mean shift along the view holds it: the poses the search leaves.
    let mut start = poses.clone();
    for render in 0..opts.renders {
        let mut snaps: Vec<Option<Snapshot>> = (0..n)
            .into_par_iter()
            .map(|f| {
                render_frame(
                    reg,
                    &pyramids[f],
                    floors[f],
                    opts.level,
                    &poses[f],
                    log_k[f],
                )
            })
            .collect();
        if let (0, Some(search)) = (render, &opts.shift_search) {
            shifted = search_run_shifts(
                reg, &pyramids, &floors, &mut poses, &log_k, roles, &mut snaps, opts, search,
            );
            start.clone_from(&poses);
        }
        let cells = number_cells(&snaps, opts);
        let seen = Sightings::new(&cells.slot_unknowns(), cells.unknowns);
        let median_depth: Vec<f64> = snaps
            .iter()
            .map(|s| s.as_ref().map_or(1.0, |s| s.median_depth))
            .collect();
        let frozen: Vec<bool> = (0..n)
            .map(|f| roles[f] != JointRole::Refined || snaps[f].is_none())
            .collect();
        let mut rows = rows_at(&snaps, &cells, &poses, &log_k);
        let mut a = solve_albedo(&rows, &seen, k, opts.reweightings);
        let expected = counted(&rows, &a);
        let (mut cost, count) = total_cost(&rows, &a, k, &expected);
        let start_cost = cost / count.max(1) as f64;
        let free: Vec<usize> = (0..n).filter(|&f| !frozen[f]).collect();
        // The hold on the mean shift along the view: its stiffness set from the data's own
        // curvature there at the first step (`None` until then, and without the hold).
        let mut hold: Option<f64> = None;
        let held = |hold: Option<f64>, p: &[Affine]| {
            hold.map_or(0.0, |w| 0.5 * w * view_shift_sum(&start, p, &free).powi(2))
        };
        let mut lambda = 1e-4;
        let mut stepped = false;
        for _ in 0..opts.steps {
            let (mut h, mut g) = reduced_system(&rows, &a, k, &seen);
            if opts.hold_mean_view_shift && !free.is_empty() && hold.is_none() {
                let mut d: Vec<f64> = free.iter().map(|&f| h[(P * f + 2, P * f + 2)]).collect();
                d.sort_by(f64::total_cmp);
                hold = Some(HOLD_STIFFNESS * d[d.len() / 2] / free.len() as f64);
                cost += held(hold, &poses);
            }
            if let Some(w) = hold {
                let sum = view_shift_sum(&start, &poses, &free);
                for &f in &free {
                    for &fg in &free {
                        h[(P * f + 2, P * fg + 2)] += w;
                    }
                    g[P * f + 2] += w * sum;
                }
            }
            let mut accepted = false;
            for _ in 0..STEP_TRIES {
                if lambda >= 1e6 {
                    break;
                }
                let mut hd = h.clone();
                let mut gd = g.clone();
                for (f, &is_frozen) in frozen.iter().enumerate() {
                    for i in 0..P {
                        let r = P * f + i;
                        if is_frozen || (i == 6 && !opts.estimate_gain) {
                            for c in 0..P * n {
                                hd[(r, c)] = 0.0;
                                hd[(c, r)] = 0.0;
                            }
                            hd[(r, r)] = 1.0;
                            gd[r] = 0.0;
                        } else {
                            hd[(r, r)] += lambda * h[(r, r)].max(1e-9) + 1e-9;
                        }
                    }
                }
                let Some(chol) = hd.cholesky() else {
                    lambda *= 4.0;
                    continue;
                };
                let step = -chol.solve(&gd);
                let mut cand = poses.clone();
                let mut cand_k = log_k.clone();
                for f in (0..n).filter(|&f| !frozen[f]) {
                    let s = step.rows(P * f, P);
                    let t = (s[0] * s[0] + s[1] * s[1] + s[2] * s[2]).sqrt();
                    let w = (s[3] * s[3] + s[4] * s[4] + s[5] * s[5]).sqrt();
                    let motion = (t / median_depth[f] + w) * px;
                    let shrink = (opts.trust_px / motion.max(1e-12)).min(1.0);
                    let xi = [s[0], s[1], s[2], s[3], s[4], s[5]].map(|v| v * shrink);
                    cand[f] = perturb(&poses[f], &xi);
                    cand_k[f] += s[6] * shrink;
                }
                let cand_rows = rows_at(&snaps, &cells, &cand, &cand_k);
                let cand_a = solve_albedo(&cand_rows, &seen, k, opts.reweightings);
                let (c, _) = total_cost(&cand_rows, &cand_a, k, &expected);
                let c = c + held(hold, &cand);
                if c < cost {
                    (poses, log_k, rows, a, cost) = (cand, cand_k, cand_rows, cand_a, c);
                    lambda = (lambda / 3.0).max(1e-7);
                    accepted = true;
                    break;
                }
                lambda *= 4.0;
            }
            if !accepted {
                break;
            }
            stepped = true;
        }
        // A render that took no step leaves the poses where it found them, and the next render
        // would repeat it to the bit (the same rays, the same start of the damping): done.
        let last = render + 1 == opts.renders || !stepped;
        if last {
            frame_costs = per_frame_costs(&rows, &a, k);
        }
        let end_cost = (cost - held(hold, &poses)) / count.max(1) as f64;
        costs.push((start_cost, end_cost));
        if let Some(p) = &opts.progress {
            p.inc(if last {
                (opts.renders - render) as u64
            } else {
                1
            });
        }
        if last {
            break;
        }
    }
    Ok(JointResult {
        poses,
        costs,
        shifted,
        frame_costs,
    })
}

/// The roles of each solve over consecutive windows of `window` of the frames `roles`
/// refines, each with the `anchors` frames refined just before it held as anchors (the
/// frames `roles` anchors stay anchors, all others are skipped); one solve, `roles` itself,
/// when they fit in one window.
pub fn joint_windows(roles: &[JointRole], window: usize, anchors: usize) -> Vec<Vec<JointRole>> {
    let refined: Vec<usize> = (0..roles.len())
        .filter(|&i| roles[i] == JointRole::Refined)
        .collect();
    if refined.len() <= window.max(1) {
        return vec![roles.to_vec()];
    }
    refined
        .chunks(window.max(1))
        .enumerate()
        .map(|(w, chunk)| {
            let start = w * window;
            let before = &refined[start.saturating_sub(anchors)..start];
            (0..roles.len())
                .map(|i| match roles[i] {
                    JointRole::Refined if chunk.contains(&i) => JointRole::Refined,
                    JointRole::Refined if before.contains(&i) => JointRole::Anchor,
                    JointRole::Anchor => JointRole::Anchor,
                    _ => JointRole::Skipped,
                })
                .collect()
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::SplitMix64 as Rng;

    /// Random rows of `frames` (at least three) frames over `unknowns` albedo unknowns, and
    /// which frames see which. Frame f sees the unknowns u with (u + f) % 4 != 0 (so every
    /// unknown at least two frames), in slots by rank, each a few times, but frame 0 has no row
    /// of its last; some rows have no unknown.
    fn random_rows(
        frames: usize,
        unknowns: usize,
        rng: &mut Rng,
    ) -> (Vec<Option<Rows>>, Sightings) {
        let sees: Vec<Vec<u32>> = (0..frames)
            .map(|f| {
                (0..unknowns as u32)
                    .filter(|u| (*u as usize + f) % 4 != 0)
                    .collect()
            })
            .collect();
        let rows = (0..frames)
            .map(|f| {
                let own = &sees[f];
                let with_rows = own.len() - usize::from(f == 0);
                let mut rows = Vec::new();
                let mut slot = Vec::new();
                let mut unknown = Vec::new();
                for i in 0..6 * unknowns {
                    let r = || std::array::from_fn(|_| 0.0f32);
                    let mut row = PointRow {
                        point: i as u32,
                        channel: 0,
                        obs: 0.0,
                        per_albedo: 0.0,
                        fixed: 0.0,
                        image: r(),
                        shade: r(),
                        specular: r(),
                    };
                    row.obs = rng.range_f32(0.5, 1.5);
                    row.per_albedo = rng.range_f32(0.3, 1.0);
                    row.fixed = rng.range_f32(0.0, 0.2);
                    for j in 0..6 {
                        row.image[j] = rng.range_f32(-1.0, 1.0);
                        row.shade[j] = rng.range_f32(-0.2, 0.2);
                        row.specular[j] = rng.range_f32(-0.1, 0.1);
                    }
                    rows.push(row);
                    let (u, s) = match i % 7 {
                        6 => (u32::MAX, u32::MAX),
                        _ => (own[i % with_rows], (i % with_rows) as u32),
                    };
                    unknown.push(u);
                    slot.push(s);
                }
                Some(Rows {
                    rows,
                    unknown,
                    slot,
                    slots: own.len(),
                })
            })
            .collect();
        (rows, Sightings::new(&sees, unknowns))
    }

    /// The reduced system equals the Schur complement of the full normal equations over the
    /// poses, gains and albedo, assembled densely from the same residuals.
    #[test]
    fn reduced_system_is_the_schur_complement_of_the_full_normal_equations() {
        let mut rng = Rng::new(7);
        let (frames, unknowns) = (3, 5);
        let (rows, seen) = random_rows(frames, unknowns, &mut rng);
        let a: Vec<f64> = (0..unknowns).map(|_| rng.range(0.8, 1.2)).collect();
        // A Huber threshold that some residuals exceed: their weights are below one.
        let k = 0.3;
        let (h, g) = reduced_system(&rows, &a, k, &seen);

        let m = P * frames + unknowns;
        let mut full = DMatrix::<f64>::zeros(m, m);
        let mut grad = DVector::<f64>::zeros(m);
        let mut down_weighted = 0;
        for (f, r) in rows.iter().enumerate() {
            let r = r.as_ref().unwrap();
            for (row, &u) in r.rows.iter().zip(&r.unknown) {
                if u == u32::MAX {
                    continue;
                }
                let al = a[u as usize];
                let e = row.residual(al);
                let w = huber(e, k).1;
                down_weighted += usize::from(w < 1.0);
                let mut j = DVector::<f64>::zeros(m);
                for (i, ji) in row.jacobian(al).into_iter().enumerate() {
                    j[P * f + i] = ji;
                }
                j[P * frames + u as usize] = -f64::from(row.per_albedo);
                full += &j * j.transpose() * w;
                grad += &j * (w * e);
            }
        }
        assert!(down_weighted > 0, "no residual beyond the Huber threshold");
        let np = P * frames;
        let hpp = full.view((0, 0), (np, np));
        let hpa = full.view((0, np), (np, unknowns));
        let haa = full.view((np, np), (unknowns, unknowns));
        // The albedo block is diagonal: each residual has one unknown.
        for i in 0..unknowns {
            for l in 0..unknowns {
                assert!(i == l || haa[(i, l)] == 0.0);
            }
        }
        let haa_inv = DMatrix::from_diagonal(&haa.diagonal().map(|v| 1.0 / v));
        let schur = hpp - hpa * &haa_inv * hpa.transpose();
        let rhs = grad.rows(0, np) - hpa * &haa_inv * grad.rows(np, unknowns);
        let scale = schur.amax();
        assert!(
            (&h - &schur).amax() < 1e-9 * scale,
            "{}",
            (&h - &schur).amax()
        );
        assert!((&g - &rhs).amax() < 1e-9 * rhs.amax().max(1.0));
        assert!(h.amax() > 0.0 && g.amax() > 0.0);
    }

    #[test]
    fn long_videos_are_refined_in_windows_with_anchors_before_each() {
        use JointRole::{Anchor as A, Refined as R, Skipped as S};
        let roles = [A, R, R, S, R, R, R, R];
        // Six frames to refine fit one window of six: the roles as they are.
        assert_eq!(joint_windows(&roles, 6, 2), vec![roles.to_vec()]);
        let w = joint_windows(&roles, 4, 2);
        assert_eq!(
            w,
            vec![
                vec![A, R, R, S, R, R, S, S],
                // The two frames refined last in the first window hold the second.
                vec![A, S, S, S, A, A, R, R],
            ]
        );
        // Every frame to refine is refined in exactly one window.
        for i in 0..roles.len() {
            let n = w.iter().filter(|r| r[i] == R).count();
            assert_eq!(n, usize::from(roles[i] == R), "frame {i}");
        }
    }

    /// The albedo solve is the weighted least-squares mean: with no residual beyond the
    /// threshold, each unknown's value makes its residuals sum to zero.
    #[test]
    fn albedo_is_the_least_squares_value_of_each_cell() {
        let mut rng = Rng::new(3);
        let (rows, seen) = random_rows(4, 6, &mut rng);
        let a = solve_albedo(&rows, &seen, 1e9, 2);
        let mut sums = [0.0f64; 6];
        for r in rows.iter().flatten() {
            for (row, &u) in r.rows.iter().zip(&r.unknown) {
                if u != u32::MAX {
                    let pa = f64::from(row.per_albedo);
                    let e = row.residual(a[u as usize]);
                    sums[u as usize] += pa * e;
                }
            }
        }
        for s in sums {
            assert!(s.abs() < 1e-9, "{sums:?}");
        }
        assert!(
            a.iter().all(|v| v.is_finite() && *v > 0.5 && *v < 5.0),
            "{a:?}"
        );
    }
}
