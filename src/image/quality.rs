//! Image quality against a reference: exposure gains fitted by least squares, PSNR and SSIM
//! over the pixels both images cover — the one implementation every score in bronchosim uses.
//!
//! Choices (documented here because they change the numbers):
//! - The gain `g_c = Σ r·t / Σ r²` is fitted in linear light over the covered pixels of all
//!   views together; the scaled render and the reference are then encoded to sRGB (clamped to
//!   [0, 1]) and both metrics are computed on those encoded values, which is what people see.
//! - PSNR: `10 log10(1 / MSE)` over the covered pixels and the three channels, capped at
//!   [`PSNR_CAP_DB`] for identical images.
//! - SSIM: Wang et al. 2004 per channel, averaged over R, G, B; Gaussian window σ = 1.5
//!   truncated at 3.5σ (11x11), K1 = 0.01, K2 = 0.03, data range 1, population covariances —
//!   scikit-image's `structural_similarity(gaussian_weights=True, sigma=1.5,
//!   use_sample_covariance=False, data_range=1, channel_axis=2)`. Local statistics use
//!   normalised convolution over covered pixels only (`G*(m·x) / G*(m)`, borders mirrored as
//!   scipy's "reflect"), so pixels outside the mask never enter a window; with a full mask this
//!   is exactly skimage's filter. The SSIM map is averaged over covered pixels at least 5 px
//!   from the image border (skimage crops that border before averaging).

use crate::image::Frame;

/// PSNR reported for identical images (dB).
pub const PSNR_CAP_DB: f64 = 100.0;
/// SSIM constants and window (Wang et al. 2004; skimage's Gaussian variant).
const K1: f64 = 0.01;
const K2: f64 = 0.03;
const SIGMA: f64 = 1.5;
/// Window radius: skimage's `int(3.5 * sigma + 0.5)`.
const RADIUS: usize = 5;

/// The least-squares scalar k minimising `sum (k pred - obs)^2` over the pixels where
/// `mask` is true (interleaved RGB): the auto-exposure of a held-out frame, which no model can
/// know in advance. 1 when the prediction is all zero.
pub fn fit_gain(pred: &[f32], obs: &[f32], mask: &[bool]) -> f64 {
    let (mut num, mut den) = (0.0f64, 0.0f64);
    for (i, &m) in mask.iter().enumerate() {
        if !m {
            continue;
        }
        for c in 0..3 {
            let (p, o) = (f64::from(pred[3 * i + c]), f64::from(obs[3 * i + c]));
            num += p * o;
            den += p * p;
        }
    }
    if den > 0.0 {
        num / den
    } else {
        1.0
    }
}

/// Linear value at or above which an image channel counts as clipped (8-bit white is 1.0).
pub const CLIPPED: f32 = 0.999;

/// Least-squares gain per channel mapping `rendered` onto `truth` over the covered pixels of
/// all views (`masks[v][i]`); 1 for a channel that is zero everywhere. A pixel whose channel
/// is clipped ([`CLIPPED`]) in either image says nothing about the gain and is left out of that
/// channel's fit (a reference view saturates near the wall; a rendered PNG clips at white).
pub fn fit_gains(rendered: &[&Frame], truth: &[&Frame], masks: &[Vec<bool>]) -> [f64; 3] {
    let (mut rt, mut rr) = ([0.0f64; 3], [0.0f64; 3]);
    for ((r, t), m) in rendered.iter().zip(truth).zip(masks) {
        for (i, &covered) in m.iter().enumerate() {
            if covered {
                for k in 0..3 {
                    let (a, b) = (r.rgb[3 * i + k], t.rgb[3 * i + k]);
                    if a >= CLIPPED || b >= CLIPPED {
                        continue;
                    }
                    let (a, b) = (a as f64, b as f64);
                    rt[k] += a * b;
                    rr[k] += a * a;
                }
            }
        }
    }
    std::array::from_fn(|k| if rr[k] > 0.0 { rt[k] / rr[k] } else { 1.0 })
}

/// PSNR (dB) of two sRGB-encoded interleaved RGB images over the covered pixels; `None`
/// without covered pixels.
pub fn psnr_masked(a: &[f32], b: &[f32], mask: &[bool]) -> Option<f64> {
    let (mut se, mut n) = (0.0f64, 0usize);
    for (i, &c) in mask.iter().enumerate() {
        if c {
            for k in 0..3 {
                let d = a[3 * i + k] as f64 - b[3 * i + k] as f64;
                se += d * d;
            }
            n += 3;
        }
    }
    (n > 0).then(|| {
        let mse = se / n as f64;
        (10.0 * (1.0 / mse).log10()).min(PSNR_CAP_DB)
    })
}

/// The 1-D Gaussian window (scipy's `gaussian_filter` weights for σ = 1.5, radius 5).
fn kernel() -> [f64; 2 * RADIUS + 1] {
    let mut k: [f64; 2 * RADIUS + 1] = std::array::from_fn(|i| {
        (-((i as f64 - RADIUS as f64).powi(2)) / (2.0 * SIGMA * SIGMA)).exp()
    });
    let s: f64 = k.iter().sum();
    k.iter_mut().for_each(|v| *v /= s);
    k
}

/// scipy "reflect" index: d c b a | a b c d | d c b a.
#[inline]
fn reflect(i: isize, n: usize) -> usize {
    let n = n as isize;
    let mut i = i;
    loop {
        if i < 0 {
            i = -i - 1;
        } else if i >= n {
            i = 2 * n - i - 1;
        } else {
            return i as usize;
        }
    }
}

/// Separable Gaussian filter of a `w` x `h` plane with mirrored borders.
fn gauss(plane: &[f64], w: usize, h: usize, k: &[f64]) -> Vec<f64> {
    let mut tmp = vec![0.0; w * h];
    for y in 0..h {
        for x in 0..w {
            let mut s = 0.0;
            for (j, kv) in k.iter().enumerate() {
                s += kv * plane[y * w + reflect(x as isize + j as isize - RADIUS as isize, w)];
            }
            tmp[y * w + x] = s;
        }
    }
    let mut out = vec![0.0; w * h];
    for y in 0..h {
        for x in 0..w {
            let mut s = 0.0;
            for (j, kv) in k.iter().enumerate() {
                s += kv * tmp[reflect(y as isize + j as isize - RADIUS as isize, h) * w + x];
            }
            out[y * w + x] = s;
        }
    }
    out
}

/// SSIM map of two single-channel images (values in [0, 1], data range 1) with local statistics
/// over covered pixels only (normalised convolution). Entries of uncovered pixels are NaN.
pub fn ssim_map(x: &[f64], y: &[f64], w: usize, h: usize, mask: &[bool]) -> Vec<f64> {
    let k = kernel();
    let m: Vec<f64> = mask.iter().map(|&c| if c { 1.0 } else { 0.0 }).collect();
    let prod = |f: &dyn Fn(usize) -> f64| -> Vec<f64> { (0..w * h).map(|i| m[i] * f(i)).collect() };
    let gm = gauss(&m, w, h, &k);
    let gx = gauss(&prod(&|i| x[i]), w, h, &k);
    let gy = gauss(&prod(&|i| y[i]), w, h, &k);
    let gxx = gauss(&prod(&|i| x[i] * x[i]), w, h, &k);
    let gyy = gauss(&prod(&|i| y[i] * y[i]), w, h, &k);
    let gxy = gauss(&prod(&|i| x[i] * y[i]), w, h, &k);
    let (c1, c2) = (K1 * K1, K2 * K2);
    (0..w * h)
        .map(|i| {
            if !mask[i] || gm[i] <= 0.0 {
                return f64::NAN;
            }
            let n = 1.0 / gm[i];
            let (ux, uy) = (gx[i] * n, gy[i] * n);
            let vx = gxx[i] * n - ux * ux;
            let vy = gyy[i] * n - uy * uy;
            let vxy = gxy[i] * n - ux * uy;
            ((2.0 * ux * uy + c1) * (2.0 * vxy + c2)) / ((ux * ux + uy * uy + c1) * (vx + vy + c2))
        })
        .collect()
}

/// Mean SSIM of two sRGB-encoded interleaved RGB images: per channel, averaged over covered
/// pixels at least 5 px inside the border, then over the channels. `None` without such pixels.
pub fn ssim_masked(a: &[f32], b: &[f32], w: usize, h: usize, mask: &[bool]) -> Option<f64> {
    let inner = |i: usize| {
        let (x, y) = (i % w, i / w);
        x >= RADIUS && y >= RADIUS && x + RADIUS < w && y + RADIUS < h
    };
    let count = (0..w * h).filter(|&i| mask[i] && inner(i)).count();
    if count == 0 {
        return None;
    }
    let mut total = 0.0;
    for ch in 0..3 {
        let x: Vec<f64> = (0..w * h).map(|i| a[3 * i + ch] as f64).collect();
        let y: Vec<f64> = (0..w * h).map(|i| b[3 * i + ch] as f64).collect();
        let s = ssim_map(&x, &y, w, h, mask);
        let sum: f64 = (0..w * h)
            .filter(|&i| mask[i] && inner(i))
            .map(|i| s[i])
            .sum();
        total += sum / count as f64;
    }
    Some(total / 3.0)
}
