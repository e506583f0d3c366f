//! One correction of the calibrated light's per-frame gains against the fused texture.
//!
//! The pooled fit assumes a uniform albedo, so each frame's gain absorbs the mean albedo of the
//! mucosa it sees (vessels, pale patches): a few percent per frame. The fused texture averages
//! many frames per texel, so each frame's de-lit texels against it show that frame's own gain
//! error: `delta_f = weighted median over texels of log(v_f / A)` (luminance; texels that at
//! least `min_frames` frames saw). The build makes two steps (the texture includes the frame
//! itself, so one step recovers only part of the error); many steps tie every frame to its
//! neighbours and let small biases of the light model accumulate along the video (see
//! BENCHMARKS.md, the texel-linked solve). Measured on the 80-frame demo, gains RMS relative to the
//! reference: 1 step 2.8%, 2 steps 2.3%, 3 steps 2.2% but worst frame 4.6% -> 5.5%.

use super::light::Consensus;
use crate::shading::frame_shading::LUMA;
use crate::shading::CalibratedModel;
use crate::texture::delight::{delight_frame, DelightOptions};
use crate::texture::fusion::fuse;
use crate::texture::fusion::{FrameStream, FusedTexture};
use crate::texture::texels::TexelSet;
use crate::Result;

/// Fewest frames a texel must be fused from to serve as a reference.
pub const MIN_FRAMES: u32 = 3;

/// One correction of `model`'s gains against the consensus texture fused with it.
pub fn correct_gains(consensus: &Consensus, model: &mut CalibratedModel) -> Result<()> {
    let first = model.clone();
    let mut stream = consensus.frames(&first, "refine gains", consensus.fusion.method.passes() + 1);
    let fused = fuse(&consensus.texels, &mut stream, &consensus.fusion)?;
    refine_gains_against_texture(
        model,
        &consensus.texels,
        &fused,
        &mut stream,
        &consensus.fusion.delight,
    )?;
    stream.progress.finish();
    Ok(())
}

/// Correct `model.gains` in place with one step against `fused` (fused from `frames`, whose
/// shading is `model`); the reference frame keeps gain 1. Returns the correction factor of
/// every frame (before renormalisation to the reference).
pub fn refine_gains_against_texture<S: FrameStream + ?Sized>(
    model: &mut CalibratedModel,
    texels: &TexelSet,
    fused: &FusedTexture,
    frames: &mut S,
    opts: &DelightOptions,
) -> Result<Vec<f64>> {
    let n = frames.frame_count();
    let lum = |c: [f32; 3]| LUMA[0] * c[0] as f64 + LUMA[1] * c[1] as f64 + LUMA[2] * c[2] as f64;
    let mut factors = vec![1.0; n];
    for (f, factor) in factors.iter_mut().enumerate() {
        let obs = frames.observation(f)?;
        let delit = delight_frame(texels, &obs, opts)?;
        let mut pairs: Vec<(f64, f64)> = Vec::new();
        for (slot, (&w, v)) in delit.weight.iter().zip(&delit.value).enumerate() {
            if w.is_nan() || w <= 0.0 {
                continue;
            }
            let t = texels.texel[slot] as usize;
            if fused.frames_seen[t] < MIN_FRAMES || !fused.covered[t] {
                continue;
            }
            let a = lum([fused.rgb[3 * t], fused.rgb[3 * t + 1], fused.rgb[3 * t + 2]]);
            let b = lum(*v);
            if a > 0.0 && b > 0.0 {
                pairs.push(((b / a).ln(), w as f64));
            }
        }
        if pairs.len() >= 100 {
            *factor = weighted_median(&mut pairs).exp();
        }
    }
    // De-lit values scale as 1 / gain: a frame whose texels come out too bright has too small
    // a gain.
    let r = model.reference_frame.min(n.saturating_sub(1));
    let reference = factors.get(r).copied().unwrap_or(1.0);
    for (g, k) in model.gains.iter_mut().zip(&factors) {
        *g *= k / reference;
    }
    Ok(factors)
}

/// The weighted median of (value, weight) pairs (sorted in place).
fn weighted_median(pairs: &mut [(f64, f64)]) -> f64 {
    pairs.sort_by(|a, b| a.0.total_cmp(&b.0));
    let total: f64 = pairs.iter().map(|p| p.1).sum();
    let mut acc = 0.0;
    for &(v, w) in pairs.iter() {
        acc += w;
        if acc >= 0.5 * total {
            return v;
        }
    }
    pairs.last().map_or(0.0, |p| p.0)
}

#[cfg(test)]
mod tests {
    use super::weighted_median;

    #[test]
    fn weighted_median_follows_the_weights() {
        let mut p = vec![(3.0, 1.0), (1.0, 1.0), (2.0, 1.0)];
        assert_eq!(weighted_median(&mut p), 2.0);
        let mut p = vec![(3.0, 10.0), (1.0, 1.0), (2.0, 1.0)];
        assert_eq!(weighted_median(&mut p), 3.0);
    }
}
