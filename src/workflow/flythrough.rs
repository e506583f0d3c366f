//! `bronchosim flythrough MODEL --out DIR`: fly along the airway's centre line through the
//! textured region and write the frames (DIR/frame_0000.png …), their poses (DIR/path.json,
//! the poses.json schema, so `bronchosim render MODEL --views DIR/path.json` reproduces them)
//! and, when ffmpeg is installed, DIR/flythrough.mp4.
//!
//! The path runs from the first training camera to the last (the video goes from the trachea
//! into the bronchi, so that stretch is textured): both centres are snapped to the nearest
//! voxel of the model's segmentation.nii.gz, joined by the centred Dijkstra path
//! ([`crate::volume::geodesic::centred_path`]), smoothed ([`SmoothPath`]) and sampled at equal
//! arc steps. Each camera looks at the path point `look_ahead_mm` ahead; image "down" starts as
//! the first training camera's and is parallel-transported along the path (no roll).

use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::Instant;

use crate::camera::pose::camera_centre;
use crate::camera::Camera;
use crate::camera::Pose;
use crate::io::nifti::read_nifti;
use crate::io::output_dir::OutputDir;
use crate::io::png::write_png_srgb8;
use crate::io::poses::{write_poses, FrameRef, PoseEntry};
use crate::math::{Affine, Point3, Vector3};
use crate::model::Model;
use crate::phantom::path::{look_pose, SmoothPath};
use crate::render::{render_view_with, RenderOptions, ViewRays};
use crate::shading::paper::PsiLookup;
use crate::volume::geodesic::{centred_path, inside_distance};
use crate::volume::Volume;
use crate::workflow::progress::Progress;
use crate::{Error, Result};

/// Options of [`flythrough`]. Lengths in mm.
#[derive(Clone, Debug)]
pub struct FlythroughOptions {
    /// Number of frames (at least 2).
    pub frames: usize,
    /// Frame rate of the video (frames per second).
    pub fps: u32,
    /// The camera to render with (default: the model's training camera).
    pub camera: Option<Camera>,
    /// How the paper's fitted viewpoints are chosen (default: k-nearest blending, no jumps).
    pub psi_lookup: PsiLookup,
    /// Arc step of the resampled centre line (mm).
    pub step_mm: f64,
    /// Gaussian smoothing of the centre line (mm, standard deviation along the arc).
    pub smoothing_mm: f64,
    /// Each camera looks at the path point this far ahead (mm).
    pub look_ahead_mm: f64,
    /// Largest distance (mm) from the first/last training camera to the airway mask.
    pub max_snap_mm: f64,
    /// Expose each frame with the scope's learnt auto-exposure (calibrated light; see
    /// [`RenderOptions::auto_exposure`]) rather than at the fixed reference gain.
    pub auto_exposure: bool,
    /// Replace an existing output folder.
    pub force: bool,
    /// No progress bar.
    pub quiet: bool,
}

impl Default for FlythroughOptions {
    fn default() -> Self {
        FlythroughOptions {
            frames: 120,
            fps: 25,
            camera: None,
            psi_lookup: PsiLookup::default(),
            step_mm: 0.5,
            smoothing_mm: 3.0,
            look_ahead_mm: 8.0,
            max_snap_mm: 3.0,
            auto_exposure: true,
            force: false,
            quiet: false,
        }
    }
}

/// What [`flythrough`] wrote.
#[derive(Clone, Debug)]
pub struct FlythroughSummary {
    /// The output folder.
    pub out: PathBuf,
    /// Frames written.
    pub frames: usize,
    /// Length of the smoothed path (mm).
    pub path_length_mm: f64,
    /// Smallest distance (mm) from a camera centre to the wall of the mask (distance transform,
    /// trilinear).
    pub min_clearance_mm: f64,
    /// The video, when ffmpeg made one.
    pub video: Option<PathBuf>,
    /// Why there is no video (ffmpeg missing or failing), or which encoder made it.
    pub video_note: String,
    /// Seconds spent rendering and writing the frames.
    pub render_seconds: f64,
}

/// Fly through the model folder `model_dir` into `out` (atomically; an existing `out` is
/// replaced only with `opts.force`).
pub fn flythrough(
    model_dir: &Path,
    out: &Path,
    opts: &FlythroughOptions,
) -> Result<FlythroughSummary> {
    if opts.frames < 2 || opts.fps == 0 {
        return Err(Error::BadOptions {
            stage: "flythrough",
            message: format!(
                "need at least 2 frames and a positive frame rate (got {} frames, {} fps)",
                opts.frames, opts.fps
            ),
        });
    }
    let model = Model::load(model_dir)?;
    let seg_path = model_dir.join("segmentation.nii.gz");
    let mask = read_lumen_mask(&seg_path)?;
    let (poses, path_length_mm, min_clearance_mm) =
        training_path_poses(&model, &mask, &seg_path, opts)?;

    let dir = OutputDir::create(out, opts.force)?;
    let camera = opts.camera.unwrap_or(model.manifest.camera);
    let rays = ViewRays::new(&camera, 1)?;
    let ropts = RenderOptions {
        psi_lookup: opts.psi_lookup,
        auto_exposure: opts.auto_exposure,
        ..Default::default()
    };
    let inputs = model.render_inputs();
    let progress = Progress::new("flythrough", poses.len() as u64, opts.quiet);
    let t = Instant::now();
    let mut entries = Vec::with_capacity(poses.len());
    for (i, pose) in poses.iter().enumerate() {
        let (frame, _) = render_view_with(&inputs, &rays, pose, &ropts)?;
        let path = dir.join(format!("frame_{i:04}.png"));
        write_png_srgb8(&path, &frame)?;
        entries.push(PoseEntry {
            frame: FrameRef::Image(path),
            pose: Pose::new(*pose),
        });
        progress.inc();
    }
    progress.finish();
    let render_seconds = t.elapsed().as_secs_f64();
    write_poses(&dir.join("path.json"), &entries, dir.path())?;
    let (video, video_note) = match encode_video(dir.path(), opts.fps) {
        Ok(encoder) => (
            Some(out.join("flythrough.mp4")),
            format!("flythrough.mp4 encoded with {encoder}"),
        ),
        Err(note) => (None, note),
    };
    let out = dir.commit()?;
    Ok(FlythroughSummary {
        out,
        frames: poses.len(),
        path_length_mm,
        min_clearance_mm,
        video,
        video_note,
        render_seconds,
    })
}

/// The model's airway mask (segmentation.nii.gz at `path`) as 0/1 voxels.
pub fn read_lumen_mask(path: &Path) -> Result<Volume<u8>> {
    Ok(read_nifti(path)?.map(|v| u8::from(v > 0.5)))
}

/// The flythrough poses of `model` through `mask` (its segmentation, read from `mask_path`):
/// from the first fitted viewpoint to the last, image "down" starting as the first one's.
/// Also the path length (mm) and the smallest wall clearance of a camera centre (mm).
pub fn training_path_poses(
    model: &Model,
    mask: &Volume<u8>,
    mask_path: &Path,
    opts: &FlythroughOptions,
) -> Result<(Vec<Affine>, f64, f64)> {
    let vps = &model.shading.viewpoints;
    let first_pose = Affine::from_row_slice(&vps[0].camera_to_world);
    let first = camera_centre(&first_pose);
    let last = camera_centre(&Affine::from_row_slice(&vps[vps.len() - 1].camera_to_world));
    let down0 = Vector3::new(first_pose[(0, 1)], first_pose[(1, 1)], first_pose[(2, 1)]);
    flythrough_poses(mask, mask_path, first, last, down0, opts)
}

/// The flythrough camera poses (camera→world) through `mask` (nonzero = lumen; `mask_path`
/// names it in errors) from `first` to `last` (world mm), with image "down" starting along
/// `down0`; also the path length (mm) and the smallest wall clearance of a centre (mm).
pub fn flythrough_poses(
    mask: &Volume<u8>,
    mask_path: &Path,
    first: Point3<f64>,
    last: Point3<f64>,
    down0: Vector3<f64>,
    opts: &FlythroughOptions,
) -> Result<(Vec<Affine>, f64, f64)> {
    let dt = inside_distance(mask);
    let a = snap(mask, first, opts.max_snap_mm)
        .ok_or_else(|| outside(mask_path, "first", first, opts.max_snap_mm))?;
    let b = snap(mask, last, opts.max_snap_mm)
        .ok_or_else(|| outside(mask_path, "last", last, opts.max_snap_mm))?;
    let voxels = centred_path(mask, &dt, a, b).map_err(|e| {
        Error::invalid(
            mask_path,
            format!("no airway path from the first to the last training camera ({e})"),
        )
    })?;
    let dims = mask.dims;
    let mut poly: Vec<Point3<f64>> = vec![first];
    poly.extend(voxels.iter().map(|&i| {
        mask.index_to_world(Point3::new(
            (i % dims[0]) as f64,
            ((i / dims[0]) % dims[1]) as f64,
            (i / (dims[0] * dims[1])) as f64,
        ))
    }));
    poly.push(last);
    poly.dedup_by(|p, q| (*p - *q).norm() < 1e-9);
    let path = SmoothPath::new(&poly, opts.step_mm, opts.smoothing_mm).map_err(|e| {
        Error::invalid(
            mask_path,
            format!("the path between the first and last training cameras is too short: {e}"),
        )
    })?;
    let len = path.length();
    let end_t = path.tangent(len);
    // Past the end the look-ahead target continues straight along the last tangent.
    let ahead = |s: f64| {
        if s <= len {
            path.at(s)
        } else {
            path.at(len) + end_t * (s - len)
        }
    };
    let dt_vol = Volume::from_data(dims, mask.affine, dt)?;
    let mut down = down0;
    let mut min_clear = f64::INFINITY;
    let n = opts.frames;
    let mut poses = Vec::with_capacity(n);
    for i in 0..n {
        let s = len * i as f64 / (n - 1) as f64;
        let c = path.at(s);
        let t = path.tangent(s);
        let f = (ahead(s + opts.look_ahead_mm) - c)
            .try_normalize(1e-9)
            .unwrap_or(t);
        // Parallel transport of "down": remove its component along the new tangent.
        down = (down - t * down.dot(&t))
            .try_normalize(1e-9)
            .unwrap_or_else(|| t.cross(&Vector3::x()).normalize());
        poses.push(look_pose(&c, &f, &down, 0.0));
        min_clear = min_clear.min(dt_vol.sample_world(c).unwrap_or(0.0) as f64);
    }
    Ok((poses, len, min_clear))
}

fn outside(mask_path: &Path, which: &str, p: Point3<f64>, max_mm: f64) -> Error {
    Error::invalid(
        mask_path,
        format!(
            "the {which} training camera ({:.1}, {:.1}, {:.1}) mm is more than {max_mm} mm \
             outside the airway mask",
            p.x, p.y, p.z
        ),
    )
}

/// The flat index of the mask voxel nearest to `p` (world mm) within `max_mm`, if any.
fn snap(mask: &Volume<u8>, p: Point3<f64>, max_mm: f64) -> Option<usize> {
    let ijk = mask.world_to_index(p);
    let sp = mask.spacing();
    // Index ranges of the box of half-width `max_mm` around `p`, clamped to the grid (empty
    // when the box misses it).
    let range = |k: usize| {
        let lo = (ijk[k] - max_mm / sp[k]).floor().max(0.0);
        let hi = (ijk[k] + max_mm / sp[k])
            .ceil()
            .min(mask.dims[k] as f64 - 1.0);
        lo as usize..(hi + 1.0).max(lo) as usize
    };
    let mut best: Option<(f64, usize)> = None;
    for z in range(2) {
        for y in range(1) {
            for x in range(0) {
                let i = mask.index(x, y, z);
                if mask.data[i] == 0 {
                    continue;
                }
                let d = (mask.index_to_world(Point3::new(x as f64, y as f64, z as f64)) - p).norm();
                if d <= max_mm && best.is_none_or(|(bd, _)| d < bd) {
                    best = Some((d, i));
                }
            }
        }
    }
    best.map(|(_, i)| i)
}

/// Encode DIR/frame_%04d.png into DIR/flythrough.mp4: H.264 (yuv420p), or MPEG-4 part 2 when
/// libx264 is not available. Returns the encoder used, or why there is no video.
fn encode_video(dir: &Path, fps: u32) -> std::result::Result<&'static str, String> {
    let mp4 = dir.join("flythrough.mp4");
    let mut last_error = String::new();
    for (encoder, extra) in [("libx264", ["-crf", "18"]), ("mpeg4", ["-q:v", "3"])] {
        let output = Command::new("ffmpeg")
            .args(["-y", "-v", "error", "-framerate", &fps.to_string()])
            .arg("-i")
            .arg(dir.join("frame_%04d.png"))
            // yuv420p needs even sizes; pad by one pixel when odd.
            .args(["-vf", "pad=ceil(iw/2)*2:ceil(ih/2)*2", "-c:v", encoder])
            .args(extra)
            .args(["-pix_fmt", "yuv420p", "-movflags", "+faststart"])
            .arg(&mp4)
            .stdin(Stdio::null())
            .output();
        match output {
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => {
                return Err("ffmpeg not found: frames only (install ffmpeg for the video)".into())
            }
            Err(e) => return Err(format!("ffmpeg could not start ({e}): frames only")),
            Ok(o) if o.status.success() && mp4.is_file() => return Ok(encoder),
            Ok(o) => {
                let stderr = String::from_utf8_lossy(&o.stderr);
                last_error = stderr
                    .lines()
                    .rev()
                    .find(|l| !l.trim().is_empty())
                    .unwrap_or("no message")
                    .trim()
                    .to_string();
                let _ = std::fs::remove_file(&mp4);
            }
        }
    }
    Err(format!(
        "ffmpeg could not encode the video ({last_error}): frames only"
    ))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A bent tube of radius 4 mm on a 0.5 mm grid: along +z from (10, 10, 2) to (10, 10, 25),
    /// then along +x to (38, 10, 25).
    fn bent_tube() -> Volume<u8> {
        let dims = [84, 40, 64];
        let mut a = Affine::identity();
        for k in 0..3 {
            a[(k, k)] = 0.5;
        }
        let mut m = Volume::filled(dims, a, 0u8);
        let seg = |p: Point3<f64>, a: Point3<f64>, b: Point3<f64>| {
            let ab = b - a;
            let t = ((p - a).dot(&ab) / ab.norm_squared()).clamp(0.0, 1.0);
            (p - (a + ab * t)).norm()
        };
        let (p0, p1, p2) = (
            Point3::new(10.0, 10.0, 2.0),
            Point3::new(10.0, 10.0, 25.0),
            Point3::new(38.0, 10.0, 25.0),
        );
        for z in 0..dims[2] {
            for y in 0..dims[1] {
                for x in 0..dims[0] {
                    let p = m.index_to_world(Point3::new(x as f64, y as f64, z as f64));
                    if seg(p, p0, p1).min(seg(p, p1, p2)) <= 4.0 {
                        m.set(x, y, z, 1);
                    }
                }
            }
        }
        m
    }

    #[test]
    fn poses_follow_the_centre_of_a_bent_tube_evenly() {
        let m = bent_tube();
        let opts = FlythroughOptions {
            frames: 20,
            ..Default::default()
        };
        // Start 1.5 mm off-centre, end on the axis.
        let first = Point3::new(11.5, 10.0, 4.0);
        let last = Point3::new(36.0, 10.0, 25.0);
        let down0 = Vector3::new(0.0, -1.0, 0.0);
        let (poses, len, clear) =
            flythrough_poses(&m, Path::new("seg.nii.gz"), first, last, down0, &opts).unwrap();
        assert_eq!(poses.len(), 20);
        // Roughly 21 mm down the first leg and 26 mm along the second, less the cut corner.
        assert!(len > 38.0 && len < 49.0, "length {len}");
        assert!(clear > 2.0, "clearance {clear}");
        let c: Vec<Point3<f64>> = poses.iter().map(camera_centre).collect();
        // The resampled path ends within one step (0.5 mm) of the last camera.
        let (d0, d1) = ((c[0] - first).norm(), (c[19] - last).norm());
        assert!(d0 < 1e-6 && d1 < 0.5, "ends {d0} mm, {d1} mm off");
        let steps: Vec<f64> = c.windows(2).map(|w| (w[1] - w[0]).norm()).collect();
        let (lo, hi) = steps
            .iter()
            .fold((f64::INFINITY, 0.0f64), |(a, b), &s| (a.min(s), b.max(s)));
        assert!(hi / lo < 1.2, "steps {lo}..{hi}");
        for (i, p) in poses.iter().enumerate() {
            // Rotations orthonormal, no roll: image x stays perpendicular to world y (the
            // tube bends in the x-z plane, so the transported "down" stays -y).
            let r = p.fixed_view::<3, 3>(0, 0).into_owned();
            assert!((r.transpose() * r - crate::math::Matrix3::identity()).norm() < 1e-9);
            assert!((r.determinant() - 1.0).abs() < 1e-9);
            assert!(r[(1, 0)].abs() < 1e-6, "pose {i}: rolled");
            assert!(r[(1, 1)] < -0.999, "pose {i}: down is {:?}", r.column(1));
        }
        // Looks along the tube: down (+z) at the start, along +x at the end.
        assert!(poses[0][(2, 2)] > 0.9 && poses[19][(0, 2)] > 0.9);
    }

    #[test]
    fn cameras_outside_the_mask_or_disconnected_are_errors_naming_the_file() {
        let mut m = bent_tube();
        let opts = FlythroughOptions::default();
        let down = Vector3::new(0.0, -1.0, 0.0);
        let inside = Point3::new(10.0, 10.0, 4.0);
        let far = Point3::new(30.0, 10.0, 5.0); // 16 mm from the tube
        let e = flythrough_poses(&m, Path::new("seg.nii.gz"), inside, far, down, &opts)
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("seg.nii.gz") && e.contains("last training camera"),
            "{e}"
        );
        // Cut the tube: no path.
        for y in 0..40 {
            for x in 0..84 {
                m.set(x, y, 30, 0);
            }
        }
        let e = flythrough_poses(
            &m,
            Path::new("seg.nii.gz"),
            inside,
            Point3::new(36.0, 10.0, 25.0),
            down,
            &opts,
        )
        .unwrap_err()
        .to_string();
        assert!(
            e.contains("seg.nii.gz") && e.contains("no airway path"),
            "{e}"
        );
    }
}
