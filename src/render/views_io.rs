//! views.json (the poses.json schema, CASE_FORMAT.md) for rendering and evaluation, and the
//! image folders that go with it.
//!
//! An output folder holds, per view, the sRGB PNG named by `"image"` and a hit mask beside it,
//! `<stem>_mask.png` (255 = the pixel sees the mesh). A truth folder (the phantom's `truth/`)
//! has the same layout: views.json, the images it names, and optional `<stem>_mask.png`.

use std::path::{Path, PathBuf};

use super::evaluate::{evaluate_methods, MaskedImage, MethodScore};
use super::novel_view::{render_view_with, RenderInputs, RenderOptions, ViewRays};
use crate::camera::Camera;
use crate::image::Frame;
use crate::io::paths::relative_slash_path;
use crate::io::png::{read_png, write_png_srgb8};
use crate::io::poses::{read_poses, FrameRef};
use crate::math::Affine;
use crate::{Error, Result};

/// One view of views.json.
#[derive(Clone, Debug)]
pub struct View {
    /// The `"image"` name, normalised, relative to the folder, `/`-separated.
    pub name: String,
    /// The image path (inside the folder).
    pub path: PathBuf,
    /// Camera → world (world mm).
    pub camera_to_world: Affine,
}

/// Read views.json; every `"image"` is resolved inside `base_dir` (the output folder when
/// rendering, the truth folder when evaluating). Absolute names, names that climb out of
/// `base_dir` and `"frame"` entries are refused with an error naming `views_json`.
pub fn read_views(views_json: &Path, base_dir: &Path) -> Result<Vec<View>> {
    read_poses(views_json, base_dir)?
        .into_iter()
        .enumerate()
        .map(|(i, p)| match p.frame {
            FrameRef::Image(path) => Ok(View {
                name: relative_slash_path(base_dir, &path, views_json)?,
                path,
                camera_to_world: p.pose.camera_to_world,
            }),
            FrameRef::VideoIndex(_) => Err(Error::invalid(
                views_json,
                format!("frame {i}: views need an \"image\" output name, not a video \"frame\""),
            )),
        })
        .collect()
}

/// The mask file of an image: `<stem>_mask.png` beside it.
pub fn mask_path(image: &Path) -> PathBuf {
    let stem = image
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_default();
    image.with_file_name(format!("{stem}_mask.png"))
}

/// Render every view of `views_json` with `camera` into `out_dir` (created if needed): the
/// sRGB 8-bit image and its hit mask. Returns the image paths written.
pub fn render_views(
    inputs: &RenderInputs,
    camera: &Camera,
    views_json: &Path,
    out_dir: &Path,
    opts: &RenderOptions,
) -> Result<Vec<PathBuf>> {
    std::fs::create_dir_all(out_dir).map_err(|e| Error::io(out_dir, e))?;
    let views = read_views(views_json, out_dir)?;
    let rays = ViewRays::new(camera, opts.supersample)?;
    let mut written = Vec::with_capacity(views.len());
    for v in &views {
        if let Some(parent) = v.path.parent() {
            std::fs::create_dir_all(parent).map_err(|e| Error::io(parent, e))?;
        }
        let (frame, mask) = render_view_with(inputs, &rays, &v.camera_to_world, opts)?;
        write_png_srgb8(&v.path, &frame)?;
        write_png_srgb8(&mask_path(&v.path), &mask_frame(&mask, camera))?;
        written.push(v.path.clone());
    }
    Ok(written)
}

fn mask_frame(mask: &[bool], camera: &Camera) -> Frame {
    Frame {
        width: camera.width,
        height: camera.height,
        rgb: mask
            .iter()
            .flat_map(|&m| [if m { 1.0 } else { 0.0 }; 3])
            .collect(),
    }
}

/// Read an image and its mask; without a mask file, `default_mask` decides per pixel.
fn read_masked(path: &Path, default_mask: &dyn Fn(&Frame, usize) -> bool) -> Result<MaskedImage> {
    let frame = read_png(path)?;
    let n = frame.width as usize * frame.height as usize;
    let mp = mask_path(path);
    let mask = if mp.exists() {
        let m = read_png(&mp)?;
        if m.width != frame.width || m.height != frame.height {
            return Err(Error::invalid(
                &mp,
                format!(
                    "mask is {}x{}, its image {}x{}",
                    m.width, m.height, frame.width, frame.height
                ),
            ));
        }
        (0..n).map(|i| m.rgb[3 * i] > 0.5).collect()
    } else {
        (0..n).map(|i| default_mask(&frame, i)).collect()
    };
    Ok(MaskedImage { frame, mask })
}

/// The reference views of a truth folder: `truth_dir/views.json`, its images and masks (a
/// missing mask covers every pixel).
pub fn load_truth(truth_dir: &Path) -> Result<(Vec<View>, Vec<MaskedImage>)> {
    let views = read_views(&truth_dir.join("views.json"), truth_dir)?;
    let images = views
        .iter()
        .map(|v| read_masked(&v.path, &|_, _| true))
        .collect::<Result<Vec<_>>>()?;
    Ok((views, images))
}

/// The rendered images of `views` (by name) in `rendered_dir`, with their masks (a missing
/// mask covers the pixels that are not exactly black).
pub fn load_rendered(rendered_dir: &Path, views: &[View]) -> Result<Vec<MaskedImage>> {
    views
        .iter()
        .map(|v| {
            let p = rendered_dir.join(&v.name);
            if !p.exists() {
                return Err(Error::missing(&p, format!("the rendered view {}", v.name)));
            }
            read_masked(&p, &|f, i| f.rgb[3 * i..3 * i + 3].iter().any(|&c| c > 0.0))
        })
        .collect()
}

/// `bronchosim evaluate RENDERED --truth DIR`: score the rendered folder against the truth
/// folder, plus any `extra` methods (e.g. baselines rendered in memory, one image per truth
/// view in views.json order). All methods are scored on the same pixels.
pub fn evaluate_folders(
    rendered_dir: &Path,
    truth_dir: &Path,
    extra: Vec<(String, Vec<MaskedImage>)>,
) -> Result<Vec<MethodScore>> {
    let (views, truth) = load_truth(truth_dir)?;
    let rendered = load_rendered(rendered_dir, &views)?;
    let mut methods = vec![("rendered".to_string(), rendered)];
    methods.extend(extra);
    let names: Vec<String> = views.iter().map(|v| v.name.clone()).collect();
    evaluate_methods(&methods, &truth, &names)
}
