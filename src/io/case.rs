//! A case folder (CASE_FORMAT.md): find and validate every part, load what is small, and
//! stream the frames on demand.

use crate::camera::Camera;
use crate::image::Frame;
use crate::io::camera_file::{find_camera, read_camera};
use crate::io::case_untracked::complete_poses;
use crate::io::ct::{find_ct, read_ct, CtInfo, CtSource};
use crate::io::frame_source::FrameSource;
use crate::io::image_mask::{read_case_mask, ImageMask};
use crate::io::poses::{read_poses, FrameRef, PoseEntry};
use crate::io::video::VideoReader;
use crate::volume::Volume;
use crate::{Error, Result};
use rayon::prelude::*;
use std::collections::{BTreeMap, HashSet};
use std::path::{Path, PathBuf};

/// Video containers accepted as `video.<ext>` (anything ffmpeg reads would do; these are
/// the ones a bronchoscope recorder writes).
pub const VIDEO_EXTENSIONS: [&str; 6] = ["mp4", "mkv", "avi", "mov", "webm", "mpg"];

/// Where the frames of a case are.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum FramesLocation {
    /// PNG files (in poses.json order).
    Png {
        /// The frames/ folder.
        dir: PathBuf,
        /// The files, in poses order.
        files: Vec<PathBuf>,
    },
    /// A video file and the number of frames it holds.
    Video {
        /// The video file.
        path: PathBuf,
        /// Decoded frame count.
        count: usize,
    },
}

impl FramesLocation {
    /// "png" or "video".
    pub fn kind(&self) -> &'static str {
        match self {
            FramesLocation::Png { .. } => "png",
            FramesLocation::Video { .. } => "video",
        }
    }

    /// frames/ or the video file.
    pub fn path(&self) -> &Path {
        match self {
            FramesLocation::Png { dir, .. } => dir,
            FramesLocation::Video { path, .. } => path,
        }
    }
}

/// An opened, validated case: CT, camera and poses in memory, frames streamed on demand.
#[derive(Clone, Debug)]
pub struct Case {
    /// The case folder.
    pub dir: PathBuf,
    /// Where the CT came from.
    pub ct_source: CtSource,
    /// The CT in HU, with its index→world affine (RAS mm).
    pub ct: Volume<f32>,
    /// Facts about the CT file.
    pub ct_info: CtInfo,
    /// The camera file.
    pub camera_path: PathBuf,
    /// Intrinsics and distortion.
    pub camera: Camera,
    /// poses.json.
    pub poses_path: PathBuf,
    /// Camera→world pose of every frame, in order.
    pub poses: Vec<PoseEntry>,
    /// How many of `poses` poses.json gave: every frame's, unless the case was opened with
    /// [`Case::open_untracked`] and poses.json holds fewer (then the others start at the first
    /// frame's pose, for a tracker to replace).
    pub poses_given: usize,
    /// Where the frames are.
    pub frames: FramesLocation,
    /// Which pixels of every frame are image (`mask.png`); `None`: all of them.
    pub mask: Option<ImageMask>,
}

impl Case {
    /// Open and validate the case in `dir`: every part present and well-formed, as many poses
    /// as frames, frame size equal to the camera's (checked on PNG headers / the video stream).
    pub fn open(dir: &Path) -> Result<Case> {
        Case::open_with(dir, false)
    }

    /// [`Case::open`] for a video without a tracker (`--poses first`): poses.json may hold
    /// fewer poses than the case has frames, down to the first frame's alone; the frames are
    /// then every PNG of frames/ in file-name order (or every frame of the video), see
    /// [`crate::io::case_untracked`].
    pub fn open_untracked(dir: &Path) -> Result<Case> {
        Case::open_with(dir, true)
    }

    fn open_with(dir: &Path, untracked: bool) -> Result<Case> {
        if !dir.is_dir() {
            return Err(Error::missing(dir, "case folder"));
        }
        let camera_path = find_camera(dir)?;
        let camera = read_camera(&camera_path)?;
        let poses_path = dir.join("poses.json");
        if !poses_path.is_file() {
            return Err(Error::missing(
                &poses_path,
                "poses.json (camera-to-world pose of each frame)",
            ));
        }
        let mut poses = read_poses(&poses_path, dir)?;
        let mut poses_given = poses.len();
        if untracked {
            if let Some((all, given)) = complete_poses(dir, &poses_path, &poses)? {
                (poses, poses_given) = (all, given);
            }
        }
        let frames = locate_frames(dir, &poses_path, &poses, &camera)?;
        let mask = read_case_mask(dir, &camera)?;
        let ct_source = find_ct(dir)?;
        let (ct, ct_info) = read_ct(&ct_source)?;
        Ok(Case {
            dir: dir.to_path_buf(),
            ct_source,
            ct,
            ct_info,
            camera_path,
            camera,
            poses_path,
            poses,
            poses_given,
            frames,
            mask,
        })
    }

    /// Number of frames (= number of poses, checked by [`Case::open`]).
    pub fn frame_count(&self) -> usize {
        self.poses.len()
    }

    /// The frames whose indices are in `wanted`, decoded in one pass over the frame source
    /// (stopping after the last wanted one); keyed by index.
    pub fn frames_at(&self, wanted: &[usize]) -> Result<BTreeMap<usize, Frame>> {
        let mut out = BTreeMap::new();
        let Some(last) = wanted.iter().copied().max() else {
            return Ok(out);
        };
        for (i, f) in self.frame_source()?.enumerate() {
            if i > last {
                break;
            }
            let f = f?;
            if wanted.contains(&i) {
                out.insert(i, f);
            }
        }
        if let Some(w) = wanted.iter().find(|w| !out.contains_key(w)) {
            return Err(Error::invalid(
                &self.poses_path,
                format!("frame {w} could not be read from the frame source"),
            ));
        }
        Ok(out)
    }

    /// The frames in poses order, streamed one at a time.
    pub fn frame_source(&self) -> Result<FrameSource> {
        let video = match &self.frames {
            FramesLocation::Video { path, .. } => Some(path.as_path()),
            FramesLocation::Png { .. } => None,
        };
        FrameSource::from_poses(&self.poses, video, self.camera.width, self.camera.height)
    }

    /// Decode every frame (in parallel for PNG, one streaming pass for video) to prove they
    /// are readable; returns the number of frames.
    pub fn decode_all_frames(&self) -> Result<usize> {
        match &self.frames {
            FramesLocation::Png { files, .. } => {
                files.par_iter().try_for_each(|f| {
                    let frame = crate::io::png::read_png(f)?;
                    check_frame_size(f, frame.width, frame.height, &self.camera)
                })?;
                Ok(files.len())
            }
            FramesLocation::Video { .. } => {
                let mut n = 0;
                for frame in self.frame_source()? {
                    frame?;
                    n += 1;
                }
                Ok(n)
            }
        }
    }
}

fn check_frame_size(path: &Path, w: u32, h: u32, camera: &Camera) -> Result<()> {
    if (w, h) != (camera.width, camera.height) {
        return Err(Error::invalid(
            path,
            format!(
                "image size {w}x{h} differs from the camera's {}x{}",
                camera.width, camera.height
            ),
        ));
    }
    Ok(())
}

/// PNG width and height from the header alone.
fn png_size(path: &Path) -> Result<(u32, u32)> {
    let file = std::fs::File::open(path).map_err(|e| Error::io(path, e))?;
    let decoder = png::Decoder::new(std::io::BufReader::new(file));
    let reader = decoder
        .read_info()
        .map_err(|e| Error::invalid(path, format!("not a readable PNG: {e}")))?;
    let info = reader.info();
    Ok((info.width, info.height))
}

/// Find the frames (frames/ or video.*) and check them against the poses and the camera.
fn locate_frames(
    dir: &Path,
    poses_path: &Path,
    poses: &[PoseEntry],
    camera: &Camera,
) -> Result<FramesLocation> {
    let uses_video = poses
        .iter()
        .any(|p| matches!(p.frame, FrameRef::VideoIndex(_)));
    if uses_video {
        locate_video(dir, poses_path, poses, camera)
    } else {
        locate_pngs(dir, poses_path, poses, camera)
    }
}

/// "fewer poses than frames" or "more poses than frames", for a count mismatch.
fn fewer_or_more(poses: usize, frames: usize) -> &'static str {
    if poses < frames {
        "fewer poses than frames"
    } else {
        "more poses than frames"
    }
}

/// The one `video.<ext>` of the case: its frame size must be the camera's, and the poses must
/// refer to each of its frames exactly once.
fn locate_video(
    dir: &Path,
    poses_path: &Path,
    poses: &[PoseEntry],
    camera: &Camera,
) -> Result<FramesLocation> {
    let videos: Vec<PathBuf> = VIDEO_EXTENSIONS
        .iter()
        .map(|e| dir.join(format!("video.{e}")))
        .filter(|p| p.is_file())
        .collect();
    let path = match videos.as_slice() {
        [one] => one.clone(),
        [] => {
            return Err(Error::missing(
                dir.join("video.mp4"),
                "poses.json refers to video frames (\"frame\") but there is no video file",
            ))
        }
        _ => {
            return Err(Error::invalid(
                dir,
                format!(
                    "more than one video file ({}): keep exactly one",
                    videos.len()
                ),
            ))
        }
    };
    let reader = VideoReader::open(&path)?;
    check_frame_size(&path, reader.width(), reader.height(), camera)?;
    let count = reader.frame_count();
    drop(reader);
    let mut seen = HashSet::new();
    for (n, p) in poses.iter().enumerate() {
        if let FrameRef::VideoIndex(i) = p.frame {
            if i >= count {
                return Err(Error::invalid(
                    poses_path,
                    format!(
                        "pose {n} refers to frame {i}, but {} has {count} frames",
                        path.display()
                    ),
                ));
            }
            if !seen.insert(i) {
                return Err(Error::invalid(
                    poses_path,
                    format!("pose {n}: frame {i} is listed twice"),
                ));
            }
        }
    }
    if poses.len() != count {
        return Err(Error::invalid(
            poses_path,
            format!(
                "{} poses for {count} video frames: {}",
                poses.len(),
                fewer_or_more(poses.len(), count)
            ),
        ));
    }
    Ok(FramesLocation::Video { path, count })
}

/// The PNG files named in the poses: each present and listed once, as many as frames/ holds
/// (when the case has one), each of the camera's size (read from its header).
fn locate_pngs(
    dir: &Path,
    poses_path: &Path,
    poses: &[PoseEntry],
    camera: &Camera,
) -> Result<FramesLocation> {
    let frames_dir = dir.join("frames");
    let files: Vec<PathBuf> = poses
        .iter()
        .map(|p| match &p.frame {
            FrameRef::Image(f) => f.clone(),
            FrameRef::VideoIndex(_) => unreachable!("the caller sends video cases elsewhere"),
        })
        .collect();
    let mut seen = HashSet::new();
    for (n, f) in files.iter().enumerate() {
        if !f.is_file() {
            return Err(Error::missing(
                f,
                format!("frame of pose {n} in {}", poses_path.display()),
            ));
        }
        if !seen.insert(f.clone()) {
            return Err(Error::invalid(
                poses_path,
                format!("pose {n}: {} is listed twice", f.display()),
            ));
        }
    }
    if frames_dir.is_dir() {
        let on_disk = std::fs::read_dir(&frames_dir)
            .map_err(|e| Error::io(&frames_dir, e))?
            .filter_map(|e| e.ok())
            .filter(|e| {
                e.path()
                    .extension()
                    .is_some_and(|x| x.eq_ignore_ascii_case("png"))
            })
            .count();
        if on_disk != files.len() {
            return Err(Error::invalid(
                poses_path,
                format!(
                    "{} poses for {on_disk} PNG frames in {}: {}",
                    files.len(),
                    frames_dir.display(),
                    fewer_or_more(files.len(), on_disk)
                ),
            ));
        }
    }
    files.par_iter().try_for_each(|f| {
        let (w, h) = png_size(f)?;
        check_frame_size(f, w, h, camera)
    })?;
    Ok(FramesLocation::Png {
        dir: frames_dir,
        files,
    })
}
