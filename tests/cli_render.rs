//! New views from the command line (issue 7): `build --truth` puts Fig. 4 in the report,
//! `render` writes the truth views from the model folder, `evaluate --baselines` scores them
//! next to the paper's method and the two baselines on the same pixels.

use bronchosim::phantom::analysis::albedo_error;
use bronchosim::phantom::analysis::shading::{shading_residuals, spread, ShadingLaw};
use std::path::Path;

#[path = "common/cli.rs"]
mod cli;
use cli::{ok, phantom, run};

fn mean_psnr(scores: &serde_json::Value, method_prefix: &str) -> f64 {
    scores
        .as_array()
        .unwrap()
        .iter()
        .find(|m| m["method"].as_str().unwrap().starts_with(method_prefix))
        .unwrap_or_else(|| panic!("no method {method_prefix} in {scores}"))["mean_psnr_db"]
        .as_f64()
        .unwrap()
}

#[test]
fn render_and_evaluate_the_truth_views_against_the_baselines() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    phantom(dir, 24, "160x160");
    ok(&run(
        &[
            "build",
            "case",
            "--out",
            "model",
            "--truth",
            "case/truth",
            "--quiet",
            "--poses",
            "fixed",
        ],
        dir,
    ));
    let html = std::fs::read_to_string(dir.join("model/report.html")).unwrap();
    assert!(html.contains("New views (paper Fig. 4)"));
    assert!(html.contains("(a) reprojected frame"));
    let built: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("model/evaluation.json")).unwrap())
            .unwrap();

    ok(&run(
        &[
            "render",
            "model",
            "--views",
            "case/truth/views.json",
            "--camera",
            "case/truth/camera.json",
            "--out",
            "views",
            "--quiet",
        ],
        dir,
    ));
    assert!(dir.join("views/views/000000.png").is_file());
    assert!(dir.join("views/views/000000_mask.png").is_file());
    assert!(dir.join("views/render.json").is_file());

    let o = run(
        &[
            "evaluate",
            "views",
            "--truth",
            "case/truth",
            "--baselines",
            "model",
            "--json",
        ],
        dir,
    );
    ok(&o);
    let scores: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    let rendered = mean_psnr(&scores, "rendered");
    let calibrated = mean_psnr(&scores, "calibrated light");
    let nearest = mean_psnr(&scores, "paper (nearest");
    let blended = mean_psnr(&scores, "paper, k-nearest");
    let reprojected = mean_psnr(&scores, "(a)");
    let flat = mean_psnr(&scores, "(b)");
    println!(
        "mean PSNR (dB): rendered {rendered:.2}, calibrated {calibrated:.2}, paper nearest \
         {nearest:.2}, paper k-nearest {blended:.2}, (a) reprojected {reprojected:.2}, (b) flat \
         {flat:.2}"
    );
    // The render command writes what the in-memory renderer makes with the model's shading
    // (the calibrated light, chosen by cross-validation).
    let m: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("model/model.json")).unwrap())
            .unwrap();
    assert_eq!(m["shading_model"], "calibrated");
    // Tolerance: the PNG clips at white, the in-memory view keeps values above 1 that the
    // evaluation's gain (< 1 here) brings back under white.
    assert!(
        (rendered - calibrated).abs() < 0.3,
        "{rendered} vs {calibrated}"
    );
    // The report's table is the same evaluation.
    assert!((mean_psnr(&built, "paper, k-nearest") - blended).abs() < 1e-6);
    // Issue 7: the paper's method beats projecting the nearest frame without de-lighting.
    assert!(blended > reprojected, "{blended} <= {reprojected}");
    assert!(nearest > reprojected, "{nearest} <= {reprojected}");
    // Not a tautology: the views are recognisably the airway.
    assert!(blended > 16.0, "{blended}");
    // Issue 8: the calibrated light beats the paper's Psi by at least 3 dB and both baselines.
    assert!(
        calibrated >= nearest + 3.0,
        "{calibrated} vs paper {nearest}"
    );
    assert!(
        calibrated >= blended + 3.0,
        "{calibrated} vs paper k-nearest {blended}"
    );
    assert!(calibrated > reprojected && calibrated > flat);
    // Cross-validation ran for both models and its winner is the model's shading.
    let cv = &m["cross_validation"];
    let cv_psnr = |name: &str| {
        cv["models"]
            .as_array()
            .unwrap()
            .iter()
            .find(|x| x["model"] == name)
            .unwrap()["mean_psnr_db"]
            .as_f64()
            .unwrap()
    };
    let (cv_paper, cv_cal) = (cv_psnr("paper"), cv_psnr("calibrated"));
    println!("held-out frames: paper {cv_paper:.2} dB, calibrated {cv_cal:.2} dB");
    assert!(
        cv_cal > cv_paper && cv_paper > 15.0,
        "{cv_cal} vs {cv_paper}"
    );
    assert!(dir.join("model/albedo_paper.png").is_file());

    // Issue 8 on the phantom: the light model recovers the per-frame auto-gains (relative to
    // the reference frame) within 2% and the spot cone cos(theta)^k (truth/gains.json) within
    // 5% RMS over the field of view the fit saw.
    let read = |p: &str| -> serde_json::Value {
        serde_json::from_str(&std::fs::read_to_string(dir.join(p)).unwrap()).unwrap()
    };
    let shading = read("model/shading.json");
    let truth = read("case/truth/gains.json");
    let cal = &shading["calibrated"];
    let GainErrors {
        worst: worst_gain,
        rms: rms_gain,
        worst_scaled,
        rms_scaled,
    } = gain_errors(dir);
    let k = truth["cone_exponent"].as_f64().unwrap();
    let coeffs = cli::matrix(&cal["s"]);
    let edge = cal["cos_theta_edge"].as_f64().unwrap();
    let model: bronchosim::shading::CalibratedModel = serde_json::from_value(cal.clone()).unwrap();
    assert_eq!(model.s, coeffs);
    let theta_edge = edge.acos();
    let m = 50;
    let cone_rms = ((0..=m)
        .map(|i| {
            let th = theta_edge * i as f64 / m as f64;
            (model.s(th.cos()) / th.cos().powf(k) - 1.0).powi(2)
        })
        .sum::<f64>()
        / (m + 1) as f64)
        .sqrt();
    println!(
        "gains relative to the reference frame: worst {:.2}%, RMS {:.2}%; with the global scale fitted: \
         worst {:.2}%, RMS {:.2}%; cone: {:.2}% RMS over 0..{:.1} deg",
        100.0 * worst_gain,
        100.0 * rms_gain,
        100.0 * worst_scaled,
        100.0 * rms_scaled,
        100.0 * cone_rms,
        theta_edge.to_degrees()
    );
    // Issue 8 aims at 5%. Measured 0.17% (the light's shape refitted with the fused texture's
    // albedo, workflow::light_refine); 5.87% from the uniform-albedo fit with the
    // inter-reflection term, 2.18% without that term (by luck of this albedo: on the 80-frame
    // demo phantom seeds 2 and 3 measure 10-11% without it; BENCHMARKS.md "Inter-reflection").
    assert!(cone_rms < 0.02, "cone RMS {cone_rms}");
    // Issue 8 aims at 2% per gain; measured here (24 frames, reference = the middle frame):
    // worst 3.47%, RMS 1.85%; with the global scale fitted worst 3.19%, RMS 1.66% (session 4,
    // before the albedo predicted from colour: 7.6% / 2.65% and 6.9% / 2.5%; 7.5% / 3.2%
    // before the light's refit with the fused albedo, 7.4% / 3.1% without the inter-reflection
    // term; before the Huber loss and the second correction: 9.8% / 4.1% and 7.5% / 3.5%).
    // The albedo predicted from each pixel's colour (shading::chroma_albedo) keeps the vessels
    // and pale patches out of the gains; the corrections against the fused texture
    // (workflow::gain_refine) remove most of the rest frame to frame. The bounds pin today's
    // level so a regression shows.
    assert!(worst_gain < 0.05, "worst gain error {worst_gain}");
    assert!(rms_gain < 0.025, "gain RMS error {rms_gain}");
    assert!(
        rms_scaled < 0.025,
        "gain RMS error, global scale fitted: {rms_scaled}"
    );

    // An existing output folder is kept without --force; with it, replaced.
    let again = run(
        &[
            "render",
            "model",
            "--views",
            "case/truth/views.json",
            "--out",
            "views",
        ],
        dir,
    );
    assert!(!again.status.success());
    let err = String::from_utf8_lossy(&again.stderr);
    assert!(err.contains("views") && err.contains("--force"), "{err}");
    assert!(dir.join("views/views/000000.png").is_file());

    // A model folder that is not one fails naming the file.
    let bad = run(
        &[
            "render",
            "case",
            "--views",
            "case/truth/views.json",
            "--out",
            "x",
        ],
        dir,
    );
    assert!(!bad.status.success());
    let err = String::from_utf8_lossy(&bad.stderr);
    assert!(err.contains("model.json"), "{err}");
}

/// Issue 6 on the phantom: the fused albedo against the true albedo, for the model's texture
/// (de-lit with the calibrated light) and the paper's (de-lit with each frame's Psi).
#[test]
fn fused_albedo_matches_the_phantom_truth() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    phantom(dir, 24, "160x160");
    ok(&run(
        &[
            "build", "case", "--out", "model", "--quiet", "--poses", "fixed",
        ],
        dir,
    ));
    let model = bronchosim::model::Model::load(&dir.join("model")).unwrap();
    let truth = dir.join("case/truth");
    let cal = albedo_error(&model, &model.texture, &truth).unwrap();
    let n = cal.pixels;
    let cal = cal.relative_rms;
    let paper = model
        .paper_texture
        .as_ref()
        .expect("a calibrated model keeps the paper's texture");
    let pap = albedo_error(&model, paper, &truth).unwrap().relative_rms;
    println!(
        "fused albedo vs truth over {n} pixels of the truth views: calibrated {:.1}%, paper \
         {:.1}% relative RMS",
        100.0 * cal,
        100.0 * pap
    );
    assert!(n > 20_000, "{n} pixels compared");
    // Measured with the default fusion (average, squared weights): 10.8% (calibrated) and
    // 13.2% (paper); 12.4% and 13.9% before the mesh kept the CT's ring relief and the weights
    // were squared. At this size (24 frames of 160x160) the bound pins today's level; issue 6's
    // 10% is asserted on the demo-size phantom below. The calibrated light must keep beating
    // the paper's Psi.
    assert!(cal < 0.115, "calibrated {cal}");
    assert!(cal < pap, "{cal} vs {pap}");
}

/// Errors of the calibrated light's gains against the phantom's true auto-gains.
struct GainErrors {
    /// Largest |fitted / true - 1| relative to the model's reference frame.
    worst: f64,
    /// RMS of the same.
    rms: f64,
    /// Largest error with the one free global scale fitted (geometric mean of fitted / true =
    /// 1) instead of taken from the reference frame alone.
    worst_scaled: f64,
    /// RMS of the same.
    rms_scaled: f64,
}

/// [`GainErrors`] of the model in `dir/model` built from the phantom case `dir/case`.
fn gain_errors(dir: &Path) -> GainErrors {
    let read = |p: &str| -> serde_json::Value {
        serde_json::from_str(&std::fs::read_to_string(dir.join(p)).unwrap()).unwrap()
    };
    let cal = read("model/shading.json")["calibrated"].clone();
    let gains = cli::matrix(&cal["gains"]);
    let tg: Vec<f64> = read("case/truth/gains.json")["frames"]
        .as_array()
        .unwrap()
        .iter()
        .map(|f| f["gain"].as_f64().unwrap())
        .collect();
    assert_eq!(gains.len(), tg.len());
    // Relative to the model's reference frame (its gain is 1 by definition).
    let r = cal["reference_frame"].as_u64().unwrap() as usize;
    assert!((gains[r] - 1.0).abs() < 1e-12);
    let worst = |e: &[f64]| e.iter().fold(0.0f64, |m, e| m.max(e.abs()));
    let rms = |e: &[f64]| (e.iter().map(|e| e * e).sum::<f64>() / e.len() as f64).sqrt();
    let rel: Vec<f64> = gains
        .iter()
        .zip(&tg)
        .map(|(g, t)| g / (t / tg[r]) - 1.0)
        .collect();
    let log_err: Vec<f64> = gains.iter().zip(&tg).map(|(g, t)| (g / t).ln()).collect();
    let mean_log = log_err.iter().sum::<f64>() / log_err.len() as f64;
    let scaled: Vec<f64> = log_err.iter().map(|l| (l - mean_log).exp() - 1.0).collect();
    GainErrors {
        worst: worst(&rel),
        rms: rms(&rel),
        worst_scaled: worst(&scaled),
        rms_scaled: rms(&scaled),
    }
}

/// Issues 6 and 8 on the demo-size phantom (80 frames of 320x320, what `bronchosim demo`
/// builds): the default model's texture within 10% relative RMS of the true albedo, and the
/// per-frame gains against the true auto-gains.
#[test]
fn demo_phantom_albedo_is_within_ten_percent() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    phantom(dir, 80, "320x320");
    ok(&run(
        &[
            "build", "case", "--out", "model", "--quiet", "--poses", "fixed",
        ],
        dir,
    ));
    let model = bronchosim::model::Model::load(&dir.join("model")).unwrap();
    let e = albedo_error(&model, &model.texture, &dir.join("case/truth")).unwrap();
    println!(
        "demo-size phantom: fused albedo vs truth {:.2}% over {} pixels",
        100.0 * e.relative_rms,
        e.pixels
    );
    // Measured 9.95% (9.89% before the light's refit, 9.75% without the inter-reflection term;
    // release and test builds alike).
    assert!(e.pixels > 700_000, "{} pixels compared", e.pixels);
    assert!(e.relative_rms < 0.10, "{}", e.relative_rms);
    // Issue 8 aims at 2%; measured worst 3.81% (frame 0, the top of the trachea that no other
    // frame sees), RMS 1.65% relative to the reference (the middle frame), 3.36% / 1.58% with
    // the global scale fitted (session 4, before the albedo predicted from colour: 4.28% /
    // 1.85%; 6.5% / 2.14% before the light's refit with the fused albedo; 4.6% / 2.3% without
    // the inter-reflection term). With the true albedo a per-frame estimate would still miss
    // 2% on four frames (the floor, printed below; BENCHMARKS.md). The bounds pin today's
    // level: the RMS within 2%, not every frame.
    let g = gain_errors(dir);
    println!(
        "demo-size phantom: gains worst {:.2}%, RMS {:.2}% relative to the reference; {:.2}% / \
         {:.2}% scale-free",
        100.0 * g.worst,
        100.0 * g.rms,
        100.0 * g.worst_scaled,
        100.0 * g.rms_scaled
    );
    assert!(
        g.worst < 0.045 && g.rms < 0.0185,
        "{:.4} {:.4}",
        g.worst,
        g.rms
    );
    // The floor under those errors: each frame's residual with the true gains and the true
    // albedo (every 8th frame). The phantom's own light law on its true mesh explains every
    // frame (this checks the truth record: gains, light, albedo seed, conventions); on the
    // CT-derived mesh the phantom's own law leaves 0.76% RMS (1.9% worst), the fitted light
    // 0.58% (1.2%): it absorbs part of the CT geometry's bias.
    let case = bronchosim::io::case::Case::open(&dir.join("case")).unwrap();
    let truth = dir.join("case/truth");
    let true_mesh = bronchosim::io::mesh_export::read_ply(&truth.join("lumen.ply")).unwrap();
    let true_scene = bronchosim::raycast::Scene::new(&true_mesh).unwrap();
    let floor = |scene: &bronchosim::raycast::Scene, law: ShadingLaw| {
        let r = shading_residuals(&case, scene, &truth, law, 8).unwrap();
        spread(&r.frame_median)
    };
    let exact = floor(&true_scene, ShadingLaw::Phantom);
    let law_on_ct = floor(&model.scene, ShadingLaw::Phantom);
    let fitted = floor(
        &model.scene,
        ShadingLaw::Fitted(model.calibrated().unwrap()),
    );
    println!(
        "per-frame median residual (RMS, worst): phantom law on the true mesh {:.3}%, {:.3}%;          on the CT mesh {:.2}%, {:.2}%; fitted light on the CT mesh {:.2}%, {:.2}%",
        100.0 * exact.0,
        100.0 * exact.1,
        100.0 * law_on_ct.0,
        100.0 * law_on_ct.1,
        100.0 * fitted.0,
        100.0 * fitted.1
    );
    assert!(exact.1 < 0.002, "{exact:?}");
    assert!(
        law_on_ct.0 < 0.02 && fitted.0 < 0.02,
        "{law_on_ct:?} {fitted:?}"
    );
}
