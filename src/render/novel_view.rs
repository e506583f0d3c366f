//! Rendering a new view (paper §2.4): ray cast the mesh from the new viewpoint, shade with the
//! fitted shading evaluated at the new view's gamma, z and theta (the light moves with the
//! camera), multiply by the fused albedo texture; with the gathered inter-reflection, add the
//! view's own light once reflected by the wall (`shading::indirect`) times the albedo.

use rayon::prelude::*;

use super::texture_sampler::MipTexture;
use crate::camera::Camera;
use crate::image::Frame;
use crate::image::ImageError;
use crate::math::Affine;
use crate::mesh::GeometryError;
use crate::raycast::Scene;
use crate::shading::indirect::{gather_grid, IndirectField, TextureAlbedo, ViewGrid};
use crate::shading::paper::PsiLookup;
use crate::shading::{masked_luminance_sum, FittedShading, ShadingKind};
use crate::texture::atlas::Atlas;
use crate::Result;

/// Everything a view is rendered from. Triangle `t` of `scene` has UV corners `tri_uv[t]`
/// (the atlas keeps the mesh's triangle order, so the scene may be built from the original
/// mesh, whose smooth normals do not break at chart seams).
#[derive(Clone, Copy)]
pub struct RenderInputs<'a> {
    /// The lumen mesh, ready for ray casting.
    pub scene: &'a Scene,
    /// UV (atlas convention, [0, 1]) of the three corners of every triangle.
    pub tri_uv: &'a [[[f32; 2]; 3]],
    /// The fused albedo with its mip chain.
    pub texture: &'a MipTexture,
    /// The fitted shading models.
    pub shading: &'a FittedShading,
    /// Which of them shades the view.
    pub kind: ShadingKind,
}

/// UV corners of every triangle of an atlas (input to [`RenderInputs::tri_uv`]).
pub fn triangle_uvs(atlas: &Atlas) -> Vec<[[f32; 2]; 3]> {
    atlas
        .mesh
        .triangles
        .iter()
        .map(|t| t.map(|v| atlas.uv[v as usize]))
        .collect()
}

/// Options of [`render_view`]. Steps per pixel: cast `supersample²` rays (stratified in the
/// pixel), shade each hit (the model `RenderInputs::kind`) × texture (trilinear, level from the ray's
/// footprint on the surface), average the hits, multiply by `gain`.
#[derive(Clone, Debug)]
pub struct RenderOptions {
    /// Which fitted viewpoints' Psi shade the view (the paper's model only).
    pub psi_lookup: PsiLookup,
    /// Rays per pixel along each axis (1 = one ray through the pixel centre).
    pub supersample: u32,
    /// Choose the texture level from the footprint (false = bilinear on level 0 only).
    pub mipmap: bool,
    /// Exposure: output = gain × shading × albedo (linear).
    pub gain: f32,
    /// Write the texture alone (the relative albedo the shading multiplies), unshaded.
    pub albedo_only: bool,
    /// Expose as the patient's scope would: multiply by the gain its auto-exposure (learnt by
    /// `build`, [`crate::shading::calibrated::AutoExposure`]) picks for the view's mean
    /// luminance. Calibrated light only; ignored by the paper's Psi (each Psi holds its frame's
    /// gain) and by models built without it.
    pub auto_exposure: bool,
}

impl Default for RenderOptions {
    fn default() -> Self {
        RenderOptions {
            psi_lookup: PsiLookup::default(),
            supersample: 1,
            mipmap: true,
            gain: 1.0,
            albedo_only: false,
            auto_exposure: false,
        }
    }
}

/// Sub-pixel ray directions of a camera (camera coordinates, unit, lens distortion undone) and
/// the angle one pixel subtends at each pixel. Build once per camera and supersampling factor.
#[derive(Clone, Debug)]
pub struct ViewRays {
    /// Image width (pixels).
    pub width: u32,
    /// Image height (pixels).
    pub height: u32,
    /// Rays per pixel along each axis.
    pub supersample: u32,
    /// `supersample²` unit directions per pixel, pixel-major (row-major pixels).
    pub dirs: Vec<[f32; 3]>,
    /// Angle between neighbouring pixel-centre rays at each pixel (radians; the larger of the
    /// horizontal and vertical one).
    pub pixel_angle: Vec<f32>,
}

impl ViewRays {
    /// Tabulate the rays of `camera` with `supersample` x `supersample` rays per pixel.
    pub fn new(camera: &Camera, supersample: u32) -> Result<ViewRays> {
        camera
            .validate()
            .map_err(|message| ImageError::Inconsistent {
                stage: "render",
                message: format!("bad camera: {message}"),
            })?;
        let s = supersample.max(1) as usize;
        let (w, h) = (camera.width as usize, camera.height as usize);
        let ray = |u: f64, v: f64| {
            let d = camera.pixel_ray(u, v);
            [d.x as f32, d.y as f32, d.z as f32]
        };
        let dirs: Vec<[f32; 3]> = (0..w * h)
            .into_par_iter()
            .with_min_len(256)
            .flat_map_iter(|i| {
                let (x, y) = ((i % w) as f64, (i / w) as f64);
                (0..s * s).map(move |j| {
                    let ox = ((j % s) as f64 + 0.5) / s as f64 - 0.5;
                    let oy = ((j / s) as f64 + 0.5) / s as f64 - 0.5;
                    ray(x + ox, y + oy)
                })
            })
            .collect();
        let angle = |a: [f32; 3], b: [f32; 3]| {
            let c = (a[0] * b[0] + a[1] * b[1] + a[2] * b[2]).clamp(-1.0, 1.0);
            c.acos()
        };
        let pixel_angle = (0..w * h)
            .into_par_iter()
            .with_min_len(256)
            .map(|i| {
                let (x, y) = ((i % w) as f64, (i / w) as f64);
                let c = ray(x, y);
                angle(c, ray(x + 1.0, y)).max(angle(c, ray(x, y + 1.0)))
            })
            .collect();
        Ok(ViewRays {
            width: camera.width,
            height: camera.height,
            supersample: s as u32,
            dirs,
            pixel_angle,
        })
    }
}

/// Render one view: linear RGB and the hit mask (true where some ray of the pixel hits the
/// mesh). `camera_to_world` is the new camera's pose (world mm, OpenCV axes).
pub fn render_view(
    inputs: &RenderInputs,
    camera: &Camera,
    camera_to_world: &Affine,
    opts: &RenderOptions,
) -> Result<(Frame, Vec<bool>)> {
    let rays = ViewRays::new(camera, opts.supersample)?;
    render_view_with(inputs, &rays, camera_to_world, opts)
}

/// [`render_view`] with precomputed rays (`opts.supersample` is taken from `rays`). Parallel
/// over bands of image rows, traced as packets of neighbouring rays.
pub fn render_view_with(
    inputs: &RenderInputs,
    rays: &ViewRays,
    camera_to_world: &Affine,
    opts: &RenderOptions,
) -> Result<(Frame, Vec<bool>)> {
    if inputs.tri_uv.len() != inputs.scene.triangle_count() {
        return Err(GeometryError::LengthMismatch {
            stage: "render",
            what: "triangle UVs",
            got: inputs.tri_uv.len(),
            expected: inputs.scene.triangle_count(),
        }
        .into());
    }
    let shade = inputs
        .shading
        .view_shader(inputs.kind, camera_to_world, opts.psi_lookup)?;
    let m = camera_to_world;
    let org = [m[(0, 3)] as f32, m[(1, 3)] as f32, m[(2, 3)] as f32];
    let rot: [[f32; 3]; 3] = std::array::from_fn(|i| std::array::from_fn(|j| m[(i, j)] as f32));
    let (w, h) = (rays.width as usize, rays.height as usize);
    let ss = (rays.supersample as usize).pow(2);
    let tex = inputs.texture;
    let indirect = gathered_light(inputs, rays, camera_to_world, opts);
    // The footprint of one sub-pixel ray: the pixel angle shrinks with supersampling.
    let angle_scale = 1.0 / rays.supersample as f32;

    let mut frame = Frame::new(rays.width, rays.height);
    let mut mask = vec![false; w * h];
    frame
        .rgb
        .par_chunks_mut(3 * w * Scene::TILE_ROWS)
        .zip(mask.par_chunks_mut(w * Scene::TILE_ROWS))
        .enumerate()
        .for_each_init(
            || (Vec::new(), Vec::new()),
            |(dirs, hits), (c, (rows, mrows))| {
                // Trace a band of rows together (packets of neighbouring rays), then shade.
                let (y0, ny) = (Scene::TILE_ROWS * c, mrows.len() / w);
                let row_dirs = &rays.dirs[y0 * w * ss..(y0 + ny) * w * ss];
                dirs.clear();
                dirs.extend(row_dirs.iter().map(|d| -> [f32; 3] {
                    std::array::from_fn(|i| rot[i][0] * d[0] + rot[i][1] * d[1] + rot[i][2] * d[2])
                }));
                hits.clear();
                hits.resize(dirs.len(), None);
                inputs
                    .scene
                    .closest_hits_image_rows(org, dirs, w * ss, f32::INFINITY, hits);
                for i in 0..ny * w {
                    let p = y0 * w + i;
                    let mut acc = [0.0f32; 3];
                    let mut n_hit = 0u32;
                    let cam_dirs = &row_dirs[i * ss..(i + 1) * ss];
                    for ((dir, hit), d) in dirs[i * ss..(i + 1) * ss]
                        .iter()
                        .zip(&hits[i * ss..(i + 1) * ss])
                        .zip(cam_dirs)
                    {
                        let Some(hit) = hit else {
                            continue;
                        };
                        let n = inputs.scene.shading_normal(hit.tri, hit.u, hit.v);
                        let gamma = (n[0] * dir[0] + n[1] * dir[1] + n[2] * dir[2])
                            .abs()
                            .min(1.0);
                        let z = hit.t;
                        let [a, b, c] = inputs.tri_uv[hit.tri as usize];
                        let wa = 1.0 - hit.u - hit.v;
                        let u = wa * a[0] + hit.u * b[0] + hit.v * c[0];
                        let v = wa * a[1] + hit.u * b[1] + hit.v * c[1];
                        let albedo = if opts.mipmap {
                            // Footprint along the surface's steepest direction: z·angle/gamma.
                            let fp = z * rays.pixel_angle[p] * angle_scale / gamma.max(1e-3);
                            tex.sample(u, v, tex.lod(fp))
                        } else {
                            tex.sample_bilinear(u, v)
                        };
                        let (scale, offset) = if opts.albedo_only {
                            ([1.0; 3], [0.0; 3])
                        } else {
                            shade.eval_rgb(gamma, z, d[2])
                        };
                        for k in 0..3 {
                            acc[k] += scale[k] * albedo[k] + offset[k];
                        }
                        if let Some((field, kc)) = &indirect {
                            let e = field.at_pixel(p, w, h);
                            for k in 0..3 {
                                acc[k] += kc[k] * e[k] * albedo[k];
                            }
                        }
                        n_hit += 1;
                    }
                    if n_hit > 0 {
                        let s = opts.gain / n_hit as f32;
                        for k in 0..3 {
                            rows[3 * i + k] = acc[k] * s;
                        }
                        mrows[i] = true;
                    }
                }
            },
        );
    if !opts.albedo_only {
        shade.finish(&mut frame, &mask, opts.gain);
        if opts.auto_exposure {
            apply_auto_exposure(inputs, &mut frame, &mask, opts.gain);
        }
    }
    Ok((frame, mask))
}

/// The gathered inter-reflection of the view's own light with the texture's albedo, and its
/// factor k_c, when the calibrated light shades the view with it.
fn gathered_light(
    inputs: &RenderInputs,
    rays: &ViewRays,
    camera_to_world: &Affine,
    opts: &RenderOptions,
) -> Option<(IndirectField, [f32; 3])> {
    let model = match (inputs.kind, &inputs.shading.calibrated) {
        (ShadingKind::Calibrated, Some(m)) if !opts.albedo_only => m,
        _ => return None,
    };
    let g = model.gathered?;
    let (w, h) = (rays.width as usize, rays.height as usize);
    let ss = (rays.supersample as usize).pow(2);
    // The ray of the nearest pixel's first sub-pixel ray: the field is low-frequency.
    let ray = |x: f64, y: f64| {
        let (i, j) = (
            (x.round().max(0.0) as usize).min(w - 1),
            (y.round().max(0.0) as usize).min(h - 1),
        );
        rays.dirs[(j * w + i) * ss].map(f64::from)
    };
    let view = ViewGrid {
        width: rays.width,
        height: rays.height,
        nodes_across: g.nodes_across,
        ray: &ray,
    };
    let albedo = TextureAlbedo::new(inputs.texture, inputs.tri_uv);
    let field = gather_grid(
        inputs.scene,
        &view,
        camera_to_world,
        model,
        &albedo,
        0,
        &g.gather_options(),
    );
    Some((field, g.k.map(|k| k as f32)))
}

/// The auto-exposure gain of a view rendered at exposure `gain` (the mean luminance over its
/// surface pixels at the reference gain decides it); 1 without a learnt auto-exposure.
pub fn auto_exposure_gain(inputs: &RenderInputs, frame: &Frame, mask: &[bool], gain: f32) -> f64 {
    let ae = match (inputs.kind, &inputs.shading.calibrated) {
        (ShadingKind::Calibrated, Some(c)) => c.auto_exposure.as_ref(),
        _ => None,
    };
    let Some(ae) = ae.filter(|_| gain > 0.0) else {
        return 1.0;
    };
    let (sum, hits) = masked_luminance_sum(&frame.rgb, mask);
    let light = sum / hits.max(1) as f64 / f64::from(gain);
    ae.gain(light)
}

/// Multiply `frame` by [`auto_exposure_gain`].
fn apply_auto_exposure(inputs: &RenderInputs, frame: &mut Frame, mask: &[bool], gain: f32) {
    let g = auto_exposure_gain(inputs, frame, mask, gain) as f32;
    for v in &mut frame.rgb {
        *v *= g;
    }
}
