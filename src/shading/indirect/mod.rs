//! Inter-reflection computed from the geometry (issue 18, item 1): the light of the lens-mounted
//! light once reflected by the lumen's wall, gathered by ray casting the lumen mesh
//! ([`gather`]) on a coarse grid of each view's pixels ([`field`]).
//!
//! The calibrated light then predicts a pixel as `g alb(x) (rho s / z^2 + k_c E_c(x))`
//! (`--interreflection gathered`), in place of the uniform `kappa_c L_f` of each frame.

pub mod field;
#[cfg(test)]
mod fit_tests;
pub mod frames;
pub mod gather;

pub use field::{gather_grid, gather_view, IndirectField, ViewGrid};
pub use frames::{gather_frames, sample_fields};
pub use gather::{
    gather_one, gather_points, GatherOptions, LensLight, SurfaceAlbedo, TextureAlbedo,
    UniformAlbedo,
};

/// How the calibrated light models inter-reflection (`build --interreflection`).
#[derive(
    Clone,
    Copy,
    Debug,
    PartialEq,
    Eq,
    Default,
    clap::ValueEnum,
    serde::Serialize,
    serde::Deserialize,
)]
#[serde(rename_all = "snake_case")]
pub enum InterreflectionMode {
    /// `kappa_c L_f`: each frame's mean observed light times one factor per channel.
    #[default]
    Uniform,
    /// `g_f alb(x) k_c E_c(x)`: the lamp's light once reflected by the wall, gathered from the
    /// mesh at every surface point.
    Gathered,
    /// Both terms: the gathered light and `kappa_c L_f` beside it (what the gather misses:
    /// later bounces, light the mesh does not hold).
    Both,
}

/// How the gathered inter-reflection is sampled, as recorded in shading.json.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct GatheredInterreflection {
    /// k_c per channel R, G, B: the gathered light's factor (unitless; for one Lambertian
    /// bounce the wall's mean albedo, larger when it absorbs later bounces).
    pub k: [f64; 3],
    /// Grid nodes across each view (rows in proportion to the image's aspect).
    pub nodes_across: usize,
    /// Hemisphere rays per node.
    pub rays: usize,
    /// Whether each bounce point's visibility from the light was tested.
    pub visibility: bool,
}

impl GatheredInterreflection {
    /// The gather options these settings stand for.
    pub fn gather_options(&self) -> GatherOptions {
        GatherOptions {
            rays: self.rays,
            visibility: self.visibility,
            ..GatherOptions::default()
        }
    }

    /// Check the numbers of a loaded model; the message says which is wrong.
    pub fn validate(&self) -> Result<(), String> {
        if self.k.iter().any(|k| !(k.is_finite() && *k >= 0.0)) {
            return Err(format!(
                "calibrated.gathered.k must be finite and >= 0, got {:?}",
                self.k
            ));
        }
        if !(1..=4096).contains(&self.nodes_across) || !(1..=65536).contains(&self.rays) {
            return Err(format!(
                "calibrated.gathered: nodes_across {} (1..4096) or rays {} (1..65536) out of range",
                self.nodes_across, self.rays
            ));
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::camera::Camera;
    use crate::math::Affine;
    use crate::mesh::TriMesh;
    use crate::raycast::Scene;
    use crate::shading::calibrated::CalibratedModel;
    use nalgebra::Point3;

    /// A latitude–longitude sphere of radius `r` (mm) about the origin.
    fn sphere(r: f32, rings: usize, segments: usize) -> TriMesh {
        let mut positions = vec![Point3::new(0.0, 0.0, r)];
        for i in 1..rings {
            let th = std::f32::consts::PI * i as f32 / rings as f32;
            for j in 0..segments {
                let ph = std::f32::consts::TAU * j as f32 / segments as f32;
                positions.push(Point3::new(
                    r * th.sin() * ph.cos(),
                    r * th.sin() * ph.sin(),
                    r * th.cos(),
                ));
            }
        }
        positions.push(Point3::new(0.0, 0.0, -r));
        let south = (positions.len() - 1) as u32;
        let at = |i: usize, j: usize| (1 + (i - 1) * segments + j % segments) as u32;
        let mut triangles = Vec::new();
        for j in 0..segments {
            triangles.push([0, at(1, j), at(1, j + 1)]);
            triangles.push([south, at(rings - 1, j + 1), at(rings - 1, j)]);
        }
        for i in 1..rings - 1 {
            for j in 0..segments {
                triangles.push([at(i, j), at(i + 1, j), at(i + 1, j + 1)]);
                triangles.push([at(i, j), at(i + 1, j + 1), at(i, j + 1)]);
            }
        }
        TriMesh {
            positions,
            triangles,
        }
    }

    /// A Lambertian light, rho(gamma) = rho1 gamma per channel, isotropic (s = 1 everywhere).
    fn lambertian(rho1: [f64; 3]) -> CalibratedModel {
        CalibratedModel::new(rho1.map(|r| vec![0.0, r]), vec![1.0], -0.999)
    }

    /// Albedo 0.5 on the triangles with x > 0, 1 elsewhere.
    struct HalfDark<'a>(&'a Scene);
    impl SurfaceAlbedo for HalfDark<'_> {
        fn albedo(&self, tri: u32, _u: f32, _v: f32) -> [f32; 3] {
            let t = self.0.triangles[tri as usize];
            let x: f32 = t.iter().map(|&v| self.0.positions[v as usize][0]).sum();
            if x > 0.0 {
                [0.5; 3]
            } else {
                [1.0; 3]
            }
        }
    }

    // Inside a Lambertian sphere of radius R, a wall patch dA at y sends to x the irradiance
    // L(y) cos_x cos_y dA / d^2 with cos_x = cos_y = d / 2R, so the once-reflected light is the
    // same at every x wherever the light is: E = (1 / (4 pi R^2)) * integral of L over the
    // sphere. With L = rho1 gamma / r^2 (a point light) the integral is rho1 times the solid
    // angle 4 pi, so E = rho1 / R^2; with albedo 1/2 on the half x > 0 and the light on the
    // plane x = 0, 3/4 of that.
    #[test]
    fn gather_matches_the_closed_form_inside_a_sphere() {
        let r = 10.0f32;
        let scene = Scene::new(&sphere(r, 96, 192)).unwrap();
        let rho1 = [100.0, 50.0, 25.0];
        let model = lambertian(rho1);
        let want = rho1.map(|v| v / f64::from(r * r));
        let opts = GatherOptions {
            rays: 4096,
            visibility: true,
            seed: 7,
        };
        for (centre, half) in [([0.0, 0.0, 0.0], false), ([0.0, 4.0, -3.0], true)] {
            let light = LensLight {
                model: &model,
                centre,
                axis: [0.0, 0.0, 1.0],
            };
            // Points on the wall in several directions (the light's side and the far side).
            let dirs = [[1.0f32, 0.0, 0.0], [0.0, -0.6, 0.8], [-0.48, 0.6, -0.64]];
            let points: Vec<[f32; 3]> = dirs.iter().map(|d| d.map(|v| 0.999 * r * v)).collect();
            let normals: Vec<[f32; 3]> = dirs.iter().map(|d| d.map(|v| -v)).collect();
            let ids: Vec<u64> = (0..dirs.len() as u64).collect();
            let dark = HalfDark(&scene);
            let albedo: &dyn SurfaceAlbedo = if half { &dark } else { &UniformAlbedo };
            let e = gather_points(&scene, &light, albedo, &points, &normals, &ids, &opts);
            let f = if half { 0.75 } else { 1.0 };
            for (p, got) in e.iter().enumerate() {
                for c in 0..3 {
                    let rel = f64::from(got[c]) / (f * want[c]) - 1.0;
                    assert!(rel.abs() < 0.02, "point {p} channel {c}: {rel:+.4}");
                }
            }
        }
    }

    /// A new view from the centre of a sphere of radius 8 mm: every pixel sees the wall at
    /// z = R, gamma = 1, so the direct light is rho1 / R^2 = 1 and the gathered light
    /// k_c rho1 / R^2 = k_c (see the closed form above) with a uniform texture.
    #[test]
    fn a_new_view_adds_its_own_gathered_light() {
        use crate::image::Frame;
        use crate::render::{render_view, MipOptions, MipTexture, RenderInputs, RenderOptions};
        use crate::shading::{FittedShading, ShadingKind};
        let r = 8.0f32;
        let scene = Scene::new(&sphere(r, 48, 96)).unwrap();
        let k = [0.5, 0.4, 0.3];
        let model = CalibratedModel {
            gathered: Some(GatheredInterreflection {
                k,
                nodes_across: 6,
                rays: 256,
                visibility: false,
            }),
            ..lambertian([64.0; 3])
        };
        let image = Frame {
            width: 4,
            height: 4,
            rgb: vec![0.8; 48],
        };
        let texture = MipTexture::new(&image, None, 0.5, &MipOptions::default()).unwrap();
        let tri_uv = vec![[[0.5f32, 0.5]; 3]; scene.triangle_count()];
        let camera = Camera {
            width: 24,
            height: 18,
            fx: 12.0,
            fy: 12.0,
            cx: 11.5,
            cy: 8.5,
            k1: 0.0,
            k2: 0.0,
            p1: 0.0,
            p2: 0.0,
            k3: 0.0,
        };
        let render = |m: CalibratedModel| {
            let shading = FittedShading::new(ShadingKind::Calibrated, Vec::new(), Some(m));
            let inputs = RenderInputs {
                scene: &scene,
                tri_uv: &tri_uv,
                texture: &texture,
                shading: &shading,
                kind: ShadingKind::Calibrated,
            };
            let pose = Affine::identity();
            render_view(&inputs, &camera, &pose, &RenderOptions::default())
                .unwrap()
                .0
        };
        let with = render(model.clone());
        let without = render(CalibratedModel {
            gathered: None,
            ..model
        });
        for (a, b) in with.rgb.chunks_exact(3).zip(without.rgb.chunks_exact(3)) {
            for c in 0..3 {
                // The texture's albedo 0.8 multiplies both terms.
                assert!((b[c] / 0.8 - 1.0).abs() < 0.01, "direct {b:?}");
                let gathered = (a[c] - b[c]) / 0.8;
                assert!((gathered / k[c] as f32 - 1.0).abs() < 0.04, "{a:?} {b:?}");
            }
        }
    }

    #[test]
    fn a_view_inside_a_sphere_gathers_the_same_light_everywhere() {
        let r = 8.0f32;
        let scene = Scene::new(&sphere(r, 48, 96)).unwrap();
        let model = lambertian([64.0; 3]);
        let camera = Camera {
            width: 40,
            height: 30,
            fx: 20.0,
            fy: 20.0,
            cx: 19.5,
            cy: 14.5,
            k1: 0.0,
            k2: 0.0,
            p1: 0.0,
            p2: 0.0,
            k3: 0.0,
        };
        let mut pose = Affine::identity();
        pose[(1, 3)] = 2.0;
        let opts = GatherOptions {
            rays: 1024,
            ..GatherOptions::default()
        };
        let field = gather_view(&scene, &camera, &pose, &model, &UniformAlbedo, 8, 3, &opts);
        assert_eq!((field.nx, field.ny), (8, 6));
        for v in &field.values {
            assert!((f64::from(v[0]) / 1.0 - 1.0).abs() < 0.04, "{v:?}");
        }
        // Outside the light's cone nothing is lit: a light whose profile the fit saw to 30°
        // tapers to 0 at 90°, halfway in cos theta between its edge and 90°.
        let narrow = CalibratedModel {
            s: vec![1.0, 0.5],
            cos_theta_edge: 30f64.to_radians().cos(),
            ..model.clone()
        };
        let light = LensLight {
            model: &narrow,
            centre: [0.0; 3],
            axis: [0.0, 0.0, 1.0],
        };
        let edge = narrow.cos_theta_edge;
        assert!((light.profile(edge) - 0.5).abs() < 1e-12);
        assert!((light.profile(edge / 2.0) - 0.25).abs() < 1e-12);
        assert_eq!(light.profile(-0.3), 0.0);
    }
}
