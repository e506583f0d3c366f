//! The `bronchosim` command line: parse, call the library, print. Nothing else lives here.

use anyhow::Context;
use bronchosim::inspect::{inspect, InspectOptions};
use bronchosim::math::Point3;
use bronchosim::phantom::{write_phantom_case, PhantomOptions};
use bronchosim::render::{RenderOptions, ShadingMode};
use bronchosim::workflow::build::{build_model, BuildOptions, ShadingChoice};
use bronchosim::workflow::convert::{convert_ct, ConvertOptions};
use bronchosim::workflow::demo::run_demo;
use bronchosim::workflow::flythrough::{flythrough, FlythroughOptions};
use bronchosim::workflow::render::{render_command, RenderCommandOptions};
use bronchosim::workflow::segment::{
    default_segment_out, parse_point, segment_command, SegmentCommandOptions,
};
use bronchosim::workflow::truth_eval::evaluate_with_baselines;
use clap::{Parser, Subcommand};
use std::path::PathBuf;
use std::process::ExitCode;

/// Patient-specific, photo-realistic airway models from CT and bronchoscope video.
#[derive(Parser, Debug)]
#[command(name = "bronchosim", version, about, long_about = None)]
struct Cli {
    /// Silence progress bars and informational output.
    #[arg(long, global = true)]
    quiet: bool,
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand, Debug)]
enum Command {
    /// Validate a case folder (CT, camera, poses, frames), or a bare CT, and print a summary.
    Inspect {
        /// A case folder (see CASE_FORMAT.md), a NIfTI file (.nii / .nii.gz) or a DICOM folder.
        case: PathBuf,
        /// Print the summary as JSON instead of text.
        #[arg(long)]
        json: bool,
        /// Only read frame headers instead of decoding every frame (faster, checks less).
        #[arg(long)]
        quick: bool,
    },
    /// Convert a CT (a DICOM folder, a NIfTI file or a case's CT) to one NIfTI file in HU with
    /// its affine, as 3D Slicer and ITK-SNAP open it.
    Convert {
        /// A DICOM folder, a NIfTI file (.nii / .nii.gz) or a case folder.
        input: PathBuf,
        /// The NIfTI file to write (.nii or .nii.gz).
        #[arg(long)]
        out: PathBuf,
        /// Replace an existing output file.
        #[arg(long)]
        force: bool,
    },
    /// Segment the airway in a CT and extract the lumen mesh (segmentation.nii.gz, lumen.ply/.obj/.glb,
    /// summary.json).
    Segment {
        /// A case folder, a NIfTI file (.nii / .nii.gz) or a DICOM folder.
        input: PathBuf,
        /// Output folder (default: <input>_segment beside the input).
        #[arg(long)]
        out: Option<PathBuf>,
        /// Seed point inside the trachea, world mm (RAS): X,Y,Z. Default: found automatically.
        #[arg(long, value_parser = parse_point, allow_hyphen_values = true)]
        seed: Option<[f64; 3]>,
        /// First upper threshold of the adaptive region growing (HU).
        #[arg(long, default_value_t = -950.0, allow_hyphen_values = true)]
        start_hu: f32,
        /// Highest threshold the adaptive region growing may reach (HU).
        #[arg(long, default_value_t = -500.0, allow_hyphen_values = true)]
        max_hu: f32,
        /// Threshold increase per step (HU).
        #[arg(long, default_value_t = 25.0)]
        step_hu: f32,
        /// A step whose volume grows by more than this factor is a leak: growing stops before it.
        #[arg(long, default_value_t = 2.0)]
        leak_growth_limit: f64,
        /// Radius of the morphological closing (mm).
        #[arg(long, default_value_t = 1.0)]
        closing_mm: f64,
        /// Marching-cubes level between lumen air and wall (HU).
        #[arg(long, default_value_t = -500.0, allow_hyphen_values = true)]
        iso_hu: f32,
        /// Target edge length of the decimated lumen mesh (mm).
        #[arg(long, default_value_t = 0.7)]
        edge_mm: f64,
        /// Replace an existing output folder.
        #[arg(long)]
        force: bool,
    },
    /// Build the photo-realistic model of a case: segment, mesh, atlas, fit Psi per frame,
    /// de-light and fuse the texture; writes the model folder (model.json, airway.glb, albedo.png,
    /// shading.json, segmentation.nii.gz, report.html).
    Build {
        /// The case folder (see CASE_FORMAT.md).
        case: PathBuf,
        /// The model folder to write.
        #[arg(long)]
        out: PathBuf,
        /// Texel size of the albedo atlas (mm).
        #[arg(long, default_value_t = 0.15)]
        texel_mm: f64,
        /// Target edge length of the decimated lumen mesh (mm).
        #[arg(long, default_value_t = 0.7)]
        edge_mm: f64,
        /// Fusion of the de-lit frames: "max" (the paper's max-weight choice with smoothed
        /// weights) or "average" (weighted by the predicted intensity to the power
        /// --fusion-weight-exponent).
        #[arg(long, default_value = "average")]
        fusion: String,
        /// Power of the predicted intensity that weights the average (1: the paper's first
        /// attempt; 2: inverse-variance weights for intensity errors of constant size).
        #[arg(long, default_value_t = 2.0)]
        fusion_weight_exponent: f32,
        /// Shading model of the texture and of new views: "paper" (per-viewpoint Psi),
        /// "calibrated" (one light for the whole video) or "auto" (the one that predicts
        /// held-out frames better).
        #[arg(long, default_value = "auto")]
        shading: String,
        /// Fit the calibrated light's inter-reflection term a_f (off by default: measured on the
        /// phantom it did not clearly help, see BENCHMARKS.md).
        #[arg(long)]
        ambient: bool,
        /// Leave out the calibrated light's inter-reflection term (kappa times the frame's mean
        /// observed light, 3 parameters for the whole video; on by default, see BENCHMARKS.md).
        #[arg(long)]
        no_interreflection: bool,
        /// Rounds of refitting the calibrated light and its gains with each pixel's albedo
        /// predicted from its colour, right after the uniform-albedo fit (0 keeps the uniform
        /// albedo; see BENCHMARKS.md).
        #[arg(long, default_value_t = 2)]
        chroma_refits: usize,
        /// Rounds of refitting the calibrated light's shape with the fused texture's albedo
        /// (each followed by a gain correction; 0 keeps the uniform-albedo light).
        #[arg(long, default_value_t = 2)]
        light_refits: usize,
        /// Hold out every N-th frame to cross-validate both shading models (0: skip).
        #[arg(long, default_value_t = 5)]
        cross_validate_every: usize,
        /// Reference views (views.json, camera.json, images; e.g. the phantom's truth/): the
        /// report then scores new views against them next to two baselines.
        #[arg(long)]
        truth: Option<PathBuf>,
        /// Replace an existing model folder.
        #[arg(long)]
        force: bool,
    },
    /// The embedded default: write the phantom case (CT, video, poses, camera, truth) and build
    /// its model; open DIR/model/report.html afterwards.
    Demo {
        /// Folder for the case and the model.
        #[arg(long, default_value = "bronchosim-demo")]
        out: PathBuf,
        /// Number of video frames of the phantom.
        #[arg(long, default_value_t = 80)]
        frames: usize,
        /// Replace the folder if it exists.
        #[arg(long)]
        force: bool,
    },
    /// Write a synthetic case (CT, frames, poses, camera) with its truth in CASE/truth/.
    Phantom {
        /// The case folder to create.
        #[arg(long)]
        out: PathBuf,
        /// Number of video frames.
        #[arg(long, default_value_t = 80)]
        frames: usize,
        /// Frame size in pixels, WIDTHxHEIGHT.
        #[arg(long, default_value = "320x320", value_parser = parse_size)]
        size: (u32, u32),
        /// Master seed (same seed, identical files).
        #[arg(long, default_value_t = 1)]
        seed: u64,
        /// Take the airway from this binary mask (NIfTI) instead of the built-in tree.
        #[arg(long)]
        anatomy: Option<PathBuf>,
        /// Average blocks of N³ mask voxels first (with --anatomy; faster, coarser).
        #[arg(long, default_value_t = 1)]
        downsample: usize,
        /// Sub-samples per pixel along each axis (antialiasing).
        #[arg(long, default_value_t = 1)]
        supersample: u32,
        /// Replace CASE if it exists.
        #[arg(long)]
        force: bool,
    },
    /// Render new views of a built model (paper Fig. 4) from the poses of a views.json.
    Render {
        /// The model folder (from `build`).
        model: PathBuf,
        /// Poses of the new views, in the poses.json schema; each "image" names the output PNG
        /// inside --out.
        #[arg(long)]
        views: PathBuf,
        /// Camera of the new views (camera.json or OpenCV YAML/XML); default: the training camera.
        #[arg(long)]
        camera: Option<PathBuf>,
        /// Output folder.
        #[arg(long)]
        out: PathBuf,
        /// For a model shaded with the paper's Psi: "nearest" (the paper: Psi of the nearest
        /// fitted viewpoint) or "blend" (the k nearest viewpoints' Psi blended continuously).
        /// A model with the calibrated light needs no viewpoint lookup and ignores it.
        #[arg(long, default_value = "blend")]
        shading: String,
        /// Viewpoints blended by --shading blend.
        #[arg(long, default_value_t = 4)]
        k: usize,
        /// Rays per pixel along each axis (antialiasing).
        #[arg(long, default_value_t = 1)]
        supersample: u32,
        /// Write the texture alone (the fused albedo, unshaded), e.g. to inspect the texture.
        #[arg(long)]
        albedo_only: bool,
        /// Replace an existing output folder.
        #[arg(long)]
        force: bool,
    },
    /// Fly along the airway's centre line through the textured region (first to last training
    /// camera): DIR/frame_0000.png …, DIR/path.json (views for `render`) and, with ffmpeg,
    /// DIR/flythrough.mp4.
    Flythrough {
        /// The model folder (from `bronchosim build`).
        model: PathBuf,
        /// Output folder.
        #[arg(long)]
        out: PathBuf,
        /// Number of frames.
        #[arg(long, default_value_t = 120)]
        frames: usize,
        /// Frame rate of the video (frames per second).
        #[arg(long, default_value_t = 25)]
        fps: u32,
        /// Replace the output folder if it exists.
        #[arg(long)]
        force: bool,
    },
    /// Score rendered views against reference images: PSNR and SSIM on the pixels both cover,
    /// after one least-squares gain per channel over all views.
    Evaluate {
        /// Folder of rendered views: the images named in the truth's views.json (and their
        /// `<stem>_mask.png` hit masks, when present).
        rendered: PathBuf,
        /// Truth folder: views.json, the reference images it names, optional `<stem>_mask.png`.
        #[arg(long)]
        truth: PathBuf,
        /// Also render and score, from this model folder, the paper's method (nearest and
        /// k-nearest Psi) and the two baselines ((a) nearest training frame reprojected,
        /// (b) flat albedo with cos(gamma)/z^2 shading) on the same pixels.
        #[arg(long, value_name = "MODEL")]
        baselines: Option<PathBuf>,
        /// The case the model was built from (default: the one model.json names).
        #[arg(long, requires = "baselines")]
        case: Option<PathBuf>,
        /// Print the scores as JSON.
        #[arg(long)]
        json: bool,
    },
}

/// Parse "WxH" into (width, height).
fn parse_size(s: &str) -> Result<(u32, u32), String> {
    let (w, h) = s
        .split_once(['x', 'X'])
        .ok_or_else(|| format!("size {s:?} is not WIDTHxHEIGHT"))?;
    let p = |v: &str| {
        v.trim()
            .parse::<u32>()
            .map_err(|e| format!("size {s:?}: {e}"))
    };
    Ok((p(w)?, p(h)?))
}

fn run(cli: Cli) -> anyhow::Result<()> {
    match cli.command {
        Command::Demo { out, frames, force } => {
            let phantom = PhantomOptions {
                frames,
                ..Default::default()
            };
            let build = BuildOptions {
                quiet: cli.quiet,
                ..Default::default()
            };
            let d = run_demo(&out, &phantom, &build, force)
                .with_context(|| format!("demo {}", out.display()))?;
            if !cli.quiet {
                let m = &d.manifest;
                println!(
                    "phantom case {} ({} frames, {:.1} s)\nmodel {} in {:.1} s: {} triangles, atlas {}x{}, {:.0}% of chart texels seen, mean R² of Psi {:.3}, shading {}{}\nreport {}",
                    d.case.display(),
                    m.counts.frames,
                    d.phantom_seconds,
                    d.model.display(),
                    m.timings.total,
                    m.counts.triangles,
                    m.counts.atlas_size[0],
                    m.counts.atlas_size[1],
                    100.0 * m.counts.covered_texels as f64 / m.counts.chart_texels.max(1) as f64,
                    m.mean_r2,
                    m.shading_model,
                    m.cross_validation.as_ref().map_or(String::new(), |cv| {
                        let parts: Vec<String> = cv
                            .models
                            .iter()
                            .map(|mc| {
                                format!("{} {:.2} dB", mc.model, mc.mean_psnr_db.unwrap_or(f64::NAN))
                            })
                            .collect();
                        format!(" (held-out frames: {})", parts.join(", "))
                    }),
                    d.model.join("report.html").display()
                );
                println!(
                    "truth views rendered into {}; scores (PSNR dB / SSIM, same pixels, per-channel gain):\n{}",
                    d.views.display(),
                    bronchosim::render::evaluate::scores_text(&d.scores)
                );
            }
            Ok(())
        }
        Command::Build {
            case,
            out,
            texel_mm,
            edge_mm,
            fusion,
            fusion_weight_exponent,
            shading,
            cross_validate_every,
            ambient,
            no_interreflection,
            light_refits,
            chroma_refits,
            truth,
            force,
        } => {
            let mut opts = BuildOptions {
                force,
                truth,
                cross_validate_every,
                shading: match shading.as_str() {
                    "auto" => ShadingChoice::Auto,
                    "paper" => ShadingChoice::Paper,
                    "calibrated" => ShadingChoice::Calibrated,
                    other => anyhow::bail!("--shading {other}: expected auto, paper or calibrated"),
                },
                quiet: cli.quiet,
                ..Default::default()
            };
            opts.atlas.texel_mm = texel_mm;
            opts.segment.mesh.decimate.target_edge_mm = edge_mm;
            opts.calibrated.ambient = ambient;
            opts.calibrated.interreflection = !no_interreflection;
            opts.refine_light = light_refits;
            opts.chroma_refits = chroma_refits;
            opts.fusion.method = match fusion.as_str() {
                "max" => bronchosim::texture::fusion::FusionMethod::MaxWeightSmoothed {
                    sigma_texels: 2.0,
                },
                "average" if fusion_weight_exponent >= 1.0 => {
                    bronchosim::texture::fusion::FusionMethod::WeightedAverage {
                        weight_exponent: fusion_weight_exponent,
                    }
                }
                "average" => anyhow::bail!(
                    "--fusion-weight-exponent {fusion_weight_exponent}: expected 1 or more"
                ),
                other => anyhow::bail!("--fusion {other}: expected max or average"),
            };
            let m = build_model(&case, &out, &opts)
                .with_context(|| format!("build {}", case.display()))?;
            if !cli.quiet {
                println!(
                    "built {} from {} frames in {:.1} s: {} triangles, atlas {}x{} ({} of {} texels seen), mean R² of Psi {:.3}, shading {}",
                    out.display(),
                    m.counts.frames,
                    m.timings.total,
                    m.counts.triangles,
                    m.counts.atlas_size[0],
                    m.counts.atlas_size[1],
                    m.counts.covered_texels,
                    m.counts.chart_texels,
                    m.mean_r2,
                    m.shading_model
                );
                if let Some(cv) = &m.cross_validation {
                    for mc in &cv.models {
                        println!(
                            "  held-out frames ({} of {}): {} predicts them at {:.2} dB PSNR, SSIM {:.4}",
                            cv.held_out.len(),
                            m.counts.frames,
                            mc.model,
                            mc.mean_psnr_db.unwrap_or(f64::NAN),
                            mc.mean_ssim.unwrap_or(f64::NAN)
                        );
                    }
                }
                for w in &m.warnings {
                    eprintln!("warning: {w}");
                }
            }
            Ok(())
        }
        Command::Segment {
            input,
            out,
            seed,
            start_hu,
            max_hu,
            step_hu,
            leak_growth_limit,
            closing_mm,
            iso_hu,
            edge_mm,
            force,
        } => {
            let mut opts = SegmentCommandOptions {
                force,
                ..Default::default()
            };
            opts.segment.seed_world = seed.map(|[x, y, z]| Point3::new(x, y, z));
            opts.segment.growth.start_hu = start_hu;
            opts.segment.growth.max_hu = max_hu;
            opts.segment.growth.step_hu = step_hu;
            opts.segment.growth.leak_growth_limit = leak_growth_limit;
            opts.segment.closing_radius_mm = closing_mm;
            opts.mesh.iso_hu = iso_hu;
            opts.mesh.decimate.target_edge_mm = edge_mm;
            let out = out.unwrap_or_else(|| default_segment_out(&input));
            let summary = segment_command(&input, &out, &opts)
                .with_context(|| format!("segment {}", input.display()))?;
            if !cli.quiet {
                print!("{}", summary.to_text(&out));
            }
            Ok(())
        }
        Command::Convert { input, out, force } => {
            let s = convert_ct(&input, &out, &ConvertOptions { force })
                .with_context(|| format!("convert {}", input.display()))?;
            if !cli.quiet {
                print!("{}", s.to_text());
                for w in &s.warnings {
                    eprintln!("warning: {w}");
                }
            }
            Ok(())
        }
        Command::Inspect { case, json, quick } => {
            let opts = InspectOptions {
                decode_all_frames: !quick,
            };
            let report =
                inspect(&case, &opts).with_context(|| format!("inspect {}", case.display()))?;
            if json {
                println!("{}", serde_json::to_string_pretty(&report)?);
            } else {
                print!("{}", report.to_text());
            }
            for w in &report.warnings {
                if !cli.quiet {
                    eprintln!("warning: {w}");
                }
            }
            Ok(())
        }
        Command::Phantom {
            out,
            frames,
            size,
            seed,
            anatomy,
            downsample,
            supersample,
            force,
        } => {
            let mut opts = PhantomOptions {
                frames,
                width: size.0,
                height: size.1,
                seed,
                anatomy,
                supersample,
                force,
                ..Default::default()
            };
            opts.mask.downsample = downsample;
            let t = std::time::Instant::now();
            let s = write_phantom_case(&out, &opts)
                .with_context(|| format!("phantom {}", out.display()))?;
            if !cli.quiet {
                println!(
                    "wrote {}: CT {:?}, mesh {} triangles, {} frames, {} truth views in {:.1} s \
                     (CT {:.1}, mesh {:.1}, path {:.1}, frames {:.1}, views {:.1}, CT file {:.1})",
                    out.display(),
                    s.ct_dims,
                    s.mesh_triangles,
                    s.frames,
                    s.views,
                    t.elapsed().as_secs_f64(),
                    s.seconds[0],
                    s.seconds[1],
                    s.seconds[2],
                    s.seconds[3],
                    s.seconds[4],
                    s.seconds[5]
                );
            }
            Ok(())
        }
        Command::Render {
            model,
            views,
            camera,
            out,
            shading,
            k,
            supersample,
            albedo_only,
            force,
        } => {
            let shading = match shading.as_str() {
                "nearest" => ShadingMode::Nearest,
                "blend" => ShadingMode::KNearest { k: k.max(1) },
                other => anyhow::bail!("--shading {other}: expected nearest or blend"),
            };
            let opts = RenderCommandOptions {
                camera,
                render: RenderOptions {
                    shading,
                    supersample: supersample.max(1),
                    albedo_only,
                    ..Default::default()
                },
                force,
            };
            let s = render_command(&model, &views, &out, &opts)
                .with_context(|| format!("render {}", model.display()))?;
            if !cli.quiet {
                println!(
                    "rendered {} views into {} in {:.2} s ({:.1} views/s; shading {}; model loaded in {:.2} s)",
                    s.images.len(),
                    out.display(),
                    s.render_seconds,
                    s.images.len() as f64 / s.render_seconds.max(1e-9),
                    s.shading,
                    s.load_seconds
                );
            }
            Ok(())
        }
        Command::Flythrough {
            model,
            out,
            frames,
            fps,
            force,
        } => {
            let opts = FlythroughOptions {
                frames,
                fps,
                force,
                quiet: cli.quiet,
                ..Default::default()
            };
            let s = flythrough(&model, &out, &opts)
                .with_context(|| format!("flythrough {}", model.display()))?;
            if !cli.quiet {
                println!(
                    "{}: {} frames along {:.1} mm (clearance >= {:.1} mm) in {:.1} s ({:.1} frames/s); {}",
                    s.out.display(),
                    s.frames,
                    s.path_length_mm,
                    s.min_clearance_mm,
                    s.render_seconds,
                    s.frames as f64 / s.render_seconds.max(1e-9),
                    s.video_note
                );
            }
            Ok(())
        }
        Command::Evaluate {
            rendered,
            truth,
            baselines,
            case,
            json,
        } => {
            let scores = match &baselines {
                Some(model) => evaluate_with_baselines(&rendered, &truth, model, case.as_deref()),
                None => bronchosim::render::evaluate_folders(&rendered, &truth, Vec::new()),
            }
            .with_context(|| format!("evaluate {}", rendered.display()))?;
            if json {
                println!("{}", serde_json::to_string_pretty(&scores)?);
            } else {
                print!("{}", bronchosim::render::evaluate::scores_text(&scores));
            }
            Ok(())
        }
    }
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    match run(cli) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e:#}");
            ExitCode::FAILURE
        }
    }
}
