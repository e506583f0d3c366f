//! Scoring rendered views against reference images: PSNR and SSIM on the pixels both cover,
//! after one least-squares gain per channel over all views (absolute exposure is unknowable).
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

use serde::Serialize;

use crate::image::srgb::linear_to_srgb;
use crate::image::Frame;
use crate::{Error, Result};

/// PSNR reported for identical images (dB).
pub const PSNR_CAP_DB: f64 = 100.0;
/// SSIM constants and window (Wang et al. 2004; skimage's Gaussian variant).
const K1: f64 = 0.01;
const K2: f64 = 0.03;
const SIGMA: f64 = 1.5;
/// Window radius: skimage's `int(3.5 * sigma + 0.5)`.
const RADIUS: usize = 5;

/// One image and the pixels it covers (row-major flags, one per pixel).
#[derive(Clone, Debug)]
pub struct MaskedImage {
    /// Linear RGB.
    pub frame: Frame,
    /// True where the image holds a value (a surface hit).
    pub mask: Vec<bool>,
}

/// Scores of one view.
#[derive(Clone, Debug, Serialize)]
pub struct ViewScore {
    /// The view's name (its image path in views.json).
    pub name: String,
    /// Pixels scored (covered by both images).
    pub pixels: usize,
    /// PSNR of the sRGB-encoded images (dB); `None` without covered pixels.
    pub psnr_db: Option<f64>,
    /// Mean SSIM over the covered pixels; `None` without covered pixels.
    pub ssim: Option<f64>,
}

/// Scores of one method over all views.
#[derive(Clone, Debug, Serialize)]
pub struct MethodScore {
    /// The method's name.
    pub method: String,
    /// Fitted linear gain per channel R, G, B.
    pub gain: [f64; 3],
    /// Per view.
    pub views: Vec<ViewScore>,
    /// Mean PSNR over views with covered pixels (dB).
    pub mean_psnr_db: f64,
    /// Mean SSIM over views with covered pixels.
    pub mean_ssim: f64,
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

fn encode(frame: &Frame, gain: [f64; 3]) -> Vec<f32> {
    frame
        .rgb
        .iter()
        .enumerate()
        .map(|(i, &v)| linear_to_srgb((v as f64 * gain[i % 3]) as f32))
        .collect()
}

/// Score several methods against the same references. The scored pixels of view v are those
/// covered by the reference and by every method (the same pixels for all); each method gets its
/// own gain fit over those pixels of all views. `names[v]` labels view v.
pub fn evaluate_methods(
    methods: &[(String, Vec<MaskedImage>)],
    truth: &[MaskedImage],
    names: &[String],
) -> Result<Vec<MethodScore>> {
    if names.len() != truth.len() {
        return Err(Error::Other(format!(
            "evaluate: {} names for {} reference views",
            names.len(),
            truth.len()
        )));
    }
    for (name, views) in methods {
        if views.len() != truth.len() {
            return Err(Error::Other(format!(
                "evaluate: method {name} has {} views, the reference {}",
                views.len(),
                truth.len()
            )));
        }
        for (v, (r, t)) in views.iter().zip(truth).enumerate() {
            let n = t.frame.width as usize * t.frame.height as usize;
            if r.frame.width != t.frame.width
                || r.frame.height != t.frame.height
                || r.mask.len() != n
                || t.mask.len() != n
            {
                return Err(Error::Other(format!(
                    "evaluate: view {} of method {name} is {}x{}, the reference {}x{} (or a mask has the wrong size)",
                    names[v], r.frame.width, r.frame.height, t.frame.width, t.frame.height
                )));
            }
        }
    }
    let masks: Vec<Vec<bool>> = truth
        .iter()
        .enumerate()
        .map(|(v, t)| {
            (0..t.mask.len())
                .map(|i| t.mask[i] && methods.iter().all(|(_, views)| views[v].mask[i]))
                .collect()
        })
        .collect();
    let truth_frames: Vec<&Frame> = truth.iter().map(|t| &t.frame).collect();
    let truth_srgb: Vec<Vec<f32>> = truth.iter().map(|t| encode(&t.frame, [1.0; 3])).collect();
    Ok(methods
        .iter()
        .map(|(method, views)| {
            let frames: Vec<&Frame> = views.iter().map(|r| &r.frame).collect();
            let gain = fit_gains(&frames, &truth_frames, &masks);
            let scores: Vec<ViewScore> = views
                .iter()
                .enumerate()
                .map(|(v, r)| {
                    let (w, h) = (r.frame.width as usize, r.frame.height as usize);
                    let a = encode(&r.frame, gain);
                    ViewScore {
                        name: names[v].clone(),
                        pixels: masks[v].iter().filter(|&&c| c).count(),
                        psnr_db: psnr_masked(&a, &truth_srgb[v], &masks[v]),
                        ssim: ssim_masked(&a, &truth_srgb[v], w, h, &masks[v]),
                    }
                })
                .collect();
            let mean = |f: &dyn Fn(&ViewScore) -> Option<f64>| {
                let vals: Vec<f64> = scores.iter().filter_map(f).collect();
                if vals.is_empty() {
                    f64::NAN
                } else {
                    vals.iter().sum::<f64>() / vals.len() as f64
                }
            };
            MethodScore {
                method: method.clone(),
                gain,
                mean_psnr_db: mean(&|s| s.psnr_db),
                mean_ssim: mean(&|s| s.ssim),
                views: scores,
            }
        })
        .collect())
}

/// A plain-text table of scores: per view, each method's PSNR and SSIM, then the means.
pub fn scores_text(scores: &[MethodScore]) -> String {
    let mut s = String::new();
    let fmt = |x: Option<f64>, d: usize| x.map_or("-".to_string(), |v| format!("{v:.d$}"));
    s.push_str(&format!("{:<28}", "view"));
    for m in scores {
        s.push_str(&format!(
            " {:>14} {:>8}",
            format!("{} PSNR", m.method),
            "SSIM"
        ));
    }
    s.push('\n');
    let n = scores.first().map_or(0, |m| m.views.len());
    for v in 0..n {
        s.push_str(&format!("{:<28}", scores[0].views[v].name));
        for m in scores {
            let vs = &m.views[v];
            s.push_str(&format!(
                " {:>14} {:>8}",
                fmt(vs.psnr_db, 2),
                fmt(vs.ssim, 4)
            ));
        }
        s.push('\n');
    }
    s.push_str(&format!("{:<28}", "mean"));
    for m in scores {
        s.push_str(&format!(
            " {:>14} {:>8}",
            format!("{:.2}", m.mean_psnr_db),
            format!("{:.4}", m.mean_ssim)
        ));
    }
    s.push('\n');
    s
}
