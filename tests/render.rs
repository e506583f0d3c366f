//! Novel-view rendering and evaluation (issue 7, parts 1 and 5) on a bent tube with a known
//! albedo painted into a real texture atlas.

// Index loops over parallel per-pixel arrays read more clearly than zipped iterators here.
#![allow(clippy::needless_range_loop)]

use std::path::Path;

use bronchosim::camera::Camera;
use bronchosim::image::quality::{psnr_masked, ssim_masked};
use bronchosim::image::srgb::{linear_to_srgb, srgb_to_linear};
use bronchosim::image::Frame;
use bronchosim::math::{Affine, Point3, Vector3};
use bronchosim::mesh::TriMesh;
use bronchosim::raycast::{cast_frame, Scene};
use bronchosim::render::{
    evaluate_methods, flat_albedo_view, read_views, render_view, reproject_nearest_frame,
    triangle_uvs, MaskedImage, MipOptions, MipTexture, RenderInputs, RenderOptions, TrainingView,
};
use bronchosim::shading::paper::PsiLookup;
use bronchosim::shading::{CalibratedModel, ExclusionCounts, FittedShading, PsiModel, ShadingKind};
use bronchosim::texture::atlas::{build_atlas, rasterize_texels, AtlasOptions};

/// Bend radius of the tube's centreline (mm) and tube radius (mm).
const BEND: f32 = 40.0;
const RADIUS: f32 = 6.0;

/// A quarter torus: centreline (BEND cos t, 0, BEND sin t), t in [0, pi/2].
fn bent_tube(rings: usize, around: usize) -> TriMesh {
    let mut positions = Vec::new();
    for i in 0..=rings {
        let t = std::f32::consts::FRAC_PI_2 * i as f32 / rings as f32;
        let radial = Vector3::new(t.cos(), 0.0, t.sin());
        for j in 0..around {
            let a = std::f32::consts::TAU * j as f32 / around as f32;
            let p = radial * (BEND + RADIUS * a.cos()) + Vector3::new(0.0, RADIUS * a.sin(), 0.0);
            positions.push(Point3::from(p));
        }
    }
    let mut triangles = Vec::new();
    let id = |i: usize, j: usize| (i * around + j % around) as u32;
    for i in 0..rings {
        for j in 0..around {
            triangles.push([id(i, j), id(i + 1, j), id(i + 1, j + 1)]);
            triangles.push([id(i, j), id(i + 1, j + 1), id(i, j + 1)]);
        }
    }
    TriMesh {
        positions,
        triangles,
    }
}

/// Arc length (mm) along the centreline of the point's cross-section.
fn arc_mm(p: [f32; 3]) -> f32 {
    BEND * p[2].atan2(p[0])
}

/// A smooth mucosa-like albedo: a few mm wavelengths along and around the tube.
fn smooth_albedo(p: [f32; 3]) -> [f32; 3] {
    let s = arc_mm(p);
    let a = p[1].atan2((p[0] * p[0] + p[2] * p[2]).sqrt() - BEND);
    let v = 0.5 + 0.25 * (s / 2.5).sin() * (2.0 * a).cos();
    [v, 0.8 * v + 0.1, 0.4 * v + 0.05]
}

/// Stripes of period 0.6 mm along the tube (4 texels at 0.15 mm): aliases when distant.
fn stripes(p: [f32; 3]) -> [f32; 3] {
    let v = if (arc_mm(p) / 0.3).floor() as i64 % 2 == 0 {
        0.9
    } else {
        0.1
    };
    [v; 3]
}

struct Fixture {
    mesh: TriMesh,
    scene: Scene,
    tri_uv: Vec<[[f32; 2]; 3]>,
    texture: MipTexture,
    plain: MipTexture,
}

fn fixture(albedo: fn([f32; 3]) -> [f32; 3]) -> Fixture {
    let mesh = bent_tube(120, 48);
    let atlas = build_atlas(&mesh, &AtlasOptions::default()).unwrap();
    let texels = rasterize_texels(&atlas, &mesh).unwrap();
    let mut img = Frame::new(atlas.width, atlas.height);
    let mut cov = vec![false; (atlas.width * atlas.height) as usize];
    for (k, &t) in texels.texel.iter().enumerate() {
        let c = albedo(texels.point[k]);
        img.rgb[3 * t as usize..3 * t as usize + 3].copy_from_slice(&c);
        cov[t as usize] = true;
    }
    let texture =
        MipTexture::new(&img, Some(&cov), atlas.texel_mm, &MipOptions::default()).unwrap();
    let plain = MipTexture::new(
        &img,
        Some(&cov),
        atlas.texel_mm,
        &MipOptions { max_level: 0 },
    )
    .unwrap();
    Fixture {
        scene: Scene::new(&mesh).unwrap(),
        tri_uv: triangle_uvs(&atlas),
        mesh,
        texture,
        plain,
    }
}

/// A camera on the centreline at arc angle `t` (rad), looking along the tube, shifted by
/// `lateral` mm towards the outer wall.
fn pose_at(t: f32, lateral: f32) -> Affine {
    let (t, l) = (t as f64, lateral as f64);
    let z = Vector3::new(-t.sin(), 0.0, t.cos());
    let y = Vector3::new(0.0, 1.0, 0.0);
    let x = y.cross(&z);
    let c = Vector3::new(t.cos(), 0.0, t.sin()) * (BEND as f64 + l);
    let mut m = Affine::identity();
    for r in 0..3 {
        m[(r, 0)] = x[r];
        m[(r, 1)] = y[r];
        m[(r, 2)] = z[r];
        m[(r, 3)] = c[r];
    }
    m
}

fn psi_at(pose: &Affine, scale: f64) -> PsiModel {
    let mut c2w = [0.0; 16];
    for k in 0..16 {
        c2w[k] = pose[(k / 4, k % 4)];
    }
    PsiModel {
        camera_to_world: c2w,
        z_min: 2.0,
        z_max: 40.0,
        c: [
            [0.05 * scale, 0.3 * scale, 0.6 * scale, 0.9 * scale],
            [0.04 * scale, 0.25 * scale, 0.55 * scale, 0.8 * scale],
            [0.03 * scale, 0.2 * scale, 0.5 * scale, 0.7 * scale],
        ],
        d: [[0.6, 0.3, 0.1]; 3],
        rms_residual: [0.0; 3],
        samples_used: 0,
        excluded: ExclusionCounts::default(),
    }
}

fn camera(n: u32, f: f64) -> Camera {
    Camera {
        width: n,
        height: n,
        fx: f,
        fy: f,
        cx: (n as f64 - 1.0) / 2.0,
        cy: (n as f64 - 1.0) / 2.0,
        k1: 0.0,
        k2: 0.0,
        p1: 0.0,
        p2: 0.0,
        k3: 0.0,
    }
}

fn srgb(frame: &Frame) -> Vec<f32> {
    frame.rgb.iter().map(|&v| linear_to_srgb(v)).collect()
}

fn and(a: &[bool], b: &[bool]) -> Vec<bool> {
    a.iter().zip(b).map(|(x, y)| *x && *y).collect()
}

#[test]
fn render_matches_brute_force_shading_times_albedo() {
    let fx = fixture(smooth_albedo);
    let pose = pose_at(0.2, 1.0);
    let psi = vec![
        psi_at(&pose_at(0.1, 0.0), 1.0),
        psi_at(&pose_at(0.6, 0.0), 0.5),
    ];
    let shading = FittedShading::new(ShadingKind::Paper, psi.clone(), None);
    let inputs = RenderInputs {
        scene: &fx.scene,
        tri_uv: &fx.tri_uv,
        texture: &fx.texture,
        shading: &shading,
        kind: ShadingKind::Paper,
    };
    // A distorted camera: rendering takes any camera.json.
    let cam = Camera {
        k1: -0.2,
        k2: 0.05,
        ..camera(128, 80.0)
    };
    let opts = RenderOptions {
        psi_lookup: PsiLookup::Nearest,
        ..Default::default()
    };
    let (img, mask) = render_view(&inputs, &cam, &pose, &opts).unwrap();
    // Brute force: the albedo function at the hit point times the nearest Psi (index 0).
    let g = cast_frame(&fx.scene, &cam, &pose);
    let mut truth = Frame::new(cam.width, cam.height);
    let tmask: Vec<bool> = (0..g.tri.len()).map(|i| g.hit(i)).collect();
    for i in 0..g.tri.len() {
        if g.hit(i) {
            let a = smooth_albedo(g.point[i]);
            let s = psi[0].eval_rgb(g.gamma[i] as f64, g.z[i] as f64);
            for k in 0..3 {
                truth.rgb[3 * i + k] = a[k] * s[k] as f32;
            }
        }
    }
    assert_eq!(mask, tmask);
    let hits = mask.iter().filter(|&&m| m).count();
    assert!(hits > 10_000, "{hits}");
    let psnr = psnr_masked(&srgb(&img), &srgb(&truth), &mask).unwrap();
    println!("render vs brute force: {psnr:.2} dB over {hits} pixels");
    assert!(psnr > 50.0, "PSNR {psnr}");
}

/// RMS difference of the sRGB values over the pixels both cover.
fn rms(a: &(Frame, Vec<bool>), b: &(Frame, Vec<bool>)) -> f64 {
    let m = and(&a.1, &b.1);
    let p = psnr_masked(&srgb(&a.0), &srgb(&b.0), &m).unwrap();
    10f64.powf(-p / 20.0)
}

#[test]
fn mip_mapping_reduces_aliasing_on_distant_grazing_walls() {
    let fx = fixture(stripes);
    // Flat shading: only the texture varies.
    let mut psi = psi_at(&pose_at(0.0, 0.0), 1.0);
    psi.c = [[0.5; 4]; 3];
    psi.d = [[1.0; 3]; 3];
    let psi = vec![psi];
    let shading = FittedShading::new(ShadingKind::Paper, psi.clone(), None);
    let inputs = |tex| RenderInputs {
        scene: &fx.scene,
        tri_uv: &fx.tri_uv,
        texture: tex,
        shading: &shading,
        kind: ShadingKind::Paper,
    };
    let cam = camera(96, 60.0);
    let pose = pose_at(0.02, -2.0);
    let o = |mipmap: bool, supersample: u32| RenderOptions {
        psi_lookup: PsiLookup::Nearest,
        mipmap,
        supersample,
        gain: 1.0,
        albedo_only: false,
        auto_exposure: false,
    };
    let reference = render_view(&inputs(&fx.plain), &cam, &pose, &o(false, 8)).unwrap();
    let no_mip = render_view(&inputs(&fx.plain), &cam, &pose, &o(false, 1)).unwrap();
    let mip = render_view(&inputs(&fx.texture), &cam, &pose, &o(true, 1)).unwrap();
    let mip_ss = render_view(&inputs(&fx.texture), &cam, &pose, &o(true, 2)).unwrap();
    let (e_no, e_mip, e_ss) = (
        rms(&no_mip, &reference),
        rms(&mip, &reference),
        rms(&mip_ss, &reference),
    );
    println!("RMS vs 8x8 supersampled: no mips {e_no:.4}, mips {e_mip:.4}, mips + 2x2 {e_ss:.4}");
    assert!(e_mip < 0.7 * e_no, "mips {e_mip} vs none {e_no}");
    assert!(e_ss < e_mip, "2x2 {e_ss} vs 1x1 {e_mip}");
}

#[test]
fn blending_makes_shading_continuous_while_flying() {
    let fx = fixture(smooth_albedo);
    // Fitted viewpoints every 0.1 rad (4 mm) with alternating brightness.
    let psi: Vec<PsiModel> = (0..12)
        .map(|i| {
            psi_at(
                &pose_at(0.1 * i as f32, 0.0),
                if i % 2 == 0 { 1.0 } else { 0.6 },
            )
        })
        .collect();
    let shading = FittedShading::new(ShadingKind::Paper, psi.clone(), None);
    let inputs = RenderInputs {
        scene: &fx.scene,
        tri_uv: &fx.tri_uv,
        texture: &fx.texture,
        shading: &shading,
        kind: ShadingKind::Paper,
    };
    let cam = camera(48, 30.0);
    let mean_brightness = |psi_lookup| -> Vec<f64> {
        (0..60)
            .map(|s| {
                let pose = pose_at(0.25 + 0.005 * s as f32, 0.5);
                let opts = RenderOptions {
                    psi_lookup,
                    ..Default::default()
                };
                let (img, mask) = render_view(&inputs, &cam, &pose, &opts).unwrap();
                let n = mask.iter().filter(|&&m| m).count();
                img.rgb.iter().map(|&v| v as f64).sum::<f64>() / (3 * n) as f64
            })
            .collect()
    };
    let max_step = |v: &[f64]| {
        v.windows(2)
            .map(|w| (w[1] - w[0]).abs() / w[0])
            .fold(0.0, f64::max)
    };
    let near = max_step(&mean_brightness(PsiLookup::Nearest));
    let blend = max_step(&mean_brightness(PsiLookup::KNearest { k: 4 }));
    println!("largest relative frame-to-frame change: nearest {near:.4}, 4-nearest {blend:.4}");
    assert!(
        near > 0.2,
        "nearest should jump where the viewpoint switches: {near}"
    );
    assert!(blend < 0.05, "blended shading jumps by {blend}");
}

#[derive(serde::Deserialize)]
struct SsimRef {
    width: usize,
    height: usize,
    a_srgb_codes: Vec<u8>,
    b_srgb_codes: Vec<u8>,
    ssim: f64,
    psnr_db: f64,
}

#[test]
fn ssim_and_psnr_agree_with_skimage() {
    let text = std::fs::read_to_string(
        Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/ssim_reference.json"),
    )
    .unwrap();
    let r: SsimRef = serde_json::from_str(&text).unwrap();
    let a: Vec<f32> = r.a_srgb_codes.iter().map(|&c| c as f32 / 255.0).collect();
    let b: Vec<f32> = r.b_srgb_codes.iter().map(|&c| c as f32 / 255.0).collect();
    let mask = vec![true; r.width * r.height];
    let ssim = ssim_masked(&a, &b, r.width, r.height, &mask).unwrap();
    let psnr = psnr_masked(&a, &b, &mask).unwrap();
    println!(
        "SSIM {ssim} (skimage {}), PSNR {psnr} (skimage {})",
        r.ssim, r.psnr_db
    );
    assert!((ssim - r.ssim).abs() < 1e-4);
    assert!((psnr - r.psnr_db).abs() < 1e-4);
}

#[test]
fn gain_fit_recovers_a_known_scale_exactly() {
    let (w, h) = (40u32, 30u32);
    let scale = [0.5f64, 0.8, 0.3];
    let mut views = Vec::new();
    let mut truth = Vec::new();
    for v in 0..3 {
        let mut f = Frame::new(w, h);
        let mut mask = vec![false; (w * h) as usize];
        for i in 0..(w * h) as usize {
            for k in 0..3 {
                f.rgb[3 * i + k] = srgb_to_linear(((i * 7 + k * 31 + v * 13) % 200) as f32 / 255.0);
            }
            mask[i] = (i % 11) != 0;
        }
        let t = Frame {
            width: w,
            height: h,
            rgb: f
                .rgb
                .iter()
                .enumerate()
                .map(|(i, &x)| (x as f64 * scale[i % 3]) as f32)
                .collect(),
        };
        truth.push(MaskedImage {
            frame: t,
            mask: vec![true; (w * h) as usize],
        });
        views.push(MaskedImage { frame: f, mask });
    }
    let names: Vec<String> = (0..3).map(|v| format!("v{v}.png")).collect();
    let s = evaluate_methods(&[("m".into(), views)], &truth, &names).unwrap();
    for k in 0..3 {
        assert!(
            (s[0].gain[k] - scale[k]).abs() < 1e-6 * scale[k],
            "{:?}",
            s[0].gain
        );
    }
    assert!(s[0].mean_psnr_db > 90.0, "{}", s[0].mean_psnr_db);
    assert!((s[0].mean_ssim - 1.0).abs() < 1e-9);
    // Scored pixels: the rendered mask (truth covers all).
    assert_eq!(
        s[0].views[0].pixels,
        (0..1200).filter(|i| i % 11 != 0).count()
    );
}

#[test]
fn baselines_reproduce_a_training_view_and_follow_inverse_square() {
    let fx = fixture(smooth_albedo);
    let cam = camera(40, 25.0);
    let poses = [pose_at(0.1, 0.0), pose_at(0.5, 0.0)];
    let frames: Vec<Frame> = (0..2)
        .map(|k| {
            let mut f = Frame::new(40, 40);
            for (i, v) in f.rgb.iter_mut().enumerate() {
                *v = ((i * (k + 3)) % 97) as f32 / 97.0;
            }
            f
        })
        .collect();
    let training: Vec<TrainingView> = frames
        .iter()
        .zip(&poses)
        .map(|(frame, p)| TrainingView {
            frame,
            camera_to_world: p,
            image_mask: None,
        })
        .collect();
    // Seen from the second training pose itself, (a) is that frame on every hit pixel.
    let (img, mask) = reproject_nearest_frame(&fx.scene, &cam, &poses[1], &cam, &training).unwrap();
    let g = cast_frame(&fx.scene, &cam, &poses[1]);
    let mut n = 0;
    for i in 0..mask.len() {
        assert_eq!(mask[i], g.hit(i));
        if mask[i] {
            for k in 0..3 {
                assert!((img.rgb[3 * i + k] - frames[1].rgb[3 * i + k]).abs() < 1e-3);
            }
            n += 1;
        }
    }
    assert!(n > 1000);
    // (b) is gamma / z^2 of the ray cast.
    let (flat, fmask) = flat_albedo_view(&fx.scene, &cam, &poses[0]);
    let g = cast_frame(&fx.scene, &cam, &poses[0]);
    for i in 0..fmask.len() {
        if fmask[i] {
            let e = g.gamma[i] / (g.z[i] * g.z[i]);
            assert!((flat.rgb[3 * i] - e).abs() <= 1e-6 * e);
        }
    }
    let _ = &fx.mesh;
}

#[test]
fn views_json_outside_the_output_folder_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("out");
    std::fs::create_dir_all(&out).unwrap();
    let views = dir.path().join("views.json");
    let m = "[1,0,0,0, 0,1,0,0, 0,0,1,0, 0,0,0,1]";
    for bad in ["/abs.png", "../x.png", "a/../../x.png"] {
        std::fs::write(
            &views,
            format!("{{\"frames\": [{{\"image\": \"{bad}\", \"camera_to_world\": {m}}}]}}"),
        )
        .unwrap();
        let e = read_views(&views, &out).unwrap_err().to_string();
        assert!(e.contains("views.json") && e.contains(bad), "{e}");
    }
    std::fs::write(
        &views,
        format!("{{\"frames\": [{{\"image\": \"sub/./v0.png\", \"camera_to_world\": {m}}}]}}"),
    )
    .unwrap();
    let v = read_views(&views, &out).unwrap();
    assert_eq!(v[0].name, "sub/v0.png");
    assert_eq!(v[0].path, out.join("sub/v0.png"));
}

#[test]
fn calibrated_new_views_reflect_their_own_light() {
    let fx = fixture(smooth_albedo);
    let psi = vec![psi_at(&pose_at(0.1, 0.0), 1.0)];
    // A light with a cone and 6% / 5% / 4% inter-reflection per unit of the view's light.
    let kappa = [0.06, 0.05, 0.04];
    let light = CalibratedModel {
        gains: vec![1.0],
        ambient: Some(vec![[0.0; 3]]),
        interreflection: Some(kappa),
        frame_light: Some(vec![0.0]),
        ..CalibratedModel::new(
            [
                vec![0.0, 40.0, 80.0, 120.0],
                vec![0.0, 20.0, 40.0, 60.0],
                vec![0.0, 15.0, 30.0, 45.0],
            ],
            vec![1.0, 0.7],
            0.5,
        )
    };
    let shading = FittedShading::new(ShadingKind::Calibrated, psi, Some(light.clone()));
    let inputs = RenderInputs {
        scene: &fx.scene,
        tri_uv: &fx.tri_uv,
        texture: &fx.plain,
        shading: &shading,
        kind: ShadingKind::Calibrated,
    };
    let cam = camera(96, 60.0);
    let opts = RenderOptions {
        mipmap: false,
        ..Default::default()
    };
    let mut reflected = Vec::new();
    for pose in [pose_at(0.3, 0.0), pose_at(0.3, 4.5)] {
        let (img, mask) = render_view(&inputs, &cam, &pose, &opts).unwrap();
        // Brute force: direct light at every hit, then the view's mean luminance with the
        // inter-reflection found by fixed-point iteration (independent of the closed form).
        let g = cast_frame(&fx.scene, &cam, &pose);
        let hits: Vec<usize> = (0..g.tri.len()).filter(|&i| g.hit(i)).collect();
        let cos_t: Vec<f64> = (0..g.tri.len())
            .map(|i| {
                let (x, y) = ((i % 96) as f64, (i / 96) as f64);
                cam.pixel_ray(x, y).z
            })
            .collect();
        let direct: Vec<[f64; 3]> = hits
            .iter()
            .map(|&i| {
                let a = smooth_albedo(g.point[i]);
                let s = light.eval_rgb(g.gamma[i] as f64, cos_t[i], g.z[i] as f64, 1.0);
                std::array::from_fn(|c| a[c] as f64 * s[c])
            })
            .collect();
        let luma = [0.2126, 0.7152, 0.0722];
        let mean_lum = |add: [f64; 3]| {
            direct
                .iter()
                .map(|d| (0..3).map(|c| luma[c] * (d[c] + add[c])).sum::<f64>())
                .sum::<f64>()
                / direct.len() as f64
        };
        let mut l = 0.0;
        for _ in 0..50 {
            l = mean_lum(kappa.map(|k| k * l));
        }
        let mut truth = Frame::new(cam.width, cam.height);
        for (&i, d) in hits.iter().zip(&direct) {
            for c in 0..3 {
                truth.rgb[3 * i + c] = (d[c] + kappa[c] * l) as f32;
            }
        }
        let tmask: Vec<bool> = (0..g.tri.len()).map(|i| g.hit(i)).collect();
        assert_eq!(mask, tmask);
        let psnr = psnr_masked(&srgb(&img), &srgb(&truth), &mask).unwrap();
        println!("calibrated view with its own inter-reflection (L = {l:.4}): {psnr:.2} dB vs brute force");
        assert!(psnr > 50.0, "PSNR {psnr}");
        reflected.push(kappa[1] * l);
    }
    // Nearer the wall the view holds more light, and so more inter-reflected light.
    println!(
        "inter-reflection (G): centreline {:.4}, near the wall {:.4}",
        reflected[0], reflected[1]
    );
    assert!(reflected[1] > 1.3 * reflected[0], "{reflected:?}");
}

/// Where the reference is saturated it cannot show the surface: the unsaturated score leaves
/// those pixels out and equals the PSNR over the others alone (computed here directly), while
/// the score over every pixel pays for them.
#[test]
fn evaluate_scores_the_unsaturated_reference_pixels_apart() {
    let (w, h) = (40u32, 30u32);
    let n = (w * h) as usize;
    let mut render = Frame::new(w, h);
    let mut truth = Frame::new(w, h);
    let mut saturated = vec![false; n];
    for i in 0..n {
        let base = 0.1 + 0.5 * ((i * 13 % 97) as f32 / 97.0);
        for k in 0..3 {
            render.rgb[3 * i + k] = base;
            // A small error everywhere, and a band the reference's exposure clips.
            truth.rgb[3 * i + k] = base * (1.0 + 0.02 * (((i + k) % 5) as f32 - 2.0));
        }
        if (i as u32 % w) < 10 {
            truth.rgb[3 * i..3 * i + 3].copy_from_slice(&[1.0; 3]);
            saturated[i] = true;
        }
    }
    let all = vec![true; n];
    let s = evaluate_methods(
        &[(
            "m".into(),
            vec![MaskedImage {
                frame: render.clone(),
                mask: all.clone(),
            }],
        )],
        &[MaskedImage {
            frame: truth.clone(),
            mask: all.clone(),
        }],
        &["v.png".to_string()],
    )
    .unwrap();
    let v = &s[0].views[0];
    assert_eq!(v.pixels, n);
    assert_eq!(v.unsaturated_pixels, n - 10 * h as usize);
    // The same PSNR from the unsaturated pixels alone, at the gain the evaluation fitted.
    let keep: Vec<usize> = (0..n).filter(|&i| !saturated[i]).collect();
    let se: f64 = keep
        .iter()
        .flat_map(|&i| (0..3).map(move |k| 3 * i + k))
        .map(|j| {
            let r = linear_to_srgb((render.rgb[j] as f64 * s[0].gain[j % 3]) as f32) as f64;
            let t = linear_to_srgb(truth.rgb[j]) as f64;
            (r - t) * (r - t)
        })
        .sum();
    let expected = 10.0 * (1.0 / (se / (3 * keep.len()) as f64)).log10();
    let got = v.unsaturated_psnr_db.unwrap();
    assert!((got - expected).abs() < 1e-6, "{got} vs {expected}");
    assert!(got > v.psnr_db.unwrap() + 3.0, "{got} vs {:?}", v.psnr_db);
    assert!((s[0].mean_unsaturated_psnr_db - got).abs() < 1e-12);
}
