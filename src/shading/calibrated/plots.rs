//! Plots of the calibrated light model for the report: rho(gamma) per channel, the light's
//! angular profile s(theta) in degrees, and the per-frame gains. `.svg` paths write SVG,
//! anything else PNG (see [`crate::shading::plotting`]).

// Indexing the channel colour table by channel reads clearer than zips.
#![allow(clippy::needless_range_loop)]

use super::model::CalibratedModel;
use crate::shading::plotting::{render, CURVE_RGB, FONT_NAME};
use crate::{Error, Result};
use plotters::coord::Shift;
use plotters::prelude::*;
use std::path::Path;

type DrawResult<DB> =
    std::result::Result<(), DrawingAreaErrorKind<<DB as DrawingBackend>::ErrorType>>;

/// rho(gamma) of R, G, B over gamma in [0, 1] (linear intensity x mm² at the reference gain).
pub fn plot_rho(model: &CalibratedModel, path: &Path) -> Result<()> {
    render!(path, (800, 560), |root| draw_rho(root, model))
}

/// s(theta) over theta in degrees from 0 to the fitted edge, with an optional reference curve
/// (e.g. the phantom's true cone profile) drawn dashed in grey.
pub fn plot_light_profile(
    model: &CalibratedModel,
    truth: Option<&dyn Fn(f64) -> f64>,
    path: &Path,
) -> Result<()> {
    render!(path, (800, 560), |root| draw_profile(root, model, truth))
}

/// The gain of every fitted frame (the reference frame's is 1).
pub fn plot_gains(model: &CalibratedModel, path: &Path) -> Result<()> {
    if model.gains.is_empty() {
        return Err(Error::invalid(path, "no gains to plot"));
    }
    render!(path, (900, 480), |root| draw_gains(root, model))
}

fn draw_rho<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
    m: &CalibratedModel,
) -> DrawResult<DB> {
    root.fill(&WHITE)?;
    let curve =
        |ch: usize| (0..=100).map(move |k| (f64::from(k) / 100.0, m.rho(ch, f64::from(k) / 100.0)));
    let hi = (0..3)
        .flat_map(curve)
        .map(|(_, v)| v)
        .fold(1e-9f64, f64::max);
    let lo = (0..3)
        .flat_map(curve)
        .map(|(_, v)| v)
        .fold(0.0f64, f64::min);
    let mut chart = ChartBuilder::on(root)
        .caption("rho(gamma) per channel", (FONT_NAME, 22))
        .margin(12)
        .x_label_area_size(45)
        .y_label_area_size(70)
        .build_cartesian_2d(0.0..1.0, lo..hi * 1.05)?;
    chart
        .configure_mesh()
        .x_desc("gamma = cos(view, normal)")
        .y_desc("rho (intensity x mm², reference gain)")
        .label_style((FONT_NAME, 15))
        .draw()?;
    for ch in 0..3 {
        chart.draw_series(LineSeries::new(curve(ch), CURVE_RGB[ch].stroke_width(2)))?;
    }
    Ok(())
}

fn draw_profile<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
    m: &CalibratedModel,
    truth: Option<&dyn Fn(f64) -> f64>,
) -> DrawResult<DB> {
    root.fill(&WHITE)?;
    let edge = m.theta_edge_deg();
    let pts: Vec<(f64, f64)> = (0..=120)
        .map(|k| {
            let th = edge * f64::from(k) / 120.0;
            (th, m.s(th.to_radians().cos()))
        })
        .collect();
    let tr: Vec<(f64, f64)> = truth
        .map(|f| pts.iter().map(|&(th, _)| (th, f(th))).collect())
        .unwrap_or_default();
    let hi = pts.iter().chain(&tr).map(|p| p.1).fold(1.0f64, f64::max);
    let mut chart = ChartBuilder::on(root)
        .caption(
            "Light profile s(theta) (1 on the optical axis)",
            (FONT_NAME, 22),
        )
        .margin(12)
        .x_label_area_size(45)
        .y_label_area_size(55)
        .build_cartesian_2d(0.0..edge.max(1e-3), 0.0..hi * 1.05)?;
    chart
        .configure_mesh()
        .x_desc("theta off the optical axis (degrees)")
        .y_desc("s")
        .label_style((FONT_NAME, 15))
        .draw()?;
    if !tr.is_empty() {
        chart
            .draw_series(DashedLineSeries::new(
                tr,
                6,
                4,
                RGBColor(120, 120, 120).stroke_width(2),
            ))?
            .label("reference")
            .legend(|(x, y)| PathElement::new([(x, y), (x + 20, y)], RGBColor(120, 120, 120)));
    }
    chart
        .draw_series(LineSeries::new(pts, BLACK.stroke_width(2)))?
        .label("fitted")
        .legend(|(x, y)| PathElement::new([(x, y), (x + 20, y)], BLACK));
    chart
        .configure_series_labels()
        .label_font((FONT_NAME, 15))
        .background_style(WHITE.mix(0.8))
        .border_style(BLACK)
        .draw()?;
    Ok(())
}

fn draw_gains<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
    m: &CalibratedModel,
) -> DrawResult<DB> {
    root.fill(&WHITE)?;
    let n = m.gains.len();
    let hi = m.gains.iter().copied().fold(1.0f64, f64::max);
    let mut chart = ChartBuilder::on(root)
        .caption(
            format!("Per-frame gain (frame {} = 1)", m.reference_frame),
            (FONT_NAME, 22),
        )
        .margin(12)
        .x_label_area_size(45)
        .y_label_area_size(55)
        .build_cartesian_2d(-0.5..(n as f64 - 0.5), 0.0..hi * 1.1)?;
    chart
        .configure_mesh()
        .x_desc("frame")
        .y_desc("gain")
        .label_style((FONT_NAME, 15))
        .draw()?;
    let pts: Vec<(f64, f64)> = m
        .gains
        .iter()
        .enumerate()
        .map(|(f, &g)| (f as f64, g))
        .collect();
    chart.draw_series(LineSeries::new(
        pts.clone(),
        RGBColor(60, 60, 160).stroke_width(1),
    ))?;
    chart.draw_series(
        pts.into_iter()
            .map(|p| Circle::new(p, 3, RGBColor(20, 20, 120).filled())),
    )?;
    Ok(())
}
