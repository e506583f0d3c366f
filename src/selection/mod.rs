//! Frame selection for long videos (issue 21): which frames a build uses.
//!
//! Steps, each on plain data: (1) [`score::score_frame`] measures every decoded frame once
//! (sharpness in its least sharp direction, saturated and dark shares inside the mask);
//! (2) [`judge::judge_frames`] compares each frame's sharpness with its neighbours' in time and
//! gives it a score and possibly a hard failure (blurred, badly exposed); (3) the caller
//! ray casts each frame on a coarse grid into a [`coverage::FrameCoverage`] (the wall cells it
//! sees and how well); (4) [`choose_frames`] picks, under the budget, the frames that add the
//! most coverage weighted by their scores ([`greedy`]). Frames with a hard failure are only
//! considered afterwards, for wall no healthy chosen frame sees at all. A video within the
//! budget is used whole.

pub mod coverage;
pub mod greedy;
pub mod judge;
pub mod score;

pub use coverage::{CoverageGrid, FrameCoverage, WallHit};
pub use greedy::{greedy_cover, CoverState, GainOver};
pub use judge::{judge_frames, Failure, JudgeOptions, Judgement};
pub use score::{score_frame, FrameStats, ScoreOptions};

/// Options of the frame selection.
#[derive(Clone, Debug)]
pub struct SelectionOptions {
    /// Most frames used (0: every frame, no selection runs).
    pub max_frames: usize,
    /// Per-frame measurements.
    pub score: ScoreOptions,
    /// Blur and exposure verdicts.
    pub judge: JudgeOptions,
    /// Views kept per wall cell: a frame adds coverage when it sees a cell better than the
    /// cell's K-th best chosen view (1: only the best view counts).
    pub views_per_cell: usize,
    /// A frame adds no coverage when its gain is below this share of the mean healthy
    /// frame's value on an empty wall.
    pub min_gain_share: f64,
    /// Edge of a coverage cell on the wall (mm).
    pub cell_mm: f64,
    /// Most rays per frame of the coverage ray cast (the camera is reduced by powers of two
    /// until it has no more pixels than this).
    pub max_rays: usize,
}

impl Default for SelectionOptions {
    fn default() -> Self {
        SelectionOptions {
            max_frames: 0,
            score: ScoreOptions::default(),
            judge: JudgeOptions::default(),
            // The texture averages sensor noise over the views of each texel: on 300 frames
            // 640x640 (no blur), 2 views per cell keep 66 frames and score 0.70 dB under all
            // frames on new views, 4 keep 113 and score 0.25 dB under (BENCHMARKS.md).
            views_per_cell: 4,
            min_gain_share: 0.01,
            cell_mm: 1.0,
            max_rays: 8192,
        }
    }
}

/// Why a frame is used or not.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Reason {
    /// Used.
    Chosen,
    /// Far less sharp than its neighbours, and its wall is seen by better frames.
    Blurred,
    /// Mostly saturated or dark, and its wall is seen by better frames.
    BadlyExposed,
    /// The chosen frames already see its wall as well.
    NoNewCoverage,
    /// It would add coverage, but the budget was spent on frames that add more.
    OverBudget,
    /// Without a tracker (`--poses first`), between the frames tracked: a video longer than
    /// the tracking's budget is tracked on frames evenly spaced in time.
    NotTracked,
}

impl Reason {
    /// Every reason, in report order.
    pub const ALL: [Reason; 6] = [
        Reason::Chosen,
        Reason::Blurred,
        Reason::BadlyExposed,
        Reason::NoNewCoverage,
        Reason::OverBudget,
        Reason::NotTracked,
    ];

    /// The reason a frame with the hard failure `f` is not used.
    pub fn of_failure(f: Failure) -> Reason {
        match f {
            Failure::Blurred => Reason::Blurred,
            Failure::BadlyExposed | Failure::Blank => Reason::BadlyExposed,
        }
    }

    /// The failure whose reason has the name `name` (as [`Reason::name`]).
    pub fn failure_named(name: &str) -> Option<Failure> {
        [Failure::Blurred, Failure::BadlyExposed]
            .into_iter()
            .find(|&f| Reason::of_failure(f).name() == name)
    }

    /// The name used in model.json and the report.
    pub fn name(self) -> &'static str {
        match self {
            Reason::Chosen => "chosen",
            Reason::Blurred => "blurred",
            Reason::BadlyExposed => "badly_exposed",
            Reason::NoNewCoverage => "adds_no_coverage",
            Reason::OverBudget => "over_budget",
            Reason::NotTracked => "not_tracked",
        }
    }
}

/// The decision on one frame.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Decision {
    /// Why (used = `Reason::Chosen`).
    pub reason: Reason,
    /// Coverage the frame added when chosen, or would have added at the end (weighted
    /// quality summed over cells).
    pub gain: f64,
}

/// True when [`choose_frames`] needs every frame's coverage: more frames than the budget
/// (within it every frame is used: a short video's neighbouring frames are too far apart in
/// content for their sharpness to be compared; the 80-frame demo has sharp frames at 0.52
/// of their neighbours').
pub fn needs_coverage(judged: &[Judgement], max_frames: usize) -> bool {
    max_frames > 0 && judged.len() > max_frames
}

/// Decide every frame: `judged` from [`judge_frames`], `coverage` one per frame on a grid
/// of `cells` cells (may be empty when [`needs_coverage`] is false).
pub fn choose_frames(
    judged: &[Judgement],
    coverage: &[FrameCoverage],
    cells: usize,
    opts: &SelectionOptions,
) -> Vec<Decision> {
    let n = judged.len();
    let budget = if opts.max_frames == 0 {
        n
    } else {
        opts.max_frames
    };
    let chosen = |gain| Decision {
        reason: Reason::Chosen,
        gain,
    };
    if !needs_coverage(judged, budget) || coverage.len() != n {
        // Within the budget every frame is used but those that show nothing.
        return judged
            .iter()
            .map(|j| match j.failure {
                Some(Failure::Blank) => Decision {
                    reason: Reason::BadlyExposed,
                    gain: 0.0,
                },
                _ => chosen(0.0),
            })
            .collect();
    }
    // From here on there are more frames than the budget.
    let weights: Vec<f64> = judged.iter().map(|j| j.score).collect();
    let (healthy, failed) = healthy_and_failed(judged);
    let mean_value = healthy
        .iter()
        .map(|&i| weights[i] * coverage[i].total())
        .sum::<f64>()
        / healthy.len().max(1) as f64;
    let min_gain = (opts.min_gain_share * mean_value).max(1e-9);
    let mut state = CoverState::new(cells, opts.views_per_cell);
    let mut decisions: Vec<Decision> = vec![chosen(0.0); n];
    let (picked, gains) = greedy_cover(
        coverage,
        &weights,
        &healthy,
        budget,
        min_gain,
        GainOver::AnyCell,
        &mut state,
    );
    let spent = picked.len() >= budget;
    for &i in &healthy {
        decisions[i] = Decision {
            reason: if gains[i] >= min_gain && spent {
                Reason::OverBudget
            } else {
                Reason::NoNewCoverage
            },
            gain: gains[i],
        };
    }
    for &i in &picked {
        decisions[i] = chosen(gains[i]);
    }
    let used = picked.len();
    // Failed frames, only for wall no chosen frame sees.
    let (picked, gains) = greedy_cover(
        coverage,
        &weights,
        &failed,
        budget.saturating_sub(used),
        min_gain,
        GainOver::UnseenCells,
        &mut state,
    );
    for i in 0..n {
        if judged[i].failure.is_some() {
            decisions[i] = Decision {
                reason: failure_reason(judged[i].failure, Reason::BadlyExposed),
                gain: gains[i],
            };
        }
    }
    for &i in &picked {
        decisions[i] = chosen(gains[i]);
    }
    decisions
}

/// The frames judged healthy, and those judged blurred or badly exposed (a blank frame is
/// neither: it is never used, not even for wall no other frame sees).
fn healthy_and_failed(judged: &[Judgement]) -> (Vec<usize>, Vec<usize>) {
    let healthy = (0..judged.len())
        .filter(|&i| judged[i].failure.is_none())
        .collect();
    let failed = (0..judged.len())
        .filter(|&i| matches!(judged[i].failure, Some(f) if f != Failure::Blank))
        .collect();
    (healthy, failed)
}

/// The reason of a frame judged `failure`, `healthy` when it was not.
fn failure_reason(failure: Option<Failure>, healthy: Reason) -> Reason {
    failure.map_or(healthy, Reason::of_failure)
}

/// The frames to track when the poses are not known yet (`--poses first`: coverage cannot
/// be cast before the frames are tracked): the first (its pose is the one given) and the
/// frames not judged failed, at most `most` of them, evenly spaced in time from the first to
/// the last. They are `Chosen` for now, the others `NotTracked` (or their failure's reason);
/// once they are tracked [`choose_frames`] chooses among them. A blurred frame is left out of
/// the tracking as of the texture: smeared, it fits the model's smooth shading better than a
/// sharp frame, and the tracker's cost gate, set by the frames it accepted, then refused the
/// sharp ones (a minute of HD video with 20% blurred frames, the first among them: lost at
/// its fourth tracked frame).
pub fn frames_to_track(judged: &[Judgement], most: usize) -> Vec<Decision> {
    let n = judged.len();
    let mut decisions: Vec<Decision> = judged
        .iter()
        .map(|j| Decision {
            reason: failure_reason(j.failure, Reason::NotTracked),
            gain: 0.0,
        })
        .collect();
    let candidates: Vec<usize> = (0..n)
        .filter(|&i| i == 0 || judged[i].failure.is_none())
        .collect();
    let m = most.max(1).min(candidates.len());
    for k in 0..m {
        // Strictly increasing in k, as m <= candidates.len().
        decisions[candidates[k * (candidates.len() - 1) / (m - 1).max(1)]].reason = Reason::Chosen;
    }
    decisions
}

#[cfg(test)]
mod tests {
    use super::*;

    fn judged(score: f64, failure: Option<Failure>) -> Judgement {
        Judgement {
            relative_sharpness: score,
            score,
            failure,
        }
    }

    fn cov(cells: std::ops::Range<u32>) -> FrameCoverage {
        FrameCoverage {
            quality: vec![1.0; cells.len()],
            cells: cells.collect(),
        }
    }

    #[test]
    fn within_the_budget_every_frame_is_used_but_the_blank() {
        let j = vec![
            judged(1.0, None),
            judged(0.3, Some(Failure::Blurred)),
            judged(0.0, Some(Failure::Blank)),
            judged(0.5, Some(Failure::BadlyExposed)),
        ];
        let reasons: Vec<Reason> = choose_frames(&j, &[], 10, &SelectionOptions::default())
            .iter()
            .map(|d| d.reason)
            .collect();
        assert_eq!(
            reasons,
            [
                Reason::Chosen,
                Reason::Chosen,
                Reason::BadlyExposed,
                Reason::Chosen
            ]
        );
    }

    #[test]
    fn failed_frames_only_fill_wall_nobody_else_sees() {
        // Frames 0-3 see cells 0..40 in overlapping strips; frame 4 (blurred) sees 0..10,
        // covered by frame 0; frame 5 (badly exposed) alone sees 60..70.
        let j = vec![
            judged(1.0, None),
            judged(1.0, None),
            judged(1.0, None),
            judged(0.9, None),
            judged(0.3, Some(Failure::Blurred)),
            judged(0.5, Some(Failure::BadlyExposed)),
        ];
        let c = vec![
            cov(0..12),
            cov(10..22),
            cov(20..32),
            cov(28..40),
            cov(0..10),
            cov(60..70),
        ];
        let opts = SelectionOptions {
            views_per_cell: 1,
            ..Default::default()
        };
        use Reason::*;
        let with = |max_frames| SelectionOptions {
            max_frames,
            ..opts.clone()
        };
        // Budget 5: the four healthy frames, then frame 5 for its own wall, not frame 4.
        let d = choose_frames(&j, &c, 80, &with(5));
        let reasons: Vec<Reason> = d.iter().map(|d| d.reason).collect();
        assert_eq!(
            reasons,
            vec![Chosen, Chosen, Chosen, Chosen, Blurred, Chosen]
        );
        assert!((d[5].gain - 5.0).abs() < 1e-9);
        // Within the budget the whole video is used.
        let d = choose_frames(&j, &c, 80, &with(6));
        assert!(d.iter().all(|d| d.reason == Chosen));
        // A blank frame is not used even for wall no other frame sees (what its pose casts
        // is not what it shows), over the budget or within it.
        let mut jb = j.clone();
        jb.push(judged(0.04, Some(Failure::Blank)));
        let mut cb = c.clone();
        cb.push(cov(70..80));
        for budget in [6, 7] {
            let d = choose_frames(&jb, &cb, 80, &with(budget));
            assert_eq!(d[6].reason, BadlyExposed, "budget {budget}");
        }
        // Budget 3: frames 0, 2, 1 (gains 12, 12, 8); frame 3 would add 8 x 0.9: over budget;
        // frame 5 has no budget left.
        let d = choose_frames(
            &j,
            &c,
            80,
            &SelectionOptions {
                max_frames: 3,
                ..opts
            },
        );
        let reasons: Vec<Reason> = d.iter().map(|d| d.reason).collect();
        assert_eq!(
            reasons,
            vec![Chosen, Chosen, Chosen, OverBudget, Blurred, BadlyExposed]
        );
        assert!((d[3].gain - 7.2).abs() < 1e-6);
    }

    #[test]
    fn frames_to_track_are_spaced_evenly_over_the_healthy_from_the_first() {
        use Reason::*;
        // Frame 0 blurred (tracked all the same: its pose is the one given), 4 and 7 failed.
        let mut j = vec![judged(1.0, None); 12];
        j[0].failure = Some(Failure::Blurred);
        j[4].failure = Some(Failure::Blurred);
        j[7].failure = Some(Failure::BadlyExposed);
        let reasons =
            |most| -> Vec<Reason> { frames_to_track(&j, most).iter().map(|d| d.reason).collect() };
        // Candidates 0 1 2 3 5 6 8 9 10 11; four of them: positions 0, 3, 6, 9.
        let r = reasons(4);
        let tracked: Vec<usize> = (0..12).filter(|&i| r[i] == Chosen).collect();
        assert_eq!(tracked, vec![0, 3, 8, 11]);
        assert_eq!((r[1], r[4], r[7]), (NotTracked, Blurred, BadlyExposed));
        // A budget above the candidates tracks all of them.
        assert_eq!(reasons(50).iter().filter(|&&r| r == Chosen).count(), 10);
        assert_eq!(reasons(1)[0], Chosen);
    }
}
