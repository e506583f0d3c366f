//! Runs of frames moved along their views before the joint solve. In a smooth stretch of
//! airway a run of consecutive frames can settle together a millimetre or so along the
//! airway from the truth, each frame painting the walls only the run sees where the run puts
//! them, so every frame agrees with its neighbours and neither the rounds nor the joint
//! solve's small steps move the run out again: the reduced cost rises on the way, although
//! it is lower at the truth, where the run's walls join those its neighbours see.
//!
//! The search takes runs of consecutive frames (overlapping by half), renders each a step
//! forward and back along its frames' views, moves on while the video's mean reduced cost
//! falls by a set share, then tries half a step either way; the joint solve then places the
//! run. Only the albedo cells a run sees before or after a shift change, so only their cost
//! is summed again.
//!
//! Measured on the demo phantom with 3 mm / 4 deg tracker drift: the video's last six
//! frames ended 1.0 mm ahead along their views after the rounds (the reduced cost 0.595,
//! 0.560 with the true poses in their place); the search moves them back 0.75 mm (0.582) and
//! the joint solve leaves them 0.2-0.4 mm off. From the other phantoms' rounds (1.5 mm / 2 deg
//! drift, seed 7, the real airway trees ATM_307 and ATM_384) it moves nothing
//! (BENCHMARKS.md, session 39).

use super::align::huber;
use super::frame::FrameRegistrar;
use super::joint::{cell_key, render_frame, JointOptions, JointRole};
use super::level::Snapshot;
use super::pyramid::ObservedPyramid;
use crate::math::Affine;
use rayon::prelude::*;
use std::collections::HashMap;

/// Options of the search (see the module docs).
#[derive(Clone, Debug)]
pub struct ShiftSearch {
    /// Frames of a run: consecutive refined frames, the runs overlapping by half.
    pub run_frames: usize,
    /// Shift of one step along each frame's view axis (mm): a run is tried a step forward
    /// and back, and moved on in the direction that lowers the cost.
    pub step_mm: f64,
    /// Most whole steps a run moves (then half a step either way).
    pub max_steps: usize,
    /// A shift is kept when it lowers the video's mean reduced cost by at least this share.
    pub min_gain: f64,
}

impl Default for ShiftSearch {
    fn default() -> Self {
        ShiftSearch {
            run_frames: 6,
            step_mm: 0.75,
            max_steps: 3,
            min_gain: 0.005,
        }
    }
}

/// A run the search moved.
#[derive(Clone, Debug, PartialEq)]
pub struct RunShift {
    /// The run's frames.
    pub frames: Vec<usize>,
    /// Its shift along each frame's view (mm).
    pub shift_mm: f64,
    /// The video's mean reduced cost before and after the shift.
    pub cost_before: f64,
    pub cost_after: f64,
}

/// The runs of `run` consecutive refined frames (by `roles`), each starting half a run after
/// the one before; the last ends at the last refined frame.
fn shift_runs(roles: &[JointRole], run: usize) -> Vec<Vec<usize>> {
    let refined: Vec<usize> = (0..roles.len())
        .filter(|&f| roles[f] == JointRole::Refined)
        .collect();
    let run = run.max(1);
    if refined.len() <= run {
        return match refined.is_empty() {
            true => Vec::new(),
            false => vec![refined],
        };
    }
    let stride = (run / 2).max(1);
    let mut starts: Vec<usize> = (0..=refined.len() - run).step_by(stride).collect();
    if starts.last() != Some(&(refined.len() - run)) {
        starts.push(refined.len() - run);
    }
    starts
        .into_iter()
        .map(|s| refined[s..s + run].to_vec())
        .collect()
}

/// `pose` moved `mm` along its own view axis.
fn along_view(pose: &Affine, mm: f64) -> Affine {
    let mut p = *pose;
    for i in 0..3 {
        p[(i, 3)] += mm * pose[(i, 2)];
    }
    p
}

/// A residual row reduced to what its reduced cost needs.
#[derive(Clone, Copy, Debug)]
struct CostRow {
    frame: u32,
    channel: u8,
    obs: f32,
    per_albedo: f32,
    fixed: f32,
}

/// The rows of frame `f` rendered in `snap`, at `pose` and gain `log_k`, keyed by their cell.
fn keyed_rows(
    snap: &Snapshot,
    f: usize,
    pose: &Affine,
    log_k: f64,
    cell_mm: f64,
) -> Vec<(u64, CostRow)> {
    snap.prob
        .point_rows(pose, log_k)
        .into_iter()
        .map(|r| {
            let key = cell_key(&snap.prob.points[r.point as usize].x, cell_mm);
            let row = CostRow {
                frame: f as u32,
                channel: r.channel,
                obs: r.obs,
                per_albedo: r.per_albedo,
                fixed: r.fixed,
            };
            (key, row)
        })
        .collect()
}

/// Robust cost and number of the rows of one cell that take part in the reduced cost, as
/// [`super::joint::refine_jointly`] counts them: none unless `min_frames` frames see the cell, and per
/// channel the Huber-reweighted albedo (`reweightings` passes).
fn cell_cost(rows: &[CostRow], min_frames: usize, k: f64, reweightings: usize) -> (f64, usize) {
    let mut frames = 0;
    let mut last = u32::MAX;
    for r in rows {
        if r.frame != last {
            frames += 1;
            last = r.frame;
        }
    }
    if frames < min_frames {
        return (0.0, 0);
    }
    let residual =
        |r: &CostRow, a: f64| f64::from(r.obs) - (a * f64::from(r.per_albedo) + f64::from(r.fixed));
    let (mut cost, mut count) = (0.0, 0);
    for channel in 0..3u8 {
        let of = || rows.iter().filter(move |r| r.channel == channel);
        let mut a = f64::NAN;
        for pass in 0..=reweightings {
            let (mut num, mut den) = (0.0, 0.0);
            for r in of() {
                let (pa, y) = (f64::from(r.per_albedo), residual(r, 0.0));
                let w = match pass {
                    0 => 1.0,
                    _ => huber(y - a * pa, k).1,
                };
                num += w * pa * y;
                den += w * pa * pa;
            }
            a = if den > 0.0 { num / den } else { f64::NAN };
        }
        if a.is_finite() {
            for r in of() {
                cost += huber(residual(r, a), k).0;
                count += 1;
            }
        }
    }
    (cost, count)
}

/// The video's rows, and where each cell's are, for the reduced cost of the cells a run
/// touches.
struct CellRows {
    /// Per frame, its rows and their cells.
    frame_rows: Vec<Vec<(u64, CostRow)>>,
    /// Per cell, its rows (frame, index in `frame_rows`), in frame order.
    by_key: HashMap<u64, Vec<(u32, u32)>>,
    /// Total robust cost and rows counted over every cell.
    cost: f64,
    count: usize,
}

impl CellRows {
    fn new(frame_rows: Vec<Vec<(u64, CostRow)>>, opts: &JointOptions, k: f64) -> Self {
        let mut by_key: HashMap<u64, Vec<(u32, u32)>> = HashMap::new();
        for (f, rows) in frame_rows.iter().enumerate() {
            for (i, (key, _)) in rows.iter().enumerate() {
                by_key.entry(*key).or_default().push((f as u32, i as u32));
            }
        }
        let mut cells = CellRows {
            by_key,
            frame_rows,
            cost: 0.0,
            count: 0,
        };
        // In key order, not the hash map's: the same sum in the same order on every run.
        let mut keys: Vec<u64> = cells.by_key.keys().copied().collect();
        keys.sort_unstable();
        (cells.cost, cells.count) = cells.touched(&keys, &[], &HashMap::new(), opts, k);
        cells
    }

    /// The rows of the frames `run`, grouped by cell.
    fn rows_of(&self, run: &[usize]) -> HashMap<u64, Vec<CostRow>> {
        group(run.iter().flat_map(|&f| self.frame_rows[f].iter().copied()))
    }

    /// Cost and rows counted over the cells `keys`, the frames of `run` seen through
    /// `run_rows` (grouped by cell) instead of their rows here.
    fn touched(
        &self,
        keys: &[u64],
        run: &[usize],
        run_rows: &HashMap<u64, Vec<CostRow>>,
        opts: &JointOptions,
        k: f64,
    ) -> (f64, usize) {
        // Each cell's cost in parallel, summed in key order: the same sum on every run.
        let per_cell: Vec<(f64, usize)> = keys
            .par_iter()
            .map_init(Vec::new, |list, key| {
                list.clear();
                if let Some(rows) = self.by_key.get(key) {
                    list.extend(
                        rows.iter()
                            .filter(|(f, _)| !run.contains(&(*f as usize)))
                            .map(|&(f, i)| self.frame_rows[f as usize][i as usize].1),
                    );
                }
                if let Some(rows) = run_rows.get(key) {
                    list.extend_from_slice(rows);
                }
                cell_cost(list, opts.min_frames, k, opts.reweightings)
            })
            .collect();
        per_cell
            .iter()
            .fold((0.0, 0), |(cost, count), &(c, n)| (cost + c, count + n))
    }

    /// Replace the rows of frame `f`.
    fn replace(&mut self, f: usize, rows: Vec<(u64, CostRow)>) {
        for (key, _) in &self.frame_rows[f] {
            if let Some(list) = self.by_key.get_mut(key) {
                list.retain(|&(g, _)| g as usize != f);
            }
        }
        for (i, (key, _)) in rows.iter().enumerate() {
            let list = self.by_key.entry(*key).or_default();
            let at = list.partition_point(|&(g, _)| (g as usize) < f);
            list.insert(at, (f as u32, i as u32));
        }
        self.frame_rows[f] = rows;
    }
}

/// Rows grouped by cell (in frame order within each cell).
fn group(rows: impl IntoIterator<Item = (u64, CostRow)>) -> HashMap<u64, Vec<CostRow>> {
    let mut by_key: HashMap<u64, Vec<CostRow>> = HashMap::new();
    for (key, row) in rows {
        by_key.entry(key).or_default().push(row);
    }
    by_key
}

/// A shift tried.
struct Candidate<'p> {
    /// The video's mean reduced cost with it.
    mean: f64,
    /// The shift (mm).
    mm: f64,
    /// The video's total robust cost and rows counted with it.
    cost: f64,
    count: usize,
    /// The run's poses, renders and rows there.
    poses: Vec<Affine>,
    snaps: Vec<Snapshot<'p>>,
    rows: Vec<Vec<(u64, CostRow)>>,
}

/// Move each run of [`shift_runs`] along its views in steps of `search` while the mean reduced
/// cost falls, the other frames where they are (runs in video order, each against the poses
/// the runs before it left; see the module docs). `snaps` are the frames' renders at `poses` (replaced for
/// the frames moved); `pyramids` and `floors` as [`super::joint::refine_jointly`] makes them.
#[allow(clippy::too_many_arguments)]
pub(super) fn search_run_shifts<'p>(
    reg: &'p FrameRegistrar,
    pyramids: &'p [Option<ObservedPyramid>],
    floors: &[f64],
    poses: &mut [Affine],
    log_k: &[f64],
    roles: &[JointRole],
    snaps: &mut [Option<Snapshot<'p>>],
    opts: &JointOptions,
    search: &ShiftSearch,
) -> Vec<RunShift> {
    let k = reg.opts.huber;
    let render = |f: usize, pose: &Affine| -> Option<Snapshot<'p>> {
        render_frame(reg, &pyramids[f], floors[f], opts.level, pose, log_k[f])
    };
    let frame_rows: Vec<Vec<(u64, CostRow)>> = snaps
        .par_iter()
        .enumerate()
        .map(|(f, s)| {
            s.as_ref().map_or(Vec::new(), |s| {
                keyed_rows(s, f, &poses[f], log_k[f], opts.cell_mm)
            })
        })
        .collect();
    let mut cells = CellRows::new(frame_rows, opts, k);
    let mut moved = Vec::new();
    for run in shift_runs(roles, search.run_frames) {
        if run.iter().any(|&f| snaps[f].is_none()) {
            continue;
        }
        let start_mean = cells.cost / cells.count.max(1) as f64;
        let mut total_mm = 0.0;
        let mut directions = vec![-search.step_mm, search.step_mm];
        // After the last step that lowered the cost, half a step either way places the run
        // within a quarter step (from 1 mm ahead, steps of 0.75 mm alone end 0.25 mm ahead, and
        // the joint solve turned the run 0.5 deg to meet the rest; test
        // tests/joint_registration.rs).
        let mut halved = false;
        let mut steps = 0;
        loop {
            let mean = cells.cost / cells.count.max(1) as f64;
            let here = cells.rows_of(&run);
            let mut best: Option<Candidate<'p>> = None;
            for &mm in &directions {
                let cand: Vec<Affine> = run.iter().map(|&f| along_view(&poses[f], mm)).collect();
                let Some(fresh) = run
                    .par_iter()
                    .zip(&cand)
                    .map(|(&f, p)| render(f, p))
                    .collect::<Option<Vec<_>>>()
                else {
                    continue;
                };
                let rows: Vec<Vec<(u64, CostRow)>> = run
                    .par_iter()
                    .zip(&cand)
                    .zip(&fresh)
                    .map(|((&f, p), s)| keyed_rows(s, f, p, log_k[f], opts.cell_mm))
                    .collect();
                let moved_rows = group(rows.iter().flatten().copied());
                let mut keys: Vec<u64> = here.keys().chain(moved_rows.keys()).copied().collect();
                keys.sort_unstable();
                keys.dedup();
                let (c0, n0) = cells.touched(&keys, &run, &here, opts, k);
                let (c1, n1) = cells.touched(&keys, &run, &moved_rows, opts, k);
                let cost = cells.cost - c0 + c1;
                let count = (cells.count + n1).saturating_sub(n0);
                let m = cost / count.max(1) as f64;
                if best.as_ref().is_none_or(|b| m < b.mean) {
                    best = Some(Candidate {
                        mean: m,
                        mm,
                        cost,
                        count,
                        poses: cand,
                        snaps: fresh,
                        rows,
                    });
                }
            }
            let bar = match halved {
                false => mean * (1.0 - search.min_gain),
                true => mean,
            };
            let Some(b) = best.filter(|b| b.mean < bar) else {
                if total_mm == 0.0 || halved {
                    break;
                }
                halved = true;
                directions = vec![-0.5 * search.step_mm, 0.5 * search.step_mm];
                continue;
            };
            for (((&f, p), s), rows) in run.iter().zip(b.poses).zip(b.snaps).zip(b.rows) {
                poses[f] = p;
                snaps[f] = Some(s);
                cells.replace(f, rows);
            }
            (cells.cost, cells.count) = (b.cost, b.count);
            total_mm += b.mm;
            steps += 1;
            if halved {
                break;
            }
            if steps == search.max_steps {
                halved = true;
                directions = vec![-0.5 * search.step_mm, 0.5 * search.step_mm];
            } else {
                // On in the direction that lowered the cost.
                directions = vec![b.mm];
            }
        }
        if total_mm != 0.0 {
            moved.push(RunShift {
                frames: run,
                shift_mm: total_mm,
                cost_before: start_mean,
                cost_after: cells.cost / cells.count.max(1) as f64,
            });
        }
    }
    moved
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::SplitMix64 as Rng;
    use JointRole::{Anchor as A, Refined as R, Skipped as S};

    #[test]
    fn runs_cover_every_refined_frame_and_overlap_by_half() {
        let roles = [A, R, R, S, R, R, R, R, R, R];
        let runs = shift_runs(&roles, 4);
        assert_eq!(
            runs,
            vec![vec![1, 2, 4, 5], vec![4, 5, 6, 7], vec![6, 7, 8, 9]]
        );
        // Fewer refined frames than a run: one run of them all.
        assert_eq!(shift_runs(&[R, S, R], 4), vec![vec![0, 2]]);
        assert!(shift_runs(&[A, S], 4).is_empty());
    }

    /// Random rows of `frames` frames over `cells` cells, three channels.
    fn random_rows(frames: usize, cells: u64, rng: &mut Rng) -> Vec<Vec<(u64, CostRow)>> {
        (0..frames)
            .map(|f| {
                (0..60)
                    .map(|i| {
                        let row = CostRow {
                            frame: f as u32,
                            channel: (i % 3) as u8,
                            obs: rng.range_f32(0.2, 1.2),
                            per_albedo: rng.range_f32(0.3, 1.0),
                            fixed: rng.range_f32(0.0, 0.1),
                        };
                        ((rng.next_u64() % cells) + 100 * (f as u64 % 2), row)
                    })
                    .collect()
            })
            .collect()
    }

    /// The cost of a run moved, summed again over the cells it touches only, equals the cost
    /// summed over every cell with the run's rows replaced.
    #[test]
    fn a_runs_cost_summed_over_its_cells_equals_the_whole_sum() {
        let mut rng = Rng::new(11);
        let opts = JointOptions::default();
        let k = 0.05;
        let rows = random_rows(8, 40, &mut rng);
        let mut cells = CellRows::new(rows.clone(), &opts, k);
        let run = vec![3usize, 4, 5];
        let mut moved = random_rows(8, 70, &mut rng);
        for (f, r) in moved.iter_mut().enumerate() {
            for (key, row) in r.iter_mut() {
                row.frame = f as u32;
                *key += 17;
            }
        }
        let moved: Vec<Vec<(u64, CostRow)>> = run.iter().map(|&f| moved[f].clone()).collect();
        let here = cells.rows_of(&run);
        let there = group(moved.iter().flatten().copied());
        let mut keys: Vec<u64> = here.keys().chain(there.keys()).copied().collect();
        keys.sort_unstable();
        keys.dedup();
        let (c0, n0) = cells.touched(&keys, &run, &here, &opts, k);
        let (c1, n1) = cells.touched(&keys, &run, &there, &opts, k);
        let (cost, count) = (cells.cost - c0 + c1, cells.count + n1 - n0);

        let mut all = rows;
        for (&f, r) in run.iter().zip(&moved) {
            all[f] = r.clone();
        }
        let whole = CellRows::new(all, &opts, k);
        assert_eq!(count, whole.count);
        assert!(
            (cost - whole.cost).abs() < 1e-9 * whole.cost,
            "{cost} {}",
            whole.cost
        );
        // Some rows exceed the Huber threshold, and some cells are seen by one frame only.
        assert!(c0 > 0.0 && n0 > 0 && whole.count < 8 * 60);

        // Replacing the rows in place gives the same sums.
        for (&f, r) in run.iter().zip(moved) {
            cells.replace(f, r);
        }
        let keys: Vec<u64> = cells.by_key.keys().copied().collect();
        let (c, n) = cells.touched(&keys, &[], &HashMap::new(), &opts, k);
        assert_eq!(n, whole.count);
        assert!((c - whole.cost).abs() < 1e-9 * whole.cost);
    }

    #[test]
    fn a_pose_moves_along_its_own_view_axis() {
        // A camera looking along world +x (its z axis), centre at (1, 2, 3).
        let mut p = Affine::identity();
        p[(0, 0)] = 0.0;
        p[(0, 2)] = 1.0;
        p[(2, 0)] = -1.0;
        p[(2, 2)] = 0.0;
        p[(0, 3)] = 1.0;
        p[(1, 3)] = 2.0;
        p[(2, 3)] = 3.0;
        let q = along_view(&p, -1.5);
        assert_eq!((q[(0, 3)], q[(1, 3)], q[(2, 3)]), (-0.5, 2.0, 3.0), "{q:?}");
        assert_eq!(q.fixed_view::<3, 3>(0, 0), p.fixed_view::<3, 3>(0, 0));
    }
}
