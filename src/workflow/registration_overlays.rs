//! Before/after overlays of the registration (issue 16 item 3): for the frames with the
//! largest corrections and one typical frame, the frame beside a checkerboard of the frame and
//! the model rendered at the given pose and at the registered pose.
//!
//! The model is the geometry's shading under the calibrated light with a uniform albedo: a
//! texture fused with the registered poses would agree with them by construction, while the
//! geometry (lumen edges, bifurcations, the dark far lumen) is independent of the poses.
//! Each channel of the render is scaled to the frame's mean over the pixels that see the
//! surface, so only where things are — not the mucosa's colour — differs across the squares.

use std::fmt::Write as _;

use crate::camera::pose::camera_centre;
use crate::image::srgb::linear_to_srgb8;
use crate::image::Frame;
use crate::math::Affine;
use crate::model::registration::{FramePoseResult, PoseOverlay};
use crate::registration::photometric::{PhotometricModel, RayGrid};
use crate::registration::pose::rotation_of;
use crate::registration::ModelParts;
use crate::{Error, Result};

/// Frames to show: the `largest` used frames the registration moved with the largest
/// corrections (mm), then the one with the median correction; each as its index in `frames`
/// (not its number in the video: the build may use only some of the video's frames), with why
/// it was chosen.
pub fn choose_overlay_frames(
    frames: &[FramePoseResult],
    largest: usize,
) -> Vec<(usize, &'static str)> {
    // A frame the registration did not move has nothing to show.
    let mut used: Vec<usize> = (0..frames.len())
        .filter(|&i| {
            let f = &frames[i];
            f.used && (f.correction_mm > 0.0 || f.correction_deg > 0.0)
        })
        .collect();
    used.sort_by(|&a, &b| frames[b].correction_mm.total_cmp(&frames[a].correction_mm));
    let mut out: Vec<(usize, &'static str)> = used
        .iter()
        .take(largest)
        .map(|&i| (i, "large correction"))
        .collect();
    if let Some(&m) = used.get(used.len() / 2) {
        if out.iter().all(|o| o.0 != m) {
            out.push((m, "typical correction"));
        }
    }
    out
}

/// The overlays of `chosen` frames (indices `f`: `frames[f]` linear RGB, `given[f]` and
/// `registered[f]` camera → world, `frame_results[f]` its registration) on the model `parts`
/// (its texture is not used), at most `max_width` pixels wide (the camera's size halved until
/// it fits).
pub fn pose_overlays(
    parts: ModelParts,
    frames: &[Frame],
    given: &[Affine],
    registered: &[Affine],
    chosen: &[(usize, &str)],
    frame_results: &[FramePoseResult],
    max_width: u32,
) -> Result<Vec<PoseOverlay>> {
    let model = PhotometricModel::new(ModelParts {
        texture: None,
        ..parts
    })?;
    let mut level = 0;
    while parts.camera.width >> level > max_width.max(16) {
        level += 1;
    }
    let grid = RayGrid::new(parts.camera, level, 1);
    let (w, h) = (grid.rays.width, grid.rays.height);
    let mut out = Vec::with_capacity(chosen.len());
    for &(f, why) in chosen {
        let frame = box_down(&frames[f], level, w, h);
        let at_given = render_geometry(&model, &grid, &given[f]);
        let at_registered = render_geometry(&model, &grid, &registered[f]);
        let (cb_given, mismatch_given) = checkerboard(&frame, &at_given);
        let (cb_reg, mismatch_reg) = checkerboard(&frame, &at_registered);
        let r = &frame_results[f];
        out.push(PoseOverlay {
            frame: r.frame,
            why: why.to_string(),
            correction_mm: r.correction_mm,
            correction_deg: r.correction_deg,
            frame_png: png_bytes(&frame)?,
            given_png: png_bytes(&cb_given)?,
            registered_png: png_bytes(&cb_reg)?,
            mismatch_given,
            mismatch_registered: mismatch_reg,
        });
    }
    Ok(out)
}

/// The model's shading with a uniform albedo at every ray of `grid` from `pose` (unit gain);
/// NaN where a ray meets no surface.
fn render_geometry(model: &PhotometricModel, grid: &RayGrid, pose: &Affine) -> Frame {
    let view = model.view(grid, pose, 0.0);
    let (w, h) = (grid.rays.width, grid.rays.height);
    let mut img = Frame::new(w, h);
    img.rgb.fill(f32::NAN);
    let to_cam = rotation_of(pose).transpose();
    let centre = camera_centre(pose).coords;
    for p in &view.points {
        let s = model
            .light
            .radiance(&(to_cam * (p.x - centre)), &(to_cam * p.n), [1.0; 3]);
        let i = 3 * p.ray as usize;
        for (c, v) in img.rgb[i..i + 3].iter_mut().enumerate() {
            *v = (s[c] + view.offset[c]) as f32;
        }
    }
    img
}

/// `frame` averaged over blocks of 2^level pixels, cut to `w` x `h`.
fn box_down(frame: &Frame, level: usize, w: u32, h: u32) -> Frame {
    let k = 1usize << level;
    let fw = frame.width as usize;
    let mut out = Frame::new(w, h);
    for y in 0..h as usize {
        for x in 0..w as usize {
            let mut sum = [0.0f32; 3];
            let mut n = 0.0f32;
            for yy in y * k..((y + 1) * k).min(frame.height as usize) {
                for xx in x * k..((x + 1) * k).min(fw) {
                    let j = 3 * (yy * fw + xx);
                    for (s, v) in sum.iter_mut().zip(&frame.rgb[j..j + 3]) {
                        *s += v;
                    }
                    n += 1.0;
                }
            }
            let i = 3 * (y * w as usize + x);
            for (o, s) in out.rgb[i..i + 3].iter_mut().zip(sum) {
                *o = s / n.max(1.0);
            }
        }
    }
    out
}

/// A checkerboard (8 squares across) of `frame` and `model` with each channel of `model`
/// scaled to `frame`'s mean where the model sees the surface; and the mean absolute
/// difference of the two there, relative to the frame's mean (the misfit the eye sees).
fn checkerboard(frame: &Frame, model: &Frame) -> (Frame, f64) {
    let (w, h) = (frame.width as usize, frame.height as usize);
    let hit = |i: usize| model.rgb[3 * i].is_finite();
    let mut sums = [[0.0f64; 2]; 3];
    for i in (0..w * h).filter(|&i| hit(i)) {
        for (c, s) in sums.iter_mut().enumerate() {
            s[0] += f64::from(frame.rgb[3 * i + c]);
            s[1] += f64::from(model.rgb[3 * i + c]);
        }
    }
    let scale: [f32; 3] = std::array::from_fn(|c| {
        if sums[c][1] > 0.0 {
            (sums[c][0] / sums[c][1]) as f32
        } else {
            0.0
        }
    });
    let square = (w / 8).max(1);
    let mut out = frame.clone();
    let (mut diff, mut mean) = (0.0f64, 0.0f64);
    for y in 0..h {
        for x in 0..w {
            let i = y * w + x;
            let m: [f32; 3] = std::array::from_fn(|c| {
                if hit(i) {
                    model.rgb[3 * i + c] * scale[c]
                } else {
                    0.0
                }
            });
            for (&o, mc) in frame.rgb[3 * i..3 * i + 3].iter().zip(m) {
                diff += f64::from((o - mc).abs());
                mean += f64::from(o);
            }
            if (x / square + y / square) % 2 == 1 {
                out.rgb[3 * i..3 * i + 3].copy_from_slice(&m);
            }
        }
    }
    (out, diff / mean.max(1e-12))
}

/// `frame` as an 8-bit sRGB PNG file's bytes.
fn png_bytes(frame: &Frame) -> Result<Vec<u8>> {
    let data: Vec<u8> = frame.rgb.iter().map(|&v| linear_to_srgb8(v)).collect();
    let mut bytes = Vec::new();
    let mut enc = png::Encoder::new(&mut bytes, frame.width, frame.height);
    enc.set_color(png::ColorType::Rgb);
    enc.set_depth(png::BitDepth::Eight);
    let fail = |e: png::EncodingError| Error::Other(format!("overlay PNG: {e}"));
    let mut writer = enc.write_header().map_err(fail)?;
    writer.write_image_data(&data).map_err(fail)?;
    writer.finish().map_err(fail)?;
    Ok(bytes)
}

/// The overlays as an HTML section body: one row per frame (embedded PNGs).
pub fn overlays_html(overlays: &[PoseOverlay]) -> String {
    use base64::Engine as _;
    let img = |png: &[u8], alt: &str| {
        let b64 = base64::engine::general_purpose::STANDARD.encode(png);
        format!("<img alt=\"{alt}\" width=160 src=\"data:image/png;base64,{b64}\">")
    };
    let mut html = String::from(
        "<p>Frame, then a checkerboard of the frame and the CT's airway shaded by the light \
         (uniform albedo) from the given and from the registered pose: where the pose is right, \
         the lumen's edges and dark centre continue across the squares. Misfit: mean absolute \
         difference over the frame's mean.</p><table><tr><th>frame</th><th>video</th>\
         <th>given pose</th><th>registered pose</th></tr>",
    );
    for o in overlays {
        let _ = write!(
            html,
            "<tr><td>{} ({}: {:.2} mm, {:.2}°)</td><td>{}</td><td>{}<br>misfit {:.3}</td>\
             <td>{}<br>misfit {:.3}</td></tr>",
            o.frame,
            o.why,
            o.correction_mm,
            o.correction_deg,
            img(&o.frame_png, "frame"),
            img(&o.given_png, "given pose"),
            o.mismatch_given,
            img(&o.registered_png, "registered pose"),
            o.mismatch_registered
        );
    }
    html.push_str("</table>");
    html
}
