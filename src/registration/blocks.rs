//! Blocks of frames registered to an alias. In a straight airway the geometry repeats along
//! the axis (one cartilage ring after another), so a run of frames can converge together one
//! ring period away from the truth. Each frame of the run then agrees with its neighbours in
//! the run, so neither the per-frame outlier test nor the smoother sees anything wrong, but
//! the run's corrections jump at its ends by more than a tracker's error can change between
//! two frames. The tracker's continuity decides: the longest run is trusted, and outward from
//! it each run that jumps where it meets the settled one is registered again starting from
//! that one's correction; the new poses are kept when they join it and fit their frames about
//! as well as the old ones (an alias fits its frames about as well as the truth, or it would
//! not have been found).
//!
//! A round judges the jumps twice: in its own corrections (from the poses it started at),
//! then in the corrections from the tracker's poses. A run that an earlier round moved a ring
//! away starts this round there, and this round's own corrections join its neighbours'
//! without a jump; only from the tracker's poses does it jump.
//!
//! Measured on the demo phantom with 3 mm / 4 deg tracker drift: frames 2-17 (the trachea)
//! ended 3.9-4.2 mm behind along the view, one ring period, between two well-placed runs;
//! realigned, they end within 0.4 mm (BENCHMARKS.md). With 5 mm / 6 deg, the first round
//! put frames 0-15 a ring behind; judged from each round's start poses no later round saw a
//! jump, and frames 2-12 were kept there, converged, 4.0-4.1 mm off (new views 28.64 dB);
//! judged from the tracker's poses as well, the second round realigns them (within 0.2 mm;
//! new views 29.96-30.09 dB in two builds; BENCHMARKS.md, session 45).

use super::frame::FrameRegistration;
use super::pose::{apply_delta, delta_between, PoseDelta};
use crate::camera::pose::camera_centre;
use crate::math::Affine;
use crate::Result;

/// Options of [`realign_blocks`].
#[derive(Clone, Debug)]
pub struct BlockOptions {
    /// Corrections of consecutive frames whose shifts differ by more than this (mm) are a
    /// jump no tracker makes (its error changes by a few tenths of a mm per frame). Rotations
    /// are not compared: a frame's roll about a round airway is weakly fixed by its own
    /// image, and jumps of 3 degrees in it are common before the smoother (on the demo
    /// phantom with 3 mm / 4 deg drift, testing rotations too found such runs all over the
    /// video and left 0.88 deg median error, against 0.69 deg comparing shifts alone).
    pub jump_mm: f64,
    /// Allowed growth of the jump per video frame between two kept frames (mm): after a
    /// frame selection, kept frames far apart may differ by more drift.
    pub drift_mm_per_frame: f64,
    /// A realigned run is kept when its frames' total cost is at most this factor times the
    /// old one.
    pub cost_factor: f64,
    /// Shortest run to realign (a single frame that jumps is an outlier, flagged as one).
    pub min_frames: usize,
}

impl Default for BlockOptions {
    fn default() -> Self {
        BlockOptions {
            jump_mm: 2.0,
            drift_mm_per_frame: 0.1,
            cost_factor: 1.1,
            min_frames: 2,
        }
    }
}

/// Whether frames `a` < `b` (positions `na` < `nb` in the video) with corrections `da`, `db`
/// are further apart than a tracker's error can move.
fn jumps(da: &PoseDelta, db: &PoseDelta, na: usize, nb: usize, opts: &BlockOptions) -> bool {
    let grow = opts.drift_mm_per_frame * nb.saturating_sub(na).saturating_sub(1) as f64;
    (db.translation_mm - da.translation_mm).norm() > opts.jump_mm + grow
}

/// The runs of usable frames (`usable`) whose consecutive corrections join without a jump,
/// in video order.
fn runs(
    corrections: &[PoseDelta],
    usable: &[bool],
    numbers: &[usize],
    opts: &BlockOptions,
) -> Vec<Vec<usize>> {
    let mut out: Vec<Vec<usize>> = Vec::new();
    let mut last: Option<usize> = None;
    for f in (0..corrections.len()).filter(|&f| usable[f]) {
        match last {
            Some(l)
                if !jumps(
                    &corrections[l],
                    &corrections[f],
                    numbers[l],
                    numbers[f],
                    opts,
                ) =>
            {
                if let Some(run) = out.last_mut() {
                    run.push(f);
                }
            }
            _ => out.push(vec![f]),
        }
        last = Some(f);
    }
    out
}

/// Register again, from the correction of the runs next to it, every run of frames whose
/// corrections jump where it meets them (see the module docs). The longest run is trusted;
/// the others are taken in turn outward from it, each set against the settled run on its
/// inner side. `results[f].correction` is relative to `started[f]`, the pose this round
/// started the frame at; the jumps are judged in the corrections from `judged_from[f]` to the
/// results' poses (the round's start, or the tracker's poses: see the module docs).
/// `usable[f]` says which frames converged; `numbers` are the frames' positions in the video
/// (empty: consecutive); `register(jobs)` registers each job's frame from its start pose, and
/// `fits(r)` says whether a result converged to a cost like the video's. Returns the frames
/// whose results were replaced.
#[allow(clippy::too_many_arguments)]
pub fn realign_blocks<R, F>(
    results: &mut [FrameRegistration],
    started: &[Affine],
    judged_from: &[Affine],
    usable: &[bool],
    numbers: &[usize],
    opts: &BlockOptions,
    register: R,
    fits: F,
) -> Result<Vec<usize>>
where
    R: Fn(&[(usize, Affine)]) -> Result<Vec<FrameRegistration>>,
    F: Fn(&FrameRegistration) -> bool,
{
    let n = results.len();
    let consecutive: Vec<usize> = (0..n).collect();
    let numbers = if numbers.len() == n {
        numbers
    } else {
        &consecutive
    };
    let total = |f: usize, r: &FrameRegistration| delta_between(&judged_from[f], &r.pose);
    let runs = runs(
        &(0..n).map(|f| total(f, &results[f])).collect::<Vec<_>>(),
        usable,
        numbers,
        opts,
    );
    let Some(anchor) = (0..runs.len()).max_by_key(|&i| (runs[i].len(), std::cmp::Reverse(i)))
    else {
        return Ok(Vec::new());
    };
    let mut replaced = Vec::new();
    // Outward from the anchor: towards the start of the video each run's last frame meets the
    // reference (the settled run's first), towards the end its first frame does.
    let (anchor_first, anchor_last) = (runs[anchor][0], runs[anchor][runs[anchor].len() - 1]);
    let sides = [
        ((0..anchor).rev().collect::<Vec<_>>(), anchor_first, true),
        ((anchor + 1..runs.len()).collect(), anchor_last, false),
    ];
    for (side, mut reference, towards_start) in sides {
        for i in side {
            let run = &runs[i];
            if run.len() < opts.min_frames {
                continue;
            }
            let meets = if towards_start {
                run[run.len() - 1]
            } else {
                run[0]
            };
            let (r, m) = (
                total(reference, &results[reference]),
                total(meets, &results[meets]),
            );
            let (nr, nm) = (numbers[reference], numbers[meets]);
            let jumped = |m: &PoseDelta| match towards_start {
                true => jumps(m, &r, nm, nr, opts),
                false => jumps(&r, m, nr, nm, opts),
            };
            if jumped(&m) {
                // Each frame starts turned as this round turned the settled frame, its centre
                // at its `judged_from` pose's moved as the settled frame's is from its own: the
                // tracker's continuity. (Started where the run ended instead, shifted alone,
                // the demo phantom with 3 mm / 4 deg drift kept frames 0-25 rolled 1.2-1.9
                // deg: 28.89 dB new views against 31.78 dB.)
                let turn = results[reference].correction.rotation;
                let jobs: Vec<(usize, Affine)> = run
                    .iter()
                    .map(|&f| {
                        let centre = camera_centre(&judged_from[f]).coords + r.translation_mm;
                        let step = PoseDelta {
                            translation_mm: centre - camera_centre(&started[f]).coords,
                            rotation: turn,
                        };
                        (f, apply_delta(&started[f], &step))
                    })
                    .collect();
                let fresh = register(&jobs)?;
                let old_cost: f64 = run.iter().map(|&f| results[f].cost_after).sum();
                let new_cost: f64 = fresh.iter().map(|r| r.cost_after).sum();
                let k = run.iter().position(|&f| f == meets).unwrap_or(0);
                let joins = !jumped(&total(meets, &fresh[k]));
                if joins && fresh.iter().all(&fits) && new_cost <= opts.cost_factor * old_cost {
                    for (&f, r) in run.iter().zip(fresh) {
                        results[f] = r;
                        replaced.push(f);
                    }
                }
            }
            reference = if towards_start {
                run[0]
            } else {
                run[run.len() - 1]
            };
        }
    }
    replaced.sort_unstable();
    Ok(replaced)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::math::Vector3;
    use crate::registration::frame::FrameStatus;

    /// Frames along +z, 2 mm apart, given poses exact.
    fn given(n: usize) -> Vec<Affine> {
        (0..n)
            .map(|f| {
                let mut m = Affine::identity();
                m[(2, 3)] = 2.0 * f as f64;
                m
            })
            .collect()
    }

    /// A result at `pose`, correction relative to `given`, with `cost`.
    fn result(given: &Affine, pose: Affine, cost: f64) -> FrameRegistration {
        FrameRegistration {
            pose,
            correction: delta_between(given, &pose),
            gain_factor: 1.0,
            cost_before: cost,
            cost_after: cost,
            points: 1000,
            iterations: 5,
            status: FrameStatus::Converged,
            information: [[0.0; 6]; 6],
        }
    }

    fn shifted(pose: &Affine, dz: f64) -> Affine {
        apply_delta(
            pose,
            &PoseDelta {
                translation_mm: Vector3::new(0.1, 0.0, dz),
                rotation: Vector3::zeros(),
            },
        )
    }

    /// Frames `block` sit `alias` mm along z from where the others (0.1 mm off in x, like a
    /// drift) put them; the registration converges where it starts, at cost `cost(f, start)`.
    fn run_case(
        n: usize,
        block: std::ops::Range<usize>,
        alias: f64,
        cost: impl Fn(usize, &Affine) -> f64,
    ) -> (Vec<FrameRegistration>, Vec<usize>, usize) {
        let given = given(n);
        let mut results: Vec<FrameRegistration> = (0..n)
            .map(|f| {
                let dz = if block.contains(&f) { alias } else { 0.0 };
                let p = shifted(&given[f], dz);
                result(&given[f], p, cost(f, &p))
            })
            .collect();
        let calls = std::cell::Cell::new(0);
        let register = |jobs: &[(usize, Affine)]| -> Result<Vec<FrameRegistration>> {
            calls.set(calls.get() + jobs.len());
            Ok(jobs
                .iter()
                .map(|(f, s)| result(&given[*f], *s, cost(*f, s)))
                .collect())
        };
        let replaced = realign_blocks(
            &mut results,
            &given,
            &given,
            &vec![true; n],
            &[],
            &BlockOptions::default(),
            register,
            |r| r.cost_after < 2.0,
        )
        .unwrap();
        (results, replaced, calls.get())
    }

    #[test]
    fn a_run_one_ring_away_is_moved_to_join_its_neighbours() {
        let (results, replaced, calls) = run_case(30, 3..10, -4.0, |_, _| 1.0);
        assert_eq!(replaced, (3..10).collect::<Vec<_>>());
        assert_eq!(calls, 7);
        for r in &results {
            let d = r.correction;
            assert!(
                (d.translation_mm - Vector3::new(0.1, 0.0, 0.0)).norm() < 1e-9,
                "{d:?}"
            );
        }
    }

    #[test]
    fn a_run_an_earlier_round_moved_is_judged_from_the_tracker() {
        // Frames 3-9 started this round a ring away already: their corrections from there are
        // nothing and join their neighbours', but from the tracker's poses they jump.
        let given = given(30);
        let started: Vec<Affine> = (0..30)
            .map(|f| shifted(&given[f], if (3..10).contains(&f) { -4.0 } else { 0.0 }))
            .collect();
        let mut results: Vec<FrameRegistration> =
            started.iter().map(|p| result(p, *p, 1.0)).collect();
        let register = |jobs: &[(usize, Affine)]| -> Result<Vec<FrameRegistration>> {
            Ok(jobs
                .iter()
                .map(|(f, s)| result(&started[*f], *s, 1.0))
                .collect())
        };
        let fits = |r: &FrameRegistration| r.cost_after < 2.0;
        let opts = BlockOptions::default();
        let usable = [true; 30];
        let own = realign_blocks(
            &mut results,
            &started,
            &started,
            &usable,
            &[],
            &opts,
            register,
            fits,
        );
        assert!(own.unwrap().is_empty());
        let replaced = realign_blocks(
            &mut results,
            &started,
            &given,
            &usable,
            &[],
            &opts,
            register,
            fits,
        );
        assert_eq!(replaced.unwrap(), (3..10).collect::<Vec<_>>());
        for (f, r) in results.iter().enumerate() {
            let off = delta_between(&shifted(&given[f], 0.0), &r.pose);
            assert!(off.mm() < 1e-9, "frame {f}: {off:?}");
        }
    }

    #[test]
    fn a_run_that_fits_its_frames_much_better_where_it_is_stays() {
        // The run's own place costs 1.0, its neighbours' correction 1.5 (more than 10% worse).
        let given = given(30);
        let cost = |f: usize, p: &Affine| {
            let at_alias = (p[(2, 3)] - given[f][(2, 3)]).abs() > 2.0;
            if (3..10).contains(&f) && !at_alias {
                1.5
            } else {
                1.0
            }
        };
        let (results, replaced, _) = run_case(30, 3..10, -4.0, cost);
        assert!(
            replaced.iter().all(|f| !(3..10).contains(f)),
            "{replaced:?}"
        );
        assert!((results[5].correction.translation_mm.z + 4.0).abs() < 1e-9);
    }

    #[test]
    fn single_frames_and_smooth_videos_are_left_alone() {
        // One frame off is an outlier, flagged elsewhere; no jump anywhere: nothing to do.
        let (_, replaced, calls) = run_case(30, 12..13, -4.0, |_, _| 1.0);
        assert!(replaced.is_empty() && calls == 0);
        let (_, replaced, calls) = run_case(30, 0..0, 0.0, |_, _| 1.0);
        assert!(replaced.is_empty() && calls == 0);
    }

    #[test]
    fn a_jump_within_the_drift_a_frame_gap_allows_is_not_a_break() {
        let c = |z: f64| PoseDelta {
            translation_mm: Vector3::new(0.0, 0.0, z),
            rotation: Vector3::zeros(),
        };
        let opts = BlockOptions::default();
        assert!(jumps(&c(0.0), &c(2.5), 10, 11, &opts));
        // Ten video frames apart (a frame selection kept every tenth): 2 + 9 x 0.1 mm allowed.
        assert!(!jumps(&c(0.0), &c(2.5), 10, 20, &opts));
        assert!(jumps(&c(0.0), &c(3.0), 10, 20, &opts));
    }
}
