//! report.html: one self-contained page (images embedded, opens offline) with the paper's
//! figures for the user's own data: Fig. 2 (samples in (gamma, z) and the Psi fit), Fig. 3
//! (frame / predicted shading / extracted texture), the albedo atlas, fit quality over the
//! video and per-stage timings.

use crate::image::Frame;
use crate::io::png::write_png_srgb8;
use crate::model::blur_check::BlurCheck;
use crate::model::registration::PoseRegistration;
use crate::model::ModelManifest;
use crate::raycast::{GBuffer, RayTable};
use crate::shading::calibrated::plots::{plot_gains, plot_light_profile, plot_rho};
use crate::shading::calibrated::{cos_theta_of, CalibratedModel};
use crate::shading::paper::plots::{plot_psi_slices, plot_samples_density};
use crate::shading::paper::PsiModel;
use crate::shading::{FittedShading, FrameShading, SampleSet};
use crate::workflow::new_views_figure::NewViewsFigure;
use crate::workflow::register::{correction_plots, html_escape, pose_truth_html, tracking_html};
use crate::workflow::registration_overlays::overlays_html;
use crate::{Error, Result};
use base64::Engine;
use std::fmt::Write as _;
use std::path::Path;

/// One frame shown in the report.
pub struct ReportFrame {
    /// Frame index.
    pub index: usize,
    /// The linear frame.
    pub frame: Frame,
    /// Its geometry buffer.
    pub gbuffer: GBuffer,
    /// The samples the fit used.
    pub samples: SampleSet,
    /// The fitted Psi.
    pub psi: PsiModel,
}

/// What the report shows.
pub struct ReportInputs<'a> {
    /// The model manifest (counts, timings, fit quality).
    pub manifest: &'a ModelManifest,
    /// A few frames for Fig. 2 and Fig. 3.
    pub frames: &'a [ReportFrame],
    /// albedo.png.
    pub albedo_png: &'a [u8],
    /// New views (paper Fig. 4), with scores when reference views were given.
    pub new_views: Option<&'a NewViewsFigure>,
    /// The fitted shading models and the one in use.
    pub shading: &'a FittedShading,
}

fn img_tag(png: &[u8], alt: &str, width: Option<u32>) -> String {
    let b64 = base64::engine::general_purpose::STANDARD.encode(png);
    let w = width.map(|w| format!(" width=\"{w}\"")).unwrap_or_default();
    format!("<img alt=\"{alt}\"{w} src=\"data:image/png;base64,{b64}\">")
}

fn png_of(frame: &Frame, tmp: &Path, name: &str) -> Result<Vec<u8>> {
    let p = tmp.join(name);
    write_png_srgb8(&p, frame)?;
    std::fs::read(&p).map_err(|e| Error::io(&p, e))
}

/// Fig. 3 of the paper for one frame: the predicted shading per pixel (the frame's Psi, or the
/// calibrated light at its gain) and the extracted texture (frame / shading), both scaled for
/// display.
fn shading_and_texture(
    f: &ReportFrame,
    shading: FrameShading,
    cos_theta: &[f32],
) -> (Frame, Frame) {
    let (w, h) = (f.frame.width, f.frame.height);
    let mut shade = Frame::new(w, h);
    let mut tex = Frame::new(w, h);
    let mut max_shade = 0f64;
    let mut vals = Vec::with_capacity((w * h) as usize);
    for (i, &ct) in cos_theta.iter().enumerate().take((w * h) as usize) {
        let g = &f.gbuffer;
        if g.tri[i] == u32::MAX || g.gamma[i] <= 0.0 {
            vals.push(None);
            continue;
        }
        let s = shading.shade(g.gamma[i] as f64, g.z[i] as f64, ct as f64);
        let p = s.scale;
        max_shade = max_shade.max(p[1]);
        vals.push(Some((p, s.offset)));
    }
    let mut tex_vals: Vec<f32> = Vec::new();
    for (i, v) in vals.iter().enumerate() {
        // Where Psi predicts little light (far down the airway) its quotient is noise: the
        // texture stage drops those observations too (DelightOptions::min_relative_weight).
        if let Some((p, offset)) = v {
            let lit = p[1] >= 0.05 * max_shade;
            for (ch, &pc) in p.iter().enumerate() {
                let s = (pc / max_shade.max(1e-12)) as f32;
                shade.rgb[3 * i + ch] = s;
                if lit && pc > 1e-6 {
                    let t = (f.frame.rgb[3 * i + ch] - offset[ch] as f32) / pc as f32;
                    tex.rgb[3 * i + ch] = t;
                    tex_vals.push(t);
                }
            }
        }
    }
    // Texture is relative albedo: scale its 99th percentile to 0.9 for display.
    if !tex_vals.is_empty() {
        let k = (tex_vals.len() - 1) * 99 / 100;
        let p99 = *tex_vals.select_nth_unstable_by(k, |a, b| a.total_cmp(b)).1;
        if p99 > 0.0 {
            tex.rgb
                .iter_mut()
                .for_each(|v| *v = (*v * 0.9 / p99).min(1.0));
        }
    }
    (shade, tex)
}

/// An inline SVG line chart of per-frame values (one polyline per series).
fn svg_series(title: &str, series: &[(&str, &str, Vec<f64>)], y_range: (f64, f64)) -> String {
    let (w, h, pad) = (640.0, 200.0, 36.0);
    let n = series.iter().map(|s| s.2.len()).max().unwrap_or(0).max(2);
    let (y0, y1) = y_range;
    let x = |i: usize| pad + (w - 2.0 * pad) * i as f64 / (n - 1) as f64;
    let y = |v: f64| h - pad - (h - 2.0 * pad) * ((v - y0) / (y1 - y0)).clamp(0.0, 1.0);
    let mut s = format!(
        "<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"{w}\" height=\"{h}\" font-family=\"sans-serif\" font-size=\"11\">\
         <text x=\"{pad}\" y=\"14\">{title}</text>\
         <line x1=\"{pad}\" y1=\"{}\" x2=\"{}\" y2=\"{}\" stroke=\"#888\"/>\
         <line x1=\"{pad}\" y1=\"{pad}\" x2=\"{pad}\" y2=\"{}\" stroke=\"#888\"/>\
         <text x=\"2\" y=\"{}\">{y1:.2}</text><text x=\"2\" y=\"{}\">{y0:.2}</text>\
         <text x=\"{}\" y=\"{}\">frame</text>",
        h - pad,
        w - pad,
        h - pad,
        h - pad,
        pad + 4.0,
        h - pad,
        w / 2.0,
        h - 6.0
    );
    for (k, (name, colour, vals)) in series.iter().enumerate() {
        let pts: Vec<String> = vals
            .iter()
            .enumerate()
            .map(|(i, &v)| format!("{:.1},{:.1}", x(i), y(v)))
            .collect();
        let _ = write!(
            s,
            "<polyline fill=\"none\" stroke=\"{colour}\" stroke-width=\"1.5\" points=\"{}\"/>\
             <text x=\"{}\" y=\"14\" fill=\"{colour}\">{name}</text>",
            pts.join(" "),
            w - pad - 60.0 * (series.len() - k) as f64
        );
    }
    s.push_str("</svg>");
    s
}

/// Which shading model the texture and new views use, why (held-out frame prediction of both
/// models), and the calibrated light: rho(gamma), s(theta), the per-frame gains.
fn shading_section(
    html: &mut String,
    m: &ModelManifest,
    calibrated: Option<&CalibratedModel>,
    tmp: &Path,
) -> Result<()> {
    let _ = write!(
        html,
        "<h2>Shading model: {}</h2><p>\"paper\": one Psi(gamma, z) per viewpoint (Chung et al. \
         2004); \"calibrated\": one light for the whole video, g_f · rho(gamma) · s(theta) / z².</p>",
        m.shading_model
    );
    for w in &m.warnings {
        let _ = write!(html, "<p><b>Warning:</b> {w}</p>");
    }
    if let Some(cv) = &m.cross_validation {
        let _ = write!(
            html,
            "<h3>Cross-validation: predicting held-out frames</h3><p>Every {}-th frame ({} frames) \
             was left out of the texture, rendered from its pose as a new view (the paper: Psi of the \
             nearest training viewpoint) and compared with the recorded frame after one gain per \
             channel, on the pixels that obey the shading model.</p>\
             <table><tr><th>model</th><th>mean PSNR (dB)</th><th>mean SSIM</th></tr>",
            cv.every,
            cv.held_out.len()
        );
        let fmt = |v: Option<f64>, d: usize| v.map_or("-".into(), |x| format!("{x:.d$}"));
        for mc in &cv.models {
            let _ = write!(
                html,
                "<tr><td style=\"text-align:left\">{}</td><td>{}</td><td>{}</td></tr>",
                mc.model,
                fmt(mc.mean_psnr_db, 2),
                fmt(mc.mean_ssim, 4)
            );
        }
        html.push_str("</table>");
        let colours = ["#c60", "#06c"];
        let series: Vec<(&str, &str, Vec<f64>)> = cv
            .models
            .iter()
            .zip(colours)
            .map(|(mc, c)| {
                (
                    mc.model.name(),
                    c,
                    mc.frames.iter().map(|f| f.psnr_db.unwrap_or(0.0)).collect(),
                )
            })
            .collect();
        let all: Vec<f64> = series.iter().flat_map(|s| s.2.iter().copied()).collect();
        let lo = all.iter().copied().fold(f64::INFINITY, f64::min).floor() - 1.0;
        let hi = all.iter().copied().fold(f64::NEG_INFINITY, f64::max).ceil() + 1.0;
        if lo.is_finite() && hi > lo {
            html.push_str(&svg_series(
                "PSNR (dB) of each held-out frame, in video order",
                &series,
                (lo, hi),
            ));
        }
    }
    if let Some(c) = calibrated {
        let read = |p: &Path| std::fs::read(p).map_err(|e| Error::io(p, e));
        let (rho, s, g) = (
            tmp.join("rho.png"),
            tmp.join("s.png"),
            tmp.join("gains.png"),
        );
        plot_rho(c, &rho)?;
        plot_light_profile(c, None, &s)?;
        plot_gains(c, &g)?;
        let _ = write!(
            html,
            "<h3>The calibrated light</h3>\
             <figure>{}<figcaption>rho(gamma) per channel (reflectance × light × mean albedo)</figcaption></figure>\
             <figure>{}<figcaption>s(theta): the light's angular profile and vignetting (1 on the axis)</figcaption></figure>\
             <figure>{}<figcaption>per-frame gain (auto-exposure), frame {} = 1</figcaption></figure>",
            img_tag(&read(&rho)?, "rho", Some(420)),
            img_tag(&read(&s)?, "s(theta)", Some(420)),
            img_tag(&read(&g)?, "gains", Some(520)),
            c.reference_frame
        );
    }
    Ok(())
}

/// Fig. 4: rows of images and, with references, the score table.
fn new_views_section(html: &mut String, fig: &NewViewsFigure, tmp: &Path) -> Result<()> {
    let _ = write!(
        html,
        "<h2>New views (paper Fig. 4)</h2><p>{}</p>",
        fig.caption
    );
    if !fig.scores.is_empty() {
        html.push_str(
            "<table><tr><th>method</th><th>mean PSNR (dB)</th><th>mean SSIM</th>\
             <th>mean PSNR where the reference is not saturated (dB)</th></tr>",
        );
        for s in &fig.scores {
            let _ = write!(
                html,
                "<tr><td style=\"text-align:left\">{}</td><td>{:.2}</td><td>{:.4}</td><td>{:.2}</td></tr>",
                s.method, s.mean_psnr_db, s.mean_ssim, s.mean_unsaturated_psnr_db
            );
        }
        html.push_str("</table>");
    }
    for (r, row) in fig.rows.iter().enumerate() {
        let _ = write!(html, "<h3>{}</h3>", row.name);
        for (k, (caption, img)) in row.images.iter().enumerate() {
            let png = png_of(img, tmp, &format!("fig4_{r}_{k}.png"))?;
            let _ = write!(
                html,
                "<figure>{}<figcaption>{caption}</figcaption></figure>",
                img_tag(&png, caption, Some(200))
            );
        }
    }
    Ok(())
}

/// Paper Fig. 2 and Fig. 3 for the report's frames: the samples, Psi's fit, the frame, its
/// predicted shading and the texture it gives.
fn frame_figures(html: &mut String, inputs: &ReportInputs, tmp: &Path) -> Result<()> {
    let m = inputs.manifest;
    // Fig. 2 and Fig. 3 for a few frames.
    html.push_str("<h2>Shading fit (paper Fig. 2) and de-lighting (paper Fig. 3)</h2>");
    // cos theta of every pixel's ray (the calibrated light's angular profile).
    let cos_theta = cos_theta_of(&RayTable::new(&m.camera));
    for f in inputs.frames {
        let _ = write!(html, "<h3>Frame {}</h3>", f.index);
        let dens = tmp.join(format!("dens{}.png", f.index));
        plot_samples_density(&f.samples, &dens)?;
        let mut zs: Vec<f32> = f.samples.z.clone();
        let k = zs.len() / 2;
        let zmed = *zs.select_nth_unstable_by(k, |a, b| a.total_cmp(b)).1 as f64;
        let slices = [
            (zmed - 4.0, zmed - 2.0),
            (zmed - 1.0, zmed + 1.0),
            (zmed + 2.0, zmed + 4.0),
        ];
        let fit = tmp.join(format!("fit{}.png", f.index));
        plot_psi_slices(&f.samples, &f.psi, &slices, &fit)?;
        let read = |p: &Path| std::fs::read(p).map_err(|e| Error::io(p, e));
        let shading = inputs
            .shading
            .frame_shaders(m.shading_model)?
            .frame_shading(f.index);
        let (shade, tex) = shading_and_texture(f, shading, &cos_theta);
        let name = match shading {
            FrameShading::Paper(_) => "Psi(gamma, z)",
            FrameShading::Calibrated { .. } => "g_f rho(gamma) s(theta) / z²",
        };
        let _ = write!(
            html,
            "<figure>{}<figcaption>(a) samples in (gamma, z): uneven density</figcaption></figure>\
             <figure>{}<figcaption>(b) Psi against the samples in depth slices</figcaption></figure><br>\
             <figure>{}<figcaption>frame</figcaption></figure>\
             <figure>{}<figcaption>predicted shading {name}</figcaption></figure>\
             <figure>{}<figcaption>extracted texture (frame / shading)</figcaption></figure>\
             <p>R² {:.3} / {:.3} / {:.3}; samples used {}; excluded: no hit {}, grazing {}, saturated {}, dark {}.</p>",
            img_tag(&read(&dens)?, "Fig. 2a", Some(420)),
            img_tag(&read(&fit)?, "Fig. 2b", Some(420)),
            img_tag(&png_of(&f.frame, tmp, "frame.png")?, "frame", Some(256)),
            img_tag(&png_of(&shade, tmp, "shade.png")?, "shading", Some(256)),
            img_tag(&png_of(&tex, tmp, "tex.png")?, "texture", Some(256)),
            m.fit_quality[f.index].r2[0],
            m.fit_quality[f.index].r2[1],
            m.fit_quality[f.index].r2[2],
            f.samples.len(),
            f.samples.excluded.no_hit,
            f.samples.excluded.grazing,
            f.samples.excluded.saturated,
            f.samples.excluded.dark,
        );
    }
    Ok(())
}

/// The registration's corrections over the video and its rounds (issue 16).
/// Every judged frame's sharpness against the model's prediction from its pose, and the frames
/// left out as blurred (`at_given_poses`: the poses were trusted as given; else the
/// registration judged them after its first rounds).
fn blur_check_section(html: &mut String, check: &BlurCheck, at_given_poses: bool) {
    let blurred = check.blurred_frames();
    let _ = write!(
        html,
        "<h2>Blurred frames</h2><p>Each frame's sharpness against the model's prediction from its \
         pose ({}), over the video's median. {} of {} frames under {:.2} were left out as \
         blurred{}.</p>",
        match at_given_poses {
            true => "the poses as given",
            false => "the registration's poses after its first rounds",
        },
        blurred.len(),
        check.frames.len(),
        check.blurred_below,
        match blurred.is_empty() {
            true => String::new(),
            false => format!(": frames {blurred:?}"),
        }
    );
    let values: Vec<f64> = check
        .frames
        .iter()
        .map(|f| f.relative_sharpness.unwrap_or(1.0))
        .collect();
    let unjudged = check
        .frames
        .iter()
        .filter(|f| f.relative_sharpness.is_none())
        .count();
    if unjudged > 0 {
        let _ = write!(
            html,
            "<p>{unjudged} frames showed too little to judge (drawn at 1).</p>"
        );
    }
    let line = vec![check.blurred_below; values.len()];
    html.push_str(&svg_series(
        "sharpness against the prediction, over the median",
        &[("frame", "#36c", values), ("left out below", "#c33", line)],
        (0.0, 2.0),
    ));
}

fn registration_section(html: &mut String, reg: &PoseRegistration) {
    html.push_str(&format!(
        "<h2>Registration of the poses to the CT</h2><p>{}; {} of {} frames left out \
         (their pose could not be trusted). {} {} Each frame's correction of its given pose:</p>",
        reg.rounds_text(),
        reg.left_out,
        reg.frames.len(),
        html_escape(&reg.first_light_text()),
        html_escape(&reg.kept_text())
    ));
    if let Some(t) = &reg.tracking {
        html.push_str(&tracking_html(t));
    }
    html.push_str(&correction_plots(reg));
    if !reg.overlays.is_empty() {
        html.push_str(&overlays_html(&reg.overlays));
    }
}

/// Write report.html.
pub fn write_report(path: &Path, inputs: &ReportInputs) -> Result<()> {
    let m = inputs.manifest;
    let tmp = tempfile::tempdir().map_err(|e| Error::io(std::env::temp_dir(), e))?;
    let mut html = String::new();
    html.push_str(
        "<!DOCTYPE html><html><head><meta charset=\"utf-8\"><title>bronchosim model report</title>\
         <style>body{font-family:sans-serif;max-width:1100px;margin:2em auto;color:#222}\
         table{border-collapse:collapse}td,th{border:1px solid #ccc;padding:3px 8px;text-align:right}\
         th{background:#f3f3f3}figure{display:inline-block;margin:6px;vertical-align:top}\
         figcaption{font-size:12px;color:#555}img{image-rendering:pixelated;border:1px solid #ddd}</style>\
         </head><body>",
    );
    let _ = write!(
        html,
        "<h1>bronchosim model report</h1><p>{} — case <code>{}</code>; {} frames; lumen mesh {} triangles; \
         atlas {}×{} texels ({} charts, utilisation {:.0}%, mean L2 stretch {:.3}); {} of {} chart texels seen by a frame ({:.0}%).</p>",
        m.generator,
        m.inputs.case,
        m.counts.frames,
        m.counts.triangles,
        m.counts.atlas_size[0],
        m.counts.atlas_size[1],
        m.counts.charts,
        100.0 * m.atlas_utilisation,
        m.atlas_mean_l2_stretch,
        m.counts.covered_texels,
        m.counts.chart_texels,
        100.0 * m.counts.covered_texels as f64 / m.counts.chart_texels.max(1) as f64
    );
    if let Some(u) = &m.unseen_walls {
        // coverage.png marks the seen texels; say what the others hold.
        let _ = write!(
            html,
            "<p>Walls no frame saw ({:.0}% of the surface): {:.0}% synthesised from the seen \
             mucosa (patch quilting, patches of {:.1} mm), {:.0}% filled from neighbouring \
             colours (<code>--unseen synthesise|fill</code>); <code>coverage.png</code> marks \
             the observed texels.</p>",
            100.0 * (1.0 - u.observed_share),
            100.0 * u.synthesised_share,
            u.patch_mm,
            100.0 * u.filled_share
        );
    }
    // The viewer sits beside the model folder (`bronchosim view`'s default, and the demo's).
    html.push_str(
        "<p><b>Fly through this model</b> in a browser, lit as the bronchoscope lights it: \
         <a href=\"../viewer/index.html\">../viewer/index.html</a> (written by <code>bronchosim \
         demo</code>, or by <code>bronchosim view MODEL</code> for any model).</p>",
    );
    shading_section(&mut html, m, inputs.shading.calibrated.as_ref(), tmp.path())?;
    // Fit quality over the video.
    html.push_str("<h2>Fit quality of Psi over the video</h2>");
    let r2 = |c: usize| m.fit_quality.iter().map(|f| f.r2[c]).collect::<Vec<_>>();
    html.push_str(&svg_series(
        &format!("R² of Psi against the pixels (mean {:.3})", m.mean_r2),
        &[
            ("R", "#c33", r2(0)),
            ("G", "#3a3", r2(1)),
            ("B", "#33c", r2(2)),
        ],
        (0.0, 1.0),
    ));
    frame_figures(&mut html, inputs, tmp.path())?;
    if let Some(sel) = &m.frame_selection {
        crate::workflow::selection_report::selection_section(&mut html, sel);
    }
    if let Some(reg) = &m.registration {
        registration_section(&mut html, reg);
    }
    let blur_check = m.blur_check.as_ref();
    if let Some(check) = blur_check.or(m.registration.as_ref().and_then(|r| r.blur_check.as_ref()))
    {
        blur_check_section(&mut html, check, blur_check.is_some());
    }
    if let Some(t) = &m.pose_truth {
        html.push_str(&pose_truth_html(t));
    }
    if let Some(fig) = inputs.new_views {
        new_views_section(&mut html, fig, tmp.path())?;
    }
    html.push_str("<h2>Fused albedo atlas</h2>");
    html.push_str(&img_tag(inputs.albedo_png, "albedo atlas", Some(1000)));
    // Timings.
    let t = &m.timings;
    let _ = write!(
        html,
        "<h2>Timings (s)</h2><table><tr><th>read case</th><th>segment</th><th>mesh</th><th>atlas</th>\
         <th>frame selection</th><th>registration</th><th>blur check</th><th>fit Psi</th><th>calibrated light</th><th>cross-validation</th><th>de-light + fuse</th>\
         </tr><tr><td>{:.2}</td><td>{:.2}</td><td>{:.2}</td><td>{:.2}</td><td>{:.2}</td><td>{:.2}</td><td>{:.2}</td><td>{:.2}</td>\
         <td>{:.2}</td><td>{:.2}</td><td>{:.2}</td></tr></table>",
        t.read_case,
        t.segment,
        t.mesh,
        t.atlas,
        t.selection,
        t.registration,
        t.blur_check,
        t.fit,
        t.calibrated_fit,
        t.cross_validation,
        t.fusion
    );
    html.push_str("</body></html>\n");
    crate::io::atomic::write_bytes_atomic(path, html.as_bytes())
}
