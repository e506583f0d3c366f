//! The phantom case writer: determinism, cameras in air, exposure, truth-view consistency,
//! and that the written case is a valid case for `bronchosim inspect`.

use bronchosim::camera::Camera;
use bronchosim::io::camera_file::read_camera;
use bronchosim::io::mesh_export::read_ply;
use bronchosim::io::nifti::read_nifti;
use bronchosim::io::png::read_png;
use bronchosim::io::poses::{read_poses, FrameRef};
use bronchosim::phantom::{
    write_phantom_case, AirwayTree, CtPhantomOptions, PhantomOptions, TreeOptions,
};
use bronchosim::raycast::{cast_frame, Scene};
use std::path::{Path, PathBuf};

fn small(seed: u64) -> PhantomOptions {
    PhantomOptions {
        frames: 6,
        width: 96,
        height: 96,
        seed,
        ct: CtPhantomOptions::coarse(),
        truth_grid_mm: 0.6,
        novel_views: 4,
        ..Default::default()
    }
}

fn files(dir: &Path) -> Vec<PathBuf> {
    let mut out = Vec::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        for e in std::fs::read_dir(&d).unwrap() {
            let p = e.unwrap().path();
            if p.is_dir() {
                stack.push(p);
            } else {
                out.push(p.strip_prefix(dir).unwrap().to_path_buf());
            }
        }
    }
    out.sort();
    out
}

fn read_gray(path: &Path) -> (Vec<u16>, u32, u32) {
    let dec = png::Decoder::new(std::io::BufReader::new(std::fs::File::open(path).unwrap()));
    let mut r = dec.read_info().unwrap();
    let mut buf = vec![0; r.output_buffer_size().unwrap()];
    let info = r.next_frame(&mut buf).unwrap();
    let v = match info.bit_depth {
        png::BitDepth::Sixteen => buf[..info.buffer_size()]
            .chunks_exact(2)
            .map(|c| u16::from_be_bytes([c[0], c[1]]))
            .collect(),
        _ => buf[..info.buffer_size()]
            .iter()
            .map(|&b| b as u16)
            .collect(),
    };
    (v, info.width, info.height)
}

#[test]
fn phantom_case_is_deterministic_in_air_well_exposed_and_consistent() {
    let tmp = tempfile::tempdir().unwrap();
    let (a, a2, b) = (
        tmp.path().join("a"),
        tmp.path().join("a2"),
        tmp.path().join("b"),
    );
    let sa = write_phantom_case(&a, &small(3)).unwrap();
    write_phantom_case(&a2, &small(3)).unwrap();
    write_phantom_case(&b, &small(4)).unwrap();
    // Refuses to overwrite without force.
    assert!(write_phantom_case(&a, &small(3)).is_err());

    // Same seed: identical bytes in every file; the expected files are there.
    let fa = files(&a);
    assert_eq!(fa, files(&a2));
    for f in &fa {
        assert_eq!(
            std::fs::read(a.join(f)).unwrap(),
            std::fs::read(a2.join(f)).unwrap(),
            "{} differs between two runs with the same seed",
            f.display()
        );
    }
    for need in [
        "ct.nii.gz",
        "camera.json",
        "poses.json",
        "frames/000005.png",
        "truth/lumen.ply",
        "truth/albedo_vertices.ply",
        "truth/gains.json",
        "truth/views.json",
        "truth/camera.json",
        "truth/views/000003_mask.png",
        "truth/views/000003_depth.png",
        "truth/views/000003_linear.png",
    ] {
        assert!(fa.contains(&PathBuf::from(need)), "missing {need}");
    }
    // Another seed: every frame differs.
    for i in 0..6 {
        let f = format!("frames/{i:06}.png");
        assert_ne!(
            std::fs::read(a.join(&f)).unwrap(),
            std::fs::read(b.join(&f)).unwrap()
        );
    }

    // Camera centres lie in air: CT below -700 HU and at least 1 mm inside the true lumen.
    let ct = read_nifti(&a.join("ct.nii.gz")).unwrap();
    let tree = AirwayTree::new(&TreeOptions {
        seed: 3,
        ..Default::default()
    });
    let poses = read_poses(&a.join("poses.json"), &a).unwrap();
    assert_eq!(poses.len(), 6);
    for p in &poses {
        let c = p.pose.centre();
        let hu = ct.sample_world(c).expect("camera inside the CT grid");
        assert!(hu < -700.0, "camera at {c:?} sees {hu} HU");
        let d = tree.lumen_sdf(c);
        assert!(d < -1.0, "camera at {c:?} is {d} mm from the wall");
    }

    // Frames: neither black nor saturated on average.
    for (i, p) in poses.iter().enumerate() {
        let FrameRef::Image(path) = &p.frame else {
            panic!("image frames expected")
        };
        let f = read_png(path).unwrap();
        let n = (f.width * f.height) as f64;
        let mean: f64 = f
            .rgb
            .chunks_exact(3)
            .map(|c| (0.2126 * c[0] + 0.7152 * c[1] + 0.0722 * c[2]) as f64)
            .sum::<f64>()
            / n;
        let sat = f
            .rgb
            .chunks_exact(3)
            .filter(|c| c.iter().any(|&v| v >= 0.999))
            .count() as f64
            / n;
        assert!((0.05..=0.6).contains(&mean), "frame {i}: mean {mean}");
        assert!(sat < 0.05, "frame {i}: saturated fraction {sat}");
        assert!((mean - sa.frame_mean_linear[i]).abs() < 0.01);
    }

    // Truth views: the stored hit mask and depth agree with a fresh ray cast of lumen.ply.
    let mesh = read_ply(&a.join("truth/lumen.ply")).unwrap();
    assert_eq!(mesh.triangles.len(), sa.mesh_triangles);
    let scene = Scene::new(&mesh).unwrap();
    let cam: Camera = read_camera(&a.join("truth/camera.json")).unwrap();
    assert!(cam.is_pinhole());
    let truth = a.join("truth");
    let views = read_poses(&truth.join("views.json"), &truth).unwrap();
    assert_eq!(views.len(), 4);
    for (k, v) in views.iter().enumerate() {
        assert!(tree.lumen_sdf(v.pose.centre()) < -1.0);
        // Off the training path: at least 0.3 mm from every training centre.
        let nearest = poses
            .iter()
            .map(|p| (p.pose.centre() - v.pose.centre()).norm())
            .fold(f64::INFINITY, f64::min);
        assert!(
            nearest > 0.3,
            "view {k} is {nearest} mm from a training pose"
        );
        let gb = cast_frame(&scene, &cam, &v.pose.camera_to_world);
        let (mask, w, h) = read_gray(&truth.join(format!("views/{k:06}_mask.png")));
        let (depth, _, _) = read_gray(&truth.join(format!("views/{k:06}_depth.png")));
        assert_eq!((w, h), (96, 96));
        let mut hits = 0;
        for i in 0..mask.len() {
            assert_eq!(mask[i] == 255, gb.hit(i), "view {k} pixel {i}");
            if gb.hit(i) {
                hits += 1;
                let z = depth[i] as f64 / 100.0;
                assert!(
                    (z - gb.z[i] as f64).abs() <= 0.006,
                    "view {k} pixel {i}: {z} vs {}",
                    gb.z[i]
                );
            } else {
                assert_eq!(depth[i], 0);
            }
        }
        assert!(hits > mask.len() / 2, "view {k}: only {hits} hits");
        // The sRGB view is not empty where the surface is seen.
        let img = read_png(&truth.join(format!("views/{k:06}.png"))).unwrap();
        let lit = img.rgb.chunks_exact(3).filter(|c| c[0] > 0.01).count();
        assert!(lit > hits / 2, "view {k}: {lit} lit pixels of {hits} hits");
    }

    // The case is a valid case for the inspect command.
    let st = std::process::Command::new(env!("CARGO_BIN_EXE_bronchosim"))
        .args(["inspect", a.to_str().unwrap()])
        .output()
        .unwrap();
    assert!(
        st.status.success(),
        "inspect failed: {}",
        String::from_utf8_lossy(&st.stderr)
    );
}

/// A real ATM'22 tree (downsampled twice, ~4 s): the camera stays in air and descends.
#[test]
fn phantom_from_a_real_mask() {
    // shared/ sits beside the repository (CI clones main with shared/ next to it).
    let mask = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../shared/data/atm22-airways/ATM_305_airway_mask.nii.gz");
    assert!(
        mask.exists(),
        "{}: missing (the ATM'22 masks are needed for this test)",
        mask.display()
    );
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("case");
    let mut o = small(5);
    o.anatomy = Some(mask);
    o.mask.downsample = 2;
    write_phantom_case(&out, &o).unwrap();
    let ct = read_nifti(&out.join("ct.nii.gz")).unwrap();
    let poses = read_poses(&out.join("poses.json"), &out).unwrap();
    for p in &poses {
        let hu = ct.sample_world(p.pose.centre()).unwrap();
        assert!(hu < -700.0, "{hu}");
    }
    // The path descends: the last camera is at least 60 mm below the first.
    let dz = poses[0].pose.centre().z - poses[poses.len() - 1].pose.centre().z;
    assert!(dz > 60.0, "descent {dz} mm");
}

/// `--trachea-posterior-wall` shapes the built-in tree only, and only within a radius: both
/// misuses are refused before anything is written.
#[test]
fn a_posterior_wall_out_of_range_or_with_a_mask_anatomy_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("case");
    let run = |extra: &[&str]| {
        let o = std::process::Command::new(env!("CARGO_BIN_EXE_bronchosim"))
            .args(["phantom", "--out", out.to_str().unwrap()])
            .args(extra)
            .output()
            .unwrap();
        assert!(!o.status.success());
        String::from_utf8_lossy(&o.stderr).into_owned()
    };
    let e = run(&["--trachea-posterior-wall", "1.5"]);
    assert!(
        e.contains("--trachea-posterior-wall 1.5") && e.contains("0.2 to 1"),
        "{e}"
    );
    let e = run(&[
        "--trachea-posterior-wall",
        "0.7",
        "--anatomy",
        "mask.nii.gz",
    ]);
    assert!(
        e.contains("mask.nii.gz") && e.contains("own trachea"),
        "{e}"
    );
    assert!(!out.exists());
}
