//! The `bronchosim` command line: parse, call the library, print. Nothing else lives here.

use anyhow::Context;
use bronchosim::inspect::{inspect_case, InspectOptions};
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
    /// Score rendered views against reference images: PSNR and SSIM on the pixels both cover,
    /// after one least-squares gain per channel over all views.
    Evaluate {
        /// Folder of rendered views: the images named in the truth's views.json (and their
        /// `<stem>_mask.png` hit masks, when present).
        rendered: PathBuf,
        /// Truth folder: views.json, the reference images it names, optional `<stem>_mask.png`.
        #[arg(long)]
        truth: PathBuf,
        /// Also score the baselines (nearest training frame reprojected; flat albedo with
        /// cos(gamma)/z^2 shading) on the same pixels. Needs the model folder.
        #[arg(long)]
        baselines: bool,
        /// Print the scores as JSON.
        #[arg(long)]
        json: bool,
    },
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
        Command::Evaluate {
            rendered,
            truth,
            baselines,
            json,
        } => {
            if baselines {
                // The baselines are library functions (render::baselines); producing their
                // frames needs the model folder and the case, wired with `build`.
                anyhow::bail!(
                    "evaluate --baselines: not available yet (needs the model folder written by build)"
                );
            }
            let scores = bronchosim::render::evaluate_folders(&rendered, &truth, Vec::new())
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
