//! A refit of the calibrated light's shape (rho, s, kappa) against the fused texture.
//!
//! The pooled fit assumes a uniform albedo. Within a frame the centre (far, ahead) and the edge
//! (near, beside the camera) see different mucosa, and over a single video the albedo's slow
//! variation (vessel density, pale patches, brightness on 6–10 mm scales) does not average out
//! between them, so the light's angular profile and its gamma and z dependence absorb part of
//! it. Here every pooled sample takes its albedo from a texture fused with the current light
//! (looked up at the sample's surface point, relative to each channel's mean) and the light is
//! refitted with that albedo. A texel's fused value averages the frames that saw it at many
//! angles and distances, so the refit sees each texel's own brightness instead of a uniform
//! one; the gains are kept (refitting them too chains the frames through the surface they
//! share, and small biases of the CT geometry accumulate along the video: see
//! BENCHMARKS.md, the texel-linked solve). Measured on the 80-frame demo phantom, two rounds (each
//! followed by a gain correction): cone profile 6.9% -> 0.4% RMS, gains RMS 2.14% -> 1.85%,
//! truth views 31.99 -> 32.54 dB; seeds 2 and 3 alike (BENCHMARKS.md).

use super::fit_pass::LightSamples;
use super::light::{gather_all, set_sample_light, Consensus};
use crate::image::Frame;
use crate::raycast::GBuffer;
use crate::render::{MipOptions, MipTexture};
use crate::shading::calibrated::{
    fit_calibrated_with_albedo, CalibratedModel, CalibratedOptions, PooledSamples,
};
use crate::shading::indirect::TextureAlbedo;
use crate::Result;

/// One refit of `model`'s shape (rho, s, kappa) with each pooled sample's albedo taken from
/// the consensus texture fused with the current light; the gains are kept.
pub fn refit_light_against_texture(
    consensus: &Consensus,
    model: &mut CalibratedModel,
    samples: &mut LightSamples,
    density: &[f32],
    opts: &CalibratedOptions,
) -> Result<()> {
    let scene = consensus.scene;
    let fused = consensus.fuse(model, "refit light")?;
    let image = Frame {
        width: scene.atlas.width,
        height: scene.atlas.height,
        rgb: fused.filled(&scene.texels)?,
    };
    let texel_mm = scene.atlas.texel_mm;
    let texture = MipTexture::new(&image, None, texel_mm, &MipOptions::default())?;
    let albedo = sample_albedo(&texture, &samples.uv);
    let Some(settings) = model.gathered.filter(|_| opts.gathered) else {
        return refit_light_with_albedo(model, &samples.pooled, density, &albedo, opts);
    };
    // The gathered light with the texture's albedo, before and after the refit of the light.
    let wall = TextureAlbedo::new(&texture, &scene.tri_uv);
    let fields = gather_all(scene, model, &wall, &settings);
    set_sample_light(scene, &mut samples.pooled, &fields);
    refit_light_with_albedo(model, &samples.pooled, density, &albedo, opts)?;
    model.frame_indirect = Some(gather_all(scene, model, &wall, &settings));
    Ok(())
}

/// The texture coordinates of the surface points seen by the pixels `pixels` of a frame
/// (its G-buffer `gbuffer`; `tri_uv` the UV corners of every triangle).
pub fn sample_uvs(pixels: &[u32], gbuffer: &GBuffer, tri_uv: &[[[f32; 2]; 3]]) -> Vec<[f32; 2]> {
    pixels
        .iter()
        .map(|&px| {
            let px = px as usize;
            let [a, b, c] = tri_uv[gbuffer.tri[px] as usize];
            let [u, v] = gbuffer.bary[px];
            let w = 1.0 - u - v;
            [
                w * a[0] + u * b[0] + v * c[0],
                w * a[1] + u * b[1] + v * c[1],
            ]
        })
        .collect()
}

/// Each sample's albedo from `texture` at `uvs` (bilinear), per channel relative to the
/// channel's mean over the samples; NaN where the texture holds nothing (the fit leaves
/// those samples out).
pub fn sample_albedo(texture: &MipTexture, uvs: &[[f32; 2]]) -> [Vec<f32>; 3] {
    let mut albedo: [Vec<f32>; 3] = std::array::from_fn(|_| Vec::with_capacity(uvs.len()));
    for uv in uvs {
        let a = texture.sample_bilinear(uv[0], uv[1]);
        for (ch, out) in albedo.iter_mut().enumerate() {
            out.push(a[ch]);
        }
    }
    for channel in albedo.iter_mut() {
        let (sum, count) = channel
            .iter()
            .filter(|&&x| x > 0.0)
            .fold((0.0f64, 0usize), |(s, c), &x| (s + f64::from(x), c + 1));
        let mean = sum / count.max(1) as f64;
        for x in channel.iter_mut() {
            *x = if *x > 0.0 && mean > 0.0 {
                (f64::from(*x) / mean) as f32
            } else {
                f32::NAN
            };
        }
    }
    albedo
}

/// Refit `model`'s rho, s and inter-reflection on `samples` (weights `density`) with the
/// per-sample `albedo`, keeping its gains and reference frame.
pub fn refit_light_with_albedo(
    model: &mut CalibratedModel,
    samples: &PooledSamples,
    density: &[f32],
    albedo: &[Vec<f32>; 3],
    opts: &CalibratedOptions,
) -> Result<()> {
    // From a converged light the robust weights settle in a few rounds: 3 instead of 8 gives
    // the same light to 0.05% of the cone profile on the demo phantom in half the time.
    let opts = CalibratedOptions {
        reference_frame: model.reference_frame,
        max_irls_iterations: opts.max_irls_iterations.min(3),
        ..opts.clone()
    };
    let refit = fit_calibrated_with_albedo(samples, density, albedo, Some(model), &opts)?;
    let gains = std::mem::take(&mut model.gains);
    *model = refit.model;
    model.gains = gains;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sample_albedo_is_relative_to_each_channels_mean() {
        // 8x8 texture: left half (0.2, 0.1, 0.4), right half (0.6, 0.3, 0.0).
        let (w, h) = (8u32, 8u32);
        let mut rgb = Vec::new();
        for _y in 0..h {
            for x in 0..w {
                rgb.extend_from_slice(if x < w / 2 {
                    &[0.2f32, 0.1, 0.4]
                } else {
                    &[0.6, 0.3, 0.0]
                });
            }
        }
        let image = Frame {
            width: w,
            height: h,
            rgb,
        };
        let tex = MipTexture::new(&image, None, 0.5, &MipOptions::default()).unwrap();
        // Texel centres well inside each half (bilinear reads one value there).
        let uvs = [[1.5 / 8.0, 0.5], [6.5 / 8.0, 0.5], [1.5 / 8.0, 0.25]];
        let a = sample_albedo(&tex, &uvs);
        // Red: 0.2, 0.6, 0.2 -> mean 1/3 -> 0.6, 1.8, 0.6.
        for (got, want) in a[0].iter().zip([0.6, 1.8, 0.6]) {
            assert!((got - want).abs() < 1e-5, "{:?}", a[0]);
        }
        // Blue is 0 on the right: that sample has no albedo; the others average 1.
        assert!(a[2][1].is_nan());
        assert!((a[2][0] - 1.0).abs() < 1e-5 && (a[2][2] - 1.0).abs() < 1e-5);
    }

    #[test]
    fn sample_uvs_interpolate_the_hit_triangle() {
        let mut g = GBuffer {
            width: 2,
            height: 1,
            tri: vec![1, 0],
            bary: vec![[0.25, 0.5], [0.0, 0.0]],
            ..Default::default()
        };
        g.z = vec![1.0, 1.0];
        let tri_uv = [
            [[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]],
            [[0.2, 0.2], [0.6, 0.2], [0.2, 0.8]],
        ];
        let uv = sample_uvs(&[0, 1], &g, &tri_uv);
        // Pixel 0 hits triangle 1 at weights (0.25, 0.25, 0.5).
        assert!((uv[0][0] - (0.25 * 0.2 + 0.25 * 0.6 + 0.5 * 0.2)).abs() < 1e-6);
        assert!((uv[0][1] - (0.25 * 0.2 + 0.25 * 0.2 + 0.5 * 0.8)).abs() < 1e-6);
        assert_eq!(uv[1], [0.0, 0.0]);
    }
}
