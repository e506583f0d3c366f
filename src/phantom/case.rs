//! `bronchosim phantom`: write a complete synthetic case (CASE_FORMAT.md) with its truth.
//!
//! Steps: CT (the built-in tree voxelised, or a CT-like volume from a real airway mask),
//! the true lumen mesh, the camera path (centreline + wobble), frames rendered with the
//! physically based model of [`super::render`] through the distorted camera, poses.json,
//! then `truth/`: lumen.ply, albedo_vertices.ply (linear RGB per vertex), gains.json (gain per
//! frame and the light and sensor parameters), views.json + camera.json (pinhole) and
//! views/ (sRGB 8-bit, linear 16-bit, hit mask, depth in 0.01 mm, albedo, all per view) from
//! poses off the training path, and truth.json (a manifest). Everything is written into a
//! temporary folder beside `out` and renamed into place at the end.

use super::albedo::MucosaAlbedo;
use super::ct_volume::{make_ct_phantom, CtPhantomOptions};
use super::from_mask::{ct_from_mask_file, FromMaskOptions};
use super::mask_path::mask_centreline;
use super::overlay::ScopeOverlay;
use super::path::{camera_path, novel_views, tree_centreline, PathOptions, SmoothPath};
use super::pose_noise::{tracker_poses, PoseNoise};
use super::render::{auto_gain, expose, render_radiance, LightModel, SensorModel, SubpixelRays};
use super::truth_io::{write_albedo_ply, write_gray16_png, write_gray8_png, write_linear16_png};
use super::truth_mesh::{mask_truth_mesh, tree_truth_mesh};
use crate::camera::Camera;
use crate::camera::Pose;
use crate::image::Frame;
use crate::io::atomic::write_json_atomic;
use crate::io::camera_file::write_camera_json;
use crate::io::image_mask::MASK_FILE;
use crate::io::mesh_export::write_ply;
use crate::io::nifti::write_nifti;
use crate::io::png::write_png_srgb8;
use crate::io::poses::{write_poses, FrameRef, PoseEntry};
use crate::math::{Affine, Point3};
use crate::mesh::TriMesh;
use crate::raycast::{cast_frame, Scene};
use crate::volume::Volume;
use crate::{Error, Result};
use rayon::prelude::*;
use serde::Serialize;
use std::path::{Path, PathBuf};
use std::time::Instant;

/// Options of [`write_phantom_case`].
#[derive(Clone, Debug)]
pub struct PhantomOptions {
    /// Number of video frames.
    pub frames: usize,
    /// Frame width and height (pixels); the focal length is half the width.
    pub width: u32,
    /// Frame height (pixels).
    pub height: u32,
    /// Master seed: the tree, CT noise, albedo, path wobble and sensor noise derive from it
    /// (the seed fields inside `ct` and `mask` are overwritten).
    pub seed: u64,
    /// Take the airway from this binary mask (NIfTI) instead of the built-in tree.
    pub anatomy: Option<PathBuf>,
    /// Built-in CT options.
    pub ct: CtPhantomOptions,
    /// CT-from-mask options (with `anatomy`).
    pub mask: FromMaskOptions,
    /// Grid spacing (mm) of the SDF the truth mesh is extracted from (built-in tree).
    pub truth_grid_mm: f64,
    /// Larger truth meshes are decimated to about this many triangles.
    pub max_triangles: usize,
    /// Sub-samples per pixel along each axis (antialiasing; 1 = one ray per pixel).
    pub supersample: u32,
    /// Number of novel truth views.
    pub novel_views: usize,
    /// Light and reflectance.
    pub light: LightModel,
    /// Sensor.
    pub sensor: SensorModel,
    /// Camera path (its `frames` and `seed` are overwritten).
    pub path: PathOptions,
    /// Replace an existing `out` folder.
    /// Burn a scope's overlay into the frames (black border around an octagonal field of
    /// view, on-screen text over the image) and write the matching CASE/mask.png.
    pub scope_overlay: bool,
    /// Tracker-like error of the poses written to poses.json (the true ones go to
    /// truth/poses.json either way); zero by default.
    pub pose_noise: PoseNoise,
    pub force: bool,
}

impl Default for PhantomOptions {
    fn default() -> Self {
        PhantomOptions {
            frames: 80,
            width: 320,
            height: 320,
            seed: 1,
            anatomy: None,
            ct: CtPhantomOptions::default(),
            mask: FromMaskOptions {
                crop_margin_mm: Some(15.0),
                ..Default::default()
            },
            truth_grid_mm: 0.35,
            max_triangles: 400_000,
            supersample: 1,
            novel_views: 8,
            light: LightModel::default(),
            sensor: SensorModel::default(),
            path: PathOptions::default(),
            scope_overlay: false,
            pose_noise: PoseNoise::new(0.0, 0.0),
            force: false,
        }
    }
}

/// What was written, with per-stage wall-clock seconds.
#[derive(Clone, Debug, Default, Serialize)]
pub struct PhantomSummary {
    /// CT grid size.
    pub ct_dims: [usize; 3],
    /// Truth mesh vertices and triangles.
    pub mesh_vertices: usize,
    /// Truth mesh triangles.
    pub mesh_triangles: usize,
    /// Frames written.
    pub frames: usize,
    /// Novel views written.
    pub views: usize,
    /// Mean linear luminance of each frame as written.
    pub frame_mean_linear: Vec<f64>,
    /// Fraction of pixels with a saturated channel in each frame.
    pub frame_saturated_fraction: Vec<f64>,
    /// Seconds: CT, truth mesh, path, frames, truth views, writing the CT.
    pub seconds: [f64; 6],
}

/// The bronchoscope camera of the phantom: fx = fy = width/2, barrel distortion.
pub fn phantom_camera(width: u32, height: u32) -> Camera {
    Camera {
        width,
        height,
        fx: width as f64 / 2.0,
        fy: width as f64 / 2.0,
        cx: (width as f64 - 1.0) / 2.0,
        cy: (height as f64 - 1.0) / 2.0,
        k1: -0.28,
        k2: 0.07,
        p1: 0.0,
        p2: 0.0,
        k3: 0.0,
    }
}

#[derive(Serialize)]
struct FrameGain {
    image: String,
    gain: f64,
    mean_linear: f64,
    saturated_fraction: f64,
}

#[derive(Serialize)]
struct GainsFile<'a> {
    description: &'static str,
    light: &'a LightModel,
    cone_exponent: f64,
    sensor: &'a SensorModel,
    reference_gain: f64,
    frames: Vec<FrameGain>,
}

/// The mucosa albedo of the phantom case made with master seed `seed` (`truth.json` "seed").
pub fn phantom_albedo(seed: u64) -> MucosaAlbedo {
    MucosaAlbedo::new(seed.wrapping_mul(17).wrapping_add(5))
}

/// Write the phantom case to `out` (a new folder); see the module docs.
pub fn write_phantom_case(out: &Path, opts: &PhantomOptions) -> Result<PhantomSummary> {
    if opts.frames == 0 || opts.width < 8 || opts.height < 8 {
        return Err(Error::BadOptions {
            stage: "phantom",
            message: format!(
                "need at least one frame and 8x8 pixels (got {} frames, {}x{})",
                opts.frames, opts.width, opts.height
            ),
        });
    }
    if out.exists() && !opts.force {
        return Err(Error::invalid(
            out,
            "already exists (use --force to replace it)",
        ));
    }
    let parent = match out.parent() {
        Some(p) if !p.as_os_str().is_empty() => p.to_path_buf(),
        _ => PathBuf::from("."),
    };
    std::fs::create_dir_all(&parent).map_err(|e| Error::io(&parent, e))?;
    let tmp = tempfile::Builder::new()
        .prefix(".bronchosim-phantom-")
        .tempdir_in(&parent)
        .map_err(|e| Error::io(&parent, e))?;
    let dir = tmp.path();
    let summary = write_into(dir, opts)?;
    if out.exists() {
        std::fs::remove_dir_all(out).map_err(|e| Error::io(out, e))?;
    }
    let kept = tmp.keep();
    std::fs::rename(&kept, out).map_err(|e| Error::io(out, e))?;
    Ok(summary)
}

/// Signed distance (mm) to the true lumen wall, negative inside.
type SdfFn = Box<dyn Fn(&Point3<f64>) -> f64 + Sync>;

fn write_into(dir: &Path, opts: &PhantomOptions) -> Result<PhantomSummary> {
    let mut sm = PhantomSummary::default();
    let seed = opts.seed;
    let t = Instant::now();
    // The CT, the truth mesh and the signed distance the path is checked with.
    let (ct, mesh, sdf_fn, centreline): (Volume<f32>, TriMesh, SdfFn, Vec<Point3<f64>>) =
        match &opts.anatomy {
            None => {
                let mut co = opts.ct.clone();
                co.tree.seed = seed;
                co.seed = seed.wrapping_mul(31).wrapping_add(7);
                let ph = make_ct_phantom(&co)?;
                sm.seconds[0] = t.elapsed().as_secs_f64();
                let t1 = Instant::now();
                let top = ph.tree.branches[0].control[0].z - 5.0;
                let mesh = tree_truth_mesh(&ph.tree, opts.truth_grid_mm, top, opts.max_triangles)?;
                sm.seconds[1] = t1.elapsed().as_secs_f64();
                let line = tree_centreline(&ph.tree);
                let tree = ph.tree;
                (ph.ct, mesh, Box::new(move |p| tree.lumen_sdf(*p)), line)
            }
            Some(mask_path) => {
                let mut mo = opts.mask.clone();
                mo.seed = seed.wrapping_mul(31).wrapping_add(11);
                let ph = ct_from_mask_file(mask_path, &mo)?;
                sm.seconds[0] = t.elapsed().as_secs_f64();
                let t1 = Instant::now();
                let mesh = mask_truth_mesh(&ph.truth_mask, opts.max_triangles)?;
                sm.seconds[1] = t1.elapsed().as_secs_f64();
                let cl = mask_centreline(&ph.truth_mask)
                    .map_err(|e| Error::invalid(mask_path, e.to_string()))?;
                let sdf: Volume<f32> = cl.sdf;
                (
                    ph.ct,
                    mesh,
                    Box::new(move |p| sdf.sample_world(*p).map_or(1.0, |v| v as f64)),
                    cl.points,
                )
            }
        };
    sm.ct_dims = ct.dims;
    sm.mesh_vertices = mesh.positions.len();
    sm.mesh_triangles = mesh.triangles.len();

    let t = Instant::now();
    let mut po = opts.path.clone();
    po.frames = opts.frames;
    po.seed = seed.wrapping_mul(131).wrapping_add(3);
    let path = SmoothPath::new(&centreline, 0.5, po.smoothing_mm)?;
    let poses = camera_path(&path, &*sdf_fn, &po)?;
    let views = novel_views(&path, &*sdf_fn, opts.novel_views, &po)?;
    sm.seconds[2] = t.elapsed().as_secs_f64();

    // Frames.
    let t = Instant::now();
    let scene = Scene::new(&mesh)?;
    let albedo = phantom_albedo(seed);
    let camera = phantom_camera(opts.width, opts.height);
    let rays = SubpixelRays::new(&camera, opts.supersample);
    let frames_dir = dir.join("frames");
    std::fs::create_dir_all(&frames_dir).map_err(|e| Error::io(&frames_dir, e))?;
    let mut entries = Vec::with_capacity(poses.len());
    let mut true_entries = Vec::with_capacity(poses.len());
    // What a tracker would report (the frames are rendered from the true poses).
    let reported = tracker_poses(
        &poses,
        &opts.pose_noise,
        seed.wrapping_mul(613).wrapping_add(29),
    );
    let mut gains = Vec::with_capacity(poses.len());
    let noise_seed = seed.wrapping_mul(7919).wrapping_add(1);
    let overlay = opts
        .scope_overlay
        .then(|| ScopeOverlay::new(opts.width, opts.height));
    if let Some(o) = &overlay {
        write_png_srgb8(&dir.join(MASK_FILE), &o.mask())?;
    }
    for (i, pose) in poses.iter().enumerate() {
        let rad = render_radiance(&scene, &rays, pose, &albedo, &opts.light);
        let gain = auto_gain(&rad.frame, &opts.sensor);
        let mut img = expose(&rad.frame, gain, &opts.sensor, true, noise_seed, i as u64);
        if let Some(o) = &overlay {
            o.apply(&mut img, i, 25.0);
        }
        let path = frames_dir.join(format!("{i:06}.png"));
        write_png_srgb8(&path, &img)?;
        let (mean, sat) = frame_stats(&img);
        sm.frame_mean_linear.push(mean);
        sm.frame_saturated_fraction.push(sat);
        gains.push(FrameGain {
            image: format!("frames/{i:06}.png"),
            gain,
            mean_linear: mean,
            saturated_fraction: sat,
        });
        true_entries.push(PoseEntry {
            frame: FrameRef::Image(path.clone()),
            pose: Pose::new(*pose),
        });
        entries.push(PoseEntry {
            frame: FrameRef::Image(path),
            pose: Pose::new(reported[i]),
        });
    }
    write_poses(&dir.join("poses.json"), &entries, dir)?;
    write_camera_json(&dir.join("camera.json"), &camera)?;
    sm.frames = entries.len();
    sm.seconds[3] = t.elapsed().as_secs_f64();

    // Truth.
    let t = Instant::now();
    let truth = dir.join("truth");
    let vdir = truth.join("views");
    std::fs::create_dir_all(&vdir).map_err(|e| Error::io(&vdir, e))?;
    write_ply(&truth.join("lumen.ply"), &mesh)?;
    write_poses(&truth.join("poses.json"), &true_entries, dir)?;
    let vertex_albedo: Vec<[f32; 3]> = mesh
        .positions
        .par_iter()
        .map(|p| albedo.eval(Point3::new(p.x as f64, p.y as f64, p.z as f64)))
        .collect();
    write_albedo_ply(&truth.join("albedo_vertices.ply"), &mesh, &vertex_albedo)?;
    let reference_gain = gains[0].gain;
    let gfile = GainsFile {
        description:
            "linear frame = clip(gain * radiance + noise); radiance per render.rs with the \
                      light below; truth views use reference_gain (frame 0) and no noise",
        light: &opts.light,
        cone_exponent: opts.light.cone_exponent(),
        sensor: &opts.sensor,
        reference_gain,
        frames: gains,
    };
    write_json_atomic(&truth.join("gains.json"), &gfile)?;
    let pinhole = camera.pinhole();
    write_camera_json(&truth.join("camera.json"), &pinhole)?;
    let vrays = SubpixelRays::new(&pinhole, opts.supersample);
    let mut ventries = Vec::new();
    for (k, v) in views.iter().enumerate() {
        write_view(
            &truth,
            k,
            v,
            &scene,
            &pinhole,
            &vrays,
            &albedo,
            opts,
            reference_gain,
        )?;
        ventries.push(PoseEntry {
            frame: FrameRef::Image(vdir.join(format!("{k:06}.png"))),
            pose: Pose::new(*v),
        });
    }
    write_poses(&truth.join("views.json"), &ventries, &truth)?;
    sm.views = ventries.len();
    sm.seconds[4] = t.elapsed().as_secs_f64();

    let t = Instant::now();
    // Real CT is stored as 16-bit integers.
    let hu = ct.map(|v| v.round().clamp(-32768.0, 32767.0) as i16);
    write_nifti(&dir.join("ct.nii.gz"), &hu)?;
    sm.seconds[5] = t.elapsed().as_secs_f64();
    let manifest = serde_json::json!({
        "generator": "bronchosim phantom",
        "seed": seed,
        "anatomy": opts.anatomy.as_ref().map(|p| p.display().to_string()),
        "frames": sm.frames,
        "size": [opts.width, opts.height],
        "supersample": opts.supersample,
        "truth_grid_mm": opts.truth_grid_mm,
        "pose_noise": &opts.pose_noise,
        "files": {
            "lumen.ply": "true lumen mesh, world mm (RAS+), normals into the lumen",
            "albedo_vertices.ply": "the same mesh with float red, green, blue: linear albedo per vertex",
            "gains.json": "per-frame auto-gain, light and sensor model",
            "poses.json": "the true pose of every frame, images relative to the case folder (the case's poses.json has pose_noise added)",
            "views.json": "novel view poses (camera_to_world), images relative to truth/",
            "camera.json": "pinhole camera of the views (no distortion)",
            "views/NNNNNN.png": "sRGB 8-bit, clean (no noise), reference gain",
            "views/NNNNNN_linear.png": "linear 16-bit RGB: value = code / 65535",
            "views/NNNNNN_mask.png": "8-bit: 255 where the pixel-centre ray hits the mesh",
            "views/NNNNNN_depth.png": "16-bit: distance camera centre to surface along the pixel-centre ray, code / 100 mm (0 = miss)",
            "views/NNNNNN_albedo.png": "linear 16-bit RGB albedo at the pixel-centre hit"
        },
        "mesh": { "vertices": sm.mesh_vertices, "triangles": sm.mesh_triangles },
    });
    write_json_atomic(&truth.join("truth.json"), &manifest)?;
    Ok(sm)
}

/// Render one truth view: clean image at the reference gain and pixel-centre buffers.
#[allow(clippy::too_many_arguments)]
fn write_view(
    truth: &Path,
    k: usize,
    pose: &Affine,
    scene: &Scene,
    pinhole: &Camera,
    rays: &SubpixelRays,
    albedo: &MucosaAlbedo,
    opts: &PhantomOptions,
    gain: f64,
) -> Result<()> {
    let rad = render_radiance(scene, rays, pose, albedo, &opts.light);
    let img = expose(&rad.frame, gain, &opts.sensor, false, 0, 0);
    let base = truth.join("views");
    write_png_srgb8(&base.join(format!("{k:06}.png")), &img)?;
    write_linear16_png(&base.join(format!("{k:06}_linear.png")), &img)?;
    let gb = cast_frame(scene, pinhole, pose);
    let (w, h) = (pinhole.width, pinhole.height);
    let mask: Vec<u8> = (0..gb.tri.len())
        .map(|i| if gb.hit(i) { 255 } else { 0 })
        .collect();
    let depth: Vec<u16> =
        gb.z.iter()
            .map(|&z| {
                if z.is_finite() {
                    (z as f64 * 100.0).round().clamp(1.0, 65535.0) as u16
                } else {
                    0
                }
            })
            .collect();
    let mut alb = Frame::new(w, h);
    for i in 0..gb.tri.len() {
        if gb.hit(i) {
            let p = gb.point[i];
            let a = albedo.eval(Point3::new(p[0] as f64, p[1] as f64, p[2] as f64));
            alb.rgb[3 * i..3 * i + 3].copy_from_slice(&a);
        }
    }
    write_gray8_png(&base.join(format!("{k:06}_mask.png")), w, h, &mask)?;
    write_gray16_png(&base.join(format!("{k:06}_depth.png")), w, h, &depth)?;
    write_linear16_png(&base.join(format!("{k:06}_albedo.png")), &alb)
}

/// Mean linear luminance and the fraction of pixels with a channel at 1.0.
pub fn frame_stats(f: &Frame) -> (f64, f64) {
    let n = (f.width * f.height) as f64;
    let mut mean = 0.0;
    let mut sat = 0usize;
    for c in f.rgb.chunks_exact(3) {
        mean += (0.2126 * c[0] + 0.7152 * c[1] + 0.0722 * c[2]) as f64;
        if c.iter().any(|&v| v >= 1.0) {
            sat += 1;
        }
    }
    (mean / n, sat as f64 / n)
}
