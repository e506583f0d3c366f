//! The texture stage (paper §2.4): every frame de-lit with the chosen shading model and fused
//! into one albedo atlas; with the calibrated light chosen, the paper's own texture (de-lit by
//! each frame's Psi) beside it, so the paper's method stays the reference new views are
//! compared against.

use super::frames::{DepthCache, Resolution};
use super::options::BuildOptions;
use super::scene::BuildScene;
use crate::shading::{FittedShading, ShadingKind};
use crate::texture::fusion::fuse;
use crate::texture::seams::{seam_stats, SeamStats};
use crate::texture::synthesis::SynthesisStats;
use crate::Result;

/// One fused albedo atlas.
pub struct FusedAlbedo {
    /// Linear RGB per texel (atlas-sized, holes filled), colour balanced.
    pub rgb: Vec<f32>,
    /// Texels seen by at least one frame.
    pub covered: Vec<bool>,
    /// Texels given synthesised mucosa (none seen them; `--unseen synthesise`).
    pub synthesised: Vec<bool>,
    /// Counts of the completion of the unseen texels.
    pub synthesis: SynthesisStats,
    /// Seconds spent completing the unseen texels.
    pub synthesis_seconds: f64,
    /// The per-channel factors of the colour balance.
    pub colour_balance: [f32; 3],
    /// The seam measure of the fusion.
    pub seams: SeamStats,
}

/// The textures of a model.
pub struct Textures {
    /// The albedo de-lit with the model's shading (albedo.png, the texture of airway.glb).
    pub albedo: FusedAlbedo,
    /// The paper's texture when the model's shading is not the paper's (albedo_paper.png).
    pub paper: Option<FusedAlbedo>,
}

/// De-light and fuse every frame with `shading.model` (and the paper's Psi when that is not
/// it); `pixel_sum` is the first pass's sum of the model-obeying pixels per channel.
pub fn fuse_textures(
    scene: &mut BuildScene,
    shading: &FittedShading,
    pixel_sum: [f64; 3],
    opts: &BuildOptions,
) -> Result<Textures> {
    if scene.level > 0 && shading.model != ShadingKind::Paper {
        // Two fusions from full-resolution pixels: cast every frame once for both.
        scene.cache = DepthCache::full_resolution(scene, opts.depth_cache_bytes);
    }
    let scene = &*scene;
    let albedo = fuse_albedo(
        scene,
        shading,
        shading.model,
        pixel_sum,
        opts,
        "de-light + fuse",
    )?;
    let paper = if shading.model == ShadingKind::Paper {
        None
    } else {
        Some(fuse_albedo(
            scene,
            shading,
            ShadingKind::Paper,
            pixel_sum,
            opts,
            "de-light + fuse (paper)",
        )?)
    };
    Ok(Textures { albedo, paper })
}

/// Every frame de-lit with model `kind`, fused and colour balanced.
fn fuse_albedo(
    scene: &BuildScene,
    shading: &FittedShading,
    kind: ShadingKind,
    pixel_sum: [f64; 3],
    opts: &BuildOptions,
    label: &str,
) -> Result<FusedAlbedo> {
    let shaders = shading.frame_shaders(kind)?;
    let n = scene.frame_count();
    let passes = opts.fusion.method.passes();
    // The texture keeps every pixel's detail.
    let mut stream = scene.frames(
        Resolution::Full,
        shaders,
        (0..n).collect(),
        label,
        passes,
        opts.quiet,
    );
    let fused = fuse(&scene.texels, &mut stream, &opts.fusion)?;
    stream.progress.finish();
    let seams = seam_stats(&fused, &scene.texels);
    let start = std::time::Instant::now();
    let (mut rgb, synthesis, synthesised) =
        fused.completed(&scene.texels, scene.atlas.texel_mm, &opts.unseen)?;
    let synthesis_seconds = start.elapsed().as_secs_f64();
    let colour_balance = colour_balance(&mut rgb, &fused.covered, pixel_sum);
    Ok(FusedAlbedo {
        rgb,
        covered: fused.covered,
        synthesised,
        synthesis,
        synthesis_seconds,
        colour_balance,
        seams,
    })
}

/// Scale each channel of the fused texture so its mean over the covered texels has the
/// chromaticity of the mean observed pixel (the per-channel Psi divided it out).
/// Returns the factors applied.
fn colour_balance(rgb: &mut [f32], covered: &[bool], pixel_sum: [f64; 3]) -> [f32; 3] {
    let mut tex_sum = [0f64; 3];
    for (i, _) in covered.iter().enumerate().filter(|(_, &c)| c) {
        for ch in 0..3 {
            tex_sum[ch] += rgb[3 * i + ch] as f64;
        }
    }
    let pix_mean = (pixel_sum[0] + pixel_sum[1] + pixel_sum[2]) / 3.0;
    let tex_mean = (tex_sum[0] + tex_sum[1] + tex_sum[2]) / 3.0;
    if !(pix_mean > 0.0 && tex_mean > 0.0) {
        return [1.0; 3];
    }
    let k: [f32; 3] = std::array::from_fn(|ch| {
        let want = pixel_sum[ch] / pix_mean;
        let have = tex_sum[ch] / tex_mean;
        if have > 0.0 {
            (want / have) as f32
        } else {
            1.0
        }
    });
    for px in rgb.chunks_exact_mut(3) {
        for ch in 0..3 {
            px[ch] *= k[ch];
        }
    }
    k
}
