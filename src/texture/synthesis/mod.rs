//! Walls the video never saw: example-based synthesis of mucosa on the atlas texels no frame
//! covered, from the texture the frames did cover (Chung et al., TMI 2006, fill them by
//! statistical texture synthesis; this is the patch-based variant).
//!
//! The algorithm is Efros & Freeman's image quilting (SIGGRAPH 2001) run per chart in the
//! chart's 2-D domain, with the seen texels as constraints, then a correction across the
//! border (in the spirit of Pérez et al.'s seamless cloning):
//!
//! 1. Exemplar ([`exemplar`]): every square patch of `patch_mm` whose texels and a one-texel
//!    ring around them were all seen (so it lies in one chart: charts are separated by
//!    never-seen gutter), on a stride, with the
//!    3-D point of its centre. Every chart is scaled to the same texel size (mm), so a patch
//!    covers the same surface area wherever it comes from: the synthesis follows the surface's
//!    parameterisation.
//! 2. Quilting ([`quilt`]): slots of `patch_mm` with an overlap of a quarter patch, in raster
//!    order over each chart holding unseen texels. Each slot's candidates are the patches
//!    nearest in 3-D, random patches and the continuations of the left and upper neighbours'
//!    sources (coherence, as Ashikhmin 2001); the cost is the squared colour difference on
//!    every texel of the slot already known (seen or synthesised) over the summed variance of
//!    both sides (a raw sum of squares lets bland patches win among a few hundred candidates:
//!    measured, the vessel spectrum fell 5-fold), and the choice is random among the candidates
//!    within `tolerance` of the best (Efros & Freeman). The patch goes in along the
//!    minimum-error boundary cut through the overlaps with earlier patches; seen texels are
//!    never changed.
//! 3. Border ([`border`]): where a patch lies over seen texels, its difference to them is
//!    smoothed and carried into the synthesised texels, fading over one patch (no step in
//!    brightness or colour); each synthesised texel next to seen ones is also shifted by its
//!    own `seen - patch` difference (from the patch's one-texel ring), fading over 4 texels,
//!    so the step across the border is the exemplar's own step.
//!
//! Patch-based rather than statistics matching (Heeger–Bergen, Portilla–Simoncelli): the
//! vessel network is a structured pattern of connected lines that marginal and spectral
//! statistics do not preserve, while copying patches does; quilting rather than Kwatra's
//! optimisation because one pass over the slots is cheap next to the build. Deterministic:
//! every chart draws from its own generator seeded by `seed` and the chart id, so rayon's
//! scheduling does not change the result. No crate does this on an atlas of charts (the Rust
//! `texture-synthesis` crate synthesises and inpaints whole images).

// Parallel arrays indexed by channel read clearer than zips.
#![allow(clippy::needless_range_loop)]

mod border;
mod exemplar;
mod quilt;
pub mod stats;

use rayon::prelude::*;

use super::atlas::fill_uncovered;
use super::texels::TexelSet;
use crate::image::ImageError;
use crate::{Error, Result};

/// What the build puts on texels no frame saw (`--unseen`).
#[derive(
    Clone,
    Copy,
    Debug,
    PartialEq,
    Eq,
    Default,
    clap::ValueEnum,
    serde::Serialize,
    serde::Deserialize,
)]
#[serde(rename_all = "snake_case")]
pub enum UnseenMode {
    /// The mean of the chart's nearest seen texels, pushed in wave by wave (a flat smear).
    Fill,
    /// Mucosa synthesised from the seen texture (patch quilting, see the module docs).
    #[default]
    Synthesise,
}

/// Options of [`complete_unseen`].
#[derive(Clone, Debug, PartialEq)]
pub struct SynthesisOptions {
    /// Fill or synthesise.
    pub mode: UnseenMode,
    /// Patch edge on the surface (mm); at least 8 texels. About one coarse vessel cell.
    pub patch_mm: f64,
    /// Random exemplar patches tried per slot.
    pub random_candidates: usize,
    /// Exemplar patches nearest in 3-D tried per slot.
    pub near_candidates: usize,
    /// A candidate whose cost is within `1 + tolerance` of the best may be chosen (variety).
    pub tolerance: f32,
    /// Seed of the random choices.
    pub seed: u64,
}

impl Default for SynthesisOptions {
    fn default() -> Self {
        SynthesisOptions {
            mode: UnseenMode::Synthesise,
            patch_mm: 3.0,
            random_candidates: 400,
            near_candidates: 32,
            tolerance: 0.1,
            seed: 0x0005_EED0_FA11,
        }
    }
}

/// What [`complete_unseen`] did.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct SynthesisStats {
    /// The mode asked for.
    pub mode: UnseenMode,
    /// Chart texels seen by a frame.
    pub seen_texels: usize,
    /// Chart texels given synthesised mucosa.
    pub synthesised_texels: usize,
    /// Chart texels filled from neighbours (no exemplar, or `UnseenMode::Fill`).
    pub filled_texels: usize,
    /// Patch edge used (texels; 0 when nothing was synthesised).
    pub patch_texels: usize,
    /// Exemplar patches available.
    pub exemplar_patches: usize,
}

/// Complete a fused atlas in place: unseen chart texels synthesised (or filled, per
/// `opts.mode`), then the gutter filled from the charts ([`fill_uncovered`]).
///
/// * `rgb`: `3 * width * height` linear RGB values of the atlas of `texels`; values of texels
///   that are not `covered` are ignored and overwritten.
/// * `covered[i]`: atlas texel `i` was seen by a frame.
/// * `texel_mm`: the atlas's texel edge on the surface (mm).
///
/// Returns the counts; `synthesised` (atlas-sized) marks the texels given synthesised mucosa.
pub fn complete_unseen(
    rgb: &mut [f32],
    covered: &[bool],
    texels: &TexelSet,
    texel_mm: f64,
    opts: &SynthesisOptions,
) -> Result<(SynthesisStats, Vec<bool>)> {
    let (w, h) = (texels.width as usize, texels.height as usize);
    let n = w * h;
    if rgb.len() != 3 * n || covered.len() != n {
        return Err(ImageError::BufferSize {
            stage: "unseen-wall synthesis",
            what: "the atlas (RGB values / 3 or coverage flags)",
            got: (rgb.len() / 3).min(covered.len()),
            expected: n,
        }
        .into());
    }
    if !(texel_mm > 0.0 && opts.patch_mm > 0.0 && opts.tolerance >= 0.0) {
        return Err(Error::BadOptions {
            stage: "unseen-wall synthesis",
            message: format!(
                "texel size {texel_mm} mm, patch {} mm and tolerance {} must be positive",
                opts.patch_mm, opts.tolerance
            ),
        });
    }
    let chart_map = texels.chart_map();
    let seen_texels = texels
        .texel
        .iter()
        .filter(|&&t| covered[t as usize])
        .count();
    let mut stats = SynthesisStats {
        mode: opts.mode,
        seen_texels,
        ..Default::default()
    };
    let mut synthesised = vec![false; n];
    if opts.mode == UnseenMode::Synthesise && seen_texels < texels.len() {
        let patch = ((opts.patch_mm / texel_mm).round() as usize).max(8);
        if let Some(ex) = exemplar::Exemplar::find(rgb, covered, texels, patch) {
            stats.patch_texels = ex.patch;
            stats.exemplar_patches = ex.len();
            let charts: Vec<usize> = (0..texels.chart_count())
                .filter(|&c| {
                    let (lo, hi) = (texels.chart_start[c], texels.chart_start[c + 1]);
                    (lo..hi).any(|s| !covered[texels.texel[s as usize] as usize])
                })
                .collect();
            let done: Vec<quilt::ChartPatch> = charts
                .par_iter()
                .map(|&c| {
                    let mut p = quilt::quilt_chart(rgb, covered, texels, &chart_map, &ex, c, opts);
                    border::correct_border(&mut p, ex.patch);
                    p
                })
                .collect();
            for p in &done {
                p.write_back(rgb, &mut synthesised, w);
            }
        }
    }
    stats.synthesised_texels = synthesised.iter().filter(|&&s| s).count();
    stats.filled_texels = texels.len() - seen_texels - stats.synthesised_texels;
    let known: Vec<bool> = covered
        .iter()
        .zip(&synthesised)
        .map(|(&c, &s)| c || s)
        .collect();
    fill_uncovered(rgb, w, h, &known, &chart_map)?;
    Ok((stats, synthesised))
}
