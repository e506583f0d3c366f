//! The specular lobe's width: the one parameter of the calibrated light that is not linear
//! once the others are fixed, chosen among [`ALPHA_CANDIDATES`] by the fit's own cost.

use super::fit::{initial, params_of, CalibratedOptions, CalibratedReport};
use super::model::CalibratedModel;
use super::moments::{accumulate, cost, Layout};
use super::samples::PooledSamples;
use super::solver::solve;
use super::specular::ALPHA_CANDIDATES;
use crate::Result;

/// The alpha of [`ALPHA_CANDIDATES`] whose light (rho, s, gains, k, ... solved exactly by the
/// alternation, without the polish or the robust re-weighting: the candidates only need
/// ranking) has the lowest weighted cost on the samples with weights `base`. The pixels that
/// inform it are the highlights' unsaturated skirts: the pool holds no saturated pixel.
pub(super) fn choose_alpha(
    samples: &PooledSamples,
    t: &[f32],
    base: &[f32],
    albedo: Option<&[Vec<f32>; 3]>,
    lay: Layout,
    init: Option<&CalibratedModel>,
    opts: &CalibratedOptions,
) -> Result<f64> {
    let quick = CalibratedOptions {
        lm_polish: false,
        ..opts.clone()
    };
    let mut best = (f64::INFINITY, ALPHA_CANDIDATES[0]);
    for alpha in ALPHA_CANDIDATES {
        let lay = Layout {
            specular: Some(alpha),
            ..lay
        };
        let m = accumulate(samples, t, base, albedo, &lay);
        let p = match init {
            Some(model) => params_of(&lay, model)?,
            None => initial(&lay),
        };
        let p = solve(&lay, &m, p, &quick, None, &mut CalibratedReport::default());
        let c = cost(&lay, &m, &p);
        if c < best.0 {
            best = (c, alpha);
        }
    }
    Ok(best.1)
}
