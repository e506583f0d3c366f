//! Albedo from colour, for registering against the geometry's shading alone while the texture
//! is not yet trustworthy (fused from poorly registered frames, it follows their errors).
//!
//! The mucosa's albedo changes with its colour (blood darkens green and blue far more than
//! red; see `shading::chroma_albedo`). The relation is fitted on the model's texture — per
//! channel, log albedo as a quadratic in the texel's log colour ratios G/R and B/R — which a
//! blur or a misregistration does not bend (a mixed texel has mixed colour and mixed
//! brightness). A frame's pixels are then divided by the albedo their own colour predicts
//! (their neighbours' colour, with the light's own colour ratios removed): what is left is the
//! light's shading of the geometry, with the vessels mostly gone.

use super::photometric::{PhotometricModel, RayGrid};
use crate::image::Frame;
use crate::math::Affine;
use crate::{Error, Result};
use nalgebra::{SMatrix, SVector};

/// The quadratic features of a chromaticity x: 1, x1, x2, x1², x2², x1·x2.
fn phi(x: [f64; 2]) -> SVector<f64, 6> {
    SVector::<f64, 6>::from([1.0, x[0], x[1], x[0] * x[0], x[1] * x[1], x[0] * x[1]])
}

/// Log colour ratios (G/R, B/R) of an RGB value; `None` when a channel is not positive.
pub fn chroma(rgb: [f64; 3]) -> Option<[f64; 2]> {
    (rgb.iter().all(|&v| v > 1e-6)).then(|| [(rgb[1] / rgb[0]).ln(), (rgb[2] / rgb[0]).ln()])
}

/// The fitted relation between colour and albedo.
#[derive(Clone, Debug)]
pub struct ChromaAlbedo {
    /// Per channel: coefficients of [`phi`] giving log albedo.
    coeffs: [SVector<f64, 6>; 3],
    /// Clamp range of each chromaticity coordinate (the texture's 1st..99th percentiles).
    range: [[f64; 2]; 2],
    /// The light's own log colour ratios (G/R, B/R) at gamma = 0.7, removed from a frame's.
    light_ratio: [f64; 2],
}

impl ChromaAlbedo {
    /// Fit the relation on the texture albedo the model shows from `poses` on `grid`.
    pub fn fit(model: &PhotometricModel, grid: &RayGrid, poses: &[Affine]) -> Result<ChromaAlbedo> {
        let mut samples: Vec<([f64; 2], [f64; 3])> = Vec::new();
        for pose in poses {
            let view = model.view(grid, pose, 0.1);
            samples.extend(view.points.iter().filter_map(|q| {
                let a = q.albedo.map(f64::from);
                chroma(a).map(|x| (x, a.map(f64::ln)))
            }));
        }
        if samples.len() < 100 {
            return Err(Error::Other(format!(
                "registration: {} textured points to relate colour and albedo (need 100)",
                samples.len()
            )));
        }
        let mut range = [[0.0; 2]; 2];
        for (k, r) in range.iter_mut().enumerate() {
            let mut v: Vec<f64> = samples.iter().map(|s| s.0[k]).collect();
            v.sort_by(f64::total_cmp);
            *r = [v[v.len() / 100], v[v.len() * 99 / 100]];
        }
        let clamp = |x: [f64; 2]| std::array::from_fn(|k| x[k].clamp(range[k][0], range[k][1]));
        let mut ata = SMatrix::<f64, 6, 6>::zeros();
        let mut atb = [SVector::<f64, 6>::zeros(); 3];
        for (x, la) in &samples {
            let p = phi(clamp(*x));
            ata += p * p.transpose();
            for c in 0..3 {
                atb[c] += p * la[c];
            }
        }
        let chol = ata.cholesky().ok_or_else(|| {
            Error::Other("registration: colour-albedo relation is singular".into())
        })?;
        let light = &model.parts.light;
        let (r, g, b) = (light.rho(0, 0.7), light.rho(1, 0.7), light.rho(2, 0.7));
        Ok(ChromaAlbedo {
            coeffs: std::array::from_fn(|c| chol.solve(&atb[c])),
            range,
            light_ratio: [(g / r).ln(), (b / r).ln()],
        })
    }

    /// Relative albedo per channel at chromaticity `x` (the texture's scale).
    pub fn albedo(&self, x: [f64; 2]) -> [f64; 3] {
        let x = std::array::from_fn(|k| x[k].clamp(self.range[k][0], self.range[k][1]));
        let p = phi(x);
        std::array::from_fn(|c| self.coeffs[c].dot(&p).exp())
    }

    /// The albedo predicted at each pixel of `frame` from the colour of its `radius`
    /// neighbourhood (NaN where undefined or saturated), interleaved RGB.
    pub fn predict(&self, frame: &Frame, saturation_level: f32, radius: usize) -> Vec<f32> {
        let (w, h) = (frame.width as usize, frame.height as usize);
        let mut out = vec![f32::NAN; 3 * w * h];
        for y in 0..h {
            for x in 0..w {
                let i = y * w + x;
                if frame.rgb[3 * i..3 * i + 3]
                    .iter()
                    .any(|&v| v >= saturation_level)
                {
                    continue;
                }
                let Some(xo) = chroma(neighbourhood_sum(frame, x, y, radius)) else {
                    continue;
                };
                let a = self.albedo([xo[0] - self.light_ratio[0], xo[1] - self.light_ratio[1]]);
                for c in 0..3 {
                    out[3 * i + c] = a[c] as f32;
                }
            }
        }
        out
    }

    /// `frame` with every pixel divided by the albedo its 3x3 neighbourhood's colour predicts
    /// (saturated pixels are left as they are: registration does not use them).
    pub fn normalise(&self, frame: &Frame, saturation_level: f32) -> Frame {
        let (w, h) = (frame.width as usize, frame.height as usize);
        let mut out = frame.clone();
        for y in 0..h {
            for x in 0..w {
                let i = y * w + x;
                let px = &frame.rgb[3 * i..3 * i + 3];
                if px.iter().any(|&v| v >= saturation_level) {
                    continue;
                }
                let Some(xo) = chroma(neighbourhood_sum(frame, x, y, 1)) else {
                    continue;
                };
                let a = self.albedo([xo[0] - self.light_ratio[0], xo[1] - self.light_ratio[1]]);
                for c in 0..3 {
                    out.rgb[3 * i + c] = (f64::from(px[c]) / a[c].max(1e-3)) as f32;
                }
            }
        }
        out
    }

    /// Per ray of `grid` that meets the textured wall seen from `pose`: the ray's index and the
    /// log of the texture's albedo over the albedo its colour predicts, per channel (what the
    /// colour misses).
    pub fn texture_log_ratio(
        &self,
        model: &PhotometricModel,
        grid: &RayGrid,
        pose: &Affine,
    ) -> Vec<(usize, [f64; 3])> {
        model
            .view(grid, pose, 0.0)
            .points
            .iter()
            .filter_map(|p| {
                let a = p.albedo.map(f64::from);
                let pred = self.albedo(chroma(a)?);
                Some((
                    p.ray as usize,
                    std::array::from_fn(|c| (a[c] / pred[c]).ln()),
                ))
            })
            .collect()
    }

    /// `frame` (already [`ChromaAlbedo::normalise`]d) divided, per pixel, by the albedo the
    /// model's texture shows from `pose` on `grid` (the frame's own pixel grid) over the albedo
    /// the texture's colour predicts, relative to that ratio's mean over the frame: the albedo
    /// the colour misses (brightness that changes without the colour, over a few mm) held in
    /// the image, so that a pose step changes only the geometry's shading. Pixels the texture
    /// does not cover, and saturated ones (a channel at `saturation_level` or above: dividing
    /// them could bring them under it), are left as they are.
    pub fn divide_texture_albedo(
        &self,
        frame: &Frame,
        model: &PhotometricModel,
        grid: &RayGrid,
        pose: &Affine,
        saturation_level: f32,
    ) -> Frame {
        let ratios: Vec<(usize, [f64; 3])> = self
            .texture_log_ratio(model, grid, pose)
            .into_iter()
            .filter(|(i, _)| 3 * i + 2 < frame.rgb.len())
            .collect();
        let mut out = frame.clone();
        if ratios.is_empty() {
            return out;
        }
        let mean: [f64; 3] = std::array::from_fn(|c| {
            ratios.iter().map(|r| r.1[c]).sum::<f64>() / ratios.len() as f64
        });
        for (i, q) in ratios {
            if frame.rgb[3 * i..3 * i + 3]
                .iter()
                .any(|&v| v >= saturation_level)
            {
                continue;
            }
            for c in 0..3 {
                let v = f64::from(frame.rgb[3 * i + c]) / (q[c] - mean[c]).exp();
                out.rgb[3 * i + c] = v as f32;
            }
        }
        out
    }
}
/// Sum of the RGB of the pixels within `radius` of (x, y) (clipped at the image's edges).
fn neighbourhood_sum(frame: &Frame, x: usize, y: usize, radius: usize) -> [f64; 3] {
    let (w, h) = (frame.width as usize, frame.height as usize);
    let mut sum = [0.0f64; 3];
    for yy in y.saturating_sub(radius)..(y + radius + 1).min(h) {
        for xx in x.saturating_sub(radius)..(x + radius + 1).min(w) {
            let j = 3 * (yy * w + xx);
            for (s, v) in sum.iter_mut().zip(&frame.rgb[j..j + 3]) {
                *s += f64::from(*v);
            }
        }
    }
    sum
}
