//! [`FittedShading`]: the shading models fitted to one video (shading.json) and the shaders
//! they give — per training frame for de-lighting, per new view for rendering.

use std::sync::OnceLock;

use serde::{Deserialize, Serialize};

use super::calibrated::CalibratedModel;
use super::error::ShadingError;
use super::frame_shading::FrameShaders;
use super::kind::ShadingKind;
use super::paper::{BlendedPsi, PsiLookup, PsiModel, ViewpointIndex};
use super::view_shading::ViewShader;
use crate::math::Affine;

/// shading.json: every fitted model (the paper's Psi always: it is the reference), and the one
/// the texture was de-lit with and new views use.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct FittedShading {
    /// The model the texture was de-lit with and new views use.
    pub model: ShadingKind,
    /// The paper's fitted viewpoints, in frame order.
    pub viewpoints: Vec<PsiModel>,
    /// The calibrated light of the whole video (gains in frame order), when fitted.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub calibrated: Option<CalibratedModel>,
    /// Centres and directions of `viewpoints`, built on first use.
    #[serde(skip)]
    index: OnceLock<ViewpointIndex>,
}

impl FittedShading {
    /// The fitted models, `model` the one in use.
    pub fn new(
        model: ShadingKind,
        viewpoints: Vec<PsiModel>,
        calibrated: Option<CalibratedModel>,
    ) -> FittedShading {
        FittedShading {
            model,
            viewpoints,
            calibrated,
            index: OnceLock::new(),
        }
    }

    /// True when `kind` was fitted.
    pub fn has(&self, kind: ShadingKind) -> bool {
        match kind {
            ShadingKind::Paper => !self.viewpoints.is_empty(),
            ShadingKind::Calibrated => self.calibrated.is_some(),
        }
    }

    /// The fitted models, in [`ShadingKind::ALL`] order.
    pub fn kinds(&self) -> Vec<ShadingKind> {
        ShadingKind::ALL
            .into_iter()
            .filter(|&k| self.has(k))
            .collect()
    }

    /// Centres and viewing directions of the paper's fitted viewpoints.
    pub fn viewpoint_index(&self) -> &ViewpointIndex {
        self.index
            .get_or_init(|| ViewpointIndex::new(&self.viewpoints))
    }

    /// The per-frame shading of model `kind` (what de-lighting divides by).
    pub fn frame_shaders(&self, kind: ShadingKind) -> Result<&dyn FrameShaders, ShadingError> {
        match kind {
            ShadingKind::Paper if !self.viewpoints.is_empty() => Ok(&self.viewpoints),
            ShadingKind::Calibrated => match &self.calibrated {
                Some(c) => Ok(c),
                None => Err(ShadingError::NotFitted(kind)),
            },
            ShadingKind::Paper => Err(ShadingError::NotFitted(kind)),
        }
    }

    /// The shader of a new camera at `camera_to_world` with model `kind`; `lookup` chooses the
    /// paper's viewpoints (the calibrated light needs none).
    pub fn view_shader(
        &self,
        kind: ShadingKind,
        camera_to_world: &Affine,
        lookup: PsiLookup,
    ) -> Result<ViewShader<'_>, ShadingError> {
        match kind {
            ShadingKind::Paper if !self.viewpoints.is_empty() => {
                Ok(ViewShader::Paper(BlendedPsi::new(
                    &self.viewpoints,
                    self.viewpoint_index(),
                    camera_to_world,
                    lookup,
                )))
            }
            ShadingKind::Calibrated => match &self.calibrated {
                Some(model) => Ok(ViewShader::Calibrated {
                    model,
                    ambient: model.new_view_ambient().map(|a| a as f32),
                }),
                None => Err(ShadingError::NotFitted(kind)),
            },
            ShadingKind::Paper => Err(ShadingError::NotFitted(kind)),
        }
    }

    /// Check what a reader relies on: the model in use was fitted and its numbers are usable.
    pub fn validate(&self) -> Result<(), String> {
        if self.viewpoints.is_empty() {
            return Err("no fitted viewpoints".into());
        }
        if !self.has(self.model) {
            return Err(format!(
                "model \"{}\" but no \"{}\" shading",
                self.model, self.model
            ));
        }
        if let Some(c) = &self.calibrated {
            c.validate().map_err(|m| format!("calibrated light: {m}"))?;
        }
        Ok(())
    }
}
