//! Issue 6's accuracy measure on any phantom model: the relative RMS error of the model's
//! texture (and of the paper's texture it keeps) against the true albedo.
//!
//! `cargo run --release --example albedo_error -- MODEL_DIR CASE_DIR/truth`

use std::path::Path;

use bronchosim::model::Model;
use bronchosim::phantom::analysis::albedo_error;

fn main() -> bronchosim::Result<()> {
    let args: Vec<String> = std::env::args().collect();
    let [_, model, truth] = args.as_slice() else {
        eprintln!("usage: albedo_error MODEL_DIR TRUTH_DIR");
        std::process::exit(2);
    };
    let model = Model::load(Path::new(model))?;
    let truth = Path::new(truth);
    let own = albedo_error(&model, &model.texture, truth)?;
    print!(
        "albedo error over {} pixels: model texture {:.2}%",
        own.pixels,
        100.0 * own.relative_rms
    );
    if let Some(paper) = &model.paper_texture {
        let p = albedo_error(&model, paper, truth)?;
        print!(", paper's texture {:.2}%", 100.0 * p.relative_rms);
    }
    println!();
    Ok(())
}
