//! The mucosa's albedo predicted from its colour: a better prior for the calibrated light's
//! gains than a uniform albedo.
//!
//! With a uniform albedo each frame's gain absorbs the mean albedo of what it sees. But most of
//! the mucosa's albedo variation comes with a change of colour: blood (vessels, hyperaemia)
//! darkens green and blue far more than red, pale mucosa brightens green and blue most. A
//! pixel's chromaticity — its log colour ratios G/R and B/R, with the light's own ratios
//! `rho_G(gamma) / rho_R(gamma)` divided out — does not depend on the gain, the distance or
//! the light's profile, so a relation between chromaticity and albedo, fitted over all pooled
//! pixels, gives each pixel an albedo estimate that no frame's gain can bias and that ties no
//! frame to another (unlike a fused texture's albedo, whose links between frames make the
//! gains drift; see `workflow::light_refine`).
//!
//! Per channel c, a robust (Huber IRLS) weighted least-squares fit of
//! `log(I_c / pred_c) = a_fc + b_c . phi(x)` over the pooled samples, with
//! - x the chromaticity of the sample's 8 neighbouring pixels (their mean log G/R and B/R)
//!   minus the light's own log ratios `log(pred_G / pred_R)`, `log(pred_B / pred_R)` at the
//!   sample: the pixel's own colour would put its own noise on both sides of the regression
//!   (measured on a synthetic video: the relation's slope came out negative and the gains
//!   improved only from 15.6% to 13.3%; with the neighbours' colour to 5.0%);
//! - phi the quadratic monomials of x (5 terms), x clamped to its 1st..99th percentiles;
//! - a_fc one intercept per frame and channel, eliminated (each frame's weighted means are
//!   subtracted), so a frame's gain error cannot enter the relation.
//!
//! On the phantom's mucosa such a quadratic explains 95% of the log-luminance variance of the
//! albedo; where colour and brightness are unrelated the fit finds b = 0 and the uniform albedo
//! comes back.

use nalgebra::{Matrix5, Vector5, Vector6};
use rayon::prelude::*;

use super::fit::{fit_calibrated_with_albedo, CalibratedOptions};
use super::model::CalibratedModel;
use super::samples::PooledSamples;
use crate::shading::error::check_weights;
use crate::shading::ShadingError;
use crate::Result;

/// The name errors give this fit.
const FIT: &str = "chroma albedo";

/// Huber constant of the regression's IRLS.
const HUBER: f64 = 1.345;
/// IRLS rounds of the regression.
const IRLS_ROUNDS: usize = 5;
/// The regression uses every n-th sample (18 coefficients need far fewer than the pool's
/// millions; measured on the demo: the same gains to 0.01%).
const REGRESSION_STRIDE: usize = 4;

/// One row of the regression: a sample's monomials (without the constant), its log residuals
/// per channel and its density weight.
struct Row {
    feat: Vector5<f64>,
    r: [f64; 3],
    weight: f64,
}

/// The fitted relation between chromaticity and log albedo.
#[derive(Clone, Debug, PartialEq)]
pub struct ChromaAlbedo {
    /// Per channel R, G, B: coefficients of phi(x) = (1, x1, x2, x1², x2², x1·x2); the
    /// constant's is 0 (each frame has its own intercept, eliminated in the fit).
    pub coeffs: [[f64; 6]; 3],
    /// Clamp range of x1 and x2 (1st and 99th percentiles of the samples').
    pub range: [[f64; 2]; 2],
}

/// Per sample: the log residuals `log(I_c / pred_c)` under a light and the chromaticity x
/// (NaN where undefined). f32: they live beside the pool's millions of samples.
struct Residuals {
    r: Vec<[f32; 3]>,
    x: Vec<[f32; 2]>,
}

/// [`Residuals`] of `s` under `model`. x is the neighbours' mean log colour ratios
/// ([`PooledSamples::neighbour_chroma`]) with the light's own ratios at the sample divided
/// out: a pixel's own noise would enter both sides of the regression (its red channel in
/// `log(I_R / pred_R)` and, negated, in `log(I_G / I_R)`) and tilt the fitted relation.
fn residuals(model: &CalibratedModel, s: &PooledSamples) -> Residuals {
    let (r, x) = (0..s.frames())
        .into_par_iter()
        .flat_map_iter(|f| {
            (s.frame_start[f]..s.frame_start[f + 1]).map(move |i| {
                let (g, ct, z) = (
                    f64::from(s.gamma[i]),
                    f64::from(s.cos_theta[i]),
                    f64::from(s.z[i]),
                );
                let pred: [f64; 3] =
                    std::array::from_fn(|c| model.eval_frame(c, g, ct, z, f).unwrap_or(f64::NAN));
                let r = std::array::from_fn(|c| {
                    let v = f64::from(s.rgb[c][i]);
                    if pred[c] > 0.0 && v > 0.0 {
                        (v / pred[c]).ln() as f32
                    } else {
                        f32::NAN
                    }
                });
                let nc = s.neighbour_chroma.get(i).copied().unwrap_or([f32::NAN; 2]);
                let x = [
                    (f64::from(nc[0]) - (pred[1] / pred[0]).ln()) as f32,
                    (f64::from(nc[1]) - (pred[2] / pred[0]).ln()) as f32,
                ];
                (r, x)
            })
        })
        .unzip();
    Residuals { r, x }
}

fn phi(x: [f64; 2]) -> Vector6<f64> {
    Vector6::new(1.0, x[0], x[1], x[0] * x[0], x[1] * x[1], x[0] * x[1])
}

impl ChromaAlbedo {
    /// The fit on the samples' residuals and chromaticities `res` (every
    /// [`REGRESSION_STRIDE`]-th sample), with one intercept per frame (`frame_start`).
    fn fit_residuals(res: &Residuals, density: &[f32], frame_start: &[usize]) -> Result<Self> {
        let mut range = [[0.0; 2]; 2];
        for (k, rg) in range.iter_mut().enumerate() {
            let mut v: Vec<f32> = res
                .x
                .iter()
                .map(|a| a[k])
                .filter(|v| v.is_finite())
                .collect();
            if v.len() < 100 {
                return Err(ShadingError::TooFewSamples {
                    fit: FIT,
                    got: v.len(),
                    needed: 100,
                }
                .into());
            }
            let n = v.len();
            let lo = *v.select_nth_unstable_by(n / 100, f32::total_cmp).1;
            let hi = *v.select_nth_unstable_by(n - 1 - n / 100, f32::total_cmp).1;
            *rg = [f64::from(lo), f64::from(hi)];
        }
        let mut out = ChromaAlbedo {
            coeffs: [[0.0; 6]; 3],
            range,
        };
        // The regression's rows, frame by frame: every REGRESSION_STRIDE-th sample with a
        // colour, its monomials without the constant (within a frame only differences count).
        let mut rows: Vec<Row> = Vec::new();
        let mut row_start = vec![0usize];
        for fr in frame_start.windows(2) {
            for i in (fr[0]..fr[1]).filter(|i| i % REGRESSION_STRIDE == 0) {
                let (r, x) = (res.r[i], res.x[i]);
                if density[i] > 0.0 && r.iter().chain(&x).all(|v| v.is_finite()) {
                    let x = out.clamp(x.map(f64::from));
                    let feat = phi(x).fixed_rows::<5>(1).into_owned();
                    rows.push(Row {
                        feat,
                        r: r.map(f64::from),
                        weight: f64::from(density[i]),
                    });
                }
            }
            row_start.push(rows.len());
        }
        let frames: Vec<&[Row]> = row_start.windows(2).map(|w| &rows[w[0]..w[1]]).collect();
        for c in 0..3 {
            let mut robust = vec![1.0f64; rows.len()];
            let mut b = Vector5::zeros();
            for _ in 0..IRLS_ROUNDS {
                let rw: Vec<&[f64]> = row_start.windows(2).map(|w| &robust[w[0]..w[1]]).collect();
                // Each frame's weighted means: its gain (and any error of it) drops out.
                let means: Vec<(Vector5<f64>, f64)> = frames
                    .par_iter()
                    .zip(&rw)
                    .map(|(rows, rw)| {
                        let (mut sw, mut sp, mut sr) = (0.0, Vector5::zeros(), 0.0);
                        for (row, q) in rows.iter().zip(rw.iter()) {
                            let w = row.weight * q;
                            sw += w;
                            sp += row.feat * w;
                            sr += w * row.r[c];
                        }
                        if sw > 0.0 {
                            (sp / sw, sr / sw)
                        } else {
                            (Vector5::zeros(), 0.0)
                        }
                    })
                    .collect();
                let (ata, atb) = frames
                    .par_iter()
                    .zip(&rw)
                    .zip(&means)
                    .map(|((rows, rw), (mp, mr))| {
                        let (mut a, mut v) = (Matrix5::<f64>::zeros(), Vector5::<f64>::zeros());
                        for (row, q) in rows.iter().zip(rw.iter()) {
                            let w = row.weight * q;
                            let p = row.feat - mp;
                            a += p * p.transpose() * w;
                            v += p * (w * (row.r[c] - mr));
                        }
                        (a, v)
                    })
                    .reduce(
                        || (Matrix5::zeros(), Vector5::zeros()),
                        |a, b| (a.0 + b.0, a.1 + b.1),
                    );
                b = ata
                    .cholesky()
                    .map(|ch| ch.solve(&atb))
                    .ok_or(ShadingError::Singular { fit: FIT })?;
                // Huber weights at the robust scale (the median absolute residual).
                let abs_res: Vec<f64> = frames
                    .iter()
                    .zip(&means)
                    .flat_map(|(rows, (mp, mr))| {
                        rows.iter()
                            .map(move |row| (row.r[c] - mr - (row.feat - mp).dot(&b)).abs())
                    })
                    .collect();
                let mut sorted = abs_res.clone();
                let mid = sorted.len() / 2;
                let sigma = 1.4826 * *sorted.select_nth_unstable_by(mid, f64::total_cmp).1;
                for (w, e) in robust.iter_mut().zip(&abs_res) {
                    let u = e / (HUBER * sigma.max(1e-12));
                    *w = if u > 1.0 { 1.0 / u } else { 1.0 };
                }
            }
            out.coeffs[c][1..].copy_from_slice(b.as_slice());
        }
        Ok(out)
    }

    fn clamp(&self, x: [f64; 2]) -> [f64; 2] {
        std::array::from_fn(|k| x[k].clamp(self.range[k][0], self.range[k][1]))
    }

    /// Log albedo of channel `c` at chromaticity `x`, relative (no constant term).
    pub fn log_albedo(&self, c: usize, x: [f64; 2]) -> f64 {
        let p = phi(self.clamp(x));
        (1..6).map(|j| self.coeffs[c][j] * p[j]).sum()
    }

    /// Each sample's albedo per channel (mean 1 per channel; NaN where a sample has no colour).
    fn albedo_of(&self, res: &Residuals) -> [Vec<f32>; 3] {
        std::array::from_fn(|c| {
            let mut a: Vec<f64> = res
                .x
                .iter()
                .map(|&x| self.log_albedo(c, x.map(f64::from)).exp())
                .collect();
            let (sum, n) = a
                .iter()
                .filter(|v| v.is_finite())
                .fold((0.0, 0usize), |(s, n), v| (s + v, n + 1));
            let mean = sum / n.max(1) as f64;
            for v in a.iter_mut() {
                *v /= mean;
            }
            a.into_iter().map(|v| v as f32).collect()
        })
    }
}

/// One round: fit the chromaticity relation under `model`, then refit the whole light — gains
/// included — with each sample's albedo from it (`opts.max_irls_iterations` capped at 3: the
/// refit starts from a converged light). Returns the relation used.
pub fn refit_with_chroma_albedo(
    model: &mut CalibratedModel,
    samples: &PooledSamples,
    density: &[f32],
    opts: &CalibratedOptions,
) -> Result<ChromaAlbedo> {
    check_weights(FIT, density, samples.len())?;
    let res = residuals(model, samples);
    let chroma = ChromaAlbedo::fit_residuals(&res, density, &samples.frame_start)?;
    let albedo = chroma.albedo_of(&res);
    let opts = CalibratedOptions {
        reference_frame: model.reference_frame,
        max_irls_iterations: opts.max_irls_iterations.min(3),
        ..opts.clone()
    };
    *model = fit_calibrated_with_albedo(samples, density, &albedo, Some(model), &opts)?.model;
    Ok(chroma)
}
