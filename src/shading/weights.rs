//! Density weights (paper, §2.3): a 2-D histogram over (gamma, r) and `w_i = 1 / density`
//! of sample i's bin, so sparse regions of the (gamma, z) domain count as much as dense ones.

use super::samples::SampleSet;

/// How the histogram is laid out.
#[derive(Debug, Clone, PartialEq)]
pub struct WeightOptions {
    /// Samples per bin aimed at on average: bins per axis = sqrt(N / target), so a bin's
    /// count is a usable density estimate. Default 20.
    pub target_per_bin: f64,
    /// Fewest bins per axis. Default 4.
    pub min_bins: usize,
    /// Most bins per axis. Default 64.
    pub max_bins: usize,
}

impl Default for WeightOptions {
    fn default() -> Self {
        WeightOptions {
            target_per_bin: 20.0,
            min_bins: 4,
            max_bins: 64,
        }
    }
}

/// The weights and the histogram they came from.
#[derive(Debug, Clone, PartialEq)]
pub struct DensityWeights {
    /// One weight per sample, scaled so their mean is 1 (the scale does not change the fit,
    /// and keeps the cost comparable to an unweighted one).
    pub weights: Vec<f32>,
    /// Bins along gamma.
    pub bins_gamma: usize,
    /// Bins along r = normalised depth.
    pub bins_r: usize,
    /// Bins holding at least one sample.
    pub occupied_bins: usize,
}

/// Density weights for `samples`: the histogram spans the samples' gamma range and r in [0, 1];
/// each sample's weight is the inverse of its bin's count (all bins have the same area, so the
/// count is the density up to a constant).
pub fn density_weights(samples: &SampleSet, opts: &WeightOptions) -> DensityWeights {
    let n = samples.len();
    if n == 0 {
        return DensityWeights {
            weights: Vec::new(),
            bins_gamma: 0,
            bins_r: 0,
            occupied_bins: 0,
        };
    }
    let per_axis = (n as f64 / opts.target_per_bin.max(1.0)).sqrt().round() as usize;
    let nb = per_axis.clamp(
        opts.min_bins.max(1),
        opts.max_bins.max(opts.min_bins.max(1)),
    );
    let (g_lo, g_hi) = samples
        .gamma
        .iter()
        .fold((f32::INFINITY, f32::NEG_INFINITY), |(lo, hi), &g| {
            (lo.min(g), hi.max(g))
        });
    let g_span = f64::from(g_hi - g_lo).max(1e-12);
    let bin_of = |i: usize| -> usize {
        let gi = ((f64::from(samples.gamma[i] - g_lo) / g_span) * nb as f64) as usize;
        let ri = (samples.r(i) * nb as f64) as usize;
        gi.min(nb - 1) * nb + ri.min(nb - 1)
    };
    let bins: Vec<usize> = (0..n).map(bin_of).collect();
    let mut counts = vec![0u32; nb * nb];
    for &b in &bins {
        counts[b] += 1;
    }
    let occupied = counts.iter().filter(|&&c| c > 0).count();
    // Sum of 1/count over samples = number of occupied bins; rescale to mean 1.
    let scale = n as f64 / occupied as f64;
    let weights = bins
        .iter()
        .map(|&b| (scale / f64::from(counts[b])) as f32)
        .collect();
    DensityWeights {
        weights,
        bins_gamma: nb,
        bins_r: nb,
        occupied_bins: occupied,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_occupied_bin_gets_equal_total_weight() {
        // 900 samples in one corner, 100 spread elsewhere.
        let mut s = SampleSet {
            z_min: 10.0,
            z_max: 20.0,
            ..Default::default()
        };
        for i in 0..1000 {
            let (g, z) = if i < 900 {
                (0.1 + 0.01 * (i % 10) as f32, 10.5)
            } else {
                let k = (i - 900) as f32;
                (0.1 + 0.009 * k, 10.0 + 0.1 * k)
            };
            s.gamma.push(g);
            s.z.push(z);
        }
        let w = density_weights(&s, &WeightOptions::default());
        assert_eq!(w.bins_gamma, 7); // sqrt(1000/20) = 7.07
        let mean = w.weights.iter().map(|&x| f64::from(x)).sum::<f64>() / 1000.0;
        assert!((mean - 1.0).abs() < 1e-5);
        // The dense corner's samples weigh far less than the sparse ones.
        assert!(w.weights[0] * 20.0 < w.weights[950]);
    }
}
