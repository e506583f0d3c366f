//! What each command prints when it is done: one formatter per command's result, so the
//! command line only parses, calls and prints.

use crate::model::registration::{PoseRegistration, PoseTruth};
use crate::registration::accuracy::PoseAccuracy;
use crate::workflow::register::RegisterSummary;
use std::path::Path;

use crate::model::ModelManifest;
use crate::phantom::PhantomSummary;
use crate::render::evaluate::scores_text;
use crate::workflow::demo::DemoSummary;
use crate::workflow::flythrough::FlythroughSummary;
use crate::workflow::render::RenderSummary;

/// "held-out frames: paper 31.19 dB, calibrated 33.76 dB" (empty without cross-validation).
fn held_out_text(m: &ModelManifest) -> String {
    m.cross_validation.as_ref().map_or(String::new(), |cv| {
        let parts: Vec<String> = cv
            .models
            .iter()
            .map(|mc| format!("{} {:.2} dB", mc.model, mc.mean_psnr_db.unwrap_or(f64::NAN)))
            .collect();
        format!(" (held-out frames: {})", parts.join(", "))
    })
}

impl DemoSummary {
    /// The case, the model, its report and the truth views' scores.
    pub fn to_text(&self) -> String {
        let m = &self.manifest;
        format!(
            "phantom case {} ({} frames, {:.1} s)\nmodel {} in {:.1} s: {} triangles, atlas {}x{}, {:.0}% of chart texels seen, mean R² of Psi {:.3}, shading {}{}\nreport {}\n\
             truth views rendered into {}; scores (PSNR dB / SSIM, same pixels, per-channel gain):\n{}\n\
             fly through the model: open {} in a browser (WebGL2)\n",
            self.case.display(),
            m.counts.frames,
            self.phantom_seconds,
            self.model.display(),
            m.timings.total,
            m.counts.triangles,
            m.counts.atlas_size[0],
            m.counts.atlas_size[1],
            100.0 * m.counts.covered_texels as f64 / m.counts.chart_texels.max(1) as f64,
            m.mean_r2,
            m.shading_model,
            held_out_text(m),
            self.model.join("report.html").display(),
            self.views.display(),
            scores_text(&self.scores),
            self.viewer.join("index.html").display(),
        )
    }
}

/// What `build` made in `out`, and how well each model predicted the held-out frames.
pub fn build_text(out: &Path, m: &ModelManifest) -> String {
    let mut text = format!(
        "built {} from {} frames in {:.1} s: {} triangles, atlas {}x{} ({} of {} texels seen), mean R² of Psi {:.3}, shading {}\n",
        out.display(),
        m.counts.frames,
        m.timings.total,
        m.counts.triangles,
        m.counts.atlas_size[0],
        m.counts.atlas_size[1],
        m.counts.covered_texels,
        m.counts.chart_texels,
        m.mean_r2,
        m.shading_model
    );
    if let Some(reg) = &m.registration {
        text.push_str(&registration_line(reg));
    }
    if let Some(check) = &m.blur_check {
        let blurred = check.blurred_frames();
        text.push_str(&format!(
            "  blurred frames at the given poses: {} of {} left out{}\n",
            blurred.len(),
            check.frames.len(),
            match blurred.is_empty() {
                true => String::new(),
                false => format!(" ({blurred:?})"),
            }
        ));
    }
    if let Some(t) = &m.pose_truth {
        text.push_str(&pose_truth_line(t));
    }
    if let Some(cv) = &m.cross_validation {
        for mc in &cv.models {
            text.push_str(&format!(
                "  held-out frames ({} of {}): {} predicts them at {:.2} dB PSNR, SSIM {:.4}\n",
                cv.held_out.len(),
                m.counts.frames,
                mc.model,
                mc.mean_psnr_db.unwrap_or(f64::NAN),
                mc.mean_ssim.unwrap_or(f64::NAN)
            ));
        }
    }
    text
}

/// One line on a registration: rounds, median and largest correction, frames left out.
fn registration_line(reg: &PoseRegistration) -> String {
    let mut mm: Vec<f64> = reg.frames.iter().map(|f| f.correction_mm).collect();
    let mut deg: Vec<f64> = reg.frames.iter().map(|f| f.correction_deg).collect();
    mm.sort_by(f64::total_cmp);
    deg.sort_by(f64::total_cmp);
    let mid = mm.len() / 2;
    let tracked = reg.tracking.as_ref().map_or(String::new(), |t| {
        format!(
            "  tracked from the first pose ({}): {} of {} frames, {}, {:.2} s per frame\n",
            t.first_pose_words(),
            t.frames_tracked,
            t.frames,
            match (t.first_lost, t.resumed_at.is_empty()) {
                (Some(f), _) => format!("lost at frame {f}"),
                (None, true) => "never lost".to_string(),
                (None, false) => "held to the end".to_string(),
            } + &match t.resumed_at.as_slice() {
                [] => String::new(),
                r => format!(" (resumed at frames {r:?})"),
            },
            t.seconds_per_frame
        )
    });
    let mut first_light = match (&reg.scope_light, reg.lambert_lamp) {
        (Some(source), _) => format!("  registered against the scope light of {source}\n"),
        (None, true) => "  first round run again against a Lambertian lamp (the light fitted at the given poses converged on too few frames)\n".to_string(),
        (None, false) => String::new(),
    };
    if reg.consensus_start {
        first_light += "  first round run again from the given poses corrected as each frame's neighbours agreed (from the given poses it converged on too few frames)\n";
    }
    let kept = match (
        reg.kept_given(),
        reg.held_out_psnr_refined_db,
        reg.held_out_psnr_given_db,
    ) {
        (true, Some(r), Some(g)) => format!(
            "  the {start} poses were kept: held-out frames {r:.2} dB with the refined poses, {g:.2} dB with the {start} ones\n",
            start = reg.started_from()
        ),
        _ => String::new(),
    };
    tracked
        + &first_light
        + &kept
        + &format!(
        "  poses registered in {}: median correction {:.2} mm / {:.2} deg (largest {:.2} mm / {:.2} deg), {} of {} frames left out\n",
        reg.rounds_text(),
        mm.get(mid).copied().unwrap_or(0.0),
        deg.get(mid).copied().unwrap_or(0.0),
        mm.last().copied().unwrap_or(0.0),
        deg.last().copied().unwrap_or(0.0),
        reg.left_out,
        reg.frames.len()
    )
}

/// One line on the poses against the truth: given and used, median and frames within.
fn pose_truth_line(t: &PoseTruth) -> String {
    let one = |a: &PoseAccuracy| {
        format!(
            "{:.3} mm / {:.3} deg median, {} of {} within 1 mm and 1 deg",
            a.median_mm, a.median_deg, a.within_1mm_1deg, a.frames
        )
    };
    format!(
        "  poses against the truth: given {}; used {}\n",
        one(&t.given),
        one(&t.used)
    )
}

/// What `register` wrote into `out`.
pub fn register_text(out: &Path, s: &RegisterSummary) -> String {
    let truth = s.pose_truth.as_ref().map_or(String::new(), pose_truth_line);
    format!(
        "registered {} in {:.1} s\n{}{truth}",
        out.display(),
        s.seconds,
        registration_line(&s.registration)
    )
}

impl PhantomSummary {
    /// What was written into `out` in `seconds`, and each part's time.
    pub fn to_text(&self, out: &Path, seconds: f64) -> String {
        let s = self.seconds;
        format!(
            "wrote {}: CT {:?}, mesh {} triangles, {} frames, {} truth views in {seconds:.1} s \
             (CT {:.1}, mesh {:.1}, path {:.1}, frames {:.1}, views {:.1}, CT file {:.1})\n",
            out.display(),
            self.ct_dims,
            self.mesh_triangles,
            self.frames,
            self.views,
            s[0],
            s[1],
            s[2],
            s[3],
            s[4],
            s[5]
        )
    }
}

impl RenderSummary {
    /// How many views were rendered into `out`, how fast, with which shading.
    pub fn to_text(&self, out: &Path) -> String {
        format!(
            "rendered {} views into {} in {:.2} s ({:.1} views/s; shading {}; model loaded in {:.2} s)\n",
            self.images.len(),
            out.display(),
            self.render_seconds,
            self.images.len() as f64 / self.render_seconds.max(1e-9),
            self.shading,
            self.load_seconds
        )
    }
}

impl FlythroughSummary {
    /// The flight: frames, path length, clearance, speed and the video.
    pub fn to_text(&self) -> String {
        format!(
            "{}: {} frames along {:.1} mm (clearance >= {:.1} mm) in {:.1} s ({:.1} frames/s); {}\n",
            self.out.display(),
            self.frames,
            self.path_length_mm,
            self.min_clearance_mm,
            self.render_seconds,
            self.frames as f64 / self.render_seconds.max(1e-9),
            self.video_note
        )
    }
}
