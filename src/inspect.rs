//! `bronchosim inspect`: validate a whole case and summarise it for a person (or, as JSON, a machine).

use crate::io::case::Case;
use crate::math::Point3;
use crate::Result;
use serde::Serialize;
use std::fmt::Write as _;
use std::path::Path;

/// HU below which a camera centre counts as "in air" (the lumen is about -1000 HU).
pub const AIR_HU: f32 = -700.0;

/// How thoroughly to check.
#[derive(Clone, Debug)]
pub struct InspectOptions {
    /// Decode every frame (PNG or video) instead of reading only headers: slower, catches
    /// corrupt frames.
    pub decode_all_frames: bool,
}

impl Default for InspectOptions {
    fn default() -> Self {
        InspectOptions {
            decode_all_frames: true,
        }
    }
}

/// The CT part of the summary.
#[derive(Clone, Debug, Serialize)]
pub struct CtSummary {
    /// File or folder the CT came from.
    pub path: String,
    /// "nifti" or "dicom".
    pub format: String,
    /// Where the affine came from.
    pub affine_source: String,
    /// Grid size in voxels.
    pub dims: [usize; 3],
    /// Voxel spacing (mm).
    pub spacing_mm: [f64; 3],
    /// Orientation code of the grid axes, e.g. "LPS".
    pub orientation: String,
    /// Minimum and maximum HU.
    pub hu_range: [f32; 2],
    /// 1st and 99th percentile HU.
    pub hu_p1_p99: [f32; 2],
    /// World bounding box of the voxel centres (mm, RAS): [min, max].
    pub world_bounds_mm: [[f64; 3]; 2],
}

/// The camera part of the summary.
#[derive(Clone, Debug, Serialize)]
pub struct CameraSummary {
    /// The camera file.
    pub path: String,
    /// Image size (pixels).
    pub size: [u32; 2],
    /// Focal lengths (pixels).
    pub focal_px: [f64; 2],
    /// Principal point (pixels).
    pub principal_point_px: [f64; 2],
    /// Horizontal and vertical field of view (degrees), through the lens distortion.
    pub fov_deg: [f64; 2],
    /// k1, k2, p1, p2, k3.
    pub distortion: [f64; 5],
    /// Largest displacement distortion causes inside the image (pixels).
    pub max_distortion_px: f64,
}

/// The video part of the summary.
#[derive(Clone, Debug, Serialize)]
pub struct VideoSummary {
    /// "png" (frames/) or "video" (the video file).
    pub kind: String,
    /// frames/ or the video file.
    pub path: String,
    /// Number of frames.
    pub frames: usize,
    /// Number of poses in poses.json.
    pub poses: usize,
    /// Whether every frame was decoded (not only its header read).
    pub frames_decoded: bool,
    /// Length of the camera path through the centres (mm).
    pub path_length_mm: f64,
    /// Camera centres where the CT is below [`AIR_HU`].
    pub centres_in_air: usize,
    /// Camera centres outside the CT grid.
    pub centres_outside_ct: usize,
}

/// Everything `inspect` found.
#[derive(Clone, Debug, Serialize)]
pub struct InspectReport {
    /// The case folder.
    pub case: String,
    /// CT summary.
    pub ct: CtSummary,
    /// Camera summary.
    pub camera: CameraSummary,
    /// Frames and poses summary.
    pub video: VideoSummary,
    /// Warnings a person should read.
    pub warnings: Vec<String>,
}

/// Validate the case in `dir` and summarise it. Any invalid part is an error naming its file.
pub fn inspect_case(dir: &Path, opts: &InspectOptions) -> Result<InspectReport> {
    let case = Case::open(dir)?;
    let frames = if opts.decode_all_frames {
        case.decode_all_frames()?
    } else {
        case.frame_count()
    };
    let ct = &case.ct;
    let mut sorted: Vec<f32> = ct
        .data
        .iter()
        .copied()
        .step_by((ct.len() / 2_000_000).max(1))
        .collect();
    sorted.sort_unstable_by(f32::total_cmp);
    let pct = |q: f64| sorted[((sorted.len() - 1) as f64 * q).round() as usize];
    let (lo, hi) = ct.world_bounds();
    let (mut min, mut max) = (f32::INFINITY, f32::NEG_INFINITY);
    for &v in &ct.data {
        min = min.min(v);
        max = max.max(v);
    }
    let centres: Vec<Point3<f64>> = case.poses.iter().map(|p| p.pose.centre()).collect();
    let path_length_mm = centres.windows(2).map(|w| (w[1] - w[0]).norm()).sum();
    let mut in_air = 0;
    let mut outside = 0;
    for c in &centres {
        match ct.sample_world(*c) {
            Some(hu) if hu < AIR_HU => in_air += 1,
            Some(_) => {}
            None => outside += 1,
        }
    }
    let mut warnings = case.ct_info.warnings.clone();
    if in_air < centres.len() {
        warnings.push(format!(
            "{} of {} camera centres are not in air (CT >= {AIR_HU} HU or outside the CT): check the registration of poses.json to the CT",
            centres.len() - in_air,
            centres.len()
        ));
    }
    let cam = &case.camera;
    let fov = cam.field_of_view();
    Ok(InspectReport {
        case: dir.display().to_string(),
        ct: CtSummary {
            path: case.ct_source.path().display().to_string(),
            format: case.ct_info.format.to_string(),
            affine_source: case.ct_info.affine_source.clone(),
            dims: ct.dims,
            spacing_mm: ct.spacing(),
            orientation: ct.orientation(),
            hu_range: [min, max],
            hu_p1_p99: [pct(0.01), pct(0.99)],
            world_bounds_mm: [[lo.x, lo.y, lo.z], [hi.x, hi.y, hi.z]],
        },
        camera: CameraSummary {
            path: case.camera_path.display().to_string(),
            size: [cam.width, cam.height],
            focal_px: [cam.fx, cam.fy],
            principal_point_px: [cam.cx, cam.cy],
            fov_deg: [fov.horizontal, fov.vertical],
            distortion: [cam.k1, cam.k2, cam.p1, cam.p2, cam.k3],
            max_distortion_px: cam.max_distortion_px(),
        },
        video: VideoSummary {
            kind: case.frames.kind().to_string(),
            path: case.frames.path().display().to_string(),
            frames,
            poses: case.poses.len(),
            frames_decoded: opts.decode_all_frames,
            path_length_mm,
            centres_in_air: in_air,
            centres_outside_ct: outside,
        },
        warnings,
    })
}

impl InspectReport {
    /// The summary as a few lines a person can check at a glance.
    pub fn to_text(&self) -> String {
        let mut s = String::new();
        let c = &self.ct;
        let _ = writeln!(s, "case    {}", self.case);
        let _ = writeln!(
            s,
            "CT      {} ({}, affine from {})",
            c.path, c.format, c.affine_source
        );
        let _ = writeln!(
            s,
            "        {} x {} x {} voxels, spacing {:.3} x {:.3} x {:.3} mm, orientation {}",
            c.dims[0],
            c.dims[1],
            c.dims[2],
            c.spacing_mm[0],
            c.spacing_mm[1],
            c.spacing_mm[2],
            c.orientation
        );
        let _ = writeln!(
            s,
            "        HU {:.0} .. {:.0} (1st-99th percentile {:.0} .. {:.0})",
            c.hu_range[0], c.hu_range[1], c.hu_p1_p99[0], c.hu_p1_p99[1]
        );
        let b = &c.world_bounds_mm;
        let _ = writeln!(
            s,
            "        world (RAS mm) x {:.1} .. {:.1}, y {:.1} .. {:.1}, z {:.1} .. {:.1}",
            b[0][0], b[1][0], b[0][1], b[1][1], b[0][2], b[1][2]
        );
        let m = &self.camera;
        let _ = writeln!(
            s,
            "camera  {} {}x{}, f {:.1}/{:.1} px, c ({:.1}, {:.1}), fov {:.1} x {:.1} deg",
            m.path,
            m.size[0],
            m.size[1],
            m.focal_px[0],
            m.focal_px[1],
            m.principal_point_px[0],
            m.principal_point_px[1],
            m.fov_deg[0],
            m.fov_deg[1]
        );
        let d = &m.distortion;
        let _ = writeln!(
            s,
            "        distortion k1 {} k2 {} p1 {} p2 {} k3 {}: up to {:.1} px",
            d[0], d[1], d[2], d[3], d[4], m.max_distortion_px
        );
        let v = &self.video;
        let _ = writeln!(
            s,
            "frames  {} {} from {}{}",
            v.frames,
            v.kind,
            v.path,
            if v.frames_decoded {
                ", all decoded"
            } else {
                " (headers only)"
            }
        );
        let _ = writeln!(
            s,
            "poses   {}, camera path {:.1} mm",
            v.poses, v.path_length_mm
        );
        let _ = writeln!(
            s,
            "        camera centres in air (< {AIR_HU} HU): {} of {}{}",
            v.centres_in_air,
            v.poses,
            if v.centres_outside_ct > 0 {
                format!(" ({} outside the CT)", v.centres_outside_ct)
            } else {
                String::new()
            }
        );
        let _ = writeln!(
            s,
            "{}",
            if self.warnings.is_empty() {
                "OK"
            } else {
                "OK, with warnings"
            }
        );
        s
    }
}
