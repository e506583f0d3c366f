//! Each frame judged against its neighbours in time: its sharpness relative to theirs (the
//! content changes slowly, motion blur comes and goes), its exposure, and from both its score
//! (the weight its views of the wall get) or a hard failure.

use super::score::FrameStats;

/// Options of [`judge_frames`].
#[derive(Clone, Debug)]
pub struct JudgeOptions {
    /// Neighbours on each side whose median sharpness a frame is compared with.
    pub window: usize,
    /// A frame less sharp than this share of its neighbours' median is blurred. Phantom with
    /// 20% of its 300 frames blurred (a 3% of the width smear): blurred frames score at most
    /// 0.68, sharp ones at least 0.86.
    pub blurred_below: f64,
    /// More than this share of saturated pixels is a bad exposure.
    pub max_saturated_share: f64,
    /// More than this share of dark pixels is a bad exposure.
    pub max_dark_share: f64,
    /// Less than this share of the image pixels neither saturated nor dark: the frame shows
    /// nothing to register, fit or fuse (black, or white), and is never used, even within
    /// the budget. Used, three black frames among 80 with a tracker's poses stopped the build
    /// at its first fit of the light (BENCHMARKS.md, session 34).
    pub min_exposed_share: f64,
}

impl Default for JudgeOptions {
    fn default() -> Self {
        JudgeOptions {
            window: 7,
            blurred_below: 0.75,
            max_saturated_share: 0.25,
            max_dark_share: 0.75,
            min_exposed_share: 0.05,
        }
    }
}

/// Why a frame must not be used where a better one sees the same wall.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Failure {
    /// Far less sharp than its neighbours (motion blur, defocus).
    Blurred,
    /// Mostly saturated or dark.
    BadlyExposed,
    /// Next to nothing but saturated or dark pixels, or no image pixel at all
    /// ([`JudgeOptions::min_exposed_share`]): reported as badly exposed, and never used.
    Blank,
}

/// The verdict on one frame.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Judgement {
    /// Sharpness over the median of its neighbours' (1 = as sharp as they are).
    pub relative_sharpness: f64,
    /// Weight in (0, 1] of the frame's views of the wall: relative sharpness (capped at 1)
    /// times the share of pixels neither saturated nor dark; 0 for a frame without image.
    pub score: f64,
    /// A hard failure, if any.
    pub failure: Option<Failure>,
}

/// Judge every frame of a video from its [`FrameStats`], in video order.
pub fn judge_frames(stats: &[FrameStats], opts: &JudgeOptions) -> Vec<Judgement> {
    let n = stats.len();
    let mut near = Vec::with_capacity(2 * opts.window);
    (0..n)
        .map(|i| {
            near.clear();
            let (a, b) = (i.saturating_sub(opts.window), (i + opts.window + 1).min(n));
            near.extend((a..b).filter(|&j| j != i).map(|j| stats[j].sharpness));
            let reference = median(&mut near).unwrap_or(stats[i].sharpness);
            let s = &stats[i];
            let relative = if reference > 0.0 {
                s.sharpness / reference
            } else {
                1.0
            };
            let exposed = (1.0 - s.saturated_share - s.dark_share).max(0.0);
            let failure = if s.image_share <= 0.0 || exposed < opts.min_exposed_share {
                Some(Failure::Blank)
            } else if s.saturated_share > opts.max_saturated_share
                || s.dark_share > opts.max_dark_share
            {
                Some(Failure::BadlyExposed)
            } else if relative < opts.blurred_below {
                Some(Failure::Blurred)
            } else {
                None
            };
            Judgement {
                relative_sharpness: relative,
                score: relative.min(1.0) * exposed,
                failure,
            }
        })
        .collect()
}

fn median(v: &mut [f64]) -> Option<f64> {
    if v.is_empty() {
        return None;
    }
    let k = v.len() / 2;
    v.select_nth_unstable_by(k, f64::total_cmp);
    Some(v[k])
}

#[cfg(test)]
mod tests {
    use super::*;

    fn stats(sharpness: f64) -> FrameStats {
        FrameStats {
            sharpness,
            sharpness_max: sharpness,
            saturated_share: 0.0,
            dark_share: 0.1,
            image_share: 1.0,
        }
    }

    #[test]
    fn blur_is_judged_against_the_neighbours() {
        // Content whose sharpness triples over the video, one frame at a third of its
        // neighbours': only that one is blurred, wherever the drift is.
        let mut s: Vec<FrameStats> = (0..40).map(|i| stats(1.0 + 0.05 * i as f64)).collect();
        s[30].sharpness /= 3.0;
        s[5].saturated_share = 0.5;
        // Black but for 3 % of its pixels: the lens against the wall.
        s[39].dark_share = 0.97;
        let j = judge_frames(&s, &JudgeOptions::default());
        let failed: Vec<(usize, Failure)> = j
            .iter()
            .enumerate()
            .filter_map(|(i, v)| v.failure.map(|f| (i, f)))
            .collect();
        assert_eq!(
            failed,
            vec![
                (5, Failure::BadlyExposed),
                (30, Failure::Blurred),
                (39, Failure::Blank)
            ]
        );
        // Frame 30's reference: the upper median of frames 23..=37 but itself, frame 31's 2.55.
        assert!((j[30].relative_sharpness - (2.5 / 3.0) / 2.55).abs() < 1e-12);
        // Frame 10 (1.5) against frame 11's 1.55, times the 90% of pixels not dark.
        assert!(
            (j[10].score - 1.5 / 1.55 * 0.9).abs() < 1e-12,
            "{:?}",
            j[10]
        );
    }
}
