//! The frame selection of a case alone (issue 21), without the rest of the build: which frames
//! `build --max-frames N` would use and why not the others.
//!
//! `cargo run --release --example frame_selection -- CASE [MAX_FRAMES]` (default: the build's).

use bronchosim::model::manifest::BuildTimings;
use bronchosim::workflow::build::selection::select_frames;
use bronchosim::workflow::build::{BuildOptions, BuildScene};

fn main() -> anyhow::Result<()> {
    let args: Vec<String> = std::env::args().collect();
    let case = std::path::PathBuf::from(args.get(1).expect("usage: frame_selection CASE [MAX]"));
    let mut opts = BuildOptions {
        quiet: true,
        ..Default::default()
    };
    if let Some(m) = args.get(2) {
        opts.selection.max_frames = m.parse()?;
    }
    let mut timings = BuildTimings::default();
    let mut scene = BuildScene::prepare(&case, &opts, &mut timings)?;
    let Some(sel) = select_frames(&mut scene, &opts, &mut Vec::new())? else {
        println!("no selection (--max-frames 0)");
        return Ok(());
    };
    println!(
        "{} of {} frames used (budget {}), {:?}; cells seen {} of {}; seconds {:?}",
        sel.used,
        sel.frames.len(),
        sel.budget,
        sel.counts,
        sel.cells_seen_used,
        sel.cells_seen_all,
        sel.seconds
    );
    let mut rel: Vec<(f64, usize)> = sel
        .frames
        .iter()
        .map(|f| (f.relative_sharpness, f.frame))
        .collect();
    rel.sort_by(|a, b| a.0.total_cmp(&b.0));
    println!(
        "least relative sharpness (value, frame): {:?}",
        &rel[..rel.len().min(8)]
    );
    for f in sel.frames.iter().filter(|f| !f.used) {
        println!("frame {} not used: {:?}", f.frame, f.reason);
    }
    Ok(())
}
