//! The pooled fit of the calibrated light model over all frames.
//!
//! Steps: (1) one pass over the samples builds per-frame moments (`calibrated_moments`);
//! (2) alternate exact linear solves from s ≡ 1, g ≡ 1, a ≡ 0: rho per channel given s, g, a;
//! s (with s = 1 on the axis eliminated) given rho, g, a; g_f and a_f per frame given rho, s
//! (a 1x1 or 4x4 system each); kappa (the inter-reflection term, 3 values) given the rest; after each round the reference frame's gain is fixed to 1 by
//! moving the scale into rho; (3) a joint Levenberg–Marquardt polish over every parameter
//! (dense Gauss–Newton matrix, a few hundred parameters); (4) robust IRLS: Tukey or Huber
//! weights on each sample's relative residual, shared by the channels (vessels and
//! highlights are relative outliers at any brightness), multiply the density weights and
//! 1–3 repeat; (5) positivity: rho and s are checked on grids over [0, 1]; if either goes
//! non-positive the fit is redone with all Bernstein coefficients >= a small positive bound.
//! Gains are always kept > 0 and ambient terms >= 0 (light only adds).
//!
//! The albedo is unknown. [`fit_calibrated`] assumes its low-frequency mean is uniform (the
//! paper's assumption; the mean folds into rho and the robust weights discount vessels).
//! [`fit_calibrated_with_albedo`] refits with a known per-sample albedo: the build takes it
//! from a texture fused with the first light (`workflow::light_refine`).

// Indexing several parallel arrays (struct of arrays, channels) by one index reads clearer than zips.
#![allow(clippy::needless_range_loop)]
// `!(x > t)` on floats is deliberate: it also rejects NaN.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

use super::model::CalibratedModel;
use super::moments::{accumulate, cost, t_of, Layout};
use super::residuals::{residual_rms, robust_weights};
use super::samples::PooledSamples;
use super::solver::{bounds, clamp_to, min_positive, rho_scale, solve};
use super::specular::{SpecularLobe, SpecularMode};
use super::specular_fit::choose_alpha;
use crate::shading::error::check_weights;
use crate::shading::indirect::GatheredInterreflection;
use crate::shading::robust::Robust;
use crate::shading::ShadingError;
use crate::Result;

/// The name errors give this fit.
const FIT: &str = "calibrated fit";

/// Options of [`fit_calibrated`].
#[derive(Debug, Clone, PartialEq)]
pub struct CalibratedOptions {
    /// Degree of rho(gamma) per channel (the paper's cubic: 3). 0..=9.
    pub rho_degree: usize,
    /// Degree of s in cos theta. 0 (s ≡ 1) ..= 9. Default 3.
    pub s_degree: usize,
    /// Fit an inter-reflection term a_f per frame and channel. Default false.
    pub ambient: bool,
    /// Fit inter-reflection as `kappa_c L_f`: light scattered inside the tube, in proportion
    /// to the light the frame's view holds, measured as its mean observed luminance L_f over
    /// all surface pixels (auto-exposure included); 3 parameters kappa_c for the whole video.
    /// With the light at the lens the direct light falls as 1/z^2 but the scattered light
    /// does not, so without this term far surfaces come out brighter than the model and each
    /// gain absorbs its frame's share of far pixels. Default true: on the demo phantom
    /// (seeds 1-3) it raises the truth views by 0.9-2.1 dB and the held-out frames by
    /// 0.2-0.4 dB; with a uniform albedo it recovers the cone profile to 0.15% RMS (4.8%
    /// without). See BENCHMARKS.md "Inter-reflection".
    pub interreflection: bool,
    /// Fit the gathered inter-reflection `g_f alb k_c E_c` per sample, E the light gathered
    /// from the mesh at the sample's surface point ([`PooledSamples::indirect`], which must be
    /// set), beside `kappa_c L_f` when `interreflection` is also set. Default false (the build
    /// chooses with `--interreflection`).
    pub gathered: bool,
    /// The specular term `g_f k_c spec(gamma) s / z^2` of the light's colour
    /// ([`super::specular`]): a GGX lobe whose alpha the first fit chooses, of a white light
    /// or with its colour fitted, or none (rho then holds the highlights). Default: white
    /// (BENCHMARKS.md, "Specular term (issue 18 item 3)").
    pub specular: SpecularMode,
    /// Frame whose gain is fixed to 1. Default 0.
    pub reference_frame: usize,
    /// Most alternation rounds (each: rho, s, gains). Default 40.
    pub max_alternations: usize,
    /// Stop alternating / polishing when the cost falls by less than this fraction. Default 1e-10.
    pub tolerance: f64,
    /// Joint Levenberg–Marquardt polish after the alternation. Default true.
    pub lm_polish: bool,
    /// Most LM iterations. Default 60.
    pub max_lm_iterations: usize,
    /// Robust loss on the relative residuals. Default Huber(1.345). Not Tukey: Tukey rejects
    /// the vessels a near view resolves but keeps a far view's pixels that average them, so
    /// the light comes out brighter near than far and the gains drift with distance. Measured
    /// on the 80-frame demo phantom (build with two gain corrections): gains worst 8.2% ->
    /// 4.6%, RMS 3.2% -> 2.3% relative to the reference; truth views +0.08 dB.
    pub robust: Robust,
    /// Most IRLS re-weightings (stops earlier once no parameter moves by 1e-4 of itself). Default 8.
    pub max_irls_iterations: usize,
    /// Linear intensity added to |prediction| when forming relative residuals (keeps dark
    /// pixels from dominating the robust scale). Default 0.01.
    pub relative_floor: f64,
    /// Points of the positivity grids over gamma and t in [0, 1]. Default 65.
    pub positivity_grid: usize,
    /// Refit with non-negative Bernstein coefficients when rho or s goes non-positive. Default true.
    pub enforce_positivity: bool,
}

impl Default for CalibratedOptions {
    fn default() -> Self {
        CalibratedOptions {
            rho_degree: 3,
            s_degree: 3,
            ambient: false,
            interreflection: true,
            gathered: false,
            specular: SpecularMode::White,
            reference_frame: 0,
            max_alternations: 40,
            tolerance: 1e-10,
            lm_polish: true,
            max_lm_iterations: 60,
            robust: Robust::Huber(1.345),
            max_irls_iterations: 8,
            relative_floor: 0.01,
            positivity_grid: 65,
            enforce_positivity: true,
        }
    }
}

/// How the fit went.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct CalibratedReport {
    /// Alternation rounds (summed over IRLS rounds).
    pub alternations: usize,
    /// Accepted LM steps (summed).
    pub lm_steps: usize,
    /// IRLS re-weightings performed.
    pub irls_iterations: usize,
    /// True when the positivity-constrained fit replaced the unconstrained one.
    pub constrained: bool,
    /// Final weighted cost `sum w (I - model)^2` over channels (final weights).
    pub cost: f64,
    /// Fraction of the density weight the robust weights removed (0: none).
    pub downweighted: f64,
}

/// The fitted model, the report and the final per-sample weights (density x robust).
#[derive(Debug, Clone)]
pub struct CalibratedFit {
    /// The model.
    pub model: CalibratedModel,
    /// How the fit went.
    pub report: CalibratedReport,
    /// Final weight per sample (density x robust; 0 for samples left out).
    pub weights: Vec<f32>,
}

/// Fit the calibrated model to pooled samples with per-sample density weights, assuming a
/// uniform albedo (folded into rho).
pub fn fit_calibrated(
    samples: &PooledSamples,
    density: &[f32],
    opts: &CalibratedOptions,
) -> Result<CalibratedFit> {
    fit_inner(samples, density, None, None, opts)
}

/// Fit with a known per-sample albedo per channel (relative to its mean, which folds into
/// rho; NaN or <= 0: sample left out), starting from `init` if given (same degrees).
pub fn fit_calibrated_with_albedo(
    samples: &PooledSamples,
    density: &[f32],
    albedo: &[Vec<f32>; 3],
    init: Option<&CalibratedModel>,
    opts: &CalibratedOptions,
) -> Result<CalibratedFit> {
    if albedo.iter().any(|a| a.len() != samples.len()) {
        return Err(ShadingError::LengthMismatch {
            fit: FIT,
            what: "albedo values",
            got: albedo[0].len(),
            expected: samples.len(),
        }
        .into());
    }
    fit_inner(samples, density, Some(albedo), init, opts)
}

fn check_inputs(samples: &PooledSamples, density: &[f32], opts: &CalibratedOptions) -> Result<()> {
    let f = samples.frames();
    let need = 3 * (opts.rho_degree + 1)
        + opts.s_degree
        + f * if opts.ambient { 4 } else { 1 }
        + if opts.interreflection { 3 } else { 0 }
        + if opts.specular != SpecularMode::None {
            3
        } else {
            0
        };
    if opts.gathered {
        let ok = samples
            .indirect
            .as_ref()
            .is_some_and(|e| e.iter().all(|v| v.len() == samples.len()));
        if !ok {
            return Err(ShadingError::BadOptions {
                fit: FIT,
                message: "the gathered inter-reflection needs every sample's gathered light".into(),
            }
            .into());
        }
    }
    if opts.interreflection && samples.frame_light.len() != f {
        return Err(ShadingError::LengthMismatch {
            fit: FIT,
            what: "frames' mean light (the inter-reflection needs each frame's)",
            got: samples.frame_light.len(),
            expected: f,
        }
        .into());
    }
    if samples.len() < need {
        return Err(ShadingError::TooFewSamples {
            fit: FIT,
            got: samples.len(),
            needed: need,
        }
        .into());
    }
    if opts.rho_degree > 9 || opts.s_degree > 9 {
        return Err(ShadingError::BadOptions {
            fit: FIT,
            message: format!(
                "degrees rho {} / s {} (at most 9)",
                opts.rho_degree, opts.s_degree
            ),
        }
        .into());
    }
    if opts.reference_frame >= f {
        return Err(ShadingError::BadOptions {
            fit: FIT,
            message: format!("reference frame {} of {f} frames", opts.reference_frame),
        }
        .into());
    }
    check_weights(FIT, density, samples.len())?;
    if let Some(f) = (0..f).find(|&f| samples.frame_start[f] == samples.frame_start[f + 1]) {
        return Err(ShadingError::FrameWithoutSamples { frame: f }.into());
    }
    Ok(())
}

fn fit_inner(
    samples: &PooledSamples,
    density: &[f32],
    albedo: Option<&[Vec<f32>; 3]>,
    init: Option<&CalibratedModel>,
    opts: &CalibratedOptions,
) -> Result<CalibratedFit> {
    check_inputs(samples, density, opts)?;
    let mut lay = Layout {
        nr: opts.rho_degree + 1,
        ns: opts.s_degree + 1,
        frames: samples.frames(),
        ambient: opts.ambient,
        interreflection: opts.interreflection,
        gathered: opts.gathered,
        specular: None,
        spec_colours: if opts.specular == SpecularMode::Coloured {
            3
        } else {
            1
        },
    };
    let cos_edge = match init {
        Some(m) => m.cos_theta_edge,
        None => samples.min_cos_theta().min(1.0 - 1e-6),
    };
    let t = t_of(samples, cos_edge);
    let base: Vec<f32> = (0..samples.len())
        .map(|i| match albedo {
            Some(a) if !(0..3).all(|c| a[c][i] > 0.0) => 0.0,
            _ => density[i],
        })
        .collect();
    if opts.specular != SpecularMode::None {
        // The lobe's width is kept from the light the refits start from.
        lay.specular = Some(match init.and_then(|m| m.specular) {
            Some(s) => s.alpha,
            None => choose_alpha(samples, &t, &base, albedo, lay, init, opts)?,
        });
    }
    let mut p = match init {
        Some(m) => params_of(&lay, m)?,
        None => initial(&lay),
    };
    let mut rep = CalibratedReport::default();
    let mut w = base.clone();
    let mut constrained = false;
    for round in 0..=opts.max_irls_iterations {
        let m = accumulate(samples, &t, &w, albedo, &lay);
        let scale = rho_scale(&lay, &m);
        let prev = p.clone();
        if !constrained {
            p = solve(&lay, &m, p, opts, None, &mut rep);
            if opts.enforce_positivity && !(min_positive(&lay, &p, opts.positivity_grid) > 0.0) {
                constrained = true;
                rep.constrained = true;
            }
        }
        if constrained {
            clamp_to(&lay, &mut p, Some(bounds(scale)));
            p = solve(&lay, &m, p, opts, Some(bounds(scale)), &mut rep);
        }
        if matches!(opts.robust, Robust::None) || round == opts.max_irls_iterations {
            rep.cost = cost(&lay, &m, &p);
            break;
        }
        let change = (0..p.len())
            .map(|k| (p[k] - prev[k]).abs() / (prev[k].abs() + 1e-3))
            .fold(0.0, f64::max);
        if round > 0 && change < 1e-4 {
            rep.cost = cost(&lay, &m, &p);
            break;
        }
        rep.irls_iterations += 1;
        w = robust_weights(samples, &t, &base, albedo, &lay, &p, opts);
    }
    let (rms, _) = residual_rms(samples, &t, &w, albedo, &lay, &p);
    let wsum_base: f64 = base.iter().map(|&x| f64::from(x)).sum();
    let wsum: f64 = w.iter().map(|&x| f64::from(x)).sum();
    rep.downweighted = 1.0 - wsum / wsum_base.max(1e-300);
    let model = model_of(
        &lay,
        &p,
        &samples.frame_light,
        cos_edge,
        opts.reference_frame,
        rms,
        samples.len(),
    );
    let mut model = model;
    if let (Some(g), Some(Some(i))) = (model.gathered.as_mut(), init.map(|m| m.gathered)) {
        // The gather's settings stay those of the light the samples were gathered with.
        (g.nodes_across, g.rays, g.visibility) = (i.nodes_across, i.rays, i.visibility);
    }
    Ok(CalibratedFit {
        model,
        report: rep,
        weights: w,
    })
}

/// rho ≡ 0, s ≡ 1, g ≡ 1, a ≡ 0, k ≡ 0.
pub(super) fn initial(lay: &Layout) -> Vec<f64> {
    let mut p = vec![0.0; lay.len()];
    for k in 1..lay.ns {
        p[lay.e_off() + k - 1] = 1.0;
    }
    for f in 0..lay.frames {
        p[lay.g_off() + f] = 1.0;
    }
    p
}

pub(super) fn params_of(lay: &Layout, m: &CalibratedModel) -> Result<Vec<f64>> {
    if m.rho.iter().any(|r| r.len() != lay.nr)
        || m.s.len() != lay.ns
        || m.gains.len() != lay.frames
        || (lay.ambient && m.ambient.as_ref().is_none_or(|a| a.len() != lay.frames))
    {
        return Err(ShadingError::BadOptions {
            fit: FIT,
            message: "the initial model's degrees, frames or ambient terms differ from the options"
                .into(),
        }
        .into());
    }
    let mut p = vec![0.0; lay.len()];
    for c in 0..3 {
        p[lay.c_off(c)..lay.c_off(c) + lay.nr].copy_from_slice(&m.rho[c]);
    }
    p[lay.e_off()..lay.e_off() + lay.ns - 1].copy_from_slice(&m.s[1..]);
    p[lay.g_off()..lay.g_off() + lay.frames].copy_from_slice(&m.gains);
    if let (true, Some(g)) = (lay.gathered, &m.gathered) {
        p[lay.q_off()..lay.q_off() + 3].copy_from_slice(&g.k);
    }
    if let (Some(_), Some(sp)) = (lay.specular, &m.specular) {
        for c in 0..lay.spec_colours {
            // A white light starts from the mean of a coloured one's.
            p[lay.p_off() + c] = match lay.spec_colours {
                3 => sp.k[c],
                _ => sp.k.iter().sum::<f64>() / 3.0,
            };
        }
    }
    if lay.ambient {
        for (f, a) in m.ambient.as_ref().into_iter().flatten().enumerate() {
            p[lay.a_off() + 3 * f..lay.a_off() + 3 * f + 3].copy_from_slice(a);
        }
    }
    Ok(p)
}

fn model_of(
    lay: &Layout,
    p: &[f64],
    frame_light: &[f64],
    cos_edge: f64,
    reference: usize,
    rms: [f64; 3],
    n: usize,
) -> CalibratedModel {
    let mut s = vec![1.0];
    s.extend_from_slice(&p[lay.e_off()..lay.e_off() + lay.ns - 1]);
    CalibratedModel {
        rho: std::array::from_fn(|c| p[lay.c_off(c)..lay.c_off(c) + lay.nr].to_vec()),
        s,
        cos_theta_edge: cos_edge,
        gains: p[lay.g_off()..lay.g_off() + lay.frames].to_vec(),
        reference_frame: reference,
        ambient: (lay.ambient || lay.interreflection).then(|| {
            (0..lay.frames)
                .map(|f| {
                    let light = frame_light.get(f).copied().unwrap_or(0.0);
                    std::array::from_fn(|c| super::moments::ambient_of(lay, p, light, f, c))
                })
                .collect()
        }),
        interreflection: lay
            .interreflection
            .then(|| std::array::from_fn(|c| p[lay.k_off() + c])),
        frame_light: lay.interreflection.then(|| frame_light.to_vec()),
        // The caller records how the light was gathered.
        gathered: lay.gathered.then(|| GatheredInterreflection {
            k: std::array::from_fn(|c| p[lay.q_off() + c]),
            nodes_across: 1,
            rays: 1,
            visibility: false,
        }),
        frame_indirect: None,
        // No term when the fit found no highlight (every k_c at its bound 0).
        specular: lay
            .specular
            .map(|alpha| SpecularLobe {
                k: std::array::from_fn(|c| p[lay.k_idx(c)]),
                alpha,
            })
            .filter(|s| s.k.iter().any(|&k| k > 0.0)),
        auto_exposure: None,
        rms_residual: rms,
        samples_used: n,
    }
}
