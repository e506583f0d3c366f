//! The `bronchosim` command line: parse (the arguments are in `args.rs`), call the library,
//! print the command's summary. Nothing else lives here.

mod args;

use anyhow::Context;
use args::{Cli, Command};
use bronchosim::inspect::{inspect_case, InspectOptions};
use bronchosim::math::Point3;
use bronchosim::phantom::{write_phantom_case, PhantomOptions};
use bronchosim::render::evaluate::scores_text;
use bronchosim::render::{evaluate_folders, RenderOptions};
use bronchosim::shading::paper::PsiLookup;
use bronchosim::texture::fusion::{FusionKind, FusionMethod};
use bronchosim::workflow::build::{build_model, BuildOptions};
use bronchosim::workflow::demo::run_demo;
use bronchosim::workflow::flythrough::{flythrough, FlythroughOptions};
use bronchosim::workflow::render::{render_command, RenderCommandOptions};
use bronchosim::workflow::segment::{default_segment_out, segment_command, SegmentCommandOptions};
use bronchosim::workflow::summary::build_text;
use bronchosim::workflow::truth_eval::evaluate_with_baselines;
use clap::Parser;
use std::process::ExitCode;

fn run(command: Command, quiet: bool) -> anyhow::Result<String> {
    Ok(match command {
        Command::Demo { out, frames, force } => {
            let phantom = PhantomOptions {
                frames,
                ..Default::default()
            };
            let build = BuildOptions {
                quiet,
                ..Default::default()
            };
            let d = run_demo(&out, &phantom, &build, force)
                .with_context(|| format!("demo {}", out.display()))?;
            d.to_text()
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
            if fusion == FusionKind::Average && fusion_weight_exponent < 1.0 {
                anyhow::bail!(
                    "--fusion-weight-exponent {fusion_weight_exponent}: expected 1 or more"
                );
            }
            let mut opts = BuildOptions {
                force,
                truth,
                cross_validate_every,
                shading,
                quiet,
                refine_light: light_refits,
                chroma_refits,
                ..Default::default()
            };
            opts.atlas.texel_mm = texel_mm;
            opts.segment.mesh.decimate.target_edge_mm = edge_mm;
            opts.calibrated.ambient = ambient;
            opts.calibrated.interreflection = !no_interreflection;
            opts.fusion.method = FusionMethod::of_kind(fusion, fusion_weight_exponent);
            let m = build_model(&case, &out, &opts)
                .with_context(|| format!("build {}", case.display()))?;
            for w in &m.warnings {
                eprintln!("warning: {w}");
            }
            build_text(&out, &m)
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
            let growth = &mut opts.segment.growth;
            (growth.start_hu, growth.max_hu, growth.step_hu) = (start_hu, max_hu, step_hu);
            growth.leak_growth_limit = leak_growth_limit;
            opts.segment.closing_radius_mm = closing_mm;
            opts.mesh.iso_hu = iso_hu;
            opts.mesh.decimate.target_edge_mm = edge_mm;
            let out = out.unwrap_or_else(|| default_segment_out(&input));
            segment_command(&input, &out, &opts)
                .with_context(|| format!("segment {}", input.display()))?
                .to_text(&out)
        }
        Command::Inspect { case, json, quick } => {
            let opts = InspectOptions {
                decode_all_frames: !quick,
            };
            let report = inspect_case(&case, &opts)
                .with_context(|| format!("inspect {}", case.display()))?;
            for w in report.warnings.iter().filter(|_| !quiet) {
                eprintln!("warning: {w}");
            }
            // The summary is the command's output: printed even with --quiet.
            let text = match json {
                true => serde_json::to_string_pretty(&report)? + "\n",
                false => report.to_text(),
            };
            print!("{text}");
            String::new()
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
                seed,
                anatomy,
                supersample,
                force,
                ..Default::default()
            };
            (opts.width, opts.height) = size.unwrap_or((opts.width, opts.height));
            opts.mask.downsample = downsample;
            let t = std::time::Instant::now();
            write_phantom_case(&out, &opts)
                .with_context(|| format!("phantom {}", out.display()))?
                .to_text(&out, t.elapsed().as_secs_f64())
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
            let opts = RenderCommandOptions {
                camera,
                render: RenderOptions {
                    psi_lookup: PsiLookup::of_kind(shading, k),
                    supersample: supersample.max(1),
                    albedo_only,
                    ..Default::default()
                },
                force,
            };
            render_command(&model, &views, &out, &opts)
                .with_context(|| format!("render {}", model.display()))?
                .to_text(&out)
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
                quiet,
                ..Default::default()
            };
            flythrough(&model, &out, &opts)
                .with_context(|| format!("flythrough {}", model.display()))?
                .to_text()
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
                None => evaluate_folders(&rendered, &truth, Vec::new()),
            }
            .with_context(|| format!("evaluate {}", rendered.display()))?;
            // The scores are the command's output: printed even with --quiet.
            print!(
                "{}",
                match json {
                    true => serde_json::to_string_pretty(&scores)? + "\n",
                    false => scores_text(&scores),
                }
            );
            String::new()
        }
    })
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    match run(cli.command, cli.quiet) {
        Ok(summary) => {
            if !cli.quiet {
                print!("{summary}");
            }
            ExitCode::SUCCESS
        }
        Err(e) => {
            eprintln!("error: {e:#}");
            ExitCode::FAILURE
        }
    }
}
