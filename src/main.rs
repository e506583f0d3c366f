//! The `bronchosim` command line: parse, call the library, print. Nothing else lives here.

use anyhow::Context;
use bronchosim::inspect::{inspect_case, InspectOptions};
use bronchosim::phantom::{write_phantom_case, PhantomOptions};
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
    /// Validate a case folder (CT, camera, poses, frames) and print a summary.
    Inspect {
        /// The case folder (see CASE_FORMAT.md).
        case: PathBuf,
        /// Print the summary as JSON instead of text.
        #[arg(long)]
        json: bool,
        /// Only read frame headers instead of decoding every frame (faster, checks less).
        #[arg(long)]
        quick: bool,
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
        Command::Inspect { case, json, quick } => {
            let opts = InspectOptions {
                decode_all_frames: !quick,
            };
            let report = inspect_case(&case, &opts)
                .with_context(|| format!("inspect {}", case.display()))?;
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
