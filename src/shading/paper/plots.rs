//! Plots a person looks at, reproducing the paper's Fig. 2: (a) the samples in the (gamma, z)
//! plane with their uneven density, (b) Psi against the samples in depth slices.
//!
//! The file type follows the path: `.svg` writes SVG, anything else PNG (rendered into an RGB
//! buffer and encoded with `png`; plotters' own encoder would pull a second image crate).

// Indexing several parallel arrays (struct of arrays, channels) by one index reads clearer than zips.
#![allow(clippy::needless_range_loop)]

use super::psi::PsiModel;
use crate::shading::plotting::{render, CURVE_RGB, FONT_NAME};
use crate::shading::samples::SampleSet;
use crate::{Error, Result};
use plotters::coord::Shift;
use plotters::prelude::*;
use std::path::Path;

/// Channel colours for points (light) and curves (dark).
const POINT_RGB: [RGBColor; 3] = [
    RGBColor(230, 60, 50),
    RGBColor(40, 170, 60),
    RGBColor(50, 90, 230),
];

/// At most `max` evenly strided indices of `0..n` (keeps plots light without random sampling).
fn stride(n: usize, max: usize) -> impl Iterator<Item = usize> {
    let step = n.div_ceil(max.max(1)).max(1);
    (0..n).step_by(step)
}

/// Fig. 2a: every sample as a faint dot at (gamma, z mm), so overlapping dots show density.
pub fn plot_samples_density(samples: &SampleSet, path: &Path) -> Result<()> {
    if samples.is_empty() {
        return Err(Error::invalid(path, "no samples to plot"));
    }
    render!(path, (900, 700), |root| draw_density(root, samples))
}

/// Fig. 2b: one panel per depth slice `[z0, z1)` mm: the samples' R, G, B against gamma, and
/// Psi at the slice's middle depth.
pub fn plot_psi_slices(
    samples: &SampleSet,
    model: &PsiModel,
    z_slices_mm: &[(f64, f64)],
    path: &Path,
) -> Result<()> {
    if z_slices_mm.is_empty() {
        return Err(Error::invalid(path, "no depth slices to plot"));
    }
    let w = 460 * z_slices_mm.len() as u32;
    render!(path, (w, 480), |root| draw_slices(
        root,
        samples,
        model,
        z_slices_mm
    ))
}

type DrawResult<DB> =
    std::result::Result<(), DrawingAreaErrorKind<<DB as DrawingBackend>::ErrorType>>;

fn draw_density<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
    s: &SampleSet,
) -> DrawResult<DB> {
    root.fill(&WHITE)?;
    let (z_lo, z_hi) =
        s.z.iter()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), &z| {
                (lo.min(f64::from(z)), hi.max(f64::from(z)))
            });
    let mut chart = ChartBuilder::on(root)
        .caption(
            format!(
                "Samples in (gamma, z): {} used, {} excluded",
                s.len(),
                s.excluded.total()
            ),
            (FONT_NAME, 22),
        )
        .margin(12)
        .x_label_area_size(45)
        .y_label_area_size(55)
        .build_cartesian_2d(0.0..1.0, z_lo.floor()..z_hi.ceil())?;
    chart
        .configure_mesh()
        .x_desc("gamma = cos(view, normal)")
        .y_desc("z (mm)")
        .label_style((FONT_NAME, 15))
        .draw()?;
    let dot = RGBAColor(20, 40, 140, 0.12);
    chart.draw_series(
        stride(s.len(), 60_000)
            .map(|i| Circle::new((f64::from(s.gamma[i]), f64::from(s.z[i])), 1, dot.filled())),
    )?;
    // The depth range Psi is normalised over.
    for z in [s.z_min, s.z_max] {
        chart.draw_series(LineSeries::new([(0.0, z), (1.0, z)], RED.stroke_width(1)))?;
    }
    Ok(())
}

fn draw_slices<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
    s: &SampleSet,
    m: &PsiModel,
    slices: &[(f64, f64)],
) -> DrawResult<DB> {
    root.fill(&WHITE)?;
    let panels = root.split_evenly((1, slices.len()));
    for (panel, &(z0, z1)) in panels.iter().zip(slices) {
        let idx: Vec<usize> = (0..s.len())
            .filter(|&i| (z0..z1).contains(&f64::from(s.z[i])))
            .collect();
        // Each panel scaled to its own samples: far slices are dim.
        let p_max = idx
            .iter()
            .flat_map(|&i| (0..3).map(move |ch| f64::from(s.rgb[ch][i])))
            .fold(1e-3f64, f64::max);
        let mut chart = ChartBuilder::on(panel)
            .caption(
                format!("z {z0:.0}-{z1:.0} mm ({} samples)", idx.len()),
                (FONT_NAME, 18),
            )
            .margin(10)
            .x_label_area_size(40)
            .y_label_area_size(50)
            .build_cartesian_2d(0.0..1.0, 0.0..p_max * 1.05)?;
        chart
            .configure_mesh()
            .x_desc("gamma")
            .y_desc("linear intensity")
            .label_style((FONT_NAME, 14))
            .draw()?;
        for ch in 0..3 {
            let c = POINT_RGB[ch].mix(0.25);
            chart.draw_series(stride(idx.len(), 4000).map(|k| {
                let i = idx[k];
                Circle::new(
                    (f64::from(s.gamma[i]), f64::from(s.rgb[ch][i])),
                    1,
                    c.filled(),
                )
            }))?;
        }
        let zm = 0.5 * (z0 + z1);
        for ch in 0..3 {
            let curve = (0..=100).map(|k| {
                let g = f64::from(k) / 100.0;
                (g, m.eval(ch, g, zm))
            });
            chart.draw_series(LineSeries::new(curve, CURVE_RGB[ch].stroke_width(2)))?;
        }
    }
    Ok(())
}
