//! How well a light model explains the phantom's frames once the albedo and the gains are
//! known: the floor under the calibrated light's gain errors (issue 8).
//!
//! Every pixel of a frame that hits the mesh (the model's CT-derived mesh, or the phantom's
//! true mesh) is predicted as `true gain × true albedo(x) × shading(gamma, theta, z)`, the
//! shading being the fitted calibrated light or the phantom's own light law (read from
//! `truth/gains.json`, with its inter-reflection term); the log residual
//! `ln(observed / predicted)` is taken on luminance. A frame's mean (or median) residual,
//! relative to the mean over frames, is what its gain would be off by even with the albedo
//! known exactly; the profiles over z, theta and gamma show where the light model or the
//! geometry is biased. Saturated pixels (a channel >= 0.98) and dark ones (luminance < 0.01)
//! are left out.

use std::path::Path;

use rayon::prelude::*;

use crate::image::Frame;
use crate::io::case::Case;
use crate::phantom::baked_albedo::{AlbedoSampling, PhantomAlbedo};
use crate::phantom::case::phantom_albedo;
use crate::phantom::render::LightModel;
use crate::raycast::{cast_frame_with, GBuffer, RayTable, Scene};
use crate::shading::frame_shading::LUMA;
use crate::shading::CalibratedModel;
use crate::{Error, Result};

/// The light law the frames are predicted with.
#[derive(Clone, Copy, Debug)]
pub enum ShadingLaw<'a> {
    /// The fitted calibrated light (uniform albedo folded into rho; an ambient term, if any,
    /// taken as light that reflects off the local albedo).
    Fitted(&'a CalibratedModel),
    /// The phantom's own light, BRDF and inter-reflection, as recorded in the truth.
    Phantom,
}

/// Mean log residual of the pixels in one bin of a profile.
#[derive(Clone, Debug, PartialEq)]
pub struct ProfileBin {
    /// Lower edge of the bin (mm for z, degrees for the angles).
    pub from: f64,
    /// Mean of `ln(observed / predicted)` over the bin, minus the mean over all pixels.
    pub mean_log: f64,
    /// Pixels in the bin.
    pub pixels: usize,
}

/// Residuals of a light law against the phantom's frames.
#[derive(Clone, Debug, PartialEq)]
pub struct ShadingResiduals {
    /// The frames evaluated (case indices).
    pub frames: Vec<usize>,
    /// Per frame, the mean log residual minus its mean over the frames.
    pub frame_mean: Vec<f64>,
    /// Per frame, the median log residual minus the mean of the medians.
    pub frame_median: Vec<f64>,
    /// Profile over the distance z (1 mm bins).
    pub by_z: Vec<ProfileBin>,
    /// Profile over the angle theta off the optical axis (5 degree bins).
    pub by_theta: Vec<ProfileBin>,
    /// Profile over the angle gamma between the ray and the normal (5 degree bins).
    pub by_gamma: Vec<ProfileBin>,
    /// Pixels used.
    pub pixels: usize,
}

/// RMS and largest absolute value of `v` (log residuals, so about relative errors).
pub fn spread(v: &[f64]) -> (f64, f64) {
    let rms = (v.iter().map(|x| x * x).sum::<f64>() / v.len().max(1) as f64).sqrt();
    (rms, v.iter().fold(0.0f64, |m, x| m.max(x.abs())))
}

/// What the truth folder records about a phantom case's light, gains and albedo.
struct PhantomTruth {
    gains: Vec<f64>,
    light: LightModel,
    albedo: PhantomAlbedo,
}

fn read_json(path: &Path) -> Result<serde_json::Value> {
    let text = std::fs::read_to_string(path).map_err(|e| Error::io(path, e))?;
    serde_json::from_str(&text).map_err(|e| Error::invalid(path, e.to_string()))
}

fn read_truth(truth_dir: &Path, scene: &Scene) -> Result<PhantomTruth> {
    let gains_path = truth_dir.join("gains.json");
    let g = read_json(&gains_path)?;
    let gains = g["frames"]
        .as_array()
        .and_then(|a| {
            a.iter()
                .map(|f| f["gain"].as_f64())
                .collect::<Option<Vec<_>>>()
        })
        .ok_or_else(|| Error::invalid(&gains_path, "no frames[].gain numbers"))?;
    let light: LightModel = serde_json::from_value(g["light"].clone())
        .map_err(|e| Error::invalid(&gains_path, format!("light: {e}")))?;
    let truth_path = truth_dir.join("truth.json");
    let manifest = read_json(&truth_path)?;
    let seed = manifest["seed"]
        .as_u64()
        .ok_or_else(|| Error::invalid(&truth_path, "no integer seed"))?;
    // Cases made before the albedo could be baked evaluated it procedurally.
    let sampling: AlbedoSampling = match manifest.get("albedo") {
        None | Some(serde_json::Value::Null) => AlbedoSampling::Procedural,
        Some(v) => serde_json::from_value(v.clone())
            .map_err(|e| Error::invalid(&truth_path, format!("albedo: {e}")))?,
    };
    Ok(PhantomTruth {
        gains,
        light,
        albedo: PhantomAlbedo::new(phantom_albedo(seed), sampling, scene),
    })
}

const Z_BINS: usize = 60;
const ANGLE_BINS: usize = 18;

/// Per-frame log residuals and bin sums of one frame.
struct FrameResiduals {
    mean: f64,
    median: f64,
    bins: Vec<(f64, usize)>,
}

/// [`ShadingResiduals`] of `law` on every `frame_step`-th frame of the phantom case `case`
/// (with its truth folder `truth_dir`), ray cast against `scene`.
pub fn shading_residuals(
    case: &Case,
    scene: &Scene,
    truth_dir: &Path,
    law: ShadingLaw,
    frame_step: usize,
) -> Result<ShadingResiduals> {
    let truth = read_truth(truth_dir, scene)?;
    let n = case.frame_count();
    if truth.gains.len() != n {
        return Err(Error::invalid(
            truth_dir.join("gains.json"),
            format!("{} gains for {n} frames", truth.gains.len()),
        ));
    }
    let reference = match law {
        ShadingLaw::Fitted(m) => {
            if m.gains.len() != n {
                return Err(Error::Other(format!(
                    "shading residuals: the light was fitted to {} frames, the case has {n}",
                    m.gains.len()
                )));
            }
            truth.gains[m.reference_frame.min(n - 1)]
        }
        ShadingLaw::Phantom => 1.0,
    };
    let wanted: Vec<usize> = (0..n).step_by(frame_step.max(1)).collect();
    let frames = case.frames_at(&wanted)?;
    let evaluator = FrameEvaluator {
        case,
        scene,
        rays: RayTable::new(&case.camera),
        cone_k: truth.light.cone_exponent(),
        truth: &truth,
        law,
        reference,
    };
    let per_frame: Vec<FrameResiduals> = frames
        .par_iter()
        .map(|(&f, frame)| evaluator.residuals(f, frame))
        .collect();
    summarise(wanted, &per_frame)
}

/// Luminance of a linear RGB triple.
fn luminance(c: [f64; 3]) -> f64 {
    LUMA[0] * c[0] + LUMA[1] * c[1] + LUMA[2] * c[2]
}

/// Everything a frame's residuals need besides the frame.
struct FrameEvaluator<'a> {
    case: &'a Case,
    scene: &'a Scene,
    rays: RayTable,
    truth: &'a PhantomTruth,
    law: ShadingLaw<'a>,
    /// True gain of the fitted light's reference frame (1 for the phantom's law): the fitted
    /// gains are relative to it.
    reference: f64,
    /// Exponent of the phantom light's cone.
    cone_k: f64,
}

impl FrameEvaluator<'_> {
    /// Ray cast frame `f`, predict each usable hit pixel and bin the log residuals.
    fn residuals(&self, f: usize, frame: &Frame) -> FrameResiduals {
        let (rays, truth) = (&self.rays, self.truth);
        let gb = cast_frame_with(self.scene, rays, &self.case.poses[f].pose.camera_to_world);
        let hits: Vec<usize> = (0..gb.z.len()).filter(|&i| gb.hit(i)).collect();
        let albedo: Vec<[f32; 3]> = hits
            .iter()
            .map(|&i| truth.albedo.at(gb.tri[i], gb.bary[i], gb.point[i]))
            .collect();
        let direct = self.phantom_direct(&gb, &hits, &albedo);
        let mean_direct =
            direct.iter().map(|&d| luminance(d)).sum::<f64>() / hits.len().max(1) as f64;
        let ambient = truth.light.interreflection(mean_direct);
        let gain = truth.gains[f] / self.reference;
        let mut bins = vec![(0.0, 0usize); Z_BINS + 2 * ANGLE_BINS];
        let mut res = Vec::with_capacity(hits.len());
        for (k, &i) in hits.iter().enumerate() {
            let obs = &frame.rgb[3 * i..3 * i + 3];
            let o = luminance([obs[0], obs[1], obs[2]].map(f64::from));
            if obs.iter().any(|&v| v >= 0.98) || o < 0.01 {
                continue;
            }
            let (cos_g, cos_t, z) = (gb.gamma[i] as f64, rays.dirs[i][2] as f64, gb.z[i] as f64);
            let pred = match self.law {
                ShadingLaw::Fitted(m) => {
                    // Any ambient term reflects off the local albedo (inter-reflection).
                    let s = m.eval_rgb(cos_g, cos_t, z, gain);
                    let sp = m.specular_rgb(cos_g, cos_t, z, gain);
                    let a = m.ambient_of(f);
                    let to_gain = gain / m.gains[f];
                    luminance(
                        [0, 1, 2].map(|c| (s[c] + a[c] * to_gain) * albedo[k][c] as f64 + sp[c]),
                    )
                }
                ShadingLaw::Phantom => {
                    let d = direct[k];
                    gain * luminance([0, 1, 2].map(|c| d[c] + ambient * albedo[k][c] as f64))
                }
            };
            if pred.is_nan() || pred <= 0.0 {
                continue;
            }
            let r = (o / pred).ln();
            res.push(r);
            let zb = (z as usize).min(Z_BINS - 1);
            let tb = ((cos_t.acos().to_degrees() / 5.0) as usize).min(ANGLE_BINS - 1);
            let gbin = ((cos_g.acos().to_degrees() / 5.0) as usize).min(ANGLE_BINS - 1);
            for b in [zb, Z_BINS + tb, Z_BINS + ANGLE_BINS + gbin] {
                bins[b].0 += r;
                bins[b].1 += 1;
            }
        }
        let mean = res.iter().sum::<f64>() / res.len().max(1) as f64;
        let median = if res.is_empty() {
            0.0
        } else {
            let mid = res.len() / 2;
            *res.select_nth_unstable_by(mid, f64::total_cmp).1
        };
        FrameResiduals { mean, median, bins }
    }

    /// Under the phantom's law, its direct radiance at every hit, as its renderer computes it
    /// (the inter-reflection is a fraction of the frame's mean direct luminance); empty under
    /// the fitted law.
    fn phantom_direct(&self, gb: &GBuffer, hits: &[usize], albedo: &[[f32; 3]]) -> Vec<[f64; 3]> {
        match self.law {
            ShadingLaw::Phantom => hits
                .iter()
                .zip(albedo)
                .map(|(&i, &a)| {
                    let (cos_t, cos_g) = (self.rays.dirs[i][2] as f64, gb.gamma[i] as f64);
                    let z = gb.z[i] as f64;
                    self.truth
                        .light
                        .direct_radiance(a, cos_t, cos_g, z, self.cone_k)
                })
                .collect(),
            ShadingLaw::Fitted(_) => Vec::new(),
        }
    }
}

/// Pool the frames' bins into the profiles and centre the per-frame means and medians.
fn summarise(wanted: Vec<usize>, per_frame: &[FrameResiduals]) -> Result<ShadingResiduals> {
    let mut bins = vec![(0.0, 0usize); Z_BINS + 2 * ANGLE_BINS];
    for fr in per_frame {
        for (b, x) in bins.iter_mut().zip(&fr.bins) {
            b.0 += x.0;
            b.1 += x.1;
        }
    }
    let pixels: usize = bins[..Z_BINS].iter().map(|b| b.1).sum();
    if pixels == 0 {
        return Err(Error::Other(
            "shading residuals: no pixel of the frames hit the mesh".into(),
        ));
    }
    let overall = bins[..Z_BINS].iter().map(|b| b.0).sum::<f64>() / pixels as f64;
    let profile = |range: std::ops::Range<usize>, width: f64| -> Vec<ProfileBin> {
        bins[range]
            .iter()
            .enumerate()
            .filter(|(_, b)| b.1 > 0)
            .map(|(k, b)| ProfileBin {
                from: k as f64 * width,
                mean_log: b.0 / b.1 as f64 - overall,
                pixels: b.1,
            })
            .collect()
    };
    let centred = |v: Vec<f64>| -> Vec<f64> {
        let mu = v.iter().sum::<f64>() / v.len().max(1) as f64;
        v.into_iter().map(|x| x - mu).collect()
    };
    Ok(ShadingResiduals {
        frames: wanted,
        frame_mean: centred(per_frame.iter().map(|f| f.mean).collect()),
        frame_median: centred(per_frame.iter().map(|f| f.median).collect()),
        by_z: profile(0..Z_BINS, 1.0),
        by_theta: profile(Z_BINS..Z_BINS + ANGLE_BINS, 5.0),
        by_gamma: profile(Z_BINS + ANGLE_BINS..Z_BINS + 2 * ANGLE_BINS, 5.0),
        pixels,
    })
}
