//! Issue 18's SSIM on a phantom model, split into its two factors: each truth view predicted
//! by the model (its calibrated light times its texture, as the registration renders it), by
//! the model's light times the phantom's true albedo, and by the phantom's true light (its
//! linear view divided by its true albedo) times the model's texture; and, to part the light
//! model from the geometry it is evaluated on, the model's light on the phantom's true surface
//! (truth/lumen.ply) times the true albedo. All are scored like `bronchosim evaluate` (one gain
//! per channel over all views, PSNR and SSIM of the sRGB images against the truth views) on
//! the pixels where both surfaces are hit.
//!
//! With the case's CT as a third argument it also shades the model's surface points with
//! normals from the CT's gradient after Gaussians of 0.5, 0.7 and 1.0 mm (what a normal map
//! baked from the CT would hold).
//!
//! `cargo run --release --example ssim_budget -- MODEL_DIR CASE_DIR/truth [CASE_DIR/ct.nii.gz]`

#[path = "common/truth_surface.rs"]
mod truth_surface;

use std::path::Path;

use bronchosim::camera::pose::camera_centre;
use bronchosim::image::Frame;
use bronchosim::io::camera_file::read_camera;
use bronchosim::io::nifti::read_nifti;
use bronchosim::math::Vector3;
use bronchosim::model::Model;
use bronchosim::registration::photometric::{PhotometricModel, RayGrid};
use bronchosim::registration::pose::rotation_of;
use bronchosim::render::evaluate::{evaluate_methods, MaskedImage};
use bronchosim::render::views_io::load_truth;
use bronchosim::volume::filter::{gaussian_blur_mm, gradient_world};
use bronchosim::volume::Volume;
use truth_surface::{both_views, read_view_image, TrueSurface};

/// One pixel of a view: the model's albedo, light and additive part, and the truth's linear
/// image and albedo.
#[derive(Clone, Copy)]
struct PixelParts {
    model_albedo: [f64; 3],
    light: [f64; 3],
    additive: [f64; 3],
    /// The view's light that does not depend on the surface (inter-reflection, ambient).
    offset: [f64; 3],
    true_image: [f64; 3],
    true_albedo: [f64; 3],
    /// The model's light (without its specular part) and its specular part on the true
    /// surface.
    true_surface_light: [f64; 3],
    true_surface_specular: [f64; 3],
    /// The model's light at the model's surface point with the true surface's normal there.
    true_normal_light: [f64; 3],
    true_normal_specular: [f64; 3],
    /// The model's light at the model's surface point with the CT gradient's normal there,
    /// one per smoothing of the CT.
    ct_normal_light: [[f64; 3]; 3],
    ct_normal_specular: [[f64; 3]; 3],
}

/// The model's light at a surface point seen from the camera (camera-frame point and normal):
/// the part the albedo scales and the specular part.
fn light_parts(pm: &PhotometricModel, p: &Vector3<f64>, n: &Vector3<f64>) -> ([f64; 3], [f64; 3]) {
    let spec = pm.light.radiance(p, n, [0.0; 3]);
    let white = pm.light.radiance(p, n, [1.0; 3]);
    (std::array::from_fn(|k| white[k] - spec[k]), spec)
}

fn main() -> bronchosim::Result<()> {
    let args: Vec<String> = std::env::args().collect();
    let (model_dir, truth_dir, ct_path) = match args.as_slice() {
        [_, m, t] => (m, t, None),
        [_, m, t, ct] => (m, t, Some(Path::new(ct))),
        _ => {
            eprintln!("usage: ssim_budget MODEL_DIR TRUTH_DIR [CT]");
            std::process::exit(2);
        }
    };
    const CT_SIGMAS_MM: [f64; 3] = [0.5, 0.7, 1.0];
    let cts: Vec<Volume<f32>> = match ct_path {
        Some(p) => {
            let ct = read_nifti(p)?;
            CT_SIGMAS_MM
                .iter()
                .map(|&s| {
                    let mut v = ct.clone();
                    gaussian_blur_mm(&mut v, s);
                    v
                })
                .collect()
        }
        None => Vec::new(),
    };
    let model = Model::load(Path::new(model_dir))?;
    let truth = Path::new(truth_dir);
    let camera = read_camera(&truth.join("camera.json"))?;
    let parts = model
        .registration_parts()
        .ok_or_else(|| bronchosim::Error::Other("the model has no calibrated light".into()))?;
    let pm = PhotometricModel::new(parts)?;
    let true_surface = TrueSurface::read(truth)?;
    let true_pm = true_surface.model(parts)?;
    let grid = RayGrid::new(&camera, 0, 1);
    let (views, references) = load_truth(truth)?;
    // Per view and pixel; `None` where the model's ray misses or the truth has no albedo.
    let mut all: Vec<Vec<Option<PixelParts>>> = Vec::new();
    for view in &views {
        let true_image = read_view_image(view, "linear", &camera)?;
        let true_albedo = read_view_image(view, "albedo", &camera)?;
        let pose = view.camera_to_world;
        let (r, c) = (rotation_of(&pose).transpose(), camera_centre(&pose).coords);
        let (mv, tv, on_true) = both_views(&pm, &true_pm, &grid, &pose);
        let mut pixels = vec![None; (camera.width * camera.height) as usize];
        for q in &mv.points {
            let i = q.ray as usize;
            let Some(t) = on_true[i].map(|k| &tv.points[k]) else {
                continue;
            };
            let ta: [f64; 3] = std::array::from_fn(|k| f64::from(true_albedo.rgb[3 * i + k]));
            if ta.iter().any(|&a| a <= 1e-3) {
                continue;
            }
            let (light, spec) = light_parts(&pm, &(r * (q.x - c)), &(r * q.n));
            let (true_surface_light, true_surface_specular) =
                light_parts(&true_pm, &(r * (t.x - c)), &(r * t.n));
            let (true_normal_light, true_normal_specular) =
                light_parts(&pm, &(r * (q.x - c)), &(r * t.n));
            let mut ct_normal_light = [[0.0; 3]; 3];
            let mut ct_normal_specular = [[0.0; 3]; 3];
            for (k, ct) in cts.iter().enumerate() {
                // Air is dark: the gradient points into the wall, the normal into the lumen.
                let n = gradient_world(ct, q.x.into())
                    .filter(|g| g.norm() > 0.0)
                    .map_or(q.n, |g| -g.normalize());
                (ct_normal_light[k], ct_normal_specular[k]) =
                    light_parts(&pm, &(r * (q.x - c)), &(r * n));
            }
            pixels[i] = Some(PixelParts {
                ct_normal_light,
                ct_normal_specular,
                true_normal_light,
                true_normal_specular,
                model_albedo: q.albedo.map(f64::from),
                light,
                additive: std::array::from_fn(|k| spec[k] + mv.offset[k]),
                offset: mv.offset,
                true_image: std::array::from_fn(|k| f64::from(true_image.rgb[3 * i + k])),
                true_albedo: ta,
                true_surface_light,
                true_surface_specular,
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
    let mut methods = vec![
        (
            "model light x model texture".to_string(),
            compose(&|p, k| p.model_albedo[k] * p.light[k] + p.additive[k]),
        ),
        (
            "model light x true albedo".to_string(),
            compose(&|p, k| kappa[k] * p.true_albedo[k] * p.light[k] + p.additive[k]),
        ),
        (
            "model light on the true surface x true albedo".to_string(),
            compose(&|p, k| {
                kappa[k] * p.true_albedo[k] * p.true_surface_light[k]
                    + p.true_surface_specular[k]
                    + p.offset[k]
            }),
        ),
        (
            "model light on the model's surface with the true normals x true albedo".to_string(),
            compose(&|p, k| {
                kappa[k] * p.true_albedo[k] * p.true_normal_light[k]
                    + p.true_normal_specular[k]
                    + p.offset[k]
            }),
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
    for (k, sigma) in CT_SIGMAS_MM.iter().enumerate().take(cts.len()) {
        methods.push((
            format!("model light with CT-gradient normals ({sigma} mm) x true albedo"),
            compose(&|p, c| {
                kappa[c] * p.true_albedo[c] * p.ct_normal_light[k][c]
                    + p.ct_normal_specular[k][c]
                    + p.offset[c]
            }),
        ));
    }
    let names: Vec<String> = views.iter().map(|v| v.name.clone()).collect();
    for s in evaluate_methods(&methods, &references, &names)? {
        println!(
            "{}: PSNR {:.2} dB, SSIM {:.4}",
            s.method, s.mean_psnr_db, s.mean_ssim
        );
    }
    Ok(())
}
