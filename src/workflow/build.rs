//! `bronchosim build CASE --out MODEL`: the whole pipeline of the paper (Fig. 1), written as
//! the model folder of DESIGN.md.
//!
//! inspect → segment → lumen mesh → atlas → per frame (ray cast, samples, Psi fit) →
//! de-light and fuse (two streaming passes over the frames) → model folder.

use crate::io::atomic::write_bytes_atomic;
use crate::io::case::Case;
use crate::io::frames::Frame;
use crate::io::nifti::write_nifti;
use crate::io::output_dir::OutputDir;
use crate::math::Affine;
use crate::model::manifest::{
    relative_path, BuildTimings, ExtraTexture, FrameFit, LightFitSettings, ModelCounts,
    ModelInputs, ModelManifest, ShadingFile, MODEL_FORMAT_VERSION, PAPER_TEXTURE_FILE,
};
use crate::model::Model;
use crate::raycast::{cast_frame_with, GBuffer, RayTable, Scene};
use crate::render::{triangle_uvs, MipOptions, MipTexture};
use crate::shading::calibrated_fit::{fit_calibrated, CalibratedOptions};
use crate::shading::calibrated_predict::cos_theta_of;
use crate::shading::calibrated_samples::{
    density_weights_3d, pool_frames, FrameData, PoolOptions, PooledSamples,
};
use crate::shading::chroma_albedo::refit_with_chroma_albedo;
use crate::shading::fit::Robust;
use crate::shading::fit::{fit_psi, FitOptions};
use crate::shading::psi::PsiModel;
use crate::shading::samples::{extract_samples, SampleOptions, SampleSet};
use crate::shading::weights::{density_weights, WeightOptions};
use crate::shading::CalibratedModel;
use crate::texture::atlas::{build_atlas, rasterize_texels, AtlasOptions};
use crate::texture::fusion::{fuse, FusedTexture, FusionMethod, FusionOptions};
use crate::texture::output::{encode_albedo, write_texture_outputs};
use crate::texture::texels::TexelSet;
use crate::workflow::build_frames::{CaseFrames, DepthCache, FrameShadingSource};
use crate::workflow::cross_validate::{cross_validate, CrossValidationInputs};
use crate::workflow::gain_refine::refine_gains_against_texture;
use crate::workflow::light_refine::{refit_light_with_albedo, sample_albedo, sample_uvs};
use crate::workflow::new_views_figure::{novel_figure, truth_figure};
use crate::workflow::progress::Progress;
use crate::workflow::report::{write_report, ReportFrame, ReportInputs};
use crate::workflow::segment::{segment_and_mesh, SegmentCommandOptions};
use crate::{Error, Result};
use serde::Serialize;
use std::path::Path;
use std::time::Instant;

/// Which shading model a build uses for its texture and new views.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum ShadingChoice {
    /// The model that predicts held-out frames better (cross-validation decides).
    #[default]
    Auto,
    /// The paper's per-viewpoint Psi.
    Paper,
    /// One calibrated light for the whole video.
    Calibrated,
}

/// Options of the whole build; every stage's options with their defaults.
#[derive(Clone, Debug)]
pub struct BuildOptions {
    /// Segmentation and lumen mesh.
    pub segment: SegmentCommandOptions,
    /// Texture atlas (texel size in mm, gutter).
    pub atlas: AtlasOptions,
    /// Which pixels obey the shading model.
    pub samples: SampleOptions,
    /// The Psi fit.
    pub fit: FitOptions,
    /// De-lighting and fusion.
    pub fusion: FusionOptions,
    /// Which shading model de-lights the texture and shades new views.
    pub shading: ShadingChoice,
    /// The calibrated light fit.
    pub calibrated: CalibratedOptions,
    /// The frame whose gain is 1 in the calibrated light (`None`: the middle frame;
    /// `calibrated.reference_frame` is ignored).
    pub calibrated_reference: Option<usize>,
    /// Pooling of the calibrated fit's samples.
    pub pool: PoolOptions,
    /// Most samples pooled over the whole video (fewer per frame for long videos; at least
    /// 1000 per frame).
    pub max_pooled_samples: usize,
    /// Rounds, right after the uniform-albedo fit, of refitting the calibrated light and its
    /// gains with each pixel's albedo predicted from its colour
    /// (`shading::chroma_albedo`; 0 keeps the uniform albedo).
    pub chroma_refits: usize,
    /// Rounds of correcting the calibrated light's gains against a texture fused with them.
    pub refine_gains: usize,
    /// Rounds, after those, of refitting the calibrated light's shape (rho, s, kappa) with each
    /// sample's albedo from a texture fused with it, each followed by one more gain correction
    /// (`workflow::light_refine`).
    pub refine_light: usize,
    /// Hold out every k-th frame for the cross-validation (0: no cross-validation).
    pub cross_validate_every: usize,
    /// Most frames held out.
    pub cross_validate_max_frames: usize,
    /// Memory for depth buffers kept between passes (bytes); beyond it frames are ray cast again.
    pub depth_cache_bytes: usize,
    /// Reference views (a folder with views.json, camera.json and the images, like the
    /// phantom's truth/): the report then scores the new views against them (Fig. 4).
    pub truth: Option<std::path::PathBuf>,
    /// Replace an existing model folder.
    pub force: bool,
    /// No progress bars.
    pub quiet: bool,
}

impl Default for BuildOptions {
    fn default() -> Self {
        BuildOptions {
            segment: SegmentCommandOptions::default(),
            atlas: AtlasOptions::default(),
            samples: SampleOptions::default(),
            fit: FitOptions::default(),
            // The predicted-intensity-weighted average, not the paper's max-weight choice:
            // measured on the phantom's truth views (80 frames) it renders new views 1.6 dB
            // better with the calibrated light (31.5 vs 29.9 dB) and 0.9 dB better with Psi;
            // max-weight keeps sharper texture (albedo error 11.7% vs 12.5%, held-out frames
            // +0.25 dB). `--fusion max` selects the paper's method. Weights squared (inverse
            // variance for intensity errors of constant size), measured on the 80-frame demo
            // against exponent 1: albedo error 10.47% -> 9.88%, held-out frames +0.25 dB
            // (calibrated) and +0.38 dB (paper), truth views -0.10 dB.
            fusion: FusionOptions {
                method: FusionMethod::WeightedAverage {
                    weight_exponent: 2.0,
                },
                ..Default::default()
            },
            shading: ShadingChoice::default(),
            // No inter-reflection term a_f by default: measured on the phantom (24 and 80
            // frames) it gained 0.5 dB on the truth views but lost 0.3 dB / gained 0.15 dB on
            // held-out frames, and it trades with s(theta) (cone error 1.7% -> 6.6% RMS).
            calibrated: CalibratedOptions::default(),
            calibrated_reference: None,
            pool: PoolOptions::default(),
            max_pooled_samples: 4_000_000,
            chroma_refits: 2,
            refine_gains: 2,
            refine_light: 2,
            cross_validate_every: 5,
            cross_validate_max_frames: 24,
            depth_cache_bytes: 1 << 30,
            truth: None,
            force: false,
            quiet: false,
        }
    }
}

/// The pixels of a frame that obey the model, and the fitted Psi.
fn fit_frame(
    frame: &Frame,
    g: &GBuffer,
    pose: &Affine,
    opts: &BuildOptions,
) -> Result<(SampleSet, PsiModel, FrameFit)> {
    let samples = extract_samples(&g.gamma, &g.z, &frame.rgb, &opts.samples);
    if samples.len() < 50 {
        return Err(Error::Other(format!(
            "too few pixels obey the shading model ({} samples; excluded: {:?}): is the pose registered to the CT?",
            samples.len(),
            samples.excluded
        )));
    }
    let weights = density_weights(&samples, &WeightOptions::default());
    let fit = fit_psi(&samples, &weights.weights, &opts.fit)?;
    let mut model = fit.model;
    model.camera_to_world = row_major(pose);
    let r2 = r_squared(&samples, &model);
    let ff = FrameFit {
        frame: 0,
        samples: samples.len(),
        rms: model.rms_residual,
        r2,
        constrained: fit.channels.iter().any(|c| c.constrained),
    };
    Ok((samples, model, ff))
}

/// R² of Psi against the samples' pixel values, per channel (unweighted).
pub fn r_squared(s: &SampleSet, m: &PsiModel) -> [f64; 3] {
    let mut out = [0.0; 3];
    for (ch, o) in out.iter_mut().enumerate() {
        let vals = &s.rgb[ch];
        let mean = vals.iter().map(|&v| v as f64).sum::<f64>() / vals.len().max(1) as f64;
        let (mut ss_res, mut ss_tot) = (0.0, 0.0);
        for ((&g, &z), &v) in s.gamma.iter().zip(&s.z).zip(vals.iter()) {
            let p = m.eval(ch, g as f64, z as f64);
            let v = v as f64;
            ss_res += (v - p) * (v - p);
            ss_tot += (v - mean) * (v - mean);
        }
        *o = if ss_tot > 0.0 {
            1.0 - ss_res / ss_tot
        } else {
            0.0
        };
    }
    out
}

/// A 4x4 matrix as 16 row-major numbers.
fn row_major(m: &Affine) -> [f64; 16] {
    let mut a = [0.0; 16];
    for r in 0..4 {
        for c in 0..4 {
            a[4 * r + c] = m[(r, c)];
        }
    }
    a
}

/// Build the model of the case in `case_dir` into `out` (atomically).
pub fn build_model(case_dir: &Path, out: &Path, opts: &BuildOptions) -> Result<ModelManifest> {
    let t_all = Instant::now();
    let out_dir = OutputDir::create(out, opts.force)?;
    let mut timings = BuildTimings::default();
    let mut warnings: Vec<String> = Vec::new();

    let t = Instant::now();
    let case = Case::open(case_dir)?;
    timings.read_case = t.elapsed().as_secs_f64();

    let seg_opts = SegmentCommandOptions {
        force: false,
        ..opts.segment.clone()
    };
    let (seg, mesh, _mesh_report, [t_seg, t_mesh]) = segment_and_mesh(&case.ct, &seg_opts)?;
    timings.segment = t_seg;
    timings.mesh = t_mesh;

    let t = Instant::now();
    let atlas = build_atlas(&mesh, &opts.atlas)?;
    let geo = rasterize_texels(&atlas, &mesh)?;
    let texels = TexelSet::new(&geo)?;
    timings.atlas = t.elapsed().as_secs_f64();

    // Pass 1: ray cast, samples and the Psi fit of every frame.
    let t = Instant::now();
    let scene = Scene::new(&atlas.mesh)?;
    let rays = RayTable::new(&case.camera);
    let n = case.frame_count();
    let mut psi = Vec::with_capacity(n);
    let mut fits = Vec::with_capacity(n);
    let mut report_frames = Vec::new();
    let report_every = (n / 3).max(1);
    let progress = Progress::new("fit Psi", n as u64, opts.quiet);
    // Mean colour of the pixels that obey the model: the shading is fitted per channel, so the
    // de-lit texture has each channel's mean divided out; this puts the colour back (one scale
    // per channel).
    let mut pixel_sum = [0f64; 3];
    let cos_theta = cos_theta_of(&rays);
    let mut pooled = PooledSamples::default();
    // Where each pooled sample lies in the texture atlas (for the light's refit).
    let tri_uv = triangle_uvs(&atlas);
    let mut sample_uv: Vec<[f32; 2]> = Vec::new();
    let mut cache = DepthCache::new(n, opts.depth_cache_bytes);
    // The pooled fit's memory and time grow with its samples: a long video keeps fewer per frame.
    let pool = PoolOptions {
        max_per_frame: opts
            .pool
            .max_per_frame
            .min((opts.max_pooled_samples / n.max(1)).max(1000)),
        ..opts.pool.clone()
    };
    for (i, frame) in case.frame_source()?.enumerate() {
        let frame = frame?;
        let pose = &case.poses[i].camera_to_world;
        let g = cast_frame_with(&scene, &rays, pose);
        let (samples, model, mut ff) = fit_frame(&frame, &g, pose, opts)
            .map_err(|e| Error::Other(format!("frame {i} ({}): {e}", frame_name(&case, i))))?;
        ff.frame = i;
        for (ch, sum) in pixel_sum.iter_mut().enumerate() {
            *sum += samples.rgb[ch].iter().map(|&v| v as f64).sum::<f64>();
        }
        if opts.shading != ShadingChoice::Paper || opts.cross_validate_every > 0 {
            let data = FrameData {
                gamma: &g.gamma,
                z: &g.z,
                cos_theta: &cos_theta,
                rgb: &frame.rgb,
                texel: None,
                width: frame.width as usize,
            };
            let part = pool_frames(&[data], &pool)?;
            if opts.refine_light > 0 {
                sample_uv.extend(sample_uvs(&part.pixel, &g, &tri_uv));
            }
            pooled.append(part)?;
        }
        cache.offer(i, &g.z);
        if i % report_every == 0 && report_frames.len() < 3 {
            report_frames.push(ReportFrame {
                index: i,
                frame,
                gbuffer: g,
                samples,
                psi: model.clone(),
            });
        }
        psi.push(model);
        fits.push(ff);
        progress.inc();
    }
    progress.finish();
    timings.fit = t.elapsed().as_secs_f64();

    // The calibrated light of the whole video, on the pooled samples.
    let t = Instant::now();
    let density = density_weights_3d(&pooled, &WeightOptions::default());
    // The reference gain (g = 1, the exposure new views are rendered at): the middle frame
    // unless set, because a frame mid-video shares the most surface with the others (the
    // first frame sees the cut top of the trachea, which no other frame sees).
    let cal_opts = CalibratedOptions {
        reference_frame: opts.calibrated_reference.unwrap_or(n / 2).min(n - 1),
        ..opts.calibrated.clone()
    };
    let mut calibrated = if pooled.is_empty() {
        None
    } else {
        match fit_calibrated(&pooled, &density, &cal_opts) {
            Ok(fit) => Some(fit.model),
            Err(e) if opts.shading == ShadingChoice::Calibrated => {
                return Err(Error::Other(format!("calibrated light fit: {e}")))
            }
            Err(e) => {
                warnings.push(format!(
                    "calibrated light fit failed ({e}); using the paper's Psi"
                ));
                None
            }
        }
    };
    if let Some(model) = calibrated.as_mut() {
        // The albedo predicted from each pixel's colour instead of a uniform one (see
        // chroma_albedo)...
        for _ in 0..opts.chroma_refits {
            refit_with_chroma_albedo(model, &pooled, &density, &cal_opts)?;
        }
        let refine = LightRefinement {
            case: &case,
            scene: &scene,
            rays: &rays,
            cache: &cache,
            texels: &texels,
            // The reference texture is the plain predicted-intensity average (one pass, every
            // frame's share in every texel): a consensus, not the sharpest texture.
            consensus: FusionOptions {
                method: FusionMethod::WeightedAverage {
                    weight_exponent: 1.0,
                },
                ..opts.fusion.clone()
            },
            quiet: opts.quiet,
        };
        // ...corrections of the gains against a texture fused with them (see gain_refine)...
        for _ in 0..opts.refine_gains {
            refine.correct_gains(model)?;
        }
        // ...then refits of the light's shape with the fused texture's albedo (see
        // light_refine), each followed by one more gain correction.
        for _ in 0..opts.refine_light {
            let fused = refine.fuse(model, "refit light")?;
            let image = Frame {
                width: atlas.width,
                height: atlas.height,
                rgb: fused.filled(&texels)?,
            };
            let texture =
                MipTexture::new(&image, None, opts.atlas.texel_mm, &MipOptions::default())?;
            let albedo = sample_albedo(&texture, &sample_uv);
            refit_light_with_albedo(model, &pooled, &density, &albedo, &cal_opts)?;
            refine.correct_gains(model)?;
        }
    }
    drop(pooled);
    drop(sample_uv);
    let light_fit = calibrated.as_ref().map(|m| LightFitSettings {
        rho_degree: cal_opts.rho_degree,
        s_degree: cal_opts.s_degree,
        robust: match cal_opts.robust {
            Robust::None => "none".to_string(),
            Robust::Huber(k) => format!("huber {k}"),
            Robust::Tukey(c) => format!("tukey {c}"),
        },
        ambient_per_frame: cal_opts.ambient,
        interreflection: cal_opts.interreflection,
        reference_frame: m.reference_frame,
        gain_corrections: opts.refine_gains,
        light_refits: opts.refine_light,
        chroma_refits: opts.chroma_refits,
    });
    timings.calibrated_fit = t.elapsed().as_secs_f64();

    let t = Instant::now();
    let cross_validation = if opts.cross_validate_every > 0 {
        let inputs = CrossValidationInputs {
            case: &case,
            scene: &scene,
            rays: &rays,
            texels: &texels,
            tri_uv: &tri_uv,
            atlas_size: [atlas.width, atlas.height],
            texel_mm: opts.atlas.texel_mm,
            psi: &psi,
            calibrated: calibrated.as_ref(),
            cache: &cache,
            fusion: &opts.fusion,
            samples: &opts.samples,
            quiet: opts.quiet,
        };
        match cross_validate(
            &inputs,
            opts.cross_validate_every,
            opts.cross_validate_max_frames,
        ) {
            Ok(cv) => Some(cv),
            Err(e) => {
                warnings.push(format!("cross-validation skipped: {e}"));
                None
            }
        }
    } else {
        None
    };
    timings.cross_validation = t.elapsed().as_secs_f64();
    let shading_model = match (opts.shading, &calibrated) {
        (ShadingChoice::Paper, _) | (_, None) => "paper",
        (ShadingChoice::Calibrated, Some(_)) => "calibrated",
        (ShadingChoice::Auto, Some(_)) => cross_validation
            .as_ref()
            .map_or("calibrated", |cv| cv.winner()),
    }
    .to_string();

    // De-light and fuse all frames with the chosen model (two streaming passes for max-weight).
    let t = Instant::now();
    let passes = opts.fusion.method.passes();
    let source = match (shading_model.as_str(), &calibrated) {
        ("calibrated", Some(c)) => FrameShadingSource::Calibrated(c),
        _ => FrameShadingSource::Paper(&psi),
    };
    // Every frame de-lit with `source` and fused, streaming.
    let fuse_all = |source: FrameShadingSource, label: &str| {
        let mut stream = CaseFrames::new(
            &case,
            &scene,
            &rays,
            source,
            &cache,
            (0..n).collect(),
            Progress::new(label, (passes * n) as u64, opts.quiet),
        );
        let fused = fuse(&texels, &mut stream, &opts.fusion);
        stream.progress.finish();
        fused
    };
    let fused = fuse_all(source, "de-light + fuse")?;
    let mut filled = fused.filled(&texels)?;
    let balance = colour_balance(&mut filled, &fused.covered, pixel_sum);
    // With the calibrated light chosen, the paper's own texture (de-lit by each frame's Psi) is
    // kept beside it: the paper's method stays the reference new views are compared against.
    let paper_texture = if shading_model == "calibrated" {
        let fused = fuse_all(FrameShadingSource::Paper(&psi), "de-light + fuse (paper)")?;
        let mut rgb = fused.filled(&texels)?;
        let paper_balance = colour_balance(&mut rgb, &fused.covered, pixel_sum);
        let img = encode_albedo(&rgb, atlas.width, atlas.height, &fused.covered)?;
        write_bytes_atomic(&out_dir.join(PAPER_TEXTURE_FILE), &img.png)?;
        Some(ExtraTexture {
            file: PAPER_TEXTURE_FILE.into(),
            albedo_scale: img.scale,
            colour_balance: paper_balance,
        })
    } else {
        None
    };
    timings.fusion = t.elapsed().as_secs_f64();

    let t = Instant::now();
    let tex = write_texture_outputs(out_dir.path(), &atlas, &filled, &fused.covered)?;
    write_nifti(&out_dir.join("segmentation.nii.gz"), &seg.mask)?;
    let shading = ShadingFile {
        model: shading_model.clone(),
        viewpoints: psi,
        calibrated,
    };
    write_json(&out_dir.join("shading.json"), &shading)?;
    let mean_r2 = fits.iter().flat_map(|f| f.r2).sum::<f64>() / (3 * fits.len().max(1)) as f64;
    let mut manifest = ModelManifest {
        format_version: MODEL_FORMAT_VERSION,
        generator: format!("bronchosim {}", env!("CARGO_PKG_VERSION")),
        inputs: ModelInputs {
            case: case.dir.display().to_string(),
            case_relative: std::path::absolute(&case.dir).ok().and_then(|c| {
                let m = std::path::absolute(out_dir.target()).ok()?;
                relative_path(&m, &c)
            }),
            ct: case.ct_source.path().display().to_string(),
            camera: case.camera_path.display().to_string(),
            poses: case.poses_path.display().to_string(),
            frames: case.frames.path().display().to_string(),
        },
        counts: ModelCounts {
            frames: n,
            triangles: atlas.mesh.triangles.len(),
            atlas_size: [atlas.width, atlas.height],
            chart_texels: texels.len(),
            covered_texels: tex.covered_texels,
            charts: atlas.chart_count,
            airway_volume_ml: seg.volume_ml,
            branches: Some(seg.branch_count),
        },
        timings: timings.clone(),
        fit_quality: fits,
        mean_r2,
        camera: case.camera,
        albedo_scale: tex.albedo_scale,
        colour_balance: balance,
        texel_mm: opts.atlas.texel_mm,
        shading_model,
        paper_texture,
        cross_validation,
        light_fit,
        warnings,
        atlas_mean_l2_stretch: atlas.stats.mean_l2_stretch,
        atlas_utilisation: atlas.stats.utilisation,
    };
    // Fig. 4 is rendered from the model as written (airway.glb, shading.json, model.json).
    write_json(&out_dir.join("model.json"), &manifest)?;
    let model = Model::load(out_dir.path())?;
    let figure = match &opts.truth {
        Some(truth) => {
            let fig = truth_figure(&model, &case, truth)?;
            write_json(&out_dir.join("evaluation.json"), &fig.scores)?;
            fig
        }
        None => novel_figure(&model, &case)?,
    };
    write_report(
        &out_dir.join("report.html"),
        &ReportInputs {
            manifest: &manifest,
            frames: &report_frames,
            albedo_png: &std::fs::read(out_dir.join("albedo.png"))
                .map_err(|e| Error::io(out_dir.join("albedo.png"), e))?,
            new_views: Some(&figure),
            calibrated: shading.calibrated.as_ref(),
        },
    )?;
    manifest.timings.write = t.elapsed().as_secs_f64();
    manifest.timings.total = t_all.elapsed().as_secs_f64();
    write_json(&out_dir.join("model.json"), &manifest)?;
    out_dir.commit()?;
    Ok(manifest)
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

/// A frame's file name (PNG) or index (video), for messages.
fn frame_name(case: &Case, i: usize) -> String {
    match &case.poses[i].frame {
        crate::io::poses::FrameRef::Image(p) => p.display().to_string(),
        crate::io::poses::FrameRef::VideoIndex(k) => format!("video frame {k}"),
    }
}

/// Write a value as pretty JSON, atomically.
pub fn write_json<T: Serialize>(path: &Path, value: &T) -> Result<()> {
    let text = serde_json::to_string_pretty(value).map_err(|e| Error::Other(e.to_string()))?;
    crate::io::atomic::write_bytes_atomic(path, text.as_bytes())
}

/// What the calibrated light's refinements stream the frames with.
struct LightRefinement<'a> {
    case: &'a Case,
    scene: &'a Scene,
    rays: &'a RayTable,
    cache: &'a DepthCache,
    texels: &'a TexelSet,
    /// The fusion of the reference textures.
    consensus: FusionOptions,
    quiet: bool,
}

impl LightRefinement<'_> {
    fn frames<'b>(
        &'b self,
        model: &'b CalibratedModel,
        label: &str,
        passes: usize,
    ) -> CaseFrames<'b> {
        let n = self.case.frame_count();
        CaseFrames::new(
            self.case,
            self.scene,
            self.rays,
            FrameShadingSource::Calibrated(model),
            self.cache,
            (0..n).collect(),
            Progress::new(label, (passes * n) as u64, self.quiet),
        )
    }

    /// The consensus texture of every frame de-lit with `model`.
    fn fuse(&self, model: &CalibratedModel, label: &str) -> Result<FusedTexture> {
        let mut stream = self.frames(model, label, self.consensus.method.passes());
        let fused = fuse(self.texels, &mut stream, &self.consensus)?;
        stream.progress.finish();
        Ok(fused)
    }

    /// One correction of `model`'s gains against the consensus texture fused with it.
    fn correct_gains(&self, model: &mut CalibratedModel) -> Result<()> {
        let first = model.clone();
        let mut stream = self.frames(&first, "refine gains", self.consensus.method.passes() + 1);
        let fused = fuse(self.texels, &mut stream, &self.consensus)?;
        refine_gains_against_texture(
            model,
            self.texels,
            &fused,
            &mut stream,
            &self.consensus.delight,
        )?;
        stream.progress.finish();
        Ok(())
    }
}
