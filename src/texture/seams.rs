//! The seam measure of a fused atlas: the texture's gradient across the borders between the
//! regions that different frames dominate, against its gradient within them. A fusion that
//! pastes frames side by side shows a step where the dominant frame changes (their shading
//! errors differ); a seamless one has the same gradient there as anywhere else.

use super::fusion::FusedTexture;
use super::texels::TexelSet;

/// Mean relative luminance step between 4-neighbour covered texels of the same chart.
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct SeamStats {
    /// Mean `|L_a - L_b| / ((L_a + L_b) / 2)` over neighbours dominated by different frames.
    pub across: f64,
    /// The same over neighbours dominated by the same frame.
    pub within: f64,
    /// Neighbour pairs across borders.
    pub pairs_across: usize,
    /// Neighbour pairs within regions.
    pub pairs_within: usize,
}

impl SeamStats {
    /// `across / within`: 1 when the borders are invisible in the gradient (0 when undefined).
    pub fn ratio(&self) -> f64 {
        if self.within > 0.0 {
            self.across / self.within
        } else {
            0.0
        }
    }
}

/// [`SeamStats`] of `fused` (its `dominant_frame` labels the regions).
pub fn seam_stats(fused: &FusedTexture, texels: &TexelSet) -> SeamStats {
    let w = texels.width as usize;
    let lum = |t: usize| {
        let c = &fused.rgb[3 * t..3 * t + 3];
        0.2126 * c[0] as f64 + 0.7152 * c[1] as f64 + 0.0722 * c[2] as f64
    };
    let (mut sum, mut count) = ([0f64; 2], [0usize; 2]);
    for (s, &t) in texels.texel.iter().enumerate() {
        let t = t as usize;
        if !fused.covered[t] {
            continue;
        }
        let right = (t % w + 1 < w).then_some(t + 1);
        let down = (t + w < fused.covered.len()).then_some(t + w);
        for u in [right, down].into_iter().flatten() {
            let q = texels.slot_of_texel[u];
            if q == u32::MAX || texels.chart[q as usize] != texels.chart[s] || !fused.covered[u] {
                continue;
            }
            let (a, b) = (lum(t), lum(u));
            if a + b <= 0.0 || a.is_nan() || b.is_nan() {
                continue;
            }
            let k = usize::from(fused.dominant_frame[t] != fused.dominant_frame[u]);
            sum[k] += (a - b).abs() / (0.5 * (a + b));
            count[k] += 1;
        }
    }
    let mean = |k: usize| {
        if count[k] > 0 {
            sum[k] / count[k] as f64
        } else {
            0.0
        }
    };
    SeamStats {
        across: mean(1),
        within: mean(0),
        pairs_across: count[1],
        pairs_within: count[0],
    }
}
