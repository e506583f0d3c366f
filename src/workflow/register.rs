//! `bronchosim register CASE --out DIR`: the registration stage of the build on its own (the
//! paper's Fig. 1 "2D/3D registration"): every frame's pose refined against the CT, written as
//! DIR/poses.json (images relative to the case folder, so it can replace the case's own, with
//! each frame's correction and status: the refined poses, or the given ones when they predict
//! held-out frames better), DIR/refined_poses.json (what the rounds found, kept or not),
//! DIR/registration.json and DIR/report.html.

use std::fmt::Write as _;
use std::path::Path;

use crate::io::atomic::{write_bytes_atomic, write_json_atomic};
use crate::io::output_dir::OutputDir;
use crate::io::poses::{write_poses, write_poses_annotated};
use crate::model::manifest::BuildTimings;
use crate::model::registration::{PoseRegistration, PoseTruth, TrackingSummary};
use crate::workflow::build::PosesMode;
use crate::workflow::build::{
    check_truth_dir, pose_notes, poses_against_truth, register_poses, BuildError, BuildOptions,
    BuildScene,
};
use crate::workflow::registration_overlays::overlays_html;
use crate::Result;

/// What `register` did.
pub struct RegisterSummary {
    /// The registration.
    pub registration: PoseRegistration,
    /// The poses against the truth's (with `--truth` holding a poses.json).
    pub pose_truth: Option<PoseTruth>,
    /// Warnings (frames left out, a light that could not be fitted as asked).
    pub warnings: Vec<String>,
    /// Wall time (s).
    pub seconds: f64,
}

/// Register the poses of the case in `case_dir` to its CT into the folder `out` (atomically;
/// an existing `out` only with `opts.force`).
pub fn register_command(
    case_dir: &Path,
    out: &Path,
    opts: &BuildOptions,
) -> Result<RegisterSummary> {
    let started = std::time::Instant::now();
    if opts.poses == PosesMode::Fixed {
        return Err(BuildError::Registration(
            "--poses fixed: nothing to register (use refine or first)".into(),
        )
        .into());
    }
    check_truth_dir(opts.truth.as_deref(), false)?;
    let out_dir = OutputDir::create(out, opts.force)?;
    let mut timings = BuildTimings::default();
    let mut scene = BuildScene::prepare(case_dir, opts, &mut timings)?;
    let mut warnings = Vec::new();
    let registration = register_poses(&mut scene, opts, None, &mut warnings)?
        .ok_or_else(|| BuildError::Registration("--registration-rounds 0: nothing to do".into()))?;
    let pose_truth = poses_against_truth(
        Some(&registration),
        &scene,
        opts.truth.as_deref(),
        &mut warnings,
    )?;
    write_poses_annotated(
        &out_dir.join("poses.json"),
        &registration.poses,
        &scene.case.dir,
        &pose_notes(&registration),
    )?;
    write_poses(
        &out_dir.join("refined_poses.json"),
        &registration.refined,
        &scene.case.dir,
    )?;
    let record = serde_json::json!({
        "case": scene.case.dir.display().to_string(),
        "registration": &registration,
        "pose_truth": &pose_truth,
        "warnings": &warnings,
        "seconds": started.elapsed().as_secs_f64(),
    });
    write_json_atomic(&out_dir.join("registration.json"), &record)?;
    write_bytes_atomic(
        &out_dir.join("report.html"),
        registration_report(&registration, pose_truth.as_ref(), &scene.case.dir).as_bytes(),
    )?;
    out_dir.commit()?;
    Ok(RegisterSummary {
        registration,
        pose_truth,
        warnings,
        seconds: started.elapsed().as_secs_f64(),
    })
}

/// A self-contained HTML page: the corrections over the video (mm and degrees), the poses
/// against the truth when known, the rounds and every flagged frame.
pub fn registration_report(
    reg: &PoseRegistration,
    truth: Option<&PoseTruth>,
    case_dir: &Path,
) -> String {
    let mut html = format!(
        "<!doctype html><meta charset=utf-8><title>bronchosim registration</title>\
         <style>body{{font-family:sans-serif;max-width:60em;margin:2em auto}}td,th{{padding:0 .6em}}</style>\
         <h1>Registration of {}</h1><p>{} frames, {} left out of the model. {} {}</p>",
        html_escape(&case_dir.display().to_string()),
        reg.frames.len(),
        reg.left_out,
        html_escape(&reg.first_light_text()),
        html_escape(&reg.kept_text())
    );
    if reg.kept_given() {
        html.push_str("<p>What the rounds refined the poses to is in refined_poses.json.</p>");
    }
    if let Some(t) = &reg.tracking {
        html.push_str(&tracking_html(t));
    }
    html.push_str("<h2>Correction of every frame's pose</h2>");
    html.push_str(&correction_plots(reg));
    if let Some(t) = truth {
        html.push_str(&pose_truth_html(t));
    }
    if !reg.overlays.is_empty() {
        html.push_str("<h2>Before and after: frames on the model</h2>");
        html.push_str(&overlays_html(&reg.overlays));
    }
    html.push_str("<h2>Rounds</h2><table><tr><th>round</th><th>against</th><th>median step (mm)</th><th>median step (deg)</th><th>statuses</th><th>frames realigned</th><th>s</th></tr>");
    let numbered = reg
        .rounds
        .iter()
        .enumerate()
        .map(|(i, r)| ((i + 1).to_string(), r));
    let joint = reg.joint.iter().map(|r| ("after".to_string(), r));
    for (i, r) in numbered.chain(joint) {
        let counts: Vec<String> = r.counts.iter().map(|(k, v)| format!("{k} {v}")).collect();
        let _ = write!(
            html,
            "<tr><td>{}</td><td>{}</td><td>{:.3}</td><td>{:.3}</td><td>{}</td><td>{}</td><td>{:.1}</td></tr>",
            i,
            if r.discarded {
                format!("{} (discarded)", r.against)
            } else {
                r.against.clone()
            },
            r.median_step_mm,
            r.median_step_deg,
            counts.join(", "),
            r.realigned,
            r.seconds
        );
    }
    html.push_str("</table><h2>Flagged frames</h2>");
    let flagged: Vec<String> = reg
        .frames
        .iter()
        .filter(|f| f.status != "converged")
        .map(|f| {
            format!(
                "<tr><td>{}</td><td>{}</td><td>{:.2}</td><td>{:.2}</td><td>{}</td></tr>",
                f.frame,
                f.status,
                f.correction_mm,
                f.correction_deg,
                if f.used { "yes" } else { "no" }
            )
        })
        .collect();
    if flagged.is_empty() {
        html.push_str("<p>None: every frame converged.</p>");
    } else {
        html.push_str(
            "<table><tr><th>frame</th><th>status</th><th>mm</th><th>deg</th><th>used</th></tr>",
        );
        html.push_str(&flagged.concat());
        html.push_str("</table>");
    }
    html
}

/// A table of the poses against the truth: median, frames within 1 mm and 1 degree, and the
/// mean and RMS error along each of the true camera's axes.
pub(crate) fn pose_truth_html(t: &PoseTruth) -> String {
    let mut html = String::from(
        "<h2>Poses against the truth</h2><p>Errors along the true camera's axes (x right, y down, \
         z along the view; pitch, yaw and roll about them). A mean close to the RMS is an error \
         the frames share: held-out frames cannot show it, new views pay for it.</p>\
         <table><tr><th>poses</th><th>frames</th><th>median (mm / deg)</th><th>within 1 mm and 1 deg</th>\
         <th>mean x / y / z (mm)</th><th>RMS x / y / z (mm)</th><th>mean pitch / yaw / roll (deg)</th>\
         <th>RMS pitch / yaw / roll (deg)</th></tr>",
    );
    let three = |v: &[f64; 3], d: usize| format!("{:.d$} / {:.d$} / {:.d$}", v[0], v[1], v[2]);
    let rows = [
        Some(("given", &t.given)),
        t.refined.as_ref().map(|r| ("refined", r)),
        Some(("used by the model", &t.used)),
    ];
    for (name, a) in rows.into_iter().flatten() {
        let _ = write!(
            html,
            "<tr><td>{name}</td><td>{}</td><td>{:.3} / {:.3}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td></tr>",
            a.frames,
            a.median_mm,
            a.median_deg,
            a.within_1mm_1deg,
            three(&a.mean_mm, 3),
            three(&a.rms_mm, 3),
            three(&a.mean_deg, 2),
            three(&a.rms_deg, 2)
        );
    }
    html.push_str("</table>");
    html
}

/// One paragraph on the tracking from the first pose (`--poses first`).
pub(crate) fn tracking_html(t: &TrackingSummary) -> String {
    let resumed = match t.resumed_at.as_slice() {
        [] => String::new(),
        r => format!(
            "it was lost and resumed at frame{} {} (the frames before refined by the rounds); ",
            if r.len() > 1 { "s" } else { "" },
            r.iter()
                .map(|f| f.to_string())
                .collect::<Vec<_>>()
                .join(", ")
        ),
    };
    let lost = match t.first_lost {
        Some(f) => format!("{resumed}the track was lost at frame {f}"),
        None if resumed.is_empty() => "the track was never lost".to_string(),
        None => format!("{resumed}it then held to the end"),
    };
    let first = t.first_pose_words();
    format!(
        "<p>Tracked from the first frame's pose alone ({first}): {} of {} frames accepted; \
         {lost}; {} fits of the light; {:.2} s per frame. The corrections below are from the \
         tracked poses.</p>",
        t.frames_tracked, t.frames, t.light_fits, t.seconds_per_frame
    )
}

/// Two inline SVG plots of every frame's correction of its given pose: the camera centre's
/// shift (mm) and the rotation (degrees).
pub(crate) fn correction_plots(reg: &PoseRegistration) -> String {
    let mm: Vec<f64> = reg.frames.iter().map(|f| f.correction_mm).collect();
    let deg: Vec<f64> = reg.frames.iter().map(|f| f.correction_deg).collect();
    line_plot(&mm, "camera centre moved (mm)", "#1f77b4")
        + &line_plot(&deg, "camera turned (degrees)", "#d62728")
}

/// An inline SVG line plot of `values` over the frame index.
fn line_plot(values: &[f64], label: &str, colour: &str) -> String {
    let (w, h, pad) = (640.0, 160.0, 30.0);
    let top = values.iter().cloned().fold(0.0_f64, f64::max).max(1e-9);
    let n = values.len().max(2) as f64 - 1.0;
    let points: Vec<String> = values
        .iter()
        .enumerate()
        .map(|(i, v)| {
            let x = pad + (w - 2.0 * pad) * i as f64 / n;
            let y = h - pad - (h - 2.0 * pad) * (v / top);
            format!("{x:.1},{y:.1}")
        })
        .collect();
    format!(
        "<figure><svg width={w} height={h} viewBox='0 0 {w} {h}' role=img>\
         <line x1={pad} y1={b} x2={r} y2={b} stroke=#888 />\
         <line x1={pad} y1={pad} x2={pad} y2={b} stroke=#888 />\
         <text x={pad} y={t} font-size=11>{top:.2}</text>\
         <text x={pad} y={bl} font-size=11>0 (frame 0 … {last})</text>\
         <polyline fill=none stroke='{colour}' stroke-width=1.5 points='{}' /></svg>\
         <figcaption>{label}</figcaption></figure>",
        points.join(" "),
        b = h - pad,
        r = w - pad,
        t = pad - 6.0,
        bl = h - 8.0,
        last = values.len().saturating_sub(1),
    )
}

pub(crate) fn html_escape(s: &str) -> String {
    s.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
}
