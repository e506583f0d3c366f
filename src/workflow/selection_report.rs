//! The model report's frame selection section (issue 21): how many frames were used and why
//! the others were not, and each frame's scores over the video.

use std::fmt::Write;

use crate::model::selection::FrameSelection;
use crate::selection::Reason;

/// Colour of each reason's tick in the plot.
fn colour(r: Reason) -> &'static str {
    match r {
        Reason::Chosen => "#2ca02c",
        Reason::Blurred => "#d62728",
        Reason::BadlyExposed => "#ff7f0e",
        Reason::NoNewCoverage => "#7f7f7f",
        Reason::OverBudget => "#9467bd",
        Reason::NotTracked => "#c7c7c7",
    }
}

/// Append the section to `html`.
pub(crate) fn selection_section(html: &mut String, sel: &FrameSelection) {
    let n = sel.frames.len();
    let _ = write!(
        html,
        "<h2>Frame selection</h2><p>{} of {n} frames used (budget {}). Wall cells seen by the \
         used frames: {} of the {} any frame sees. Scoring {:.1} s, coverage cast {:.1} s, \
         choice {:.2} s.</p><table><tr>",
        sel.used,
        sel.budget,
        sel.cells_seen_used,
        sel.cells_seen_all,
        sel.seconds[0],
        sel.seconds[1],
        sel.seconds[2]
    );
    for r in Reason::ALL {
        let _ = write!(
            html,
            "<th style=\"color:{}\">{}</th>",
            colour(r),
            r.name().replace('_', " ")
        );
    }
    html.push_str("</tr><tr>");
    for r in Reason::ALL {
        let c = sel.counts.get(r.name()).copied().unwrap_or(0);
        let _ = write!(html, "<td>{c}</td>");
    }
    html.push_str("</tr></table>");
    let flagged_used = sel
        .frames
        .iter()
        .filter(|f| f.used && f.flagged.is_some())
        .count();
    if flagged_used > 0 {
        let _ = write!(
            html,
            "<p>{flagged_used} used frames were judged blurred or badly exposed (kept: no \
             better frame sees their wall, or the video is within the budget).</p>"
        );
    }
    html.push_str(&scores_plot(sel));
}

/// Each frame's sharpness relative to its neighbours and its score over the video, with a
/// tick per frame coloured by its reason.
fn scores_plot(sel: &FrameSelection) -> String {
    let (w, h, pad) = (640.0, 200.0, 30.0);
    let n = sel.frames.len().max(2) as f64 - 1.0;
    let top = 2.0;
    let x = |i: usize| pad + (w - 2.0 * pad) * i as f64 / n;
    let y = |v: f64| h - pad - 12.0 - (h - 2.0 * pad - 12.0) * (v.clamp(0.0, top) / top);
    let line = |vals: Vec<f64>, colour: &str| {
        let pts: Vec<String> = vals
            .iter()
            .enumerate()
            .map(|(i, v)| format!("{:.1},{:.1}", x(i), y(*v)))
            .collect();
        format!(
            "<polyline fill=none stroke='{colour}' stroke-width=1 points='{}' />",
            pts.join(" ")
        )
    };
    let mut s = format!(
        "<figure><svg width={w} height={h} viewBox='0 0 {w} {h}' role=img font-size=11>\
         <line x1={pad} y1={b} x2={r} y2={b} stroke=#888 />\
         <line x1={pad} y1={pad} x2={pad} y2={b} stroke=#888 />\
         <line x1={pad} y1={one:.1} x2={r} y2={one:.1} stroke=#ccc stroke-dasharray=4 />\
         <text x=2 y={t}>{top}</text><text x=2 y={one:.1}>1</text>\
         <text x={pad} y={bl}>frame 0 … {last}</text>",
        b = h - pad - 12.0,
        r = w - pad,
        one = y(1.0),
        t = pad,
        bl = h - 4.0,
        last = sel.frames.len().saturating_sub(1),
    );
    s += &line(
        sel.frames.iter().map(|f| f.relative_sharpness).collect(),
        "#1f77b4",
    );
    s += &line(sel.frames.iter().map(|f| f.score).collect(), "#bcbd22");
    for (i, f) in sel.frames.iter().enumerate() {
        let _ = write!(
            s,
            "<line x1={xi:.1} y1={y0} x2={xi:.1} y2={y1} stroke='{}' />",
            colour(f.reason),
            xi = x(i),
            y0 = h - pad - 10.0,
            y1 = h - pad - 2.0,
        );
    }
    s.push_str(
        "</svg><figcaption>sharpness relative to the neighbours (blue), score (olive: \
         relative sharpness capped at 1 × share of pixels neither saturated nor dark); ticks: \
         each frame's reason, coloured as in the table</figcaption></figure>",
    );
    s
}
