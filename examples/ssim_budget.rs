//! Issue 18's SSIM on a phantom model, split into its two factors: each truth view predicted
//! by the model (its calibrated light times its texture, as the registration renders it), by
//! the model's light times the phantom's true albedo, and by the phantom's true light (its
//! linear view divided by its true albedo) times the model's texture; all scored like
//! `bronchosim evaluate` (one gain per channel over all views, PSNR and SSIM of the sRGB
//! images against the truth views).
//!
//! `cargo run --release --example ssim_budget -- MODEL_DIR CASE_DIR/truth`

use std::path::Path;

use bronchosim::camera::pose::camera_centre;
use bronchosim::image::srgb::linear_to_srgb;
use bronchosim::image::Frame;
use bronchosim::io::camera_file::read_camera;
use bronchosim::io::png::read_png;
use bronchosim::math::Vector3;
use bronchosim::model::Model;
use bronchosim::registration::photometric::{PhotometricModel, RayGrid};
use bronchosim::registration::pose::rotation_of;
use bronchosim::render::evaluate::{evaluate_methods, MaskedImage};
use bronchosim::render::views_io::load_truth;

/// A linear PNG of the truth (`code / 65535`), which `read_png` decodes as sRGB.
fn read_linear(path: &Path) -> bronchosim::Result<Frame> {
    let mut f = read_png(path)?;
    for v in &mut f.rgb {
        *v = linear_to_srgb(*v);
    }
    Ok(f)
}

/// One pixel of a view: the model's albedo, light and additive part, and the truth's linear
/// image and albedo.
#[derive(Clone, Copy)]
struct PixelParts {
    model_albedo: [f64; 3],
    light: [f64; 3],
    additive: [f64; 3],
    true_image: [f64; 3],
    true_albedo: [f64; 3],
}

fn main() -> bronchosim::Result<()> {
    let args: Vec<String> = std::env::args().collect();
    let [_, model_dir, truth_dir] = args.as_slice() else {
        eprintln!("usage: ssim_budget MODEL_DIR TRUTH_DIR");
        std::process::exit(2);
    };
    let model = Model::load(Path::new(model_dir))?;
    let truth = Path::new(truth_dir);
    let camera = read_camera(&truth.join("camera.json"))?;
    let parts = model
        .registration_parts()
        .ok_or_else(|| bronchosim::Error::Other("the model has no calibrated light".into()))?;
    let pm = PhotometricModel::new(parts)?;
    let grid = RayGrid::new(&camera, 0, 1);
    let (views, references) = load_truth(truth)?;
    // Per view and pixel; `None` where the model's ray misses or the truth has no albedo.
    let mut all: Vec<Vec<Option<PixelParts>>> = Vec::new();
    for view in &views {
        let stem = view.path.with_extension("");
        let stem = stem.to_string_lossy();
        let true_image = read_linear(Path::new(&format!("{stem}_linear.png")))?;
        let true_albedo = read_linear(Path::new(&format!("{stem}_albedo.png")))?;
        let pose = view.camera_to_world;
        let (r, c) = (rotation_of(&pose).transpose(), camera_centre(&pose).coords);
        let mv = pm.view(&grid, &pose, 0.0);
        let mut pixels = vec![None; (camera.width * camera.height) as usize];
        for q in &mv.points {
            let i = q.ray as usize;
            let (p, n): (Vector3<f64>, Vector3<f64>) = (r * (q.x - c), r * q.n);
            let spec = pm.light.radiance(&p, &n, [0.0; 3]);
            let white = pm.light.radiance(&p, &n, [1.0; 3]);
            let ta: [f64; 3] = std::array::from_fn(|k| f64::from(true_albedo.rgb[3 * i + k]));
            if ta.iter().any(|&a| a <= 1e-3) {
                continue;
            }
            pixels[i] = Some(PixelParts {
                model_albedo: q.albedo.map(f64::from),
                light: std::array::from_fn(|k| white[k] - spec[k]),
                additive: std::array::from_fn(|k| spec[k] + mv.offset[k]),
                true_image: std::array::from_fn(|k| f64::from(true_image.rgb[3 * i + k])),
                true_albedo: ta,
            });
        }
        all.push(pixels);
    }
    // The model's albedo is relative: its scale against the true one, per channel.
    let kappa: [f64; 3] = std::array::from_fn(|k| {
        let mut r: Vec<f64> = all
            .iter()
            .flat_map(|v| v.iter().flatten())
            .map(|p| p.model_albedo[k] / p.true_albedo[k])
            .collect();
        let mid = r.len() / 2;
        *r.select_nth_unstable_by(mid, f64::total_cmp).1
    });
    let compose = |f: &dyn Fn(&PixelParts, usize) -> f64| -> Vec<MaskedImage> {
        all.iter()
            .map(|v| {
                let mut frame = Frame::new(camera.width, camera.height);
                let mask: Vec<bool> = v.iter().map(Option::is_some).collect();
                for (i, p) in v.iter().enumerate() {
                    if let Some(p) = p {
                        for k in 0..3 {
                            frame.rgb[3 * i + k] = f(p, k) as f32;
                        }
                    }
                }
                MaskedImage { frame, mask }
            })
            .collect()
    };
    let methods = vec![
        (
            "model light x model texture".to_string(),
            compose(&|p, k| p.model_albedo[k] * p.light[k] + p.additive[k]),
        ),
        (
            "model light x true albedo".to_string(),
            compose(&|p, k| kappa[k] * p.true_albedo[k] * p.light[k] + p.additive[k]),
        ),
        (
            "true light x model texture".to_string(),
            compose(&|p, k| p.true_image[k] * p.model_albedo[k] / (kappa[k] * p.true_albedo[k])),
        ),
        (
            "true light x true albedo (the truth's linear view)".to_string(),
            compose(&|p, k| p.true_image[k]),
        ),
    ];
    let names: Vec<String> = views.iter().map(|v| v.name.clone()).collect();
    for s in evaluate_methods(&methods, &references, &names)? {
        println!(
            "{}: PSNR {:.2} dB, SSIM {:.4}",
            s.method, s.mean_psnr_db, s.mean_ssim
        );
    }
    Ok(())
}
