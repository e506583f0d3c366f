//! The calibrated light of the whole video (DESIGN.md, "Beyond the paper"), fitted on the
//! samples pooled by the first pass, in four steps:
//! 1. the pooled fit with a uniform albedo (rho, s, kappa, a gain per frame);
//! 2. refits with each pixel's albedo predicted from its colour (`--chroma-refits`);
//! 3. corrections of the gains against a texture fused with them ([`super::gain_correction`]);
//! 4. refits of the light's shape with the fused texture's albedo, each followed by one more
//!    gain correction ([`super::light_refit`], `--light-refits`).
//!
//! With `--interreflection gathered` (or `both`) the uniform fit of step 1 lights the wall
//! once: each sample's gathered light ([`crate::shading::indirect`]) replaces `kappa_c L_f`
//! (`both`: joins it), the light is fitted again with it, and the later steps gather again
//! with the light (and, in step 4, the fused texture's albedo) they have by then.

use std::borrow::Cow;
use std::sync::Arc;

use super::error::BuildError;
use super::fit_pass::LightSamples;
use super::frames::{CaseFrames, Resolution};
use super::gain_correction::correct_gains;
use super::light_refit::refit_light_against_texture;
use super::options::BuildOptions;
use super::scene::BuildScene;
use crate::model::manifest::LightFitSettings;
use crate::shading::calibrated::PooledSamples;
use crate::shading::calibrated::{
    density_weights_3d, fit_calibrated, refit_with_chroma_albedo, AutoExposure, CalibratedModel,
    CalibratedOptions,
};
use crate::shading::indirect::{
    gather_frames, sample_fields, GatheredInterreflection, IndirectField, InterreflectionMode,
    SurfaceAlbedo, UniformAlbedo,
};
use crate::shading::{ShadingKind, WeightOptions};
use crate::texture::coarse::CoarseTexels;
use crate::texture::fusion::{fuse, FusedTexture, FusionMethod, FusionOptions};
use crate::texture::texels::TexelSet;
use crate::Result;

/// The fitted light and how it was fitted (model.json's `light_fit`).
pub struct CalibratedLight {
    /// The light.
    pub model: CalibratedModel,
    /// The settings it was fitted with.
    pub settings: LightFitSettings,
}

/// Fit the calibrated light on `samples`. `None` when nothing was pooled, or when the fit
/// failed and the paper's Psi can stand in (said in `warnings`).
pub fn calibrated_light(
    scene: &BuildScene,
    samples: LightSamples,
    opts: &BuildOptions,
    warnings: &mut Vec<String>,
) -> Result<Option<CalibratedLight>> {
    let n = scene.frame_count();
    if samples.pooled.is_empty() {
        return Ok(None);
    }
    let density = density_weights_3d(&samples.pooled, &WeightOptions::default());
    // The reference gain (g = 1, the exposure new views are rendered at): the middle frame
    // unless set, because a frame mid-video shares the most surface with the others (the
    // first frame sees the cut top of the trachea, which no other frame sees).
    let mut cal_opts = CalibratedOptions {
        reference_frame: opts.calibrated_reference.unwrap_or(n / 2).min(n - 1),
        ..opts.calibrated.clone()
    };
    let mut samples = samples;
    let mut model = match fit_calibrated(&samples.pooled, &density, &cal_opts) {
        Ok(fit) => fit.model,
        Err(e) if opts.shading == Some(ShadingKind::Calibrated) => {
            return Err(BuildError::CalibratedLight(Box::new(e)).into())
        }
        Err(e) => {
            warnings.push(format!(
                "calibrated light fit failed ({e}); using the paper's Psi"
            ));
            return Ok(None);
        }
    };
    let gathered = opts.interreflection != InterreflectionMode::Uniform;
    if gathered {
        // The uniform fit's light, once reflected by a uniform wall, is each sample's first
        // gathered light; the fit then takes k_c in place of kappa_c (beside it: `both`).
        cal_opts.gathered = true;
        cal_opts.interreflection &= opts.interreflection == InterreflectionMode::Both;
        let settings = gather_settings(opts);
        let fields = gather_all(scene, &model, &UniformAlbedo, &settings);
        set_sample_light(scene, &mut samples.pooled, &fields);
        model = fit_calibrated(&samples.pooled, &density, &cal_opts)?.model;
        model.gathered = Some(GatheredInterreflection {
            k: model.gathered.map_or([0.0; 3], |g| g.k),
            ..settings
        });
    }
    for _ in 0..opts.chroma_refits {
        refit_with_chroma_albedo(&mut model, &samples.pooled, &density, &cal_opts)?;
    }
    if gathered {
        model.frame_indirect = Some(gather_all(
            scene,
            &model,
            &UniformAlbedo,
            &gather_settings(opts),
        ));
    }
    let consensus = Consensus::coarse(scene, opts, opts.consensus_texel_factor)?;
    for _ in 0..opts.refine_gains {
        correct_gains(&consensus, &mut model)?;
    }
    for _ in 0..opts.refine_light {
        refit_light_against_texture(&consensus, &mut model, &mut samples, &density, &cal_opts)?;
        correct_gains(&consensus, &mut model)?;
    }
    // The scope's auto-exposure, from the finished gains (used by new views that ask for it).
    model.auto_exposure = AutoExposure::fit(&model.gains, &samples.pooled.frame_light);
    let settings = LightFitSettings {
        rho_degree: cal_opts.rho_degree,
        s_degree: cal_opts.s_degree,
        robust: cal_opts.robust.to_string(),
        ambient_per_frame: cal_opts.ambient,
        interreflection: cal_opts.interreflection,
        interreflection_mode: opts.interreflection,
        reference_frame: model.reference_frame,
        gain_corrections: opts.refine_gains,
        light_refits: opts.refine_light,
        chroma_refits: opts.chroma_refits,
    };
    Ok(Some(CalibratedLight { model, settings }))
}

/// The gather of `--interreflection gathered|both` as the build options set it.
fn gather_settings(opts: &BuildOptions) -> GatheredInterreflection {
    GatheredInterreflection {
        k: [0.0; 3],
        nodes_across: opts.gather_nodes,
        rays: opts.gather_rays,
        visibility: opts.gather_visibility,
    }
}

/// The gathered light of every frame at the working resolution, lit by `model`.
pub fn gather_all(
    scene: &BuildScene,
    model: &CalibratedModel,
    albedo: &dyn SurfaceAlbedo,
    settings: &GatheredInterreflection,
) -> Arc<Vec<IndirectField>> {
    gather_frames(
        &scene.scene,
        &scene.camera,
        &scene.poses,
        model,
        albedo,
        settings,
    )
}

/// Each pooled sample's gathered light from its frame's field.
pub fn set_sample_light(scene: &BuildScene, pooled: &mut PooledSamples, fields: &[IndirectField]) {
    let (w, h) = (scene.camera.width as usize, scene.camera.height as usize);
    pooled.indirect = Some(sample_fields(pooled, fields, w, h));
}

/// The reference texture the light's refinements compare against: every frame de-lit with the
/// current light and fused by the plain predicted-intensity average (one pass, every frame's
/// share in every texel): a consensus, not the sharpest texture. It may be fused on a coarser
/// sampling of the atlas ([`CoarseTexels`]; `BuildOptions::consensus_texel_factor`).
pub struct Consensus<'a> {
    /// The scene the frames are streamed from.
    pub scene: &'a BuildScene,
    /// The texels the consensus is fused on.
    pub texels: Cow<'a, TexelSet>,
    /// The coarse sampling `texels` is, when not the scene's own texels.
    coarse: Option<CoarseTexels>,
    /// The fusion of the reference texture.
    pub fusion: FusionOptions,
    /// No progress bars.
    pub quiet: bool,
}

impl<'a> Consensus<'a> {
    /// The consensus fusion of the build `opts` on every texel of the scene.
    pub fn new(scene: &'a BuildScene, opts: &BuildOptions) -> Consensus<'a> {
        Consensus {
            scene,
            texels: Cow::Borrowed(&scene.texels),
            coarse: None,
            fusion: FusionOptions {
                method: FusionMethod::WeightedAverage {
                    weight_exponent: 1.0,
                },
                ..opts.fusion.clone()
            },
            quiet: opts.quiet,
        }
    }

    /// The same on one texel of every `factor × factor` block of the atlas (1: every texel).
    pub fn coarse(
        scene: &'a BuildScene,
        opts: &BuildOptions,
        factor: u32,
    ) -> Result<Consensus<'a>> {
        let mut consensus = Consensus::new(scene, opts);
        if factor > 1 {
            let coarse = CoarseTexels::new(&scene.texels, factor)?;
            consensus.texels = Cow::Owned(coarse.texels.clone());
            consensus.coarse = Some(coarse);
        }
        Ok(consensus)
    }

    /// Every frame shaded by `model`, with a progress bar over `passes` passes.
    pub fn frames<'b>(
        &'b self,
        model: &'b CalibratedModel,
        label: &str,
        passes: usize,
    ) -> CaseFrames<'b> {
        let n = self.scene.frame_count();
        self.scene.frames(
            Resolution::Working,
            model,
            (0..n).collect(),
            label,
            passes,
            self.quiet,
        )
    }

    /// The consensus texture of every frame de-lit with `model`, on [`Consensus::texels`].
    fn fuse_own(&self, model: &CalibratedModel, label: &str) -> Result<FusedTexture> {
        let mut stream = self.frames(model, label, self.fusion.method.passes());
        let fused = fuse(&self.texels, &mut stream, &self.fusion)?;
        stream.progress.finish();
        Ok(fused)
    }

    /// The consensus texture of every frame de-lit with `model`, on every texel of the scene
    /// (a coarse fusion's block samples spread over their blocks).
    pub fn fuse(&self, model: &CalibratedModel, label: &str) -> Result<FusedTexture> {
        let fused = self.fuse_own(model, label)?;
        Ok(match &self.coarse {
            Some(coarse) => coarse.expand(&fused, &self.scene.texels),
            None => fused,
        })
    }
}
