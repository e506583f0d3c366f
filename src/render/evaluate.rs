//! Scoring rendered views against reference images: PSNR and SSIM on the pixels both cover,
//! after one least-squares gain per channel over all views (absolute exposure is unknowable).
//!
//! Choices (documented here because they change the numbers):
//! - The gain `g_c = Σ r·t / Σ r²` is fitted in linear light over the covered pixels of all
//!   views together; the scaled render and the reference are then encoded to sRGB (clamped to
//!   [0, 1]) and both metrics are computed on those encoded values, which is what people see.
//! - PSNR: `10 log10(1 / MSE)` over the covered pixels and the three channels, capped at
//!   [`crate::image::quality::PSNR_CAP_DB`] for identical images.
//! - SSIM: Wang et al. 2004 per channel, averaged over R, G, B; Gaussian window σ = 1.5
//!   truncated at 3.5σ (11x11), K1 = 0.01, K2 = 0.03, data range 1, population covariances —
//!   scikit-image's `structural_similarity(gaussian_weights=True, sigma=1.5,
//!   use_sample_covariance=False, data_range=1, channel_axis=2)`. Local statistics use
//!   normalised convolution over covered pixels only (`G*(m·x) / G*(m)`, borders mirrored as
//!   scipy's "reflect"), so pixels outside the mask never enter a window; with a full mask this
//!   is exactly skimage's filter. The SSIM map is averaged over covered pixels at least 5 px
//!   from the image border (skimage crops that border before averaging).
//! - Beside the PSNR over every covered pixel, the PSNR over those where no channel of the
//!   reference is saturated ([`CLIPPED`]): there the reference shows the surface, where it is
//!   saturated it only says the surface is brighter than its exposure holds, and the score
//!   follows the render's exposure instead of the model. The phantom's truth views are
//!   saturated on up to 56 % of their pixels (BENCHMARKS.md, session 44); the held-out frames
//!   of the cross-validation never are (their masks leave saturated pixels out), so both
//!   scores agree there.

use serde::Serialize;

use crate::image::quality::{fit_gains, psnr_masked, ssim_masked, CLIPPED};
use crate::image::srgb::linear_to_srgb;
use crate::image::Frame;
use crate::image::ImageError;
use crate::Result;

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
    /// Scored pixels where no channel of the reference is saturated.
    pub unsaturated_pixels: usize,
    /// PSNR over those pixels (dB); `None` without any.
    pub unsaturated_psnr_db: Option<f64>,
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
    /// Mean PSNR over views with unsaturated reference pixels, on those pixels (dB).
    pub mean_unsaturated_psnr_db: f64,
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
        return Err(ImageError::Inconsistent {
            stage: "evaluate",
            message: format!("{} names for {} reference views", names.len(), truth.len()),
        }
        .into());
    }
    for (name, views) in methods {
        if views.len() != truth.len() {
            return Err(ImageError::Inconsistent {
                stage: "evaluate",
                message: format!(
                    "method {name} has {} views, the reference {}",
                    views.len(),
                    truth.len()
                ),
            }
            .into());
        }
        for (v, (r, t)) in views.iter().zip(truth).enumerate() {
            let n = t.frame.width as usize * t.frame.height as usize;
            if r.frame.width != t.frame.width
                || r.frame.height != t.frame.height
                || r.mask.len() != n
                || t.mask.len() != n
            {
                return Err(ImageError::SizeMismatch {
                    stage: "evaluate",
                    what: format!("view {} of method {name} (or its mask)", names[v]),
                    got: [r.frame.width, r.frame.height],
                    expected: [t.frame.width, t.frame.height],
                }
                .into());
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
    let unsaturated: Vec<Vec<bool>> = truth
        .iter()
        .zip(&masks)
        .map(|(t, m)| {
            m.iter()
                .zip(t.frame.rgb.chunks_exact(3))
                .map(|(&covered, px)| covered && px.iter().all(|&c| c < CLIPPED))
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
                        unsaturated_pixels: unsaturated[v].iter().filter(|&&c| c).count(),
                        unsaturated_psnr_db: psnr_masked(&a, &truth_srgb[v], &unsaturated[v]),
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
                mean_unsaturated_psnr_db: mean(&|s| s.unsaturated_psnr_db),
                views: scores,
            }
        })
        .collect())
}

/// A plain-text table of scores: per view, each method's PSNR and SSIM, then the means.
pub fn scores_text(scores: &[MethodScore]) -> String {
    let fmt = |x: Option<f64>, d: usize| x.map_or("-".to_string(), |v| format!("{v:.d$}"));
    // One line: the label, then each method's two cells.
    let row = |s: &mut String, label: &str, cells: &dyn Fn(&MethodScore) -> (String, String)| {
        s.push_str(&format!("{label:<28}"));
        for m in scores {
            let (a, b) = cells(m);
            s.push_str(&format!(" {a:>14} {b:>8}"));
        }
        s.push('\n');
    };
    let mut s = String::new();
    row(&mut s, "view", &|m| {
        (format!("{} PSNR", m.method), "SSIM".into())
    });
    let n = scores.first().map_or(0, |m| m.views.len());
    for v in 0..n {
        row(&mut s, &scores[0].views[v].name, &|m| {
            (fmt(m.views[v].psnr_db, 2), fmt(m.views[v].ssim, 4))
        });
    }
    row(&mut s, "mean", &|m| {
        (
            format!("{:.2}", m.mean_psnr_db),
            format!("{:.4}", m.mean_ssim),
        )
    });
    row(&mut s, "mean, reference unsaturated", &|m| {
        (format!("{:.2}", m.mean_unsaturated_psnr_db), "-".into())
    });
    s
}
