//! Texture atlas of the lumen mesh (paper §2.4, "texture atlas [17]"): charts of low
//! distortion flattened by least-squares conformal maps, packed with gutters so that bilinear
//! sampling never bleeds across charts; texel geometry; filling of unseen texels.

mod charts;
mod fill;
mod lscm;
mod pack;
mod raster;

use rayon::prelude::*;

pub use fill::fill_uncovered;
pub use raster::{rasterize_texels, TexelGeometry};

use crate::math::Point3;
use crate::mesh::error::GeometryError;
use crate::mesh::TriMesh;
use crate::Result;
use charts::FaceData;
use lscm::ChartUv;

/// Options of [`build_atlas`].
///
/// Steps: (1) segment the mesh into charts by variational shape approximation on face normals
/// (`initial_chart_area_mm2` sets the first seeds, `lloyd_iterations` refines them); (2) split
/// every chart that is not a topological disc, whose normals leave a cone of
/// `max_chart_normal_angle_deg`, whose LSCM flips a triangle or whose L2 stretch exceeds
/// `max_chart_stretch`; (3) scale each chart so that its UV area equals its 3-D area at
/// `texel_mm` per texel, turn it to its minimum-area rectangle; (4) pack with `gutter_texels`
/// free texels between charts into an atlas no larger than `max_size` texels on a side.
#[derive(Clone, Debug)]
pub struct AtlasOptions {
    /// Texel edge length on the surface (mm).
    pub texel_mm: f64,
    /// Minimum number of free texels between the bilinear footprints of two charts.
    pub gutter_texels: u32,
    /// Largest angle (degrees) between a face normal and its chart's mean normal. Below 90° a
    /// chart cannot wrap around a tube.
    pub max_chart_normal_angle_deg: f64,
    /// Largest L2 stretch norm (Sander et al. 2001; 1 = isometry) a chart may keep before it is
    /// split.
    pub max_chart_stretch: f64,
    /// Surface area (mm²) per initial chart seed.
    pub initial_chart_area_mm2: f64,
    /// Weight of chart compactness against normal deviation in the segmentation (unitless; the
    /// squared distance to the chart centre is measured in units of `initial_chart_area_mm2`).
    /// Round charts pack better than charts that branch along the airway tree.
    pub compactness: f64,
    /// Lloyd iterations of the initial segmentation.
    pub lloyd_iterations: usize,
    /// Largest atlas width or height (texels).
    pub max_size: u32,
}

impl Default for AtlasOptions {
    fn default() -> Self {
        AtlasOptions {
            texel_mm: 0.15,
            gutter_texels: 2,
            max_chart_normal_angle_deg: 60.0,
            max_chart_stretch: 1.08,
            initial_chart_area_mm2: 200.0,
            compactness: 2.0,
            lloyd_iterations: 3,
            max_size: 16384,
        }
    }
}

/// Quality figures of an atlas.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct AtlasStats {
    /// Texels within bilinear reach of a chart (the texels that carry chart data) over all
    /// atlas texels.
    pub utilisation: f64,
    /// Texels whose centre lies inside a chart triangle over all atlas texels (stricter).
    pub inner_utilisation: f64,
    /// Area-weighted mean of the per-triangle L2 stretch (1 = isometry at `texel_mm`).
    pub mean_l2_stretch: f64,
    /// Sander et al.'s L2 stretch norm of the whole atlas (area-weighted RMS).
    pub rms_l2_stretch: f64,
    /// Largest per-triangle L2 stretch.
    pub max_l2_stretch: f64,
    /// Triangles with non-positive UV area (non-degenerate in 3-D).
    pub flipped_triangles: usize,
}

/// A texture atlas: the mesh with vertices split along chart seams, one UV per vertex.
#[derive(Clone, Debug)]
pub struct Atlas {
    /// Atlas size (texels).
    pub width: u32,
    pub height: u32,
    /// Texel edge length on the surface (mm).
    pub texel_mm: f64,
    /// The input mesh with one vertex per (vertex, chart) pair; triangles in the input's order.
    pub mesh: TriMesh,
    /// UV of each vertex of `mesh`, in [0, 1]: texel (x, y) covers
    /// [x / width, (x + 1) / width] × [y / height, (y + 1) / height]; row y = 0 is stored first.
    pub uv: Vec<[f32; 2]>,
    /// Input vertex id of each vertex of `mesh`.
    pub original_vertex: Vec<u32>,
    /// Chart of each triangle.
    pub chart_of_triangle: Vec<u32>,
    /// Number of charts.
    pub chart_count: usize,
    /// Utilisation and stretch.
    pub stats: AtlasStats,
}

/// Build a texture atlas for `mesh` (see [`AtlasOptions`] for the steps).
///
/// Errors on a mesh without triangles, vertex indices out of range, non-finite positions, bad
/// options, or an atlas that would exceed `max_size` (choose a larger `texel_mm`).
pub fn build_atlas(mesh: &TriMesh, opts: &AtlasOptions) -> Result<Atlas> {
    validate(mesh, opts)?;
    let fd = FaceData::new(mesh);
    let nt = mesh.triangles.len();
    let all: Vec<u32> = (0..nt as u32).collect();
    let area: f64 = fd.area.iter().sum();
    let k0 = ((area / opts.initial_chart_area_mm2).ceil() as usize).clamp(1, nt);
    let seeds: Vec<u32> = (0..k0).map(|i| (i * nt / k0) as u32).collect();
    let compact = opts.compactness / opts.initial_chart_area_mm2;
    let regions = charts::vsa(&fd, &all, &seeds, opts.lloyd_iterations, compact);

    let max_angle = opts.max_chart_normal_angle_deg.to_radians();
    let charts: Vec<ChartUv> = regions
        .into_par_iter()
        .flat_map_iter(|r| refine(mesh, &fd, r, max_angle, opts.max_chart_stretch))
        .collect();

    // Texel units from here on.
    let grow = opts.gutter_texels.div_ceil(2) as usize;
    let inv = 1.0 / opts.texel_mm;
    let fps: Vec<pack::Footprint> = charts
        .par_iter()
        .map(|c| {
            let uv: Vec<[f64; 2]> = c.uv.iter().map(|p| [p[0] * inv, p[1] * inv]).collect();
            pack::footprint(&uv, &c.tris, grow)
        })
        .collect();
    let (width, placements, height) = pack_best(&fps)?;
    if width > opts.max_size as usize || height > opts.max_size as usize {
        return Err(GeometryError::AtlasTooLarge {
            width: width as u32,
            height: height as u32,
            max_size: opts.max_size,
            texel_mm: opts.texel_mm,
        }
        .into());
    }
    Ok(assemble(
        mesh,
        &charts,
        &fps,
        &placements,
        width,
        height,
        opts,
    ))
}

fn validate(mesh: &TriMesh, opts: &AtlasOptions) -> Result<()> {
    let bad = |message: String| {
        Err(GeometryError::BadOptions {
            stage: "texture atlas",
            message,
        }
        .into())
    };
    if mesh.triangles.is_empty() {
        return bad("the mesh has no triangles".into());
    }
    let nv = mesh.positions.len();
    if let Some(t) = mesh
        .triangles
        .iter()
        .position(|t| t.iter().any(|&v| v as usize >= nv))
    {
        return bad(format!(
            "triangle {t} refers to a vertex beyond the {nv} vertices"
        ));
    }
    if let Some(v) = mesh
        .positions
        .iter()
        .position(|p| !p.coords.iter().all(|x| x.is_finite()))
    {
        return bad(format!("vertex {v} has a non-finite position"));
    }
    if !(opts.texel_mm.is_finite() && opts.texel_mm > 0.0) {
        return bad(format!("texel_mm must be positive, got {}", opts.texel_mm));
    }
    if !(opts.max_chart_normal_angle_deg > 0.0 && opts.max_chart_normal_angle_deg < 90.0) {
        return bad(format!(
            "max_chart_normal_angle_deg must be in (0, 90) so charts cannot wrap around a tube, got {}",
            opts.max_chart_normal_angle_deg
        ));
    }
    if opts.max_chart_stretch.is_nan() || opts.max_chart_stretch < 1.0 {
        return bad(format!(
            "max_chart_stretch must be at least 1, got {}",
            opts.max_chart_stretch
        ));
    }
    if opts.initial_chart_area_mm2.is_nan() || opts.initial_chart_area_mm2 <= 0.0 {
        return bad(format!(
            "initial_chart_area_mm2 must be positive, got {}",
            opts.initial_chart_area_mm2
        ));
    }
    Ok(())
}

/// Flatten a region, splitting it until every piece is a disc within the normal cone and its
/// LSCM has no flipped triangle and a stretch norm within the bound.
fn refine(
    mesh: &TriMesh,
    fd: &FaceData,
    region: Vec<u32>,
    max_angle: f64,
    max_stretch: f64,
) -> Vec<ChartUv> {
    let mut out = Vec::new();
    let mut stack = vec![region];
    while let Some(r) = stack.pop() {
        let (n, angle, _) = charts::normal_cone(fd, &r);
        let mut ok = angle <= max_angle && charts::is_disc(&mesh.triangles, &r);
        let mut chart = None;
        if ok {
            let c = lscm::lscm(mesh, &r, &n);
            ok = c.flipped == 0 && c.l2_norm() <= max_stretch;
            chart = Some(c);
        }
        if ok {
            out.extend(chart);
            continue;
        }
        match charts::split(fd, &r) {
            Some(parts) if parts.len() >= 2 => stack.extend(parts),
            // A single face (or an unsplittable remainder) is kept as it is.
            _ => out.push(chart.unwrap_or_else(|| lscm::lscm(mesh, &r, &n))),
        }
    }
    out
}

/// Pack at a few atlas widths around the square one and keep the smallest atlas.
fn pack_best(fps: &[pack::Footprint]) -> Result<(usize, Vec<pack::Placement>, usize)> {
    let total: usize = fps
        .iter()
        .map(|f| f.mask.iter().filter(|&&b| b).count())
        .sum();
    let min_w = fps.iter().map(|f| f.w.min(f.h)).max().unwrap_or(1);
    let square = (total as f64).sqrt();
    let widths: Vec<usize> = [0.95, 1.05, 1.15]
        .iter()
        .map(|s| ((square * s).ceil() as usize).max(min_w).max(1))
        .collect();
    widths
        .into_par_iter()
        .filter_map(|w| pack::raster_pack(fps, w).map(|(p, h)| (w, p, h)))
        .min_by_key(|(w, _, h)| (w * h, *w.max(h)))
        .ok_or_else(|| {
            GeometryError::Degenerate {
                stage: "texture atlas",
                message: "no chart fits the atlas width".into(),
            }
            .into()
        })
}

fn assemble(
    mesh: &TriMesh,
    charts: &[ChartUv],
    fps: &[pack::Footprint],
    placements: &[pack::Placement],
    width: usize,
    height: usize,
    opts: &AtlasOptions,
) -> Atlas {
    let nt = mesh.triangles.len();
    let mut positions = Vec::new();
    let mut uv = Vec::new();
    let mut original_vertex = Vec::new();
    let mut triangles = vec![[0u32; 3]; nt];
    let mut chart_of_triangle = vec![0u32; nt];
    let mut stats = AtlasStats::default();
    let (mut area, mut l2, mut l2sq) = (0.0, 0.0, 0.0);
    let (mut texels, mut inner) = (0usize, 0usize);
    for (ci, ((c, f), p)) in charts.iter().zip(fps).zip(placements).enumerate() {
        let base = positions.len() as u32;
        for (k, &v) in c.verts.iter().enumerate() {
            let q = pack::place_uv(f, p, f.uv[k]);
            positions.push(mesh.positions[v as usize]);
            original_vertex.push(v);
            uv.push([(q[0] / width as f64) as f32, (q[1] / height as f64) as f32]);
        }
        for (&face, t) in c.faces.iter().zip(&c.tris) {
            triangles[face as usize] = t.map(|v| v + base);
            chart_of_triangle[face as usize] = ci as u32;
        }
        area += c.area;
        l2 += c.l2_sum;
        l2sq += c.l2_sq_sum;
        stats.max_l2_stretch = stats.max_l2_stretch.max(c.l2_max);
        stats.flipped_triangles += c.flipped;
        texels += f.chart_texels;
        inner += f.inner_texels;
    }
    let atlas_texels = (width * height) as f64;
    stats.utilisation = texels as f64 / atlas_texels;
    stats.inner_utilisation = inner as f64 / atlas_texels;
    stats.mean_l2_stretch = if area > 0.0 { l2 / area } else { 1.0 };
    stats.rms_l2_stretch = if area > 0.0 {
        (l2sq / area).sqrt()
    } else {
        1.0
    };
    Atlas {
        width: width as u32,
        height: height as u32,
        texel_mm: opts.texel_mm,
        mesh: TriMesh {
            positions: positions.into_iter().map(|p: Point3<f32>| p).collect(),
            triangles,
        },
        uv,
        original_vertex,
        chart_of_triangle,
        chart_count: charts.len(),
        stats,
    }
}
