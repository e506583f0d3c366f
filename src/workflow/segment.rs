//! `bronchosim segment`: CT → airway mask → lumen mesh, written as a folder a person (and
//! 3D Slicer) can open: segmentation.nii.gz, lumen.ply / .obj / .glb, summary.json.

use crate::io::ct::{ct_folder_source, find_ct, read_ct, CtSource};
use crate::io::mesh_export::{write_glb, write_obj, write_ply};
use crate::io::nifti::write_nifti;
use crate::io::output_dir::OutputDir;
use crate::mesh::lumen::{lumen_mesh, LumenMeshOptions, MeshReport};
use crate::mesh::TriMesh;
use crate::volume::segment::{segment_airway, SegmentOptions, Segmentation};
use crate::volume::Volume;
use crate::{Error, Result};
use serde::Serialize;
use std::path::{Path, PathBuf};
use std::time::Instant;

/// Options of the whole segment command.
#[derive(Clone, Debug, Default)]
pub struct SegmentCommandOptions {
    /// Seed and region growing (thresholds in HU, closing radius in mm).
    pub segment: SegmentOptions,
    /// Marching cubes level (HU), smoothing and decimation (target edge in mm).
    pub mesh: LumenMeshOptions,
    /// Replace an existing output folder.
    pub force: bool,
}

/// One threshold tried by the adaptive region growing.
#[derive(Clone, Debug, Serialize)]
pub struct ThresholdTried {
    /// Upper threshold (HU).
    pub hu: f32,
    /// Segmented volume at that threshold (ml).
    pub volume_ml: f64,
}

/// What `segment` found, as written to summary.json.
#[derive(Clone, Debug, Serialize)]
pub struct SegmentSummary {
    /// The CT file or folder.
    pub ct: String,
    /// Seed in world mm (RAS).
    pub seed_mm: [f64; 3],
    /// Seed voxel index.
    pub seed_voxel: [usize; 3],
    /// True when the seed was found automatically (not given with --seed).
    pub seed_automatic: bool,
    /// Thresholds tried, in order.
    pub thresholds: Vec<ThresholdTried>,
    /// The threshold kept (HU).
    pub threshold_hu: f32,
    /// True when growing stopped because the next threshold leaked into the parenchyma.
    pub leak_stopped: bool,
    /// Segmented airway volume (ml).
    pub volume_ml: f64,
    /// Airway branches found (splits counted along the geodesic distance from the seed).
    pub branches: usize,
    /// CT voxels that were NaN or ±inf; they count as tissue (see
    /// [`crate::volume::segment::non_finite_as_tissue`]).
    pub non_finite_voxels: usize,
    /// Lumen surface area (mm²) of the final mesh.
    pub surface_area_mm2: f64,
    /// Triangles of the final mesh.
    pub triangles: usize,
    /// Per-step mesh statistics and the deviation each step introduced.
    pub mesh: MeshReport,
    /// Wall-clock seconds: read, segment, mesh, write.
    pub seconds: StageSeconds,
}

/// Wall-clock seconds per stage.
#[derive(Clone, Debug, Default, Serialize)]
pub struct StageSeconds {
    /// Reading the CT.
    pub read: f64,
    /// Seed, region growing, morphology, branch count.
    pub segment: f64,
    /// Marching cubes, smoothing, decimation.
    pub mesh: f64,
    /// Writing the outputs.
    pub write: f64,
}

/// The CT named by `input`: a case folder (ct.nii.gz / ct.nii / ct/), a NIfTI file, or a
/// folder holding one NIfTI file or a DICOM series ([`ct_folder_source`]).
pub fn resolve_ct_input(input: &Path) -> Result<CtSource> {
    if input.is_file() {
        return Ok(CtSource::Nifti(input.to_path_buf()));
    }
    if !input.exists() {
        return Err(Error::missing(
            input,
            "case folder, NIfTI file or DICOM folder",
        ));
    }
    match find_ct(input) {
        Ok(src) => Ok(src),
        // A folder without ct.* is the CT itself: its one NIfTI file or its DICOM series.
        Err(Error::Missing { .. }) => ct_folder_source(input),
        Err(e) => Err(e),
    }
}

/// The airway mask and lumen mesh of a CT already in memory.
pub fn segment_and_mesh(
    ct: &Volume<f32>,
    opts: &SegmentCommandOptions,
) -> Result<(Segmentation, TriMesh, MeshReport, [f64; 2])> {
    let t = Instant::now();
    let seg = segment_airway(ct, &opts.segment)?;
    let t_seg = t.elapsed().as_secs_f64();
    let t = Instant::now();
    let (mesh, report) = lumen_mesh(ct, &seg.mask, &opts.mesh)?;
    Ok((seg, mesh, report, [t_seg, t.elapsed().as_secs_f64()]))
}

/// Run the segment command: read the CT of `input`, segment, mesh, and write `out` atomically.
pub fn segment_command(
    input: &Path,
    out: &Path,
    opts: &SegmentCommandOptions,
) -> Result<SegmentSummary> {
    let out_dir = OutputDir::create(out, opts.force)?;
    let source = resolve_ct_input(input)?;
    let t = Instant::now();
    let (ct, _info) = read_ct(&source)?;
    let t_read = t.elapsed().as_secs_f64();
    let (seg, mesh, report, [t_seg, t_mesh]) = segment_and_mesh(&ct, opts)?;
    let t = Instant::now();
    write_nifti(&out_dir.join("segmentation.nii.gz"), &seg.mask)?;
    write_ply(&out_dir.join("lumen.ply"), &mesh)?;
    write_obj(&out_dir.join("lumen.obj"), &mesh, None)?;
    write_glb(&out_dir.join("lumen.glb"), &mesh, None)?;
    let sp = ct.spacing();
    let voxel_ml = sp[0] * sp[1] * sp[2] / 1000.0;
    let mut summary = SegmentSummary {
        ct: source.path().display().to_string(),
        seed_mm: [seg.seed_world.x, seg.seed_world.y, seg.seed_world.z],
        seed_voxel: seg.seed_voxel,
        seed_automatic: seg.seed_automatic,
        thresholds: seg
            .thresholds
            .iter()
            .map(|s| ThresholdTried {
                hu: s.hu,
                volume_ml: s.voxels as f64 * voxel_ml,
            })
            .collect(),
        threshold_hu: seg.threshold_hu,
        leak_stopped: seg.exploded,
        volume_ml: seg.volume_ml,
        branches: seg.branch_count,
        non_finite_voxels: seg.non_finite_voxels,
        surface_area_mm2: mesh.area(),
        triangles: mesh.triangles.len(),
        mesh: report,
        seconds: StageSeconds {
            read: t_read,
            segment: t_seg,
            mesh: t_mesh,
            write: 0.0,
        },
    };
    summary.seconds.write = t.elapsed().as_secs_f64();
    crate::io::atomic::write_json_atomic(&out_dir.join("summary.json"), &summary)?;
    out_dir.commit()?;
    Ok(summary)
}

impl SegmentSummary {
    /// A few lines for a person.
    pub fn to_text(&self, out: &Path) -> String {
        let tried: Vec<String> = self
            .thresholds
            .iter()
            .map(|t| format!("{:.0}", t.hu))
            .collect();
        let non_finite = if self.non_finite_voxels > 0 {
            format!(
                "note      {}: {} voxels are NaN or infinite, counted as tissue (never airway)\n",
                self.ct, self.non_finite_voxels
            )
        } else {
            String::new()
        };
        format!(
            "{non_finite}seed      ({:.1}, {:.1}, {:.1}) mm, voxel {:?} ({})\n\
             threshold {:.0} HU (tried {}){}\n\
             airway    {:.1} ml, {} branches\n\
             mesh      {} triangles, {:.0} mm² (marching cubes {} → smoothed, mean shift {:.3} mm → decimated, mean shift {:.3} mm)\n\
             wrote     {}\n",
            self.seed_mm[0],
            self.seed_mm[1],
            self.seed_mm[2],
            self.seed_voxel,
            if self.seed_automatic { "automatic" } else { "given" },
            self.threshold_hu,
            tried.join(", "),
            if self.leak_stopped { ", stopped before a leak" } else { "" },
            self.volume_ml,
            self.branches,
            self.triangles,
            self.surface_area_mm2,
            self.mesh.marching_cubes.triangles,
            self.mesh.smoothing_deviation.mean_mm,
            self.mesh.decimation_deviation.mean_mm,
            out.display()
        )
    }
}

/// Parse "X,Y,Z" (world mm) for `--seed`.
pub fn parse_point(s: &str) -> std::result::Result<[f64; 3], String> {
    let v: Vec<f64> = s
        .split(',')
        .map(|p| p.trim().parse::<f64>().map_err(|e| format!("'{p}': {e}")))
        .collect::<std::result::Result<_, _>>()?;
    match v.as_slice() {
        [x, y, z] if v.iter().all(|c| c.is_finite()) => Ok([*x, *y, *z]),
        _ => Err(format!("expected X,Y,Z in mm, got '{s}'")),
    }
}

/// The output folder of `segment` when `--out` is not given: `<input>_segment` beside the input.
pub fn default_segment_out(input: &Path) -> PathBuf {
    let name = input
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_else(|| "ct".into());
    input.with_file_name(format!(
        "{}_segment",
        name.trim_end_matches(".nii.gz").trim_end_matches(".nii")
    ))
}
