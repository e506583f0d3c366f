//! Novel-view rendering: one 320x320 view (90 degree field of view) from inside the trachea of
//! the ~300k-triangle benchmark airway, with a 4096² mip-mapped texture and 200 fitted
//! viewpoints, for the paper's nearest-viewpoint shading and 4-nearest blending (and 2x2
//! supersampling), and for the calibrated light. Threads follow RAYON_NUM_THREADS; throughput is in views per second.

#[path = "../tests/common/meshes.rs"]
mod meshes;

use bronchosim::camera::Camera;
use bronchosim::image::Frame;
use bronchosim::math::Affine;
use bronchosim::raycast::Scene;
use bronchosim::render::{
    render_view_with, MipOptions, MipTexture, RenderInputs, RenderOptions, ViewRays,
};
use bronchosim::shading::paper::PsiLookup;
use bronchosim::shading::{CalibratedModel, ExclusionCounts, PsiModel};
use bronchosim::shading::{FittedShading, ShadingKind};
use criterion::{criterion_group, criterion_main, Criterion, Throughput};

fn bench(c: &mut Criterion) {
    let (mesh, _, _) = meshes::bench_scene();
    let scene = Scene::new(&mesh).unwrap();
    // UVs from a planar projection (the atlas content does not change the work per pixel).
    let side = 4096u32;
    let span = side as f32 * 0.15;
    let tri_uv: Vec<[[f32; 2]; 3]> = mesh
        .triangles
        .iter()
        .map(|t| {
            t.map(|v| {
                let p = mesh.positions[v as usize];
                [(p.x / span).rem_euclid(1.0), (p.z / span).rem_euclid(1.0)]
            })
        })
        .collect();
    let mut img = Frame::new(side, side);
    for (i, v) in img.rgb.iter_mut().enumerate() {
        *v = ((i * 2654435761) % 1000) as f32 / 1000.0;
    }
    let texture = MipTexture::new(&img, None, 0.15, &MipOptions::default()).unwrap();
    let psi: Vec<PsiModel> = (0..200)
        .map(|i| {
            let mut m = [0.0; 16];
            for k in 0..4 {
                m[5 * k] = 1.0;
            }
            m[3] = 0.5;
            m[7] = -0.8;
            m[11] = 10.0 + 0.2 * i as f64;
            PsiModel {
                camera_to_world: m,
                z_min: 2.0,
                z_max: 50.0,
                c: [[0.05, 0.3, 0.6, 0.9]; 3],
                d: [[0.6, 0.3, 0.1]; 3],
                rms_residual: [0.0; 3],
                samples_used: 0,
                excluded: ExclusionCounts::default(),
            }
        })
        .collect();
    let shading = FittedShading::new(ShadingKind::Paper, psi.clone(), None);
    let inputs = RenderInputs {
        scene: &scene,
        tri_uv: &tri_uv,
        texture: &texture,
        shading: &shading,
        kind: ShadingKind::Paper,
    };
    let camera = Camera {
        width: 320,
        height: 320,
        fx: 160.0,
        fy: 160.0,
        cx: 159.5,
        cy: 159.5,
        k1: 0.0,
        k2: 0.0,
        p1: 0.0,
        p2: 0.0,
        k3: 0.0,
    };
    let mut pose = Affine::identity();
    pose[(0, 3)] = 0.5;
    pose[(1, 3)] = -0.8;
    pose[(2, 3)] = 30.3;
    let mut g = c.benchmark_group("render");
    g.sample_size(20);
    g.throughput(Throughput::Elements(1));
    for (name, psi_lookup, ss) in [
        ("view_320_nearest", PsiLookup::Nearest, 1),
        ("view_320_knearest4", PsiLookup::KNearest { k: 4 }, 1),
        ("view_320_knearest4_ss2", PsiLookup::KNearest { k: 4 }, 2),
    ] {
        let rays = ViewRays::new(&camera, ss).unwrap();
        let opts = RenderOptions {
            psi_lookup,
            supersample: ss,
            ..Default::default()
        };
        g.bench_function(name, |b| {
            b.iter(|| render_view_with(&inputs, &rays, &pose, &opts).unwrap())
        });
    }
    // The calibrated light (the default shading of a built model): rho(gamma) s(theta) / z².
    let light = CalibratedModel::new(
        [
            vec![2.0, 40.0, 80.0, 120.0],
            vec![1.0, 20.0, 40.0, 60.0],
            vec![1.0, 15.0, 30.0, 45.0],
        ],
        vec![1.0, 0.8, 0.6, 0.5],
        0.5,
    );
    let shading = FittedShading::new(ShadingKind::Calibrated, psi, Some(light));
    let calibrated = RenderInputs {
        shading: &shading,
        kind: ShadingKind::Calibrated,
        ..inputs
    };
    let rays = ViewRays::new(&camera, 1).unwrap();
    let opts = RenderOptions::default();
    g.bench_function("view_320_calibrated", |b| {
        b.iter(|| render_view_with(&calibrated, &rays, &pose, &opts).unwrap())
    });
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
