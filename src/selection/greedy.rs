//! Greedy choice of the frames that add the most coverage: each cell keeps the best `K` views
//! chosen so far (their qualities, weighted by their frames' scores), a frame's gain is what
//! it would add to the sum of every cell's best `K`, and the frame with the largest gain is
//! chosen until the budget is spent or no frame adds enough. The sum of the best K per cell is
//! monotone submodular, so gains only shrink as frames are chosen: lazy evaluation (recompute
//! the gain of the frame on top of the heap only) picks the same frames as the plain greedy.

use super::coverage::FrameCoverage;
use std::cmp::Ordering;
use std::collections::BinaryHeap;

/// The best `K` weighted qualities of each cell chosen so far, descending.
#[derive(Clone, Debug)]
pub struct CoverState {
    keep: usize,
    best: Vec<f32>,
}

/// Which cells a frame's gain counts.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum GainOver {
    /// Every improvement of a cell's best K.
    AnyCell,
    /// Only cells no chosen frame sees at all (for frames that must not replace a better view).
    UnseenCells,
}

impl CoverState {
    /// No frame chosen yet, `cells` cells keeping `keep` views each (at least 1).
    pub fn new(cells: usize, keep: usize) -> CoverState {
        let keep = keep.max(1);
        CoverState {
            keep,
            best: vec![0.0; cells * keep],
        }
    }

    /// What adding `frame` with weight `w` would add.
    pub fn gain(&self, frame: &FrameCoverage, w: f64, over: GainOver) -> f64 {
        let k = self.keep;
        frame
            .cells
            .iter()
            .zip(&frame.quality)
            .map(|(&c, &q)| {
                let top = &self.best[c as usize * k..(c as usize + 1) * k];
                if over == GainOver::UnseenCells && top[0] > 0.0 {
                    return 0.0;
                }
                (w * q as f64 - top[k - 1] as f64).max(0.0)
            })
            .sum()
    }

    /// Add `frame` with weight `w`.
    pub fn add(&mut self, frame: &FrameCoverage, w: f64) {
        let k = self.keep;
        for (&c, &q) in frame.cells.iter().zip(&frame.quality) {
            let top = &mut self.best[c as usize * k..(c as usize + 1) * k];
            let v = (w * q as f64) as f32;
            if v > top[k - 1] {
                top[k - 1] = v;
                top.sort_unstable_by(|a, b| b.total_cmp(a));
            }
        }
    }

    /// Cells seen by at least one added frame.
    pub fn seen_cells(&self) -> usize {
        self.best
            .chunks_exact(self.keep)
            .filter(|t| t[0] > 0.0)
            .count()
    }
}

/// A frame's gain as last computed (an upper bound of its gain now).
#[derive(Clone, Copy, PartialEq)]
struct Bound(f64, usize);

impl Eq for Bound {}

impl PartialOrd for Bound {
    fn partial_cmp(&self, other: &Self) -> Option<Ordering> {
        Some(self.cmp(other))
    }
}

impl Ord for Bound {
    // Larger gain first; ties to the earlier frame.
    fn cmp(&self, other: &Self) -> Ordering {
        self.0.total_cmp(&other.0).then(other.1.cmp(&self.1))
    }
}

/// Choose up to `budget` of the `candidates` (indices into `frames` and `weights`) by lazy
/// greedy over `state`, each adding at least `min_gain`; the chosen frames are added to
/// `state`. Returns the chosen frames in the order chosen and every candidate's last
/// computed gain (indexed like `frames`; the gain when chosen for the chosen ones).
pub fn greedy_cover(
    frames: &[FrameCoverage],
    weights: &[f64],
    candidates: &[usize],
    budget: usize,
    min_gain: f64,
    over: GainOver,
    state: &mut CoverState,
) -> (Vec<usize>, Vec<f64>) {
    let mut last = vec![0.0; frames.len()];
    let mut heap: BinaryHeap<Bound> = candidates
        .iter()
        .map(|&f| {
            last[f] = state.gain(&frames[f], weights[f], over);
            Bound(last[f], f)
        })
        .collect();
    let mut chosen = Vec::new();
    while chosen.len() < budget {
        let Some(Bound(_, f)) = heap.pop() else {
            break;
        };
        let g = state.gain(&frames[f], weights[f], over);
        last[f] = g;
        if g < min_gain {
            // Gains only shrink: this frame adds too little now; the others get their last
            // bound checked the same way.
            continue;
        }
        if heap.peek().is_none_or(|b| g >= b.0) {
            state.add(&frames[f], weights[f]);
            chosen.push(f);
        } else {
            heap.push(Bound(g, f));
        }
    }
    // Refresh the gains of those left, for the record of why each was not chosen.
    for Bound(_, f) in heap {
        last[f] = state.gain(&frames[f], weights[f], over);
    }
    (chosen, last)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cov(cells: &[u32], q: f32) -> FrameCoverage {
        FrameCoverage {
            cells: cells.to_vec(),
            quality: vec![q; cells.len()],
        }
    }

    /// The plain greedy (every gain recomputed every step), to check the lazy one against.
    fn plain(frames: &[FrameCoverage], w: &[f64], budget: usize, keep: usize) -> Vec<usize> {
        let mut st = CoverState::new(64, keep);
        let mut chosen = Vec::new();
        for _ in 0..budget {
            let best = (0..frames.len())
                .filter(|f| !chosen.contains(f))
                .map(|f| (st.gain(&frames[f], w[f], GainOver::AnyCell), f))
                .max_by(|a, b| a.0.total_cmp(&b.0).then(b.1.cmp(&a.1)));
            match best {
                Some((g, f)) if g > 0.0 => {
                    st.add(&frames[f], w[f]);
                    chosen.push(f);
                }
                _ => break,
            }
        }
        chosen
    }

    #[test]
    fn lazy_greedy_matches_the_plain_greedy() {
        // Seeded overlapping windows of cells with varied qualities and weights.
        let mut rng = crate::rng::Pcg32::new(7, 1);
        let frames: Vec<FrameCoverage> = (0..30)
            .map(|_| {
                let a = (rng.uniform() * 50.0) as u32;
                let len = 3 + (rng.uniform() * 12.0) as u32;
                let cells: Vec<u32> = (a..(a + len).min(64)).collect();
                let quality = cells
                    .iter()
                    .map(|_| 0.1 + 0.9 * rng.uniform() as f32)
                    .collect();
                FrameCoverage { cells, quality }
            })
            .collect();
        let w: Vec<f64> = (0..30).map(|_| 0.3 + 0.7 * rng.uniform()).collect();
        let all: Vec<usize> = (0..30).collect();
        for keep in [1, 2, 3] {
            let mut st = CoverState::new(64, keep);
            let (lazy, _) = greedy_cover(&frames, &w, &all, 8, 1e-9, GainOver::AnyCell, &mut st);
            assert_eq!(lazy, plain(&frames, &w, 8, keep), "keep {keep}");
        }
    }

    #[test]
    fn gains_count_the_best_k_and_unseen_cells() {
        let frames = [
            cov(&[0, 1, 2, 3], 1.0),
            cov(&[2, 3, 4], 0.5),
            cov(&[0, 1], 1.0),
        ];
        let w = [1.0, 1.0, 0.5];
        let mut st = CoverState::new(8, 1);
        let (chosen, gains) =
            greedy_cover(&frames, &w, &[0, 1, 2], 3, 0.01, GainOver::AnyCell, &mut st);
        // Frame 0 (gain 4), then frame 1 (only cell 4 is new: 0.5); frame 2 adds nothing.
        assert_eq!(chosen, vec![0, 1]);
        assert_eq!(gains, vec![4.0, 0.5, 0.0]);
        assert_eq!(st.seen_cells(), 5);
        // Keeping the best two views per cell, frame 2's half-weight views count in 0 and 1.
        let mut st2 = CoverState::new(8, 2);
        let (chosen, gains) = greedy_cover(
            &frames,
            &w,
            &[0, 1, 2],
            3,
            0.01,
            GainOver::AnyCell,
            &mut st2,
        );
        assert_eq!(chosen, vec![0, 1, 2]);
        assert_eq!(gains, vec![4.0, 1.5, 1.0]);
        // Over unseen cells only, a frame that sees seen cells better gains nothing.
        let mut st3 = CoverState::new(8, 1);
        st3.add(&cov(&[0], 0.1), 1.0);
        assert_eq!(st3.gain(&frames[2], 1.0, GainOver::UnseenCells), 1.0);
        assert!((st3.gain(&frames[2], 1.0, GainOver::AnyCell) - 1.9).abs() < 1e-6);
    }
}
