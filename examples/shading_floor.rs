//! Issue 8's floor on any phantom model: how far each frame's gain would be off if the albedo
//! were known exactly, for the model's fitted light and for the phantom's own light law, on
//! the model's CT-derived mesh and on the phantom's true mesh; with the residual profiles.
//!
//! `cargo run --release --example shading_floor -- MODEL_DIR CASE_DIR [FRAME_STEP] [--profiles]`

use std::path::Path;

use bronchosim::io::case::Case;
use bronchosim::io::mesh_export::read_ply;
use bronchosim::model::Model;
use bronchosim::phantom::analysis::shading::{
    shading_residuals, spread, ShadingLaw, ShadingResiduals,
};
use bronchosim::raycast::Scene;

fn main() -> bronchosim::Result<()> {
    let args: Vec<String> = std::env::args().collect();
    if args.len() < 3 {
        eprintln!("usage: shading_floor MODEL_DIR CASE_DIR [FRAME_STEP] [--profiles]");
        std::process::exit(2);
    }
    let model = Model::load(Path::new(&args[1]))?;
    let case_dir = Path::new(&args[2]);
    let step: usize = args.get(3).and_then(|s| s.parse().ok()).unwrap_or(1);
    let profiles = args.iter().any(|a| a == "--profiles");
    let case = Case::open(case_dir)?;
    let truth = case_dir.join("truth");
    let true_scene = Scene::new(&read_ply(&truth.join("lumen.ply"))?)?;
    let fitted = model
        .calibrated()
        .ok_or_else(|| bronchosim::Error::Other("the model has no calibrated light".into()))?;
    println!("per-frame log residual with true gains and true albedo (relative to the mean over frames):");
    for (law, law_name) in [
        (ShadingLaw::Fitted(fitted), "fitted light"),
        (ShadingLaw::Phantom, "phantom's light law"),
    ] {
        for (scene, mesh_name) in [(&model.scene, "model mesh"), (&true_scene, "true mesh")] {
            let r = shading_residuals(&case, scene, &truth, law, step)?;
            let (mr, mw) = spread(&r.frame_mean);
            let (dr, dw) = spread(&r.frame_median);
            println!(
                "  {law_name:>20}, {mesh_name}: mean RMS {:.2}% worst {:.2}% | median RMS {:.2}% worst {:.2}% ({} frames, {} pixels)",
                100.0 * mr, 100.0 * mw, 100.0 * dr, 100.0 * dw, r.frames.len(), r.pixels
            );
            if profiles {
                print_profiles(&r);
            }
        }
    }
    Ok(())
}

fn print_profiles(r: &ShadingResiduals) {
    for (name, bins) in [
        ("z mm", &r.by_z),
        ("theta deg", &r.by_theta),
        ("gamma deg", &r.by_gamma),
    ] {
        let cells: Vec<String> = bins
            .iter()
            .filter(|b| b.pixels >= 2000)
            .map(|b| format!("{:.0}:{:+.1}%", b.from, 100.0 * b.mean_log))
            .collect();
        println!("    {name}: {}", cells.join(" "));
    }
    let f: Vec<String> = r
        .frames
        .iter()
        .zip(&r.frame_median)
        .step_by(4)
        .map(|(f, m)| format!("{f}:{:+.1}", 100.0 * m))
        .collect();
    println!("    median per frame: {}", f.join(" "));
}
