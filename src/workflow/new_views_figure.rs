//! The report's new views (paper Fig. 4): with reference views (`build --truth`, the demo),
//! every method of [`super::truth_eval`] next to the reference and the score table; without,
//! new views between training viewpoints next to the nearest training frame.

use std::path::Path;

use crate::camera::pose::camera_centre;
use crate::image::Frame;
use crate::io::case::Case;
use crate::math::{Affine, Vector3};
use crate::model::Model;
use crate::render::{render_view_with, MethodScore, RenderOptions, ViewRays};
use crate::workflow::truth_eval::evaluate_against_truth;
use crate::Result;

/// One row of the figure: a view name and labelled images (linear, display-scaled).
pub struct FigureRow {
    /// The view's name.
    pub name: String,
    /// (caption, image) pairs, left to right.
    pub images: Vec<(String, Frame)>,
}

/// Fig. 4 of the report, and the scores when reference views were given.
pub struct NewViewsFigure {
    /// Rows of images.
    pub rows: Vec<FigureRow>,
    /// PSNR / SSIM per method against the reference views (empty without references).
    pub scores: Vec<MethodScore>,
    /// What the rows show.
    pub caption: String,
}

/// Rows shown at most.
const MAX_ROWS: usize = 4;

/// Scale a linear image by per-channel gains (the evaluation's least-squares exposure), black
/// outside `mask`.
fn with_gain(f: &Frame, mask: &[bool], gain: [f64; 3]) -> Frame {
    let mut out = f.clone();
    for (i, px) in out.rgb.chunks_exact_mut(3).enumerate() {
        for ch in 0..3 {
            px[ch] = if mask[i] {
                (px[ch] as f64 * gain[ch]) as f32
            } else {
                0.0
            };
        }
    }
    out
}

/// Fig. 4 against the reference views of `truth_dir`.
pub fn truth_figure(model: &Model, case: &Case, truth_dir: &Path) -> Result<NewViewsFigure> {
    let ev = evaluate_against_truth(model, case, truth_dir, None)?;
    let rows = (0..ev.names.len().min(MAX_ROWS))
        .map(|v| {
            let mut images = vec![("reference".to_string(), ev.truth[v].frame.clone())];
            for ((name, imgs), score) in ev.images.iter().zip(&ev.scores) {
                let psnr = score.views[v]
                    .psnr_db
                    .map_or("-".into(), |p| format!("{p:.1} dB"));
                images.push((
                    format!("{name}: {psnr}"),
                    with_gain(&imgs[v].frame, &imgs[v].mask, score.gain),
                ));
            }
            FigureRow {
                name: ev.names[v].clone(),
                images,
            }
        })
        .collect();
    Ok(NewViewsFigure {
        rows,
        scores: ev.scores,
        caption: format!(
            "New views from poses off the training path, against the reference images of {} \
             (each method with its own least-squares gain per channel, scored on the pixels all \
             cover).",
            truth_dir.display()
        ),
    })
}

/// Fig. 4 without references: new viewpoints halfway between training viewpoints, turned 12°
/// away from the path, rendered with the default (k-nearest) shading, next to the nearest
/// training frame.
pub fn novel_figure(model: &Model, case: &Case) -> Result<NewViewsFigure> {
    let n = case.poses.len();
    let picks: Vec<usize> = if n < 2 {
        Vec::new()
    } else {
        [1, 3, 5]
            .iter()
            .map(|k| (k * (n - 1) / 6).min(n - 2))
            .collect()
    };
    let rays = ViewRays::new(&case.camera, 1)?;
    let inputs = model.render_inputs();
    let mut wanted: Vec<usize> = picks.clone();
    wanted.dedup();
    let mut frames = case.frames_at(&wanted)?;
    let mut rows = Vec::new();
    for &i in &wanted {
        let (a, b) = (
            &case.poses[i].pose.camera_to_world,
            &case.poses[i + 1].pose.camera_to_world,
        );
        let pose = between_and_turned(a, b, 12f64.to_radians());
        let (view, _) = render_view_with(&inputs, &rays, &pose, &RenderOptions::default())?;
        let Some(frame) = frames.remove(&i) else {
            continue;
        };
        rows.push(FigureRow {
            name: format!("between frames {i} and {}", i + 1),
            images: vec![
                (format!("training frame {i}"), frame),
                ("new view (k-nearest Psi × albedo)".into(), view),
            ],
        });
    }
    Ok(NewViewsFigure {
        rows,
        scores: Vec::new(),
        caption: "New viewpoints halfway between training viewpoints, turned 12° off the path, \
                  next to the nearest training frame (build with --truth DIR to score against \
                  reference views)."
            .into(),
    })
}

/// The pose halfway between `a` and `b` (centres averaged, `a`'s orientation), turned by
/// `angle` radians about its own image-vertical (y) axis.
fn between_and_turned(a: &Affine, b: &Affine, angle: f64) -> Affine {
    let c = camera_centre(a) + (camera_centre(b) - camera_centre(a)) * 0.5;
    let r = nalgebra::Rotation3::from_axis_angle(&Vector3::y_axis(), angle);
    let mut m = *a;
    let rot = a.fixed_view::<3, 3>(0, 0) * r.matrix();
    m.fixed_view_mut::<3, 3>(0, 0).copy_from(&rot);
    for k in 0..3 {
        m[(k, 3)] = c[k];
    }
    m
}
