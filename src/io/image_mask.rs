//! `CASE/mask.png` (CASE_FORMAT.md): which pixels of every frame are image (white) and which are
//! not (black: the scope's border around a round or octagonal field of view, burnt-in on-screen
//! text). Masked pixels are treated as pixels that see nothing: they enter no fit, no texture,
//! no score and no registration.

use std::path::{Path, PathBuf};

use crate::camera::Camera;
use crate::image::Frame;
use crate::io::png::read_png;
use crate::{Error, Result};

/// File name of the mask in a case folder.
pub const MASK_FILE: &str = "mask.png";

/// Linear value above which a mask pixel is image (the encoded value 0.5).
const IMAGE_LEVEL: f32 = 0.214;

/// Fewest image pixels a mask must keep (a share of the frame).
const MIN_IMAGE_SHARE: f64 = 0.05;

/// Which pixels of a frame are image.
#[derive(Clone, Debug, PartialEq)]
pub struct ImageMask {
    /// The file it was read from.
    pub path: PathBuf,
    /// Width (pixels).
    pub width: u32,
    /// Height (pixels).
    pub height: u32,
    /// Row-major, true where the pixel is image.
    pub image: Vec<bool>,
}

impl ImageMask {
    /// Share of the frame's pixels that are image.
    pub fn image_share(&self) -> f64 {
        self.image.iter().filter(|&&m| m).count() as f64 / self.image.len().max(1) as f64
    }
}

/// Read `CASE/mask.png` when present: white (or any grey above mid-grey) = image. It must be
/// frame-sized (the camera's width and height) and keep at least 5% of the frame as image.
pub fn read_case_mask(case_dir: &Path, camera: &Camera) -> Result<Option<ImageMask>> {
    let path = case_dir.join(MASK_FILE);
    if !path.exists() {
        return Ok(None);
    }
    let frame = read_png(&path)?;
    if (frame.width, frame.height) != (camera.width, camera.height) {
        return Err(Error::invalid(
            &path,
            format!(
                "the mask is {}x{} pixels, the frames (camera) {}x{}",
                frame.width, frame.height, camera.width, camera.height
            ),
        ));
    }
    let image: Vec<bool> = frame
        .rgb
        .chunks_exact(3)
        .map(|p| (p[0] + p[1] + p[2]) / 3.0 > IMAGE_LEVEL)
        .collect();
    let mask = ImageMask {
        path,
        width: frame.width,
        height: frame.height,
        image,
    };
    if mask.image_share() < MIN_IMAGE_SHARE {
        return Err(Error::invalid(
            &mask.path,
            format!(
                "only {:.1}% of the pixels are image (white); the mask marks image pixels white",
                100.0 * mask.image_share()
            ),
        ));
    }
    Ok(Some(mask))
}

/// A border that is black in every frame looked at: what a mask should hide.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct BlackBorder {
    /// Share of the frame's pixels that are black in every frame (0..1).
    pub share: f64,
    /// Frames looked at.
    pub frames: usize,
}

/// Linear level under which a pixel counts as black (8-bit code 10 of 255).
const BLACK_LEVEL: f32 = 0.003;

/// Pixels that stay black in every one of `frames`, when they are more than 1% of the frame
/// and touch its border (the field-of-view edge of an endoscope, not a dark lumen).
pub fn detect_black_border<'a>(frames: impl IntoIterator<Item = &'a Frame>) -> Option<BlackBorder> {
    let mut always_black: Option<Vec<bool>> = None;
    let (mut count, mut width) = (0usize, 0usize);
    for f in frames {
        let black = f
            .rgb
            .chunks_exact(3)
            .map(|p| p.iter().all(|&v| v < BLACK_LEVEL));
        match &mut always_black {
            None => {
                always_black = Some(black.collect());
                width = f.width as usize;
            }
            Some(acc) if acc.len() == f.rgb.len() / 3 => {
                for (a, b) in acc.iter_mut().zip(black) {
                    *a &= b;
                }
            }
            Some(_) => return None,
        }
        count += 1;
    }
    let acc = always_black?;
    let share = acc.iter().filter(|&&b| b).count() as f64 / acc.len().max(1) as f64;
    let corners = [0, width - 1, acc.len() - width, acc.len() - 1];
    (count >= 2 && share > 0.01 && corners.iter().any(|&i| acc[i])).then_some(BlackBorder {
        share,
        frames: count,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_round_field_of_view_is_detected_and_a_dark_centre_is_not() {
        let (w, h) = (40u32, 30u32);
        let frame = |k: f32, round: bool| {
            let mut f = Frame::new(w, h);
            for y in 0..h {
                for x in 0..w {
                    let (dx, dy) = (x as f32 - 19.5, y as f32 - 14.5);
                    let r = (dx * dx + dy * dy).sqrt();
                    let inside = !round || r < 14.0;
                    // A dark lumen in the centre, bright walls around it.
                    let v = if inside && r > 3.0 {
                        0.2 + 0.01 * k
                    } else {
                        0.0
                    };
                    f.set(x, y, [v; 3]);
                }
            }
            f
        };
        let round: Vec<Frame> = (0..3).map(|k| frame(k as f32, true)).collect();
        let b = detect_black_border(&round).expect("a border");
        assert!(b.share > 0.45 && b.share < 0.6, "{b:?}");
        let full: Vec<Frame> = (0..3).map(|k| frame(k as f32, false)).collect();
        assert_eq!(detect_black_border(&full), None);
    }
}
