//! `bronchosim flythrough`: a small phantom is built into a model and flown through; the
//! cameras stay in the lumen, move evenly from the first training camera to the last, every
//! frame looks down a lit tube, and path.json / flythrough.mp4 are what they claim to be.

use bronchosim::camera::pose::camera_centre;
use bronchosim::io::png::read_png;
use bronchosim::io::poses::read_poses;
use bronchosim::math::{Point3, Vector3};
use bronchosim::model::Model;
use bronchosim::render::{read_views, render_view, RenderOptions};

#[path = "common/cli.rs"]
mod cli;
use cli::{ok, phantom, run};

/// Directions on the unit sphere (Fibonacci lattice).
fn sphere(n: usize) -> Vec<[f32; 3]> {
    (0..n)
        .map(|i| {
            let z = 1.0 - 2.0 * (i as f64 + 0.5) / n as f64;
            let r = (1.0 - z * z).sqrt();
            let phi = i as f64 * 2.399_963_229_728_653;
            [(r * phi.cos()) as f32, (r * phi.sin()) as f32, z as f32]
        })
        .collect()
}

/// Mean linear intensity of the sRGB PNG frames (all channels).
fn mean(frame: &bronchosim::image::Frame) -> f64 {
    frame.rgb.iter().map(|&v| v as f64).sum::<f64>() / frame.rgb.len() as f64
}

#[test]
fn flythrough_stays_in_the_lumen_and_renders_a_lit_tube() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    phantom(dir, 8, "128x128");
    ok(&run(
        &[
            "build", "case", "--out", "model", "--quiet", "--poses", "fixed",
        ],
        dir,
    ));
    let o = run(
        &["flythrough", "model", "--out", "fly", "--frames", "12"],
        dir,
    );
    ok(&o);
    println!("{}", String::from_utf8_lossy(&o.stdout));
    let fly = dir.join("fly");
    let model = Model::load(&dir.join("model")).unwrap();

    // path.json round-trips as views (the schema `render --views` reads).
    let views = read_views(&fly.join("path.json"), &fly).unwrap();
    assert_eq!(views.len(), 12);
    for (i, v) in views.iter().enumerate() {
        assert_eq!(v.name, format!("frame_{i:04}.png"));
        assert!(v.path.is_file(), "{} missing", v.name);
    }
    let centres: Vec<Point3<f64>> = views
        .iter()
        .map(|v| camera_centre(&v.camera_to_world))
        .collect();

    // Every centre is inside the lumen mesh with >= 1 mm of air around it: of 400 rays in all
    // directions, most hit the wall (the mesh is open only at the airway's cut ends), all of
    // them hit the same side of it (the inner one), and the nearest hit is >= 1 mm away.
    let dirs = sphere(400);
    for (i, c) in centres.iter().enumerate() {
        let org = [c.x as f32, c.y as f32, c.z as f32];
        let (mut hits, mut facing, mut nearest) = (0usize, 0usize, f32::INFINITY);
        for d in &dirs {
            if let Some(h) = model.scene.closest_hit(org, *d, f32::INFINITY) {
                let n = model.mesh.face_normal(h.tri as usize);
                hits += 1;
                facing += usize::from(n.x * d[0] + n.y * d[1] + n.z * d[2] < 0.0);
                nearest = nearest.min(h.t);
            }
        }
        let inner = facing.max(hits - facing);
        println!(
            "camera {i}: clearance {nearest:.2} mm, {hits} of 400 rays hit, {inner} on one side"
        );
        assert!(
            hits >= 300,
            "camera {i} at {c:?}: only {hits} of 400 rays hit the wall"
        );
        assert_eq!(
            inner, hits,
            "camera {i} at {c:?}: rays hit both sides of the wall"
        );
        assert!(
            nearest >= 1.0,
            "camera {i}: only {nearest} mm from the wall"
        );
    }

    // Even spacing along the path, from the first training camera to the last.
    let steps: Vec<f64> = centres.windows(2).map(|w| (w[1] - w[0]).norm()).collect();
    let (lo, hi) = steps
        .iter()
        .fold((f64::INFINITY, 0.0f64), |(a, b), &s| (a.min(s), b.max(s)));
    println!("steps {lo:.2}..{hi:.2} mm");
    assert!(lo > 0.5 && hi / lo < 1.5, "steps {steps:?}");
    let train = read_poses(&dir.join("case/poses.json"), &dir.join("case")).unwrap();
    let t0 = train[0].pose.centre();
    let t1 = train[train.len() - 1].pose.centre();
    let d0 = (centres[0] - t0).norm();
    let d1 = (centres[11] - t1).norm();
    assert!(
        d0 < 3.0 && d1 < 3.0,
        "ends {d0} mm and {d1} mm from the training ends"
    );
    // The cameras look ahead along the path (forward within 60° of the next centre).
    for (i, v) in views.iter().enumerate().take(11) {
        let m = v.camera_to_world;
        let f = Vector3::new(m[(0, 2)], m[(1, 2)], m[(2, 2)]);
        let to_next = (centres[i + 1] - centres[i]).normalize();
        assert!(f.dot(&to_next) > 0.5, "camera {i} looks away from the path");
    }

    // Every frame sees the tube (>= 90 % of pixels hit the mesh), is lit, and the brightness
    // does not jump between consecutive frames.
    let cam = &model.manifest.camera;
    let mut means = Vec::new();
    for (i, v) in views.iter().enumerate() {
        let (_, hit) = render_view(
            &model.render_inputs(),
            cam,
            &v.camera_to_world,
            &RenderOptions::default(),
        )
        .unwrap();
        let frac = hit.iter().filter(|&&h| h).count() as f64 / hit.len() as f64;
        assert!(
            frac >= 0.9,
            "frame {i}: {:.1} % of pixels hit",
            100.0 * frac
        );
        let img = read_png(&v.path).unwrap();
        assert_eq!((img.width, img.height), (cam.width, cam.height));
        means.push(mean(&img));
    }
    println!("frame means {means:.4?}");
    for (i, m) in means.iter().enumerate() {
        assert!(*m > 0.02, "frame {i}: mean linear intensity {m}");
    }
    for (i, w) in means.windows(2).enumerate() {
        let r = w[1] / w[0];
        assert!(
            (0.7..1.4).contains(&r),
            "frames {i}->{}: brightness ratio {r}",
            i + 1
        );
    }

    // The video has one frame per PNG.
    let mp4 = fly.join("flythrough.mp4");
    assert!(
        mp4.is_file(),
        "no flythrough.mp4 (ffmpeg is installed here)"
    );
    let probe = std::process::Command::new("ffprobe")
        .args(["-v", "error", "-select_streams", "v:0", "-count_frames"])
        .args(["-show_entries", "stream=nb_read_frames,codec_name,pix_fmt"])
        .args(["-of", "default=noprint_wrappers=1"])
        .arg(&mp4)
        .output()
        .unwrap();
    let text = String::from_utf8_lossy(&probe.stdout);
    assert!(text.contains("nb_read_frames=12"), "ffprobe: {text}");
    assert!(text.contains("pix_fmt=yuv420p"), "ffprobe: {text}");

    // An existing result is not replaced without --force; with it, it is.
    let again = run(
        &["flythrough", "model", "--out", "fly", "--frames", "4"],
        dir,
    );
    assert!(!again.status.success());
    assert!(String::from_utf8_lossy(&again.stderr).contains("--force"));
    ok(&run(
        &[
            "flythrough",
            "model",
            "--out",
            "fly",
            "--frames",
            "4",
            "--force",
            "--quiet",
        ],
        dir,
    ));
    assert_eq!(read_views(&fly.join("path.json"), &fly).unwrap().len(), 4);
}

#[test]
fn flythrough_names_a_missing_model_folder() {
    let tmp = tempfile::tempdir().unwrap();
    let o = run(&["flythrough", "nope", "--out", "fly"], tmp.path());
    assert!(!o.status.success());
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        err.contains("nope") && err.contains("model folder"),
        "{err}"
    );
    assert!(!tmp.path().join("fly").exists());
}
