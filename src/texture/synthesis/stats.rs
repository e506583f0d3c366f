//! Statistics a viewer notices in a texture region, for comparing synthesised (or filled)
//! walls with the truth: mean colour, contrast (standard deviation of the luminance), the
//! radially averaged power spectrum of the luminance (the scale and strength of the vessel
//! pattern), and the gradient across the border of the seen region against the gradient within it.

/// Rec. 709 luminance of a linear RGB colour.
#[inline]
pub fn luminance(c: [f32; 3]) -> f64 {
    0.2126 * c[0] as f64 + 0.7152 * c[1] as f64 + 0.0722 * c[2] as f64
}

/// Statistics of the texels of one region of an atlas.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct RegionStats {
    /// Texels in the region.
    pub texels: usize,
    /// Mean linear RGB.
    pub mean_rgb: [f64; 3],
    /// Standard deviation of the luminance over the region.
    pub luminance_std: f64,
    /// Mean power of the luminance (mean removed, Hann window) at radial frequency bin k,
    /// k = 1..=window/2 cycles per window (`spectrum[k - 1]`), averaged over the windows of
    /// `window` x `window` texels that lie wholly in the region.
    pub spectrum: Vec<f64>,
    /// Windows averaged in `spectrum` (0: the region holds no whole window).
    pub windows: usize,
    /// Window edge (texels).
    pub window: usize,
}

/// [`RegionStats`] of the texels of the `width` x `height` atlas `rgb` (interleaved linear RGB)
/// where `region` is true; windows of `window` texels on a `window / 2` stride.
pub fn region_stats(
    rgb: &[f32],
    width: usize,
    height: usize,
    region: &[bool],
    window: usize,
) -> RegionStats {
    let px = |i: usize| [rgb[3 * i], rgb[3 * i + 1], rgb[3 * i + 2]];
    let idx: Vec<usize> = (0..width * height).filter(|&i| region[i]).collect();
    let n = idx.len().max(1) as f64;
    let mut mean = [0.0f64; 3];
    let (mut l1, mut l2) = (0.0f64, 0.0f64);
    for &i in &idx {
        let c = px(i);
        for ch in 0..3 {
            mean[ch] += c[ch] as f64 / n;
        }
        let l = luminance(c);
        l1 += l / n;
        l2 += l * l / n;
    }
    let mut out = RegionStats {
        texels: idx.len(),
        mean_rgb: mean,
        luminance_std: (l2 - l1 * l1).max(0.0).sqrt(),
        spectrum: vec![0.0; window / 2],
        windows: 0,
        window,
    };
    if window < 4 || width < window || height < window {
        return out;
    }
    // Summed-area table of the region for the whole-window test.
    let mut sat = vec![0u32; (width + 1) * (height + 1)];
    for y in 0..height {
        let mut row = 0u32;
        for x in 0..width {
            row += region[y * width + x] as u32;
            sat[(y + 1) * (width + 1) + x + 1] = sat[y * (width + 1) + x + 1] + row;
        }
    }
    let inside = |x: usize, y: usize| {
        let at = |x: usize, y: usize| sat[y * (width + 1) + x] as i64;
        let (x1, y1) = (x + window, y + window);
        at(x1, y1) - at(x, y1) - at(x1, y) + at(x, y) == (window * window) as i64
    };
    let dft = Dft::new(window);
    let mut lum = vec![0.0f64; window * window];
    for y in (0..=height - window).step_by(window / 2) {
        for x in (0..=width - window).step_by(window / 2) {
            if !inside(x, y) {
                continue;
            }
            for wy in 0..window {
                for wx in 0..window {
                    lum[wy * window + wx] = luminance(px((y + wy) * width + x + wx));
                }
            }
            for (k, p) in dft.radial_power(&mut lum).iter().enumerate() {
                out.spectrum[k] += p;
            }
            out.windows += 1;
        }
    }
    if out.windows > 0 {
        for p in &mut out.spectrum {
            *p /= out.windows as f64;
        }
    }
    out
}

/// RMS over the frequency bins of `log10(a / b)`: 0 for equal spectra, 1 for a factor 10
/// everywhere. Bins where either is not positive are skipped; NaN when none is left.
pub fn spectrum_distance(a: &[f64], b: &[f64]) -> f64 {
    let d: Vec<f64> = a
        .iter()
        .zip(b)
        .filter(|(x, y)| **x > 0.0 && **y > 0.0)
        .map(|(x, y)| (x / y).log10())
        .collect();
    (d.iter().map(|v| v * v).sum::<f64>() / d.len() as f64).sqrt()
}

/// A naive separable DFT of a square window (the windows are small: O(n³) is cheap next to
/// a dependency).
struct Dft {
    n: usize,
    cos: Vec<f64>,
    sin: Vec<f64>,
    hann: Vec<f64>,
}

impl Dft {
    fn new(n: usize) -> Dft {
        let tau = std::f64::consts::TAU;
        let cos = (0..n * n)
            .map(|i| (tau * ((i / n) * (i % n) % n) as f64 / n as f64).cos())
            .collect();
        let sin = (0..n * n)
            .map(|i| (tau * ((i / n) * (i % n) % n) as f64 / n as f64).sin())
            .collect();
        let hann = (0..n)
            .map(|i| 0.5 - 0.5 * (tau * i as f64 / n as f64).cos())
            .collect();
        Dft { n, cos, sin, hann }
    }

    /// Power per radial bin 1..=n/2 of the window `v` (row-major, overwritten): mean removed,
    /// Hann-windowed, |F|² / (sum of the squared window), averaged within each bin.
    fn radial_power(&self, v: &mut [f64]) -> Vec<f64> {
        let n = self.n;
        let mean = v.iter().sum::<f64>() / (n * n) as f64;
        let mut wsum = 0.0;
        for y in 0..n {
            for x in 0..n {
                let w = self.hann[x] * self.hann[y];
                v[y * n + x] = (v[y * n + x] - mean) * w;
                wsum += w * w;
            }
        }
        // Rows, then columns.
        let mut re = vec![0.0f64; n * n];
        let mut im = vec![0.0f64; n * n];
        for y in 0..n {
            for k in 0..n {
                let (mut a, mut b) = (0.0, 0.0);
                for x in 0..n {
                    a += v[y * n + x] * self.cos[k * n + x];
                    b -= v[y * n + x] * self.sin[k * n + x];
                }
                re[y * n + k] = a;
                im[y * n + k] = b;
            }
        }
        let mut bins = vec![0.0f64; n / 2];
        let mut counts = vec![0usize; n / 2];
        for kx in 0..n {
            for ky in 0..n {
                let (mut a, mut b) = (0.0, 0.0);
                for y in 0..n {
                    let (c, s) = (self.cos[ky * n + y], self.sin[ky * n + y]);
                    let (r, i) = (re[y * n + kx], im[y * n + kx]);
                    a += r * c + i * s;
                    b += i * c - r * s;
                }
                let fx = if kx <= n / 2 {
                    kx as f64
                } else {
                    kx as f64 - n as f64
                };
                let fy = if ky <= n / 2 {
                    ky as f64
                } else {
                    ky as f64 - n as f64
                };
                let r = (fx * fx + fy * fy).sqrt().round() as usize;
                if (1..=n / 2).contains(&r) {
                    bins[r - 1] += (a * a + b * b) / wsum;
                    counts[r - 1] += 1;
                }
            }
        }
        bins.iter()
            .zip(&counts)
            .map(|(s, &c)| s / c.max(1) as f64)
            .collect()
    }
}

/// Luminance gradients at the border of the seen region against those within it.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct SeamStats {
    /// Mean |ΔL| over 4-neighbour pairs of one seen and one `region` texel of the same chart.
    pub across: f64,
    /// Mean |ΔL| over 4-neighbour pairs of seen texels of the same chart.
    pub within_seen: f64,
    /// Mean |ΔL| over 4-neighbour pairs of seen texels of the same chart within
    /// [`NEAR_BORDER_TEXELS`] of a `region` texel (the seen texture right at the border, which
    /// is seen by fewer frames, more obliquely, than the rest).
    pub within_seen_near: f64,
    /// Pairs across the border.
    pub border_pairs: usize,
}

/// Distance (texels, 4-connected through seen texels) within which a seen pair counts as near
/// the border in [`SeamStats::within_seen_near`].
pub const NEAR_BORDER_TEXELS: u32 = 3;

/// [`SeamStats`] of the atlas `rgb` (`width` wide): `seen` and `region` (e.g. the synthesised
/// texels) are atlas-sized masks, `chart_of_texel` the chart per texel (`u32::MAX` for none).
pub fn seam_gradients(
    rgb: &[f32],
    width: usize,
    seen: &[bool],
    region: &[bool],
    chart_of_texel: &[u32],
) -> SeamStats {
    let lum = |i: usize| luminance([rgb[3 * i], rgb[3 * i + 1], rgb[3 * i + 2]]);
    let n = seen.len();
    let pairs = |i: usize| {
        let right = (i % width + 1 < width).then_some(i + 1);
        let down = (i + width < n).then_some(i + width);
        [right, down].into_iter().flatten()
    };
    // Distance of the seen texels from the region, up to NEAR_BORDER_TEXELS.
    let mut dist = vec![u32::MAX; n];
    let mut front: Vec<usize> = (0..n).filter(|&i| region[i]).collect();
    for &i in &front {
        dist[i] = 0;
    }
    for d in 1..=NEAR_BORDER_TEXELS {
        let mut next = Vec::new();
        for &i in &front {
            let (x, y) = (i % width, i / width);
            let around = [
                (x > 0).then(|| i - 1),
                (x + 1 < width).then_some(i + 1),
                (y > 0).then(|| i - width),
                (i + width < n).then_some(i + width),
            ];
            for j in around.into_iter().flatten() {
                if seen[j] && dist[j] == u32::MAX && chart_of_texel[j] == chart_of_texel[i] {
                    dist[j] = d;
                    next.push(j);
                }
            }
        }
        front = next;
    }
    let (mut across, mut within, mut near) = ((0.0f64, 0usize), (0.0f64, 0usize), (0.0f64, 0usize));
    let add = |acc: &mut (f64, usize), g: f64| {
        acc.0 += g;
        acc.1 += 1;
    };
    for i in 0..n {
        let c = chart_of_texel[i];
        if c == u32::MAX {
            continue;
        }
        for j in pairs(i) {
            if chart_of_texel[j] != c {
                continue;
            }
            let g = (lum(i) - lum(j)).abs();
            if seen[i] && seen[j] {
                add(&mut within, g);
                if dist[i].min(dist[j]) <= NEAR_BORDER_TEXELS {
                    add(&mut near, g);
                }
            } else if (seen[i] && region[j]) || (region[i] && seen[j]) {
                add(&mut across, g);
            }
        }
    }
    let mean = |a: (f64, usize)| a.0 / a.1.max(1) as f64;
    SeamStats {
        across: mean(across),
        within_seen: mean(within),
        within_seen_near: mean(near),
        border_pairs: across.1,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn spectrum_of_a_grating_peaks_at_its_frequency() {
        // A luminance grating of 5 cycles per 32 texels along x: the power sits in bin 5.
        let (w, h) = (64usize, 64usize);
        let mut rgb = vec![0.0f32; 3 * w * h];
        for y in 0..h {
            for x in 0..w {
                let v = 0.5 + 0.2 * (std::f32::consts::TAU * 5.0 * x as f32 / 32.0).sin();
                rgb[3 * (y * w + x)..3 * (y * w + x) + 3].copy_from_slice(&[v; 3]);
            }
        }
        let s = region_stats(&rgb, w, h, &vec![true; w * h], 32);
        assert_eq!(s.windows, 9);
        let peak = (0..s.spectrum.len())
            .max_by(|&a, &b| s.spectrum[a].total_cmp(&s.spectrum[b]))
            .unwrap();
        assert_eq!(peak + 1, 5);
        // A sine of amplitude 0.2 has variance 0.02: std to within 1e-3.
        assert!(
            (s.luminance_std - 0.02f64.sqrt()).abs() < 1e-3,
            "{}",
            s.luminance_std
        );
        assert!((s.mean_rgb[0] - 0.5).abs() < 1e-4);
        assert!(spectrum_distance(&s.spectrum, &s.spectrum).abs() < 1e-12);
    }

    #[test]
    fn seam_of_a_step_is_the_step() {
        // Seen left half at 0.2, region right half at 0.6: across = 0.4, within = 0.
        let (w, h) = (8usize, 4usize);
        let mut rgb = vec![0.0f32; 3 * w * h];
        let seen: Vec<bool> = (0..w * h).map(|i| i % w < 4).collect();
        let region: Vec<bool> = seen.iter().map(|s| !s).collect();
        for i in 0..w * h {
            let v = if seen[i] { 0.2 } else { 0.6 };
            rgb[3 * i..3 * i + 3].copy_from_slice(&[v; 3]);
        }
        let s = seam_gradients(&rgb, w, &seen, &region, &vec![0; w * h]);
        assert_eq!(s.border_pairs, h);
        assert!((s.across - 0.4).abs() < 1e-6 && s.within_seen.abs() < 1e-12);
        assert!(s.within_seen_near.abs() < 1e-12);
    }
}
