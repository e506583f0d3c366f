//! Density weights (paper, §2.3): a histogram over the samples' coordinates (gamma and depth
//! for Psi; gamma, depth and the angle off the axis for the calibrated light) and
//! `w_i = 1 / count` of sample i's bin, so sparse regions of the domain count as much as
//! dense ones. One N-dimensional histogram serves every model.

use rayon::prelude::*;

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
    /// Bins along each axis.
    pub bins_per_axis: usize,
    /// Bins holding at least one sample.
    pub occupied_bins: usize,
}

/// Inverse-density weights of `n` samples whose coordinates, scaled to [0, 1] per axis, are
/// `unit(i)` (values outside are clamped into the edge bins). Bins per axis:
/// `(n / target_per_bin)^(1/D)`, clamped to `[min_bins, max_bins]`; all bins have the same
/// volume, so a bin's count is the density up to a constant.
pub fn density_weights_nd<const D: usize>(
    n: usize,
    unit: impl Fn(usize) -> [f64; D] + Sync,
    opts: &WeightOptions,
) -> DensityWeights {
    if n == 0 {
        return DensityWeights {
            weights: Vec::new(),
            bins_per_axis: 0,
            occupied_bins: 0,
        };
    }
    let per_bin = n as f64 / opts.target_per_bin.max(1.0);
    let per_axis = match D {
        1 => per_bin,
        2 => per_bin.sqrt(),
        3 => per_bin.cbrt(),
        _ => per_bin.powf(1.0 / D as f64),
    }
    .round() as usize;
    let nb = per_axis.clamp(
        opts.min_bins.max(1),
        opts.max_bins.max(opts.min_bins.max(1)),
    );
    let bin = |x: f64| ((x * nb as f64).max(0.0) as usize).min(nb - 1);
    let bins: Vec<usize> = (0..n)
        .into_par_iter()
        .with_min_len(8192)
        .map(|i| unit(i).iter().fold(0, |acc, &x| acc * nb + bin(x)))
        .collect();
    let mut counts = vec![0u32; nb.pow(D as u32)];
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
        bins_per_axis: nb,
        occupied_bins: occupied,
    }
}

/// Density weights of one frame's samples over (gamma, r) (paper, §2.3): gamma spans the
/// samples' range, r = normalised depth is already in [0, 1].
pub fn density_weights(samples: &SampleSet, opts: &WeightOptions) -> DensityWeights {
    let (g_lo, g_hi) = samples
        .gamma
        .iter()
        .fold((f32::INFINITY, f32::NEG_INFINITY), |(lo, hi), &g| {
            (lo.min(g), hi.max(g))
        });
    let g_span = f64::from(g_hi - g_lo).max(1e-12);
    density_weights_nd(
        samples.len(),
        |i| [f64::from(samples.gamma[i] - g_lo) / g_span, samples.r(i)],
        opts,
    )
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
        assert_eq!(w.bins_per_axis, 7); // sqrt(1000/20) = 7.07
        let mean = w.weights.iter().map(|&x| f64::from(x)).sum::<f64>() / 1000.0;
        assert!((mean - 1.0).abs() < 1e-5);
        // The dense corner's samples weigh far less than the sparse ones.
        assert!(w.weights[0] * 20.0 < w.weights[950]);
    }
}
