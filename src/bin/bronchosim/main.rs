//! The `bronchosim` command line: parse (the arguments are in `args.rs`), call the library,
//! print the command's summary. Nothing else lives here.

mod args;

use anyhow::Context;
use args::{
    BuildArgs, Cli, Command, ConvertArgs, DemoArgs, EvaluateArgs, FlythroughArgs, InspectArgs,
    PhantomArgs, RegisterArgs, RenderArgs, SegmentArgs, ViewArgs,
};
use bronchosim::inspect::{inspect, InspectOptions};
use bronchosim::io::scope_light::read_scope_light;
use bronchosim::math::Point3;
use bronchosim::phantom::baked_albedo::AlbedoSampling;
use bronchosim::phantom::pose_noise::PoseNoise;
use bronchosim::phantom::{write_phantom_case, PhantomOptions};
use bronchosim::render::evaluate::scores_text;
use bronchosim::render::{evaluate_folders, RenderOptions};
use bronchosim::shading::paper::PsiLookup;
use bronchosim::texture::fusion::{FusionKind, FusionMethod};
use bronchosim::workflow::build::{build_model, BuildOptions};
use bronchosim::workflow::convert::{convert_ct, ConvertOptions};
use bronchosim::workflow::demo::run_demo;
use bronchosim::workflow::flythrough::{flythrough, FlythroughOptions};
use bronchosim::workflow::register::register_command;
use bronchosim::workflow::render::{render_command, RenderCommandOptions};
use bronchosim::workflow::segment::{default_segment_out, segment_command, SegmentCommandOptions};
use bronchosim::workflow::summary::{build_text, register_text};
use bronchosim::workflow::truth_eval::evaluate_with_baselines;
use clap::Parser;
use std::process::ExitCode;

/// Run `command`; returns the summary to print (empty when the command printed its output).
fn run(command: Command, quiet: bool) -> anyhow::Result<String> {
    match command {
        Command::Demo(a) => demo(a, quiet),
        Command::Build(a) => build(a, quiet),
        Command::Register(a) => register(a, quiet),
        Command::Segment(a) => segment(a),
        Command::Inspect(a) => inspect_ct_or_case(a, quiet),
        Command::Convert(a) => convert(a, quiet),
        Command::Phantom(a) => phantom(a, quiet),
        Command::Render(a) => render(a),
        Command::Flythrough(a) => fly(a, quiet),
        Command::Evaluate(a) => evaluate(a),
        Command::View(a) => view(a),
    }
}

fn demo(a: DemoArgs, quiet: bool) -> anyhow::Result<String> {
    let phantom = PhantomOptions {
        frames: a.frames,
        quiet,
        ..Default::default()
    };
    let build = BuildOptions {
        quiet,
        ..Default::default()
    };
    let d = run_demo(&a.out, &phantom, &build, a.force)
        .with_context(|| format!("demo {}", a.out.display()))?;
    Ok(d.to_text())
}

fn build(a: BuildArgs, quiet: bool) -> anyhow::Result<String> {
    if a.fusion != FusionKind::Max && a.fusion_weight_exponent < 1.0 {
        anyhow::bail!(
            "--fusion-weight-exponent {}: expected 1 or more",
            a.fusion_weight_exponent
        );
    }
    let scale = a.fusion_residual_scale;
    if a.fusion == FusionKind::Robust && !(scale.is_finite() && scale > 0.0) {
        anyhow::bail!(
            "--fusion-residual-scale {}: expected a positive number",
            a.fusion_residual_scale
        );
    }
    let mut opts = BuildOptions {
        force: a.force,
        truth: a.truth,
        cross_validate_every: a.cross_validate_every,
        shading: a.shading,
        quiet,
        refine_light: a.light_refits,
        chroma_refits: a.chroma_refits,
        consensus_texel_factor: a.consensus_texels,
        max_pooled_samples: a.max_pooled_samples,
        working_level: a.working_level.map(usize::from),
        poses: a.poses,
        registration_rounds: a.registration_rounds,
        registration_geometry_every: a.geometry_every,
        scope_light: a.scope_light.as_deref().map(read_scope_light).transpose()?,
        ..Default::default()
    };
    opts.selection.max_frames = a.max_frames;
    opts.leave_out_blurred = !a.keep_blurred;
    opts.tracking.refine_first = !a.trust_first_pose;
    opts.atlas.texel_mm = a.texel_mm;
    opts.segment.mesh.decimate.target_edge_mm = a.edge_mm;
    opts.calibrated.ambient = a.ambient;
    opts.calibrated.interreflection = !a.no_interreflection;
    opts.interreflection = a.interreflection;
    opts.calibrated.specular = a.specular;
    opts.gather_nodes = a.gather_nodes;
    opts.gather_rays = a.gather_rays;
    opts.gather_visibility = a.gather_visibility;
    opts.fusion.method = FusionMethod::of_kind(a.fusion, a.fusion_weight_exponent);
    if let FusionMethod::RobustAverage {
        residual_scale,
        rounds,
        ..
    } = &mut opts.fusion.method
    {
        *residual_scale = a.fusion_residual_scale;
        *rounds = a.fusion_rounds;
    }
    if let FusionMethod::MultiBand {
        detail_exponent,
        sigma_texels,
        ..
    } = &mut opts.fusion.method
    {
        *detail_exponent = a.fusion_detail_exponent;
        *sigma_texels = a.fusion_band_sigma;
    }
    opts.unseen.mode = a.unseen;
    let m = build_model(&a.case, &a.out, &opts)
        .with_context(|| format!("build {}", a.case.display()))?;
    for w in &m.warnings {
        eprintln!("warning: {w}");
    }
    Ok(build_text(&a.out, &m))
}

fn register(a: RegisterArgs, quiet: bool) -> anyhow::Result<String> {
    let mut opts = BuildOptions {
        force: a.force,
        quiet,
        registration_rounds: a.rounds,
        registration_geometry_every: a.geometry_every,
        poses: a.poses,
        truth: a.truth,
        scope_light: a.scope_light.as_deref().map(read_scope_light).transpose()?,
        ..Default::default()
    };
    opts.tracking.refine_first = !a.trust_first_pose;
    let s = register_command(&a.case, &a.out, &opts)
        .with_context(|| format!("register {}", a.case.display()))?;
    for w in &s.warnings {
        eprintln!("warning: {w}");
    }
    Ok(register_text(&a.out, &s))
}

fn segment(a: SegmentArgs) -> anyhow::Result<String> {
    let mut opts = SegmentCommandOptions {
        force: a.force,
        ..Default::default()
    };
    opts.segment.seed_world = a.seed.map(|[x, y, z]| Point3::new(x, y, z));
    let growth = &mut opts.segment.growth;
    (growth.start_hu, growth.max_hu, growth.step_hu) = (a.start_hu, a.max_hu, a.step_hu);
    growth.leak_growth_limit = a.leak_growth_limit;
    opts.segment.closing_radius_mm = a.closing_mm;
    opts.mesh.iso_hu = a.iso_hu;
    opts.mesh.decimate.target_edge_mm = a.edge_mm;
    let out = a.out.unwrap_or_else(|| default_segment_out(&a.input));
    let summary = segment_command(&a.input, &out, &opts)
        .with_context(|| format!("segment {}", a.input.display()))?;
    Ok(summary.to_text(&out))
}

fn inspect_ct_or_case(a: InspectArgs, quiet: bool) -> anyhow::Result<String> {
    let opts = InspectOptions {
        decode_all_frames: !a.quick,
    };
    let report =
        inspect(&a.case, &opts).with_context(|| format!("inspect {}", a.case.display()))?;
    if !quiet {
        for w in &report.warnings {
            eprintln!("warning: {w}");
        }
    }
    // The summary is the command's output: printed even with --quiet.
    match a.json {
        true => write_stdout(&format!("{}\n", serde_json::to_string_pretty(&report)?))?,
        false => write_stdout(&report.to_text())?,
    }
    Ok(String::new())
}

fn convert(a: ConvertArgs, quiet: bool) -> anyhow::Result<String> {
    let s = convert_ct(&a.input, &a.out, &ConvertOptions { force: a.force })
        .with_context(|| format!("convert {}", a.input.display()))?;
    if !quiet {
        for w in &s.warnings {
            eprintln!("warning: {w}");
        }
    }
    Ok(s.to_text())
}

fn phantom(a: PhantomArgs, quiet: bool) -> anyhow::Result<String> {
    if !(a.pose_noise_mm >= 0.0 && a.pose_noise_deg >= 0.0) {
        anyhow::bail!(
            "--pose-noise-mm {} / --pose-noise-deg {}: expected non-negative numbers",
            a.pose_noise_mm,
            a.pose_noise_deg
        );
    }
    if !(0.0..=1.0).contains(&a.motion_blur_share) {
        anyhow::bail!(
            "--motion-blur-share {}: expected a share between 0 and 1",
            a.motion_blur_share
        );
    }
    match (a.trachea_posterior_wall, &a.anatomy) {
        (Some(_), Some(mask)) => anyhow::bail!(
            "--trachea-posterior-wall shapes the built-in tree; {} has its own trachea",
            mask.display()
        ),
        (Some(f), None) if !(0.2..=1.0).contains(&f) => anyhow::bail!(
            "--trachea-posterior-wall {f}: expected a fraction of the radius from 0.2 to 1"
        ),
        _ => {}
    }
    let albedo_sampling = match a.baked_albedo_mm {
        None => None,
        Some(0.0) => Some(AlbedoSampling::Procedural),
        Some(mm) if mm.is_finite() && mm >= 0.01 => Some(AlbedoSampling::Baked { spacing_mm: mm }),
        Some(mm) => anyhow::bail!(
            "--baked-albedo-mm {mm}: expected 0 (procedural) or a spacing of at least 0.01 mm"
        ),
    };
    let mut opts = PhantomOptions {
        frames: a.frames,
        albedo_sampling,
        seed: a.seed,
        anatomy: a.anatomy,
        supersample: a.supersample,
        scope_overlay: a.scope_overlay,
        pose_noise: PoseNoise::new(a.pose_noise_mm, a.pose_noise_deg),
        force: a.force,
        quiet,
        ..Default::default()
    };
    (opts.width, opts.height) = a.size.unwrap_or((opts.width, opts.height));
    opts.mask.downsample = a.downsample;
    opts.ct.tree.trachea_posterior_wall = a.trachea_posterior_wall;
    opts.motion_blur.share = a.motion_blur_share;
    let t = std::time::Instant::now();
    let summary = write_phantom_case(&a.out, &opts)
        .with_context(|| format!("phantom {}", a.out.display()))?;
    Ok(summary.to_text(&a.out, t.elapsed().as_secs_f64()))
}

fn render(a: RenderArgs) -> anyhow::Result<String> {
    let opts = RenderCommandOptions {
        camera: a.camera,
        render: RenderOptions {
            psi_lookup: PsiLookup::of_kind(a.shading, a.k),
            supersample: a.supersample.max(1),
            albedo_only: a.albedo_only,
            auto_exposure: a.auto_exposure,
            ..Default::default()
        },
        force: a.force,
    };
    let summary = render_command(&a.model, &a.views, &a.out, &opts)
        .with_context(|| format!("render {}", a.model.display()))?;
    Ok(summary.to_text(&a.out))
}

fn fly(a: FlythroughArgs, quiet: bool) -> anyhow::Result<String> {
    let opts = FlythroughOptions {
        frames: a.frames,
        fps: a.fps,
        auto_exposure: !a.fixed_exposure,
        force: a.force,
        quiet,
        ..Default::default()
    };
    let summary = flythrough(&a.model, &a.out, &opts)
        .with_context(|| format!("flythrough {}", a.model.display()))?;
    Ok(summary.to_text())
}

fn view(a: ViewArgs) -> anyhow::Result<String> {
    use bronchosim::viewer::{default_viewer_dir, open_in_browser, write_viewer, ViewerOptions};
    let out = a.out.unwrap_or_else(|| default_viewer_dir(&a.model));
    let opts = ViewerOptions {
        psi_lookup: PsiLookup::of_kind(a.shading, PsiLookup::DEFAULT_K),
        force: a.force,
        ..Default::default()
    };
    let summary = write_viewer(&a.model, &out, &opts)
        .with_context(|| format!("view {}", a.model.display()))?;
    if a.open {
        if let Err(e) = open_in_browser(&summary.out.join("index.html")) {
            eprintln!("warning: {e}");
        }
    }
    Ok(summary.to_text())
}

fn evaluate(a: EvaluateArgs) -> anyhow::Result<String> {
    let scores = match &a.baselines {
        Some(model) => evaluate_with_baselines(&a.rendered, &a.truth, model, a.case.as_deref()),
        None => evaluate_folders(&a.rendered, &a.truth, Vec::new()),
    }
    .with_context(|| format!("evaluate {}", a.rendered.display()))?;
    // The scores are the command's output: printed even with --quiet.
    match a.json {
        true => write_stdout(&format!("{}\n", serde_json::to_string_pretty(&scores)?))?,
        false => write_stdout(&scores_text(&scores))?,
    }
    Ok(String::new())
}

/// Write `text` to stdout. A reader that stops early (`| head`) closes the pipe: that is not
/// an error of ours (print! would panic).
fn write_stdout(text: &str) -> std::io::Result<()> {
    use std::io::Write;
    let mut out = std::io::stdout().lock();
    match out.write_all(text.as_bytes()).and_then(|_| out.flush()) {
        Err(e) if e.kind() == std::io::ErrorKind::BrokenPipe => Ok(()),
        other => other,
    }
}

/// The error and its causes on one line, each cause once: the library's messages already
/// quote the operating system's (e.g. "PATH: No such file or directory").
fn one_line(e: &anyhow::Error) -> String {
    let mut line = e.to_string();
    for cause in e.chain().skip(1) {
        let cause = cause.to_string();
        if !line.contains(&cause) {
            line = format!("{line}: {cause}");
        }
    }
    line
}

fn main() -> ExitCode {
    bronchosim::allocator::keep_freed_memory();
    let cli = Cli::parse();
    match run(cli.command, cli.quiet) {
        Ok(summary) => {
            if !cli.quiet {
                if let Err(e) = write_stdout(&summary) {
                    eprintln!("error: writing the summary: {e}");
                    return ExitCode::FAILURE;
                }
            }
            ExitCode::SUCCESS
        }
        Err(e) => {
            eprintln!("error: {}", one_line(&e));
            ExitCode::FAILURE
        }
    }
}
