//! The gathered light of every frame of a video, and of each pooled sample of the light's fit.

use std::sync::Arc;

use super::field::{gather_view, IndirectField};
use super::gather::SurfaceAlbedo;
use super::GatheredInterreflection;
use crate::camera::Camera;
use crate::math::Affine;
use crate::raycast::Scene;
use crate::shading::calibrated::{CalibratedModel, PooledSamples};

/// The gathered light of the view of every pose (`camera` its camera), lit by `model`'s rho
/// and s, with the wall's `albedo`, sampled as `settings` says (its k is not used).
pub fn gather_frames(
    scene: &Scene,
    camera: &Camera,
    poses: &[Affine],
    model: &CalibratedModel,
    albedo: &dyn SurfaceAlbedo,
    settings: &GatheredInterreflection,
) -> Arc<Vec<IndirectField>> {
    let opts = settings.gather_options();
    Arc::new(
        poses
            .iter()
            .enumerate()
            .map(|(f, pose)| {
                gather_view(
                    scene,
                    camera,
                    pose,
                    model,
                    albedo,
                    settings.nodes_across,
                    f as u64,
                    &opts,
                )
            })
            .collect(),
    )
}

/// Each pooled sample's gathered light, per channel, from its frame's field (`width` x
/// `height`: the image the samples' pixel indices refer to).
pub fn sample_fields(
    samples: &PooledSamples,
    fields: &[IndirectField],
    width: usize,
    height: usize,
) -> [Vec<f32>; 3] {
    let mut out: [Vec<f32>; 3] = std::array::from_fn(|_| Vec::with_capacity(samples.len()));
    for (&f, &px) in samples.frame.iter().zip(&samples.pixel) {
        let e = fields
            .get(f as usize)
            .map_or([0.0; 3], |field| field.at_pixel(px as usize, width, height));
        for c in 0..3 {
            out[c].push(e[c]);
        }
    }
    out
}
