//! The re-weighting passes of [`super::FusionMethod::RobustAverage`]: iteratively reweighted
//! least squares of each texel's consensus with a Cauchy loss on the relative disagreement of
//! an observation with the previous consensus, and the texture as the average weighted by the
//! predicted intensity times that agreement.
//!
//! The consensus weighs every frame alike (Cauchy weights only): weighted by the intensity it
//! would be the value of the one best-lit frame wherever one dominates, the others would all
//! disagree with it and the fusion would become the paper's max-weight choice, keeping a wrong
//! frame where it dominates.
//!
//! Why: the weighted average lets every frame pull a texel towards its own value. A frame whose
//! pose is off by a fraction of a millimetre puts a vessel where the others see mucosa; a
//! blurred frame smears an edge; a frame whose shading is wrong at a texel (a highlight, an
//! inter-reflection the model misses) is off by much more than the others. All three disagree
//! with the consensus at exactly the texels where they would blur it, and nowhere else.

// Parallel arrays indexed by channel read clearer than zips.
#![allow(clippy::needless_range_loop)]

use rayon::prelude::*;

use super::delight::{DelightOptions, FrameCtx};
use super::fusion::FrameStream;
use super::pass::{for_visible_blocks, weight_power, Acc, CameraCache};
use super::texels::TexelSet;
use crate::Result;

/// Parameters of the re-weighting (see [`super::FusionMethod::RobustAverage`]).
pub(super) struct RobustOptions {
    pub(super) weight_exponent: f32,
    pub(super) residual_scale: f32,
    pub(super) rounds: u32,
}

/// One texel during a re-weighting pass: the previous consensus and the new running sums.
#[derive(Clone, Copy, Default)]
struct Texel {
    mean: [f32; 3],
    /// `1 / (residual_scale² |mean|²)`: the squared difference that halves a weight, inverted.
    inv_scale2: f32,
    /// The consensus (agreement weights).
    consensus: Acc,
    /// The texture (intensity power times agreement).
    texture: Acc,
}

/// The Cauchy weight of an observation `v` of a texel whose consensus is `mean`.
#[inline]
fn agreement(v: [f32; 3], mean: [f32; 3], inv_scale2: f32) -> f32 {
    let d2: f32 = (0..3).map(|c| (v[c] - mean[c]) * (v[c] - mean[c])).sum();
    1.0 / (1.0 + d2 * inv_scale2)
}

/// Run `opts.rounds` re-weighting passes over `frames`, starting from the consensus sums in
/// `acc` (pass 1's plain mean) and leaving the last pass's texture sums there. Texels no frame
/// saw stay empty.
/// Returns the heap bytes of the extra per-texel state.
pub(super) fn reweight_passes<S: FrameStream + ?Sized>(
    texels: &TexelSet,
    frames: &mut S,
    delight: &DelightOptions,
    cams: &mut CameraCache,
    opts: &RobustOptions,
    acc: &mut [Acc],
) -> Result<usize> {
    if opts.rounds == 0 {
        return Ok(0);
    }
    let c2 = (opts.residual_scale.max(1e-6)).powi(2);
    let mut state = vec![Texel::default(); acc.len()];
    let e = opts.weight_exponent;
    for round in 0..opts.rounds {
        state.par_iter_mut().zip(acc.par_iter()).for_each(|(t, a)| {
            let a = if round == 0 { *a } else { t.consensus };
            *t = Texel::default();
            if a.w > 0.0 {
                t.mean = a.rgb.map(|x| x / a.w);
                let m2: f32 = t.mean.iter().map(|x| x * x).sum();
                t.inv_scale2 = 1.0 / (c2 * m2.max(1e-12));
            }
        });
        for f in 0..frames.frame_count() {
            let obs = frames.observation(f)?;
            let ctx = FrameCtx::new(&obs, delight, cams.angle(obs.camera))?;
            for_visible_blocks(texels, &ctx, &mut state, None, |t, v, w| {
                if t.inv_scale2 <= 0.0 {
                    return;
                }
                let a = agreement(v, t.mean, t.inv_scale2);
                for (acc, w) in [
                    (&mut t.consensus, a),
                    (&mut t.texture, a * weight_power(w, e)),
                ] {
                    for ch in 0..3 {
                        acc.rgb[ch] += w * v[ch];
                    }
                    acc.w += w;
                }
            });
        }
    }
    acc.par_iter_mut()
        .zip(state.par_iter())
        .for_each(|(a, t)| *a = t.texture);
    Ok(state.len() * std::mem::size_of::<Texel>())
}
