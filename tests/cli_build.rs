//! The whole pipeline from the command line: `phantom` writes a small case, `build` turns it
//! into a model folder; the folder holds what DESIGN.md promises and its numbers are sane.

#[path = "common/cli.rs"]
mod cli;
use cli::{matrix, ok, phantom, run};

#[test]
fn phantom_then_build_writes_the_model_folder() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    phantom(dir, 8, "128x128");
    ok(&run(
        &[
            "build", "case", "--out", "model", "--quiet", "--poses", "fixed",
        ],
        dir,
    ));
    let model = dir.join("model");
    for f in [
        "model.json",
        "airway.glb",
        "albedo.png",
        "coverage.png",
        "shading.json",
        "segmentation.nii.gz",
        "report.html",
    ] {
        assert!(model.join(f).is_file(), "{f} missing");
    }
    let m: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(model.join("model.json")).unwrap()).unwrap();
    assert_eq!(m["format_version"], 2);
    assert_eq!(m["counts"]["frames"], 8);
    // The phantom's tree as `segment` counts it (tests/cli_segment.rs): the cohort table's column.
    assert!(m["counts"]["branches"].as_u64().unwrap() >= 7);
    let covered = m["counts"]["covered_texels"].as_u64().unwrap();
    let chart = m["counts"]["chart_texels"].as_u64().unwrap();
    assert!(covered > 1000 && covered <= chart, "{covered} of {chart}");
    // Walls the 8 frames never saw are synthesised by default; the shares add up to the surface.
    let u = &m["unseen_walls"];
    assert_eq!(u["mode"], "synthesise");
    let share = |k: &str| u[k].as_f64().unwrap();
    assert!((share("observed_share") - covered as f64 / chart as f64).abs() < 1e-9);
    assert!(
        share("synthesised_share") > 0.05 && share("filled_share") < 0.01,
        "{u}"
    );
    assert!(
        (share("observed_share") + share("synthesised_share") + share("filled_share") - 1.0).abs()
            < 1e-9
    );
    // Psi explains most of the shading of physically based frames that are not Psi: per-frame
    // R² 0.7–0.85 in red, lower in green and blue whose dark vessels are texture, not shading.
    let r2 = m["mean_r2"].as_f64().unwrap();
    assert!(r2 > 0.45, "mean R² {r2}");
    for f in m["fit_quality"].as_array().unwrap() {
        let c: Vec<f64> = f["r2"]
            .as_array()
            .unwrap()
            .iter()
            .map(|v| v.as_f64().unwrap())
            .collect();
        println!(
            "frame {}: R² of Psi R {:.3} G {:.3} B {:.3}, {} samples",
            f["frame"], c[0], c[1], c[2], f["samples"]
        );
        assert!(
            c[0] > 0.6 && c[1] > 0.3 && c[2] > 0.3,
            "frame {}: R² {c:?}",
            f["frame"]
        );
    }
    assert!(m["atlas_mean_l2_stretch"].as_f64().unwrap() < 1.1);
    let total = m["timings"]["total"].as_f64().unwrap();
    assert!(total > 0.0);
    // How the calibrated light was fitted: the build's defaults.
    let lf = &m["light_fit"];
    assert_eq!(lf["interreflection"], true);
    assert_eq!(lf["ambient_per_frame"], false);
    assert_eq!(lf["robust"], "huber 1.345");
    assert_eq!(
        (lf["rho_degree"].as_u64(), lf["s_degree"].as_u64()),
        (Some(3), Some(3))
    );
    assert_eq!(
        (
            lf["chroma_refits"].as_u64(),
            lf["gain_corrections"].as_u64(),
            lf["light_refits"].as_u64()
        ),
        (Some(2), Some(2), Some(2))
    );
    assert_eq!(lf["reference_frame"], 4);

    // shading.json: one Psi per frame, at that frame's pose.
    let s: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(model.join("shading.json")).unwrap())
            .unwrap();
    // The shading model the cross-validation chose is the one recorded in both files.
    assert_eq!(s["model"], m["shading_model"]);
    assert!(s["model"] == "paper" || s["model"] == "calibrated");
    let vps = s["viewpoints"].as_array().unwrap();
    assert_eq!(vps.len(), 8);
    let poses: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("case/poses.json")).unwrap())
            .unwrap();
    for (vp, pose) in vps.iter().zip(poses["frames"].as_array().unwrap()) {
        let (a, b) = (
            matrix(&vp["camera_to_world"]),
            matrix(&pose["camera_to_world"]),
        );
        assert!(a.iter().zip(&b).all(|(x, y)| (x - y).abs() < 1e-9));
        assert!(vp["z_min"].as_f64().unwrap() < vp["z_max"].as_f64().unwrap());
    }

    // airway.glb: a binary glTF with the albedo embedded.
    let glb = std::fs::read(model.join("airway.glb")).unwrap();
    assert_eq!(&glb[0..4], b"glTF");
    assert_eq!(u32::from_le_bytes(glb[4..8].try_into().unwrap()), 2);
    let json_len = u32::from_le_bytes(glb[12..16].try_into().unwrap()) as usize;
    let json: serde_json::Value = serde_json::from_slice(&glb[20..20 + json_len]).unwrap();
    assert_eq!(json["images"][0]["mimeType"], "image/png");
    assert!(json["meshes"][0]["primitives"][0]["attributes"]["TEXCOORD_0"].is_number());

    // The report embeds the figures (Fig. 2 a/b and Fig. 3 for three frames, and the atlas).
    let html = std::fs::read_to_string(model.join("report.html")).unwrap();
    assert!(
        html.matches("<img").count() > 3 * 5,
        "report has too few figures"
    );
    assert!(html.contains("data:image/png;base64,"));

    // An existing model is not replaced without --force.
    let again = run(
        &[
            "build", "case", "--out", "model", "--quiet", "--poses", "fixed",
        ],
        dir,
    );
    assert!(!again.status.success());
    assert!(String::from_utf8_lossy(&again.stderr).contains("--force"));
}
