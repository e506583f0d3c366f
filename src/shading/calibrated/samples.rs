//! Samples of the calibrated fit, pooled over all frames: (gamma, cos theta, z, frame, R, G, B)
//! per pixel that obeys the model, subsampled per frame, and their density weights over
//! (gamma, z, theta) (the paper's inverse-density weights, §2.3, with the third axis).

// Indexing several parallel arrays (struct of arrays, channels) by one index reads clearer than zips.
#![allow(clippy::needless_range_loop)]
// `!(x > t)` on floats is deliberate: it also rejects NaN.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

use crate::rng::splitmix64;
use crate::shading::density::{density_weights_nd, WeightOptions};
use crate::shading::frame_shading::LUMA;
use crate::shading::samples::{ExclusionCounts, SampleOptions};
use crate::shading::ShadingError;
use crate::Result;
use rayon::prelude::*;

/// The name errors give this fit.
const POOL: &str = "calibrated samples";

/// One frame's per-pixel inputs (row-major, one entry per pixel unless said otherwise).
#[derive(Debug, Clone, Copy)]
pub struct FrameData<'a> {
    /// cos(view ray, surface normal) (unitless; see `GBuffer::gamma`).
    pub gamma: &'a [f32],
    /// Distance camera → surface (mm); `<= 0` or not finite: no hit.
    pub z: &'a [f32],
    /// cos of the pixel ray's angle off the optical axis (the ray table's `dirs[i][2]`).
    pub cos_theta: &'a [f32],
    /// Linear RGB in 0..1, interleaved (3 values per pixel).
    pub rgb: &'a [f32],
    /// Optional texel (or surface patch) id per pixel for the albedo refinement; `u32::MAX`
    /// for none.
    pub texel: Option<&'a [u32]>,
    /// Image width (pixels): the arrays are row-major images of this width (for each
    /// sample's neighbours; 0 when unknown).
    pub width: usize,
}

/// How pixels become pooled samples.
#[derive(Debug, Clone, PartialEq)]
pub struct PoolOptions {
    /// Which pixels obey the model (grazing, saturated, dark pixels are excluded and counted);
    /// its depth percentiles are not used (the calibrated model uses absolute depth).
    pub sample: SampleOptions,
    /// Most samples kept per frame (bounds the fit's cost). The kept pixels are a jittered
    /// systematic sample in raster order, i.e. spread evenly over the image. Default 20000.
    pub max_per_frame: usize,
    /// Seed of the jitter (the subsample is reproducible).
    pub seed: u64,
}

impl Default for PoolOptions {
    fn default() -> Self {
        PoolOptions {
            sample: SampleOptions::default(),
            max_per_frame: 20_000,
            seed: 0x5eed,
        }
    }
}

/// Samples of all frames, struct of arrays, grouped by frame in frame order.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct PooledSamples {
    /// cos(view ray, normal), in [min_gamma, 1].
    pub gamma: Vec<f32>,
    /// cos of the ray's angle off the optical axis.
    pub cos_theta: Vec<f32>,
    /// Distance camera → surface (mm).
    pub z: Vec<f32>,
    /// Frame index of each sample.
    pub frame: Vec<u32>,
    /// Pixel index (row-major) of each sample within its frame.
    pub pixel: Vec<u32>,
    /// Linear intensity per channel R, G, B.
    pub rgb: [Vec<f32>; 3],
    /// Texel id per sample when the frames gave them (`u32::MAX`: none).
    pub texel: Option<Vec<u32>>,
    /// Per sample, the mean log colour ratios (log G/R, log B/R) of its 8 neighbouring pixels
    /// that obey the model (NaN: none, or the image width unknown): the sample's colour
    /// measured without its own noise (`shading::chroma_albedo`).
    pub neighbour_chroma: Vec<[f32; 2]>,
    /// `frame_start[f]..frame_start[f + 1]` are frame f's samples (length frames + 1).
    pub frame_start: Vec<usize>,
    /// Pixels excluded per frame, by reason (subsampling does not count as exclusion).
    pub excluded: Vec<ExclusionCounts>,
    /// Per frame, the mean observed luminance (Rec. 709) over all its surface pixels, whatever
    /// their intensity: the light the frame's view holds, which inter-reflection scales with.
    pub frame_light: Vec<f64>,
    /// Per channel and sample, the light of its frame's lamp once reflected by the wall and
    /// gathered at the sample's surface point (camera units at the reference gain,
    /// `shading::indirect`), when the gathered inter-reflection is fitted; set after pooling.
    pub indirect: Option<[Vec<f32>; 3]>,
}

impl PooledSamples {
    /// Number of samples.
    pub fn len(&self) -> usize {
        self.gamma.len()
    }

    /// True when there are no samples.
    pub fn is_empty(&self) -> bool {
        self.gamma.is_empty()
    }

    /// Number of frames pooled.
    pub fn frames(&self) -> usize {
        self.frame_start.len().saturating_sub(1)
    }

    /// Append the samples of `other` (pooled from later frames) as the next frames: a video
    /// is pooled one frame at a time without keeping its frames. Both must agree on texel ids.
    pub fn append(&mut self, other: PooledSamples) -> Result<()> {
        if self.frame_start.is_empty() {
            self.frame_start.push(0);
        }
        if self.texel.is_some() != other.texel.is_some() && !self.is_empty() {
            return Err(ShadingError::BadOptions {
                fit: POOL,
                message: "appending frames with and without texel ids".into(),
            }
            .into());
        }
        let base = self.frames() as u32;
        let offset = self.len();
        self.gamma.extend_from_slice(&other.gamma);
        self.cos_theta.extend_from_slice(&other.cos_theta);
        self.z.extend_from_slice(&other.z);
        self.frame.extend(other.frame.iter().map(|f| f + base));
        self.pixel.extend_from_slice(&other.pixel);
        self.neighbour_chroma
            .extend_from_slice(&other.neighbour_chroma);
        for ch in 0..3 {
            self.rgb[ch].extend_from_slice(&other.rgb[ch]);
        }
        match (self.texel.as_mut(), other.texel) {
            (Some(t), Some(o)) => t.extend(o),
            (None, Some(o)) => self.texel = Some(o),
            _ => {}
        }
        self.frame_start
            .extend(other.frame_start.iter().skip(1).map(|s| s + offset));
        self.excluded.extend(other.excluded);
        self.frame_light.extend(other.frame_light);
        // Gathered for whole pools only (after pooling).
        self.indirect = None;
        Ok(())
    }

    /// Smallest cos theta among the samples (the fit's angular edge).
    pub fn min_cos_theta(&self) -> f64 {
        self.cos_theta
            .iter()
            .fold(1.0f64, |m, &c| m.min(f64::from(c)))
    }
}

/// Pool the samples of `frames` (parallel over frames). Errors name the frame whose slices
/// disagree in length.
pub fn pool_frames(frames: &[FrameData], opts: &PoolOptions) -> Result<PooledSamples> {
    for (f, fr) in frames.iter().enumerate() {
        let n = fr.gamma.len();
        if fr.z.len() != n || fr.cos_theta.len() != n || fr.rgb.len() != 3 * n {
            return Err(ShadingError::BadOptions {
                fit: POOL,
                message: format!(
                    "frame {f}: {n} gamma, {} z, {} cos_theta, {} rgb values \
                     (expected n, n, n, 3n)",
                    fr.z.len(),
                    fr.cos_theta.len(),
                    fr.rgb.len()
                ),
            }
            .into());
        }
        if fr.texel.is_some_and(|t| t.len() != n) {
            return Err(ShadingError::LengthMismatch {
                fit: POOL,
                what: "texel ids",
                got: fr.texel.map_or(0, |t| t.len()),
                expected: n,
            }
            .into());
        }
    }
    let with_texels = frames.iter().any(|f| f.texel.is_some());
    let so = &opts.sample;
    let per_frame: Vec<(Vec<u32>, ExclusionCounts, f64)> = frames
        .par_iter()
        .map(|fr| {
            let mut ex = ExclusionCounts::default();
            let mut keep = Vec::new();
            let mut light = 0.0f64;
            for i in 0..fr.gamma.len() {
                let zi = fr.z[i];
                if !(zi.is_finite() && zi > 0.0) {
                    ex.no_hit += 1;
                    continue;
                }
                light += (0..3)
                    .map(|c| LUMA[c] * f64::from(fr.rgb[3 * i + c]))
                    .sum::<f64>();
                if !(fr.gamma[i] >= so.min_gamma) || !fr.cos_theta[i].is_finite() {
                    ex.grazing += 1;
                    continue;
                }
                let px = &fr.rgb[3 * i..3 * i + 3];
                if px.iter().any(|v| !(*v < so.saturation_level)) {
                    ex.saturated += 1;
                    continue;
                }
                if px.iter().all(|v| *v < so.noise_floor) {
                    ex.dark += 1;
                    continue;
                }
                keep.push(i as u32);
            }
            let hits = fr.gamma.len() - ex.no_hit;
            (keep, ex, light / hits.max(1) as f64)
        })
        .collect();
    let mut out = PooledSamples {
        frame_start: vec![0],
        ..Default::default()
    };
    if with_texels {
        out.texel = Some(Vec::new());
    }
    for (f, ((keep, ex, light), fr)) in per_frame.into_iter().zip(frames).enumerate() {
        let m = opts.max_per_frame.max(1);
        let chosen: Vec<u32> = if keep.len() <= m {
            keep
        } else {
            // Jittered systematic sample: one pixel per stratum of len/m consecutive kept pixels.
            let step = keep.len() as f64 / m as f64;
            (0..m)
                .map(|j| {
                    let u = (splitmix64(opts.seed ^ ((f as u64) << 32) ^ j as u64) >> 11) as f64
                        / (1u64 << 53) as f64;
                    keep[(((j as f64) + u) * step) as usize % keep.len()]
                })
                .collect()
        };
        for &i in &chosen {
            let i = i as usize;
            out.gamma.push(fr.gamma[i].min(1.0));
            out.cos_theta.push(fr.cos_theta[i]);
            out.z.push(fr.z[i]);
            out.frame.push(f as u32);
            out.pixel.push(i as u32);
            out.neighbour_chroma.push(neighbour_chroma(fr, i, so));
            for ch in 0..3 {
                out.rgb[ch].push(fr.rgb[3 * i + ch]);
            }
            if let Some(t) = out.texel.as_mut() {
                t.push(fr.texel.map_or(u32::MAX, |tx| tx[i]));
            }
        }
        out.excluded.push(ex);
        out.frame_start.push(out.gamma.len());
        out.frame_light.push(light);
    }
    Ok(out)
}

/// The mean (log G/R, log B/R) of the 8 neighbours of pixel `i` that hit the surface with
/// every channel between the noise floor and saturation; NaN when none does.
fn neighbour_chroma(fr: &FrameData, i: usize, so: &SampleOptions) -> [f32; 2] {
    let w = fr.width;
    let n = fr.z.len();
    if w == 0 || n % w != 0 {
        return [f32::NAN; 2];
    }
    let (x, y) = ((i % w) as isize, (i / w) as isize);
    let h = (n / w) as isize;
    let (mut sum, mut count) = ([0.0f64; 2], 0u32);
    for dy in -1..=1isize {
        for dx in -1..=1isize {
            let (xx, yy) = (x + dx, y + dy);
            if (dx, dy) == (0, 0) || xx < 0 || yy < 0 || xx >= w as isize || yy >= h {
                continue;
            }
            let j = (yy * w as isize + xx) as usize;
            let px = &fr.rgb[3 * j..3 * j + 3];
            let zj = fr.z[j];
            if !(zj.is_finite() && zj > 0.0)
                || px
                    .iter()
                    .any(|&v| !(v > so.noise_floor && v < so.saturation_level))
            {
                continue;
            }
            let l: [f64; 3] = std::array::from_fn(|c| f64::from(px[c]).ln());
            sum[0] += l[1] - l[0];
            sum[1] += l[2] - l[0];
            count += 1;
        }
    }
    if count == 0 {
        [f32::NAN; 2]
    } else {
        sum.map(|s| (s / f64::from(count)) as f32)
    }
}

/// Inverse-density weights over (gamma, z, theta): a 3-D histogram with
/// `cbrt(N / target_per_bin)` bins per axis (clamped to `min_bins..=max_bins`) over the
/// samples' gamma range, their z range between the 0.5th and 99.5th percentiles (outside:
/// the edge bins) and t = (1 - cos theta)/(1 - min cos theta) in [0, 1]. Each weight is
/// `1 / count` of its bin, scaled to mean 1.
pub fn density_weights_3d(samples: &PooledSamples, opts: &WeightOptions) -> Vec<f32> {
    let n = samples.len();
    if n == 0 {
        return Vec::new();
    }
    let (g_lo, g_hi) = samples
        .gamma
        .iter()
        .fold((f32::INFINITY, f32::NEG_INFINITY), |(lo, hi), &g| {
            (lo.min(g), hi.max(g))
        });
    let mut zs: Vec<f32> = samples
        .z
        .iter()
        .step_by((n / 100_000).max(1))
        .copied()
        .collect();
    let m = zs.len();
    let z_lo = *zs.select_nth_unstable_by(m / 200, |a, b| a.total_cmp(b)).1;
    let z_hi = *zs
        .select_nth_unstable_by((m - 1) - m / 200, |a, b| a.total_cmp(b))
        .1;
    let c_lo = samples.min_cos_theta();
    let span = |lo: f64, hi: f64| (hi - lo).max(1e-12);
    let (gs, zsn, ts) = (
        span(f64::from(g_lo), f64::from(g_hi)),
        span(f64::from(z_lo), f64::from(z_hi)),
        span(0.0, 1.0 - c_lo),
    );
    density_weights_nd(
        n,
        |i| {
            [
                f64::from(samples.gamma[i] - g_lo) / gs,
                f64::from(samples.z[i] - z_lo) / zsn,
                (1.0 - f64::from(samples.cos_theta[i])) / ts,
            ]
        },
        opts,
    )
    .weights
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pooling_excludes_subsamples_and_groups_by_frame() {
        let n = 1000;
        let gamma: Vec<f32> = (0..n)
            .map(|i| if i % 10 == 0 { 0.01 } else { 0.5 })
            .collect();
        let z: Vec<f32> = (0..n)
            .map(|i| if i % 10 == 1 { 0.0 } else { 10.0 })
            .collect();
        let ct = vec![0.9f32; n];
        let rgb: Vec<f32> = (0..3 * n)
            .map(|k| if (k / 3) % 10 == 2 { 1.0 } else { 0.3 })
            .collect();
        let fr = FrameData {
            gamma: &gamma,
            z: &z,
            cos_theta: &ct,
            rgb: &rgb,
            texel: None,
            width: 0,
        };
        let opts = PoolOptions {
            max_per_frame: 350,
            ..Default::default()
        };
        let p = pool_frames(&[fr, fr], &opts).unwrap();
        assert_eq!(p.frames(), 2);
        assert_eq!(p.frame_start, vec![0, 350, 700]);
        let ex = p.excluded[1];
        assert_eq!((ex.no_hit, ex.grazing, ex.saturated), (100, 100, 100));
        // Subsample: distinct valid pixels, spread over the image.
        let mut px: Vec<u32> = p.pixel[..350].to_vec();
        px.dedup();
        assert_eq!(px.len(), 350);
        assert!(px.iter().all(|&i| i % 10 >= 3));
        assert!(px[0] < 10 && px[349] > 980);
        // Too few cos values: a named error.
        let bad = FrameData {
            cos_theta: &ct[..5],
            ..fr
        };
        assert!(pool_frames(&[fr, bad], &opts)
            .unwrap_err()
            .to_string()
            .contains("frame 1"));
    }

    #[test]
    fn appending_one_frame_at_a_time_equals_pooling_together() {
        let n = 400;
        let gamma: Vec<f32> = (0..n).map(|i| 0.2 + (i % 7) as f32 * 0.1).collect();
        let z: Vec<f32> = (0..n).map(|i| 5.0 + (i % 13) as f32).collect();
        let ct = vec![0.95f32; n];
        let rgb: Vec<f32> = (0..3 * n).map(|k| 0.1 + (k % 5) as f32 * 0.1).collect();
        let fr = FrameData {
            gamma: &gamma,
            z: &z,
            cos_theta: &ct,
            rgb: &rgb,
            texel: None,
            width: 0,
        };
        let opts = PoolOptions::default();
        let together = pool_frames(&[fr, fr, fr], &opts).unwrap();
        let mut appended = PooledSamples::default();
        for _ in 0..3 {
            appended.append(pool_frames(&[fr], &opts).unwrap()).unwrap();
        }
        assert_eq!(appended.frames(), 3);
        assert_eq!(appended.frame_start, together.frame_start);
        assert_eq!(appended.frame, together.frame);
        assert_eq!(appended.z, together.z);
        assert_eq!(appended.excluded.len(), 3);
    }

    #[test]
    fn density_weights_equalise_bins() {
        let mut p = PooledSamples::default();
        // 900 samples in one cell, 100 spread out.
        for i in 0..1000 {
            let (g, z, c) = if i < 900 {
                (0.2, 10.0, 0.99)
            } else {
                let k = (i - 900) as f32 / 100.0;
                (0.1 + 0.8 * k, 5.0 + 30.0 * k, 1.0 - 0.5 * k)
            };
            p.gamma.push(g);
            p.z.push(z);
            p.cos_theta.push(c);
        }
        let w = density_weights_3d(&p, &WeightOptions::default());
        let mean = w.iter().map(|&x| f64::from(x)).sum::<f64>() / 1000.0;
        assert!((mean - 1.0).abs() < 1e-5);
        assert!(w[0] * 20.0 < w[950], "{} {}", w[0], w[950]);
    }

    #[test]
    fn neighbour_chroma_averages_the_neighbours_that_obey_the_model() {
        // 3x3 image: centre (0.5, 0.25, 0.1); neighbours (0.4, 0.1, 0.2) except one saturated
        // and one without a hit.
        let mut rgb = Vec::new();
        for k in 0..9 {
            rgb.extend_from_slice(match k {
                4 => &[0.5f32, 0.25, 0.1],
                0 => &[1.0, 0.5, 0.5],
                _ => &[0.4, 0.1, 0.2],
            });
        }
        let mut z = vec![10.0f32; 9];
        z[8] = f32::INFINITY;
        let g = vec![0.8f32; 9];
        let fr = FrameData {
            gamma: &g,
            z: &z,
            cos_theta: &g,
            rgb: &rgb,
            texel: None,
            width: 3,
        };
        let so = SampleOptions::default();
        let c = neighbour_chroma(&fr, 4, &so);
        assert!((c[0] - (0.25f32).ln()).abs() < 1e-6 && (c[1] - (0.5f32).ln()).abs() < 1e-6);
        // A corner pixel has three neighbours, the centre among them.
        let c = neighbour_chroma(&fr, 2, &so);
        let want = ((0.25f64).ln() * 2.0 + (0.5f64).ln()) / 3.0;
        assert!((f64::from(c[0]) - want).abs() < 1e-6, "{c:?}");
        // Unknown layout: no colour.
        assert!(neighbour_chroma(&FrameData { width: 0, ..fr }, 4, &so)[0].is_nan());
    }
}
