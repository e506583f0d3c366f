//! The samples Psi is fitted to: (gamma, z, R, G, B) of the pixels that obey the model.

// Indexing several parallel arrays (struct of arrays, channels) by one index reads clearer than zips.
#![allow(clippy::needless_range_loop)]
// `!(x > t)` on floats is deliberate: it also rejects NaN.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

use serde::{Deserialize, Serialize};

/// Which pixels become samples, and how the depth range is set.
///
/// Order of the tests per pixel: no hit, then grazing / back-facing, then saturated, then
/// dark; a pixel is counted under the first reason that excludes it.
#[derive(Debug, Clone, PartialEq)]
pub struct SampleOptions {
    /// Smallest cosine between view ray and normal kept (unitless). Back-facing (`gamma <= 0`)
    /// and grazing hits below this are excluded: their shading is dominated by silhouette
    /// effects and geometric error. Default 0.05 (about 87 degrees).
    pub min_gamma: f32,
    /// Linear intensity at or above which a channel counts as saturated (sensor maximum is
    /// 1.0). A pixel with any saturated channel is excluded (specular highlights). Default 0.999.
    pub saturation_level: f32,
    /// Linear intensity under which a channel is noise. A pixel whose brightest channel is
    /// under it carries no measurable shading and is excluded. Default 0.004 (about sRGB code 12).
    pub noise_floor: f32,
    /// Percentile (0..100) of the hit depths that becomes `z_min`. Default 1.
    pub z_min_percentile: f64,
    /// Percentile (0..100) of the hit depths that becomes `z_max`. Default 99.
    pub z_max_percentile: f64,
}

impl Default for SampleOptions {
    fn default() -> Self {
        SampleOptions {
            min_gamma: 0.05,
            saturation_level: 0.999,
            noise_floor: 0.004,
            z_min_percentile: 1.0,
            z_max_percentile: 99.0,
        }
    }
}

/// How many pixels were left out of the fit, by reason.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct ExclusionCounts {
    /// No surface hit (z <= 0 or not finite).
    pub no_hit: usize,
    /// Back-facing or grazing hit (gamma < `min_gamma`, or gamma not finite).
    pub grazing: usize,
    /// Any channel at or above the saturation level (or not finite).
    pub saturated: usize,
    /// Brightest channel under the noise floor.
    pub dark: usize,
}

impl ExclusionCounts {
    /// All excluded pixels.
    pub fn total(&self) -> usize {
        self.no_hit + self.grazing + self.saturated + self.dark
    }

    /// What most likely left a frame without usable pixels, in words: the frame itself when
    /// it is mostly dark or saturated (a black frame with a tracker's pose is not a wrong
    /// pose), else its pose.
    pub fn likely_cause(&self) -> &'static str {
        match self.dark + self.saturated > self.no_hit + self.grazing {
            true => "the frame shows next to nothing (dark or saturated): remove it from the case (its file and its entry in poses.json), or let `build`'s frame selection (--max-frames above 0) leave it out",
            false => "is the pose registered to the CT?",
        }
    }
}

impl std::fmt::Display for ExclusionCounts {
    /// "102400 miss the mesh, 0 grazing, 0 saturated, 0 dark".
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "{} miss the mesh, {} grazing, {} saturated, {} dark",
            self.no_hit, self.grazing, self.saturated, self.dark
        )
    }
}

/// The samples of one frame, struct of arrays (index i is one pixel that obeys the model).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct SampleSet {
    /// Cosine between view ray and surface normal, in [`min_gamma`, 1] (unitless).
    pub gamma: Vec<f32>,
    /// Euclidean distance viewpoint → surface point (mm).
    pub z: Vec<f32>,
    /// Linear intensity per channel, `rgb[0]` = R, `rgb[1]` = G, `rgb[2]` = B (0..1).
    pub rgb: [Vec<f32>; 3],
    /// Pixels left out, by reason.
    pub excluded: ExclusionCounts,
    /// Lower robust percentile of the hit depths (mm): r = 0.
    pub z_min: f64,
    /// Upper robust percentile of the hit depths (mm): r = 1.
    pub z_max: f64,
}

impl SampleSet {
    /// Number of samples.
    pub fn len(&self) -> usize {
        self.gamma.len()
    }

    /// True when no pixel obeyed the model.
    pub fn is_empty(&self) -> bool {
        self.gamma.is_empty()
    }

    /// Normalised depth `r = (z - z_min) / (z_max - z_min)` of sample `i`, clamped to [0, 1]
    /// (paper, eq. 3: never extrapolated).
    #[inline]
    pub fn r(&self, i: usize) -> f64 {
        normalised_depth(f64::from(self.z[i]), self.z_min, self.z_max)
    }
}

/// `r = (z - z_min) / (z_max - z_min)` clamped to [0, 1]; 0 when the range is empty.
#[inline]
pub fn normalised_depth(z: f64, z_min: f64, z_max: f64) -> f64 {
    let span = z_max - z_min;
    if span > 0.0 {
        ((z - z_min) / span).clamp(0.0, 1.0)
    } else {
        0.0
    }
}

/// The samples of one frame from its per-pixel geometry and linear pixels.
///
/// `gamma[i]` and `z[i]` (mm) describe pixel i's surface hit (`z <= 0` or not finite: no hit);
/// `rgb` is interleaved linear RGB in 0..1, three values per pixel. Slices of unequal length
/// are truncated to the shortest (`rgb.len() / 3` pixels). `z_min`, `z_max` are percentiles
/// of the depths of the front-facing, non-grazing hits (geometry only, independent of exposure).
pub fn extract_samples(gamma: &[f32], z: &[f32], rgb: &[f32], opts: &SampleOptions) -> SampleSet {
    let n = gamma.len().min(z.len()).min(rgb.len() / 3);
    let mut set = SampleSet::default();
    let mut ex = ExclusionCounts::default();
    let mut hit_depths = Vec::with_capacity(n);
    for i in 0..n {
        let zi = z[i];
        if !(zi.is_finite() && zi > 0.0) {
            ex.no_hit += 1;
            continue;
        }
        let g = gamma[i];
        // `!(g >= min)` also catches NaN.
        if !(g >= opts.min_gamma) {
            ex.grazing += 1;
            continue;
        }
        hit_depths.push(zi);
        let px = [rgb[3 * i], rgb[3 * i + 1], rgb[3 * i + 2]];
        if px.iter().any(|v| !(*v < opts.saturation_level)) {
            ex.saturated += 1;
            continue;
        }
        if px.iter().all(|v| *v < opts.noise_floor) {
            ex.dark += 1;
            continue;
        }
        set.gamma.push(g.min(1.0));
        set.z.push(zi);
        for (c, v) in px.iter().enumerate() {
            set.rgb[c].push(*v);
        }
    }
    set.excluded = ex;
    set.z_min = percentile(&mut hit_depths, opts.z_min_percentile);
    set.z_max = percentile(&mut hit_depths, opts.z_max_percentile);
    set
}

/// The `p`-th percentile (0..100, nearest rank) of `values` (reordered in place); 0 if empty.
fn percentile(values: &mut [f32], p: f64) -> f64 {
    if values.is_empty() {
        return 0.0;
    }
    let rank = ((p.clamp(0.0, 100.0) / 100.0) * (values.len() - 1) as f64).round() as usize;
    let (_, v, _) = values.select_nth_unstable_by(rank, |a, b| a.total_cmp(b));
    f64::from(*v)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_dark_frame_is_blamed_on_itself_and_a_frame_off_the_mesh_on_its_pose() {
        let black = ExclusionCounts {
            grazing: 19,
            dark: 102_381,
            ..Default::default()
        };
        assert!(black
            .likely_cause()
            .starts_with("the frame shows next to nothing"));
        let off = ExclusionCounts {
            no_hit: 90_000,
            dark: 10_000,
            ..Default::default()
        };
        assert_eq!(off.likely_cause(), "is the pose registered to the CT?");
    }

    #[test]
    fn each_exclusion_reason_is_counted_once() {
        let opts = SampleOptions::default();
        // pixel: ok, no-hit (z=0), no-hit (NaN), back-facing, grazing, saturated, dark, ok
        let gamma = [0.8, 0.8, 0.8, -0.3, 0.01, 0.9, 0.9, 0.5];
        let z = [10.0, 0.0, f32::NAN, 12.0, 14.0, 16.0, 18.0, 20.0];
        #[rustfmt::skip]
        let rgb = [
            0.5, 0.3, 0.2,  0.5, 0.3, 0.2,  0.5, 0.3, 0.2,  0.5, 0.3, 0.2,
            0.5, 0.3, 0.2,  1.0, 0.6, 0.5,  0.001, 0.002, 0.0,  0.4, 0.2, 0.001,
        ];
        let s = extract_samples(&gamma, &z, &rgb, &opts);
        assert_eq!(s.len(), 2);
        assert_eq!(
            s.excluded,
            ExclusionCounts {
                no_hit: 2,
                grazing: 2,
                saturated: 1,
                dark: 1
            }
        );
        assert_eq!(s.rgb[2], vec![0.2, 0.001]);
        // Hit depths kept for the range: 10, 16, 18, 20 → 1st pct 10, 99th pct 20.
        assert_eq!((s.z_min, s.z_max), (10.0, 20.0));
        assert_eq!(s.r(1), 1.0);
    }

    #[test]
    fn percentiles_are_robust_to_outliers() {
        let mut z: Vec<f32> = (0..1000).map(|i| 10.0 + i as f32 * 0.01).collect();
        z[0] = 0.5; // a stray near hit
        z[999] = 500.0; // a stray far hit
        let g = vec![0.5; z.len()];
        let rgb = vec![0.3; 3 * z.len()];
        let s = extract_samples(&g, &z, &rgb, &SampleOptions::default());
        assert!((s.z_min - 10.1).abs() < 0.011, "{}", s.z_min);
        assert!((s.z_max - 19.89).abs() < 0.011, "{}", s.z_max);
    }
}
