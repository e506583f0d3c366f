//! The frames of a case, in poses.json order, from PNG files or one video, one at a time.

use std::path::{Path, PathBuf};

use crate::image::Frame;
use crate::io::png::read_png;
use crate::io::poses::{FrameRef, PoseEntry};
use crate::io::video::VideoReader;
use crate::{Error, Result};

/// A stream of linear-RGB frames, each checked to be the camera's size.
///
/// Iterating yields one `Result<Frame>` per pose, in order; an error names the file (and
/// for a video the frame index). After a video error the stream ends.
pub enum FrameSource {
    /// PNG files, read one per step.
    Images {
        /// The files, in poses order.
        paths: Vec<PathBuf>,
        /// Index of the next file to read.
        next: usize,
        /// Expected frame size in pixels (the camera's).
        size: (u32, u32),
    },
    /// A video decoded in one pass; frames not listed in `indices` are skipped undecoded.
    Video {
        /// The running decoder.
        reader: VideoReader,
        /// Wanted decoded-frame indices, strictly increasing.
        indices: Vec<usize>,
        /// Position in `indices` of the next frame to yield.
        next: usize,
    },
}

impl FrameSource {
    /// Frames from PNG files that must each be `width` x `height` pixels.
    pub fn images(paths: Vec<PathBuf>, width: u32, height: u32) -> Self {
        FrameSource::Images {
            paths,
            next: 0,
            size: (width, height),
        }
    }

    /// Frames `indices` (0-based, strictly increasing) of the video at `path`, whose frames
    /// must be `width` x `height` pixels. Size and index range are checked before decoding.
    pub fn video(path: &Path, indices: Vec<usize>, width: u32, height: u32) -> Result<Self> {
        if let Some(w) = indices.windows(2).find(|w| w[1] <= w[0]) {
            return Err(Error::invalid(
                path,
                format!(
                    "video frame indices must strictly increase ({} is followed by {})",
                    w[0], w[1]
                ),
            ));
        }
        let reader = VideoReader::open(path)?;
        if (reader.width(), reader.height()) != (width, height) {
            return Err(Error::invalid(
                path,
                format!(
                    "frame size {}x{} differs from the camera's {width}x{height}",
                    reader.width(),
                    reader.height()
                ),
            ));
        }
        if let Some(&last) = indices.last() {
            if last >= reader.frame_count() {
                return Err(Error::invalid(
                    path,
                    format!(
                        "has {} frames but frame {last} is asked for (frames count from 0)",
                        reader.frame_count()
                    ),
                ));
            }
        }
        Ok(FrameSource::Video {
            reader,
            indices,
            next: 0,
        })
    }

    /// The frames `poses` refer to: their PNG files, or frames of `video` when the poses use
    /// `"frame"` indices (then `video` is required). `width` x `height` is the camera's size.
    pub fn from_poses(
        poses: &[PoseEntry],
        video: Option<&Path>,
        width: u32,
        height: u32,
    ) -> Result<Self> {
        let mut paths = Vec::new();
        let mut indices = Vec::new();
        for pose in poses {
            match &pose.frame {
                FrameRef::Image(p) => paths.push(p.clone()),
                FrameRef::VideoIndex(i) => indices.push(*i),
            }
        }
        if !paths.is_empty() && !indices.is_empty() {
            return Err(Error::BadOptions {
                stage: "frames",
                message: "poses mix \"image\" and \"frame\" entries; use one kind".into(),
            });
        }
        if indices.is_empty() {
            return Ok(Self::images(paths, width, height));
        }
        let video = video.ok_or_else(|| Error::BadOptions {
            stage: "frames",
            message: "poses refer to video frames but the case has no video file".into(),
        })?;
        Self::video(video, indices, width, height)
    }

    /// Number of frames this source yields in total.
    pub fn len(&self) -> usize {
        match self {
            FrameSource::Images { paths, .. } => paths.len(),
            FrameSource::Video { indices, .. } => indices.len(),
        }
    }

    /// True when the source yields no frames.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
}

fn check_size(frame: &Frame, size: (u32, u32), what: impl FnOnce() -> Error) -> Result<()> {
    if (frame.width, frame.height) == size {
        Ok(())
    } else {
        Err(what())
    }
}

impl Iterator for FrameSource {
    type Item = Result<Frame>;

    fn next(&mut self) -> Option<Result<Frame>> {
        match self {
            FrameSource::Images { paths, next, size } => {
                let path = paths.get(*next)?;
                *next += 1;
                Some(read_png(path).and_then(|frame| {
                    check_size(&frame, *size, || {
                        Error::invalid(
                            path,
                            format!(
                                "frame size {}x{} differs from the camera's {}x{}",
                                frame.width, frame.height, size.0, size.1
                            ),
                        )
                    })?;
                    Ok(frame)
                }))
            }
            FrameSource::Video {
                reader,
                indices,
                next,
            } => {
                let &wanted = indices.get(*next)?;
                *next += 1;
                let result = next_video_frame(reader, wanted, indices);
                if result.is_err() {
                    // The decoder is finished or out of step: end the stream.
                    *next = indices.len();
                }
                Some(result)
            }
        }
    }

    /// The frame `n` places on, without decoding the ones passed over (a PNG is not read; a
    /// video's frames are skipped by the decoder without conversion).
    fn nth(&mut self, n: usize) -> Option<Result<Frame>> {
        match self {
            FrameSource::Images { paths, next, .. } => *next = (*next + n).min(paths.len()),
            FrameSource::Video { indices, next, .. } => *next = (*next + n).min(indices.len()),
        }
        self.next()
    }

    fn size_hint(&self) -> (usize, Option<usize>) {
        let left = match self {
            FrameSource::Images { paths, next, .. } => paths.len() - *next,
            FrameSource::Video { indices, next, .. } => indices.len() - *next,
        };
        (left, Some(left))
    }
}

/// Skip to decoded frame `wanted` and decode it.
fn next_video_frame(reader: &mut VideoReader, wanted: usize, indices: &[usize]) -> Result<Frame> {
    while reader.next_index() < wanted {
        if !reader.skip_frame()? {
            return Err(ended_early(reader, wanted, indices));
        }
    }
    reader
        .next_frame()
        .unwrap_or_else(|| Err(ended_early(reader, wanted, indices)))
}

fn ended_early(reader: &VideoReader, wanted: usize, indices: &[usize]) -> Error {
    Error::invalid(
        reader.path(),
        format!(
            "decoding ended after {} frames but frame {wanted} is asked for (last wanted: {})",
            reader.next_index(),
            indices.last().copied().unwrap_or(wanted)
        ),
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::io::png::write_png_srgb8;

    #[test]
    fn frames_passed_over_are_not_read() {
        let dir = tempfile::tempdir().unwrap();
        let mut paths = Vec::new();
        for k in 0..4 {
            let p = dir.path().join(format!("{k}.png"));
            let mut f = Frame::new(4, 3);
            f.set(0, 0, [0.1 * k as f32, 0.0, 0.0]);
            write_png_srgb8(&p, &f).unwrap();
            paths.push(p);
        }
        // Frames 0 and 2 are not PNG files: reading them would fail.
        std::fs::write(&paths[0], b"not a png").unwrap();
        std::fs::write(&paths[2], b"not a png").unwrap();
        let mut src = FrameSource::images(paths, 4, 3);
        let red = |f: Frame| f.get(0, 0)[0];
        assert!((red(src.nth(1).unwrap().unwrap()) - 0.1).abs() < 0.01);
        assert!((red(src.nth(1).unwrap().unwrap()) - 0.3).abs() < 0.01);
        assert!(src.next().is_none());
    }
}
