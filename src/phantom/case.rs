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
use super::baked_albedo::{AlbedoSampling, PhantomAlbedo};
use super::ct_volume::{make_ct_phantom, CtPhantomOptions};
use super::from_mask::{ct_from_mask_file, FromMaskOptions};
use super::mask_path::mask_centreline;
use super::motion_blur::MotionBlur;
use super::path::{camera_path, novel_views, tree_centreline, PathOptions, SmoothPath};
use super::pose_noise::PoseNoise;
use super::render::{LightModel, SensorModel};
use super::truth_mesh::{mask_truth_mesh, tree_truth_mesh};
use crate::camera::Camera;
use crate::image::Frame;
use crate::io::nifti::write_nifti;
use crate::math::Point3;
use crate::mesh::TriMesh;
use crate::raycast::Scene;
use crate::volume::Volume;
use crate::{Error, Result};
use serde::Serialize;
use std::path::{Path, PathBuf};
use std::time::Instant;

mod frames;
mod truth;
use frames::{write_frames, FrameGain};
use truth::{write_manifest, write_truth};

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
    /// Burn a scope's overlay into the frames (black border around an octagonal field of
    /// view, on-screen text over the image) and write the matching CASE/mask.png.
    pub scope_overlay: bool,
    /// Tracker-like error of the poses written to poses.json (the true ones go to
    /// truth/poses.json either way); zero by default.
    pub pose_noise: PoseNoise,
    /// Motion blur of a share of the frames (none by default).
    pub motion_blur: MotionBlur,
    /// How the albedo is evaluated; `None` = baked for long videos (more than
    /// [`BAKE_ABOVE_PIXELS`] frame pixels), procedural otherwise.
    pub albedo_sampling: Option<AlbedoSampling>,
    /// Replace an existing `out` folder.
    pub force: bool,
    /// No progress bar.
    pub quiet: bool,
}

/// Frame pixels (frames x width x height) above which the albedo is baked by default: the
/// bake costs about what 25 million procedural hits do (the demo's video is 8 million).
pub const BAKE_ABOVE_PIXELS: u64 = 50_000_000;

/// Lattice spacing (mm) of the baked albedo by default: a quarter of the finest vessels' width
/// (0.3 mm), so the vessel profile keeps its shape.
pub const BAKED_SPACING_MM: f64 = 0.075;

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
            motion_blur: MotionBlur::default(),
            albedo_sampling: None,
            force: false,
            quiet: true,
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
    /// Frames with motion blur (indices).
    pub blurred_frames: Vec<usize>,
    /// How the albedo was evaluated.
    pub albedo: Option<AlbedoSampling>,
    /// Seconds: CT, truth mesh, path, frames, truth views, writing the CT.
    pub seconds: [f64; 6],
}

impl PhantomOptions {
    /// The albedo sampling asked for, or the default for the video's size.
    pub fn resolved_albedo_sampling(&self) -> AlbedoSampling {
        self.albedo_sampling.unwrap_or_else(|| {
            let pixels = self.frames as u64 * self.width as u64 * self.height as u64;
            if pixels > BAKE_ABOVE_PIXELS {
                AlbedoSampling::Baked {
                    spacing_mm: BAKED_SPACING_MM,
                }
            } else {
                AlbedoSampling::Procedural
            }
        })
    }
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

/// The airway of the case: its CT, the true lumen mesh, the signed distance the camera path
/// is checked against and the centreline it follows.
struct Anatomy {
    ct: Volume<f32>,
    mesh: TriMesh,
    sdf: SdfFn,
    centreline: Vec<Point3<f64>>,
}

/// What the frames and the truth views are rendered from.
struct Stage<'a> {
    opts: &'a PhantomOptions,
    scene: Scene,
    albedo: PhantomAlbedo,
}

fn write_into(dir: &Path, opts: &PhantomOptions) -> Result<PhantomSummary> {
    let mut sm = PhantomSummary::default();
    let seed = opts.seed;
    let anatomy = make_anatomy(opts, &mut sm)?;
    let mesh = &anatomy.mesh;
    sm.ct_dims = anatomy.ct.dims;
    sm.mesh_vertices = mesh.positions.len();
    sm.mesh_triangles = mesh.triangles.len();

    let t = Instant::now();
    let mut po = opts.path.clone();
    po.frames = opts.frames;
    po.seed = seed.wrapping_mul(131).wrapping_add(3);
    let path = SmoothPath::new(&anatomy.centreline, 0.5, po.smoothing_mm)?;
    let poses = camera_path(&path, &*anatomy.sdf, &po)?;
    let views = novel_views(&path, &*anatomy.sdf, opts.novel_views, &po)?;
    sm.seconds[2] = t.elapsed().as_secs_f64();

    let t = Instant::now();
    let scene = Scene::new(mesh)?;
    let sampling = opts.resolved_albedo_sampling();
    sm.albedo = Some(sampling);
    let stage = Stage {
        opts,
        albedo: PhantomAlbedo::new(phantom_albedo(seed), sampling, &scene),
        scene,
    };
    let camera = phantom_camera(opts.width, opts.height);
    let gains = write_frames(dir, &stage, &camera, &poses, &mut sm)?;
    sm.seconds[3] = t.elapsed().as_secs_f64();

    let t = Instant::now();
    let truth = dir.join("truth");
    sm.views = write_truth(&truth, &stage, mesh, &camera, &views, gains)?;
    sm.seconds[4] = t.elapsed().as_secs_f64();

    let t = Instant::now();
    // Real CT is stored as 16-bit integers.
    let hu = anatomy
        .ct
        .map(|v| v.round().clamp(-32768.0, 32767.0) as i16);
    write_nifti(&dir.join("ct.nii.gz"), &hu)?;
    sm.seconds[5] = t.elapsed().as_secs_f64();
    write_manifest(&truth, opts, &sm)?;
    Ok(sm)
}

/// The CT, the truth mesh, the signed distance and the centreline: from the built-in tree, or
/// from the mask `opts.anatomy`. Their seconds go to `sm.seconds[0]` (CT) and `[1]` (mesh).
fn make_anatomy(opts: &PhantomOptions, sm: &mut PhantomSummary) -> Result<Anatomy> {
    let seed = opts.seed;
    let t = Instant::now();
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
            let centreline = tree_centreline(&ph.tree);
            let tree = ph.tree;
            Ok(Anatomy {
                ct: ph.ct,
                mesh,
                sdf: Box::new(move |p| tree.lumen_sdf(*p)),
                centreline,
            })
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
            Ok(Anatomy {
                ct: ph.ct,
                mesh,
                sdf: Box::new(move |p| sdf.sample_world(*p).map_or(1.0, |v| v as f64)),
                centreline: cl.points,
            })
        }
    }
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
