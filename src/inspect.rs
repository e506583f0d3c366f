//! `bronchosim inspect`: validate a whole case, or a bare CT (a NIfTI file or a DICOM folder),
//! and summarise it for a person (or, as JSON, a machine).

pub mod ct;

pub use ct::{summarize_ct, CtSummary, NonFiniteVoxels};

use crate::io::case::Case;
use crate::io::ct::{ct_folder_source, read_ct, CtSource};
use crate::io::image_mask::{detect_black_border, BlackBorder};
use crate::math::Point3;
use crate::{Error, Result};
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
    /// Share of each frame's pixels that mask.png marks as image, when the case has one.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub mask_image_share: Option<f64>,
    /// Without mask.png: a border that is black in every frame looked at.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub black_border: Option<BlackBorder>,
}

/// Everything `inspect` found.
#[derive(Clone, Debug, Serialize)]
pub struct InspectReport {
    /// The case folder, or the CT file or folder when `kind` is "ct".
    pub case: String,
    /// "case" (a case folder) or "ct" (a bare CT: only `ct` is filled in).
    pub kind: &'static str,
    /// CT summary.
    pub ct: CtSummary,
    /// Camera summary (cases only).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub camera: Option<CameraSummary>,
    /// Frames and poses summary (cases only).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub video: Option<VideoSummary>,
    /// Warnings a person should read.
    pub warnings: Vec<String>,
}

/// Frames looked at for a constant black border (spread over the video).
const BORDER_FRAMES: usize = 8;

/// Entries whose presence makes a folder a case (CASE_FORMAT.md) rather than a DICOM series.
const CASE_ENTRIES: &[&str] = &[
    "ct.nii.gz",
    "ct.nii",
    "ct",
    "camera.json",
    "camera.yml",
    "camera.xml",
    "poses.json",
    "frames",
    "video.mp4",
];

/// Inspect `path`: a case folder, a NIfTI file or a CT folder. A folder holding any
/// case-format entry (ct.nii.gz, camera.json, poses.json, frames/, ...) is a case, so that a
/// case missing its CT is reported as such; any other folder is a CT: the one NIfTI file it
/// holds besides documents (a downloaded scan with its licence and read-me), or else a DICOM
/// series.
pub fn inspect(path: &Path, opts: &InspectOptions) -> Result<InspectReport> {
    if path.is_file() {
        return inspect_ct(&CtSource::Nifti(path.to_path_buf()));
    }
    if path.is_dir() && !CASE_ENTRIES.iter().any(|e| path.join(e).exists()) {
        return inspect_ct(&ct_folder_source(path)?);
    }
    if !path.exists() {
        return Err(Error::missing(
            path,
            "case folder, NIfTI file or DICOM folder",
        ));
    }
    inspect_case(path, opts)
}

/// Read and summarise a bare CT. Any invalid part is an error naming its file.
pub fn inspect_ct(source: &CtSource) -> Result<InspectReport> {
    let (vol, info) = read_ct(source)?;
    let ct = summarize_ct(&vol, source, &info);
    let mut warnings = info.warnings.clone();
    warnings.extend(ct.warnings());
    Ok(InspectReport {
        case: source.path().display().to_string(),
        kind: "ct",
        ct,
        camera: None,
        video: None,
        warnings,
    })
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
    let ct_summary = summarize_ct(ct, &case.ct_source, &case.ct_info);
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
    warnings.extend(ct_summary.warnings());
    if in_air < centres.len() {
        warnings.push(format!(
            "{} of {} camera centres are not in air (CT >= {AIR_HU} HU or outside the CT): check the registration of poses.json to the CT",
            centres.len() - in_air,
            centres.len()
        ));
    }
    let black_border = match &case.mask {
        Some(_) => None,
        None => {
            let n = case.frame_count();
            let wanted: Vec<usize> = (0..BORDER_FRAMES).map(|k| k * n / BORDER_FRAMES).collect();
            let frames = case.frames_at(&wanted)?;
            detect_black_border(frames.values())
        }
    };
    if let Some(b) = &black_border {
        warnings.push(format!(
            "{:.0}% of every frame is a black border (outside the scope's field of view?) and the \
             case has no mask.png: add one (white = image) so that the border and any burnt-in \
             text enter no fit and no texture",
            100.0 * b.share
        ));
    }
    let cam = &case.camera;
    let fov = cam.field_of_view();
    Ok(InspectReport {
        case: dir.display().to_string(),
        kind: "case",
        ct: ct_summary,
        camera: Some(CameraSummary {
            path: case.camera_path.display().to_string(),
            size: [cam.width, cam.height],
            focal_px: [cam.fx, cam.fy],
            principal_point_px: [cam.cx, cam.cy],
            fov_deg: [fov.horizontal, fov.vertical],
            distortion: [cam.k1, cam.k2, cam.p1, cam.p2, cam.k3],
            max_distortion_px: cam.max_distortion_px(),
        }),
        video: Some(VideoSummary {
            kind: case.frames.kind().to_string(),
            path: case.frames.path().display().to_string(),
            frames,
            poses: case.poses.len(),
            frames_decoded: opts.decode_all_frames,
            path_length_mm,
            centres_in_air: in_air,
            centres_outside_ct: outside,
            mask_image_share: case.mask.as_ref().map(|m| m.image_share()),
            black_border,
        }),
        warnings,
    })
}

impl InspectReport {
    /// The summary as a few lines a person can check at a glance.
    pub fn to_text(&self) -> String {
        let mut s = String::new();
        if self.kind == "case" {
            let _ = writeln!(s, "case    {}", self.case);
        }
        s.push_str(&self.ct.to_text());
        if let (Some(m), Some(v)) = (&self.camera, &self.video) {
            camera_video_text(&mut s, m, v);
        }
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

/// The camera, frames and poses lines of a case's summary.
fn camera_video_text(s: &mut String, m: &CameraSummary, v: &VideoSummary) {
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
    match (v.mask_image_share, &v.black_border) {
        (Some(share), _) => {
            let _ = writeln!(
                s,
                "        mask.png: {:.1}% of each frame is image",
                100.0 * share
            );
        }
        (None, Some(b)) => {
            let _ = writeln!(
                s,
                "        no mask.png; {:.1}% of each frame is black in all {} frames looked at",
                100.0 * b.share,
                b.frames
            );
        }
        (None, None) => {}
    }
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
}
