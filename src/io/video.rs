//! Video decoding through the `ffmpeg` and `ffprobe` programs (Debian package `ffmpeg`):
//! raw RGB frames are streamed from a pipe one at a time, never all held in memory.
//!
//! Sources with more than 8 bits per component are decoded as `rgb48le` so no precision is
//! lost; 8-bit sources as `rgb24`. Samples are taken as sRGB-encoded and converted to linear.

use std::collections::VecDeque;
use std::io::{BufRead, BufReader, ErrorKind, Read};
use std::path::{Path, PathBuf};
use std::process::{Child, ChildStdout, Command, Stdio};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;

use serde_json::Value;

use crate::image::srgb::{srgb16_to_linear_lut, srgb8_to_linear_lut};
use crate::image::Frame;
use crate::{Error, Result};

/// How many of ffmpeg's last stderr lines are kept for error messages.
const STDERR_LINES_KEPT: usize = 8;

/// A streaming decoder of one video file's first video stream.
///
/// Frames come out in decoding order with timestamps ignored (`-vsync passthrough`: no
/// frame is duplicated or dropped to fit a frame rate), so frame `i` is the `i`-th decoded
/// frame as CASE_FORMAT.md defines. Rotation metadata is ignored (`-noautorotate`): frames
/// are delivered as the sensor stored them, which is what the camera calibration describes.
/// Dropping the reader kills the ffmpeg process.
pub struct VideoReader {
    path: PathBuf,
    width: u32,
    height: u32,
    frame_count: usize,
    sixteen_bit: bool,
    child: Child,
    stdout: BufReader<ChildStdout>,
    stderr_tail: Arc<Mutex<VecDeque<String>>>,
    stderr_thread: Option<JoinHandle<()>>,
    raw: Vec<u8>,
    decoded: usize,
    finished: bool,
}

/// What ffprobe says about the first video stream.
struct Probe {
    width: u32,
    height: u32,
    packets: usize,
    sixteen_bit: bool,
}

fn spawn_error(path: &Path, program: &str, e: std::io::Error) -> Error {
    if e.kind() == ErrorKind::NotFound {
        Error::Other(format!(
            "{}: cannot decode video: `{program}` was not found; install ffmpeg (Debian package ffmpeg)",
            path.display()
        ))
    } else {
        Error::io(path, e)
    }
}

/// The most useful line of a tool's stderr: the last one that says something, without
/// ffmpeg's "[h264 @ 0x...] " tag or a leading "`path`: " (the caller names the file).
fn last_message<'a>(lines: impl DoubleEndedIterator<Item = &'a str>, path: &Path) -> String {
    let line = lines
        .rev()
        .map(str::trim)
        .find(|l| !l.is_empty() && !l.starts_with("Last message repeated"))
        .unwrap_or("no message (exit status only)");
    let line = match (line.starts_with('['), line.find("] ")) {
        (true, Some(end)) if line[..end].contains(" @ ") => &line[end + 2..],
        _ => line,
    };
    let prefix = format!("{}: ", path.display());
    line.strip_prefix(&prefix).unwrap_or(line).to_string()
}

fn probe(path: &Path) -> Result<Probe> {
    let output = Command::new("ffprobe")
        .args(["-v", "error", "-select_streams", "v:0", "-count_packets"])
        .args([
            "-show_entries",
            "stream=width,height,pix_fmt,nb_read_packets,bits_per_raw_sample",
        ])
        .args(["-show_pixel_formats", "-of", "json"])
        .arg(path)
        .stdin(Stdio::null())
        .output()
        .map_err(|e| spawn_error(path, "ffprobe", e))?;
    if !output.status.success() {
        let stderr = String::from_utf8_lossy(&output.stderr);
        return Err(Error::invalid(
            path,
            format!(
                "ffmpeg could not decode: {}",
                last_message(stderr.lines(), path)
            ),
        ));
    }
    let json: Value = serde_json::from_slice(&output.stdout)
        .map_err(|e| Error::invalid(path, format!("ffprobe gave unreadable output: {e}")))?;
    let stream = json
        .get("streams")
        .and_then(|s| s.get(0))
        .ok_or_else(|| Error::invalid(path, "no video stream"))?;
    let number = |key: &str| -> Option<u64> {
        let v = stream.get(key)?;
        v.as_u64().or_else(|| v.as_str()?.parse().ok())
    };
    let (width, height) = match (number("width"), number("height")) {
        (Some(w), Some(h)) if w > 0 && h > 0 && w <= 1 << 16 && h <= 1 << 16 => {
            (w as u32, h as u32)
        }
        _ => return Err(Error::invalid(path, "video stream has no valid frame size")),
    };
    let packets = number("nb_read_packets").unwrap_or(0) as usize;
    let pix_fmt = stream.get("pix_fmt").and_then(Value::as_str).unwrap_or("");
    let sixteen_bit = number("bits_per_raw_sample").is_some_and(|b| b > 8)
        || component_depth(&json, pix_fmt).is_some_and(|b| b > 8);
    Ok(Probe {
        width,
        height,
        packets,
        sixteen_bit,
    })
}

/// Largest component bit depth of `pix_fmt`, from ffprobe's own pixel-format table.
fn component_depth(json: &Value, pix_fmt: &str) -> Option<u64> {
    json.get("pixel_formats")?
        .as_array()?
        .iter()
        .find(|f| f.get("name").and_then(Value::as_str) == Some(pix_fmt))?
        .get("components")?
        .as_array()?
        .iter()
        .filter_map(|c| c.get("bit_depth")?.as_u64())
        .max()
}

impl VideoReader {
    /// Probe `path` with ffprobe and start ffmpeg decoding it. Errors name the file: missing,
    /// not a video, no frames, or ffmpeg not installed.
    pub fn open(path: &Path) -> Result<Self> {
        if !path.is_file() {
            return Err(Error::missing(path, "video file"));
        }
        let p = probe(path)?;
        if p.packets == 0 {
            return Err(Error::invalid(path, "video stream has no frames"));
        }
        let pix_fmt = if p.sixteen_bit { "rgb48le" } else { "rgb24" };
        let mut child = Command::new("ffmpeg")
            .args(["-v", "error", "-nostdin", "-noautorotate", "-i"])
            .arg(path)
            .args(["-map", "0:v:0", "-vsync", "passthrough", "-xerror"])
            .args(["-f", "rawvideo", "-pix_fmt", pix_fmt, "-"])
            .stdin(Stdio::null())
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .map_err(|e| spawn_error(path, "ffmpeg", e))?;
        let stdout = BufReader::with_capacity(1 << 20, child.stdout.take().expect("piped stdout"));
        // Drain stderr on a thread: a chatty ffmpeg must never block on a full pipe.
        let stderr = child.stderr.take().expect("piped stderr");
        let stderr_tail = Arc::new(Mutex::new(VecDeque::new()));
        let tail = Arc::clone(&stderr_tail);
        let stderr_thread = std::thread::spawn(move || {
            for line in BufReader::new(stderr).lines().map_while(|l| l.ok()) {
                let mut t = tail.lock().unwrap_or_else(|e| e.into_inner());
                if t.len() == STDERR_LINES_KEPT {
                    t.pop_front();
                }
                t.push_back(line);
            }
        });
        let bytes = 3 * p.width as usize * p.height as usize * if p.sixteen_bit { 2 } else { 1 };
        Ok(VideoReader {
            path: path.to_path_buf(),
            width: p.width,
            height: p.height,
            frame_count: p.packets,
            sixteen_bit: p.sixteen_bit,
            child,
            stdout,
            stderr_tail,
            stderr_thread: Some(stderr_thread),
            raw: vec![0; bytes],
            decoded: 0,
            finished: false,
        })
    }

    /// The video file.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Frame width in pixels.
    pub fn width(&self) -> u32 {
        self.width
    }

    /// Frame height in pixels.
    pub fn height(&self) -> u32 {
        self.height
    }

    /// Number of frames in the video stream, counted from its packets by ffprobe (one packet
    /// per frame for the codecs in use; decoding reports any shortfall as an error).
    pub fn frame_count(&self) -> usize {
        self.frame_count
    }

    /// True when frames are decoded with 16 bits per component (the source has more than 8).
    pub fn is_sixteen_bit(&self) -> bool {
        self.sixteen_bit
    }

    /// Frames decoded (or skipped) so far: the index of the next frame.
    pub fn next_index(&self) -> usize {
        self.decoded
    }

    /// Decode the next frame into linear RGB; `None` at the end of the stream.
    pub fn next_frame(&mut self) -> Option<Result<Frame>> {
        match self.read_raw() {
            Ok(true) => Some(Ok(self.convert())),
            Ok(false) => None,
            Err(e) => Some(Err(e)),
        }
    }

    /// Advance past the next frame without converting it; `Ok(false)` at the end of the stream.
    pub fn skip_frame(&mut self) -> Result<bool> {
        self.read_raw()
    }

    fn convert(&self) -> Frame {
        let rgb = if self.sixteen_bit {
            let lut = srgb16_to_linear_lut();
            self.raw
                .chunks_exact(2)
                .map(|b| lut[u16::from_le_bytes([b[0], b[1]]) as usize])
                .collect()
        } else {
            let lut = srgb8_to_linear_lut();
            self.raw.iter().map(|&b| lut[b as usize]).collect()
        };
        Frame {
            width: self.width,
            height: self.height,
            rgb,
        }
    }

    /// Fill `self.raw` with the next frame's bytes; `Ok(false)` at a clean end of stream.
    fn read_raw(&mut self) -> Result<bool> {
        if self.finished {
            return Ok(false);
        }
        let mut filled = 0;
        while filled < self.raw.len() {
            match self.stdout.read(&mut self.raw[filled..]) {
                Ok(0) => break,
                Ok(n) => filled += n,
                Err(e) if e.kind() == ErrorKind::Interrupted => {}
                Err(e) => {
                    self.finished = true;
                    return Err(Error::io(&self.path, e));
                }
            }
        }
        if filled == self.raw.len() {
            self.decoded += 1;
            return Ok(true);
        }
        self.finished = true;
        let status = self.child.wait().map_err(|e| Error::io(&self.path, e))?;
        if let Some(t) = self.stderr_thread.take() {
            let _ = t.join();
        }
        let tail = self.stderr_tail.lock().unwrap_or_else(|e| e.into_inner());
        if !status.success() || filled != 0 {
            let why = last_message(tail.iter().map(String::as_str), &self.path);
            return Err(Error::invalid(
                &self.path,
                format!("ffmpeg could not decode frame {}: {why}", self.decoded),
            ));
        }
        Ok(false)
    }
}

impl Iterator for VideoReader {
    type Item = Result<Frame>;

    fn next(&mut self) -> Option<Self::Item> {
        self.next_frame()
    }
}

impl Drop for VideoReader {
    fn drop(&mut self) {
        // Kill even after the end of the stream (harmless then), wait to reap: no zombie.
        let _ = self.child.kill();
        let _ = self.child.wait();
        if let Some(t) = self.stderr_thread.take() {
            let _ = t.join();
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn missing_program_says_how_to_install() {
        let e = Command::new("bronchosim-test-no-such-program")
            .spawn()
            .unwrap_err();
        let msg = spawn_error(Path::new("case/video.mp4"), "ffmpeg", e).to_string();
        assert!(msg.starts_with("case/video.mp4: "), "{msg}");
        assert!(
            msg.contains("install ffmpeg (Debian package ffmpeg)"),
            "{msg}"
        );
    }

    #[test]
    fn stderr_tags_are_removed() {
        let p = Path::new("v.mp4");
        let lines = [
            "v.mp4: Invalid data found",
            "",
            "Last message repeated 1 times",
        ];
        assert_eq!(last_message(lines.into_iter(), p), "Invalid data found");
        let lines = ["[h264 @ 0x55ce] Error splitting the input into NAL units."];
        assert_eq!(
            last_message(lines.into_iter(), p),
            "Error splitting the input into NAL units."
        );
    }
}
