//! `bronchosim convert`: a CT (DICOM series folder, NIfTI file, or a case folder's CT) to one
//! NIfTI-1 file in Hounsfield units with its index → world affine, as 3D Slicer and ITK-SNAP
//! users expect.
//!
//! Steps: check the output name (.nii or .nii.gz) and that it does not exist (unless forced),
//! before any decoding; read the CT as HU with its RAS affine (DICOM: LPS → RAS); choose the
//! voxel type: int16 when every voxel is an integer in [−32768, 32767] (every lossless CT after
//! RescaleSlope/Intercept), float32 otherwise (non-integer rescale, lossy float input, NaN);
//! write atomically (a temporary file renamed into place) with the affine in the sform (code 2)
//! and the qform (code 1), as nibabel does.

use crate::inspect::{summarize_ct, CtSummary};
use crate::io::ct::read_ct;
use crate::io::nifti::{is_nifti_name, write_nifti};
use crate::workflow::segment::resolve_ct_input;
use crate::{Error, Result};
use serde::Serialize;
use std::path::{Path, PathBuf};
use std::time::Instant;

/// Options of `convert`.
#[derive(Clone, Debug, Default)]
pub struct ConvertOptions {
    /// Replace an existing output file.
    pub force: bool,
}

/// What `convert` wrote.
#[derive(Clone, Debug, Serialize)]
pub struct ConvertSummary {
    /// The NIfTI file written.
    pub out: PathBuf,
    /// NIfTI voxel type written: "int16" or "float32".
    pub datatype: &'static str,
    /// The CT that was read (grid, orientation, HU range, non-finite voxels).
    pub ct: CtSummary,
    /// Warnings a person should read (a NIfTI without orientation, non-finite voxels).
    pub warnings: Vec<String>,
    /// Wall-clock seconds to read the input.
    pub read_seconds: f64,
    /// Wall-clock seconds to write the NIfTI file.
    pub write_seconds: f64,
}

/// Convert the CT named by `input` (a DICOM folder, a NIfTI file or a case folder) into the
/// NIfTI file `out`. See the module documentation for the steps.
pub fn convert_ct(input: &Path, out: &Path, opts: &ConvertOptions) -> Result<ConvertSummary> {
    if !is_nifti_name(out) {
        return Err(Error::invalid(
            out,
            "output must be a NIfTI file ending in .nii or .nii.gz",
        ));
    }
    if out.is_dir() {
        return Err(Error::invalid(
            out,
            "is a folder; give a file name ending in .nii.gz",
        ));
    }
    if out.exists() && !opts.force {
        return Err(Error::invalid(
            out,
            "already exists; use --force to replace it (or choose another --out)",
        ));
    }
    let t = Instant::now();
    let source = resolve_ct_input(input)?;
    let (vol, info) = read_ct(&source)?;
    let read_seconds = t.elapsed().as_secs_f64();
    let ct = summarize_ct(&vol, &source, &info);
    let mut warnings = info.warnings.clone();
    warnings.extend(ct.warnings());

    let t = Instant::now();
    if let Some(parent) = out.parent().filter(|p| !p.as_os_str().is_empty()) {
        std::fs::create_dir_all(parent).map_err(|e| Error::io(parent, e))?;
    }
    let fits_i16 = vol
        .data
        .iter()
        .all(|&v| v == v.round() && (i16::MIN as f32..=i16::MAX as f32).contains(&v));
    let datatype = if fits_i16 {
        write_nifti(out, &vol.map(|v| v as i16))?;
        "int16"
    } else {
        write_nifti(out, &vol)?;
        "float32"
    };
    Ok(ConvertSummary {
        out: out.to_path_buf(),
        datatype,
        ct,
        warnings,
        read_seconds,
        write_seconds: t.elapsed().as_secs_f64(),
    })
}

impl ConvertSummary {
    /// A few lines for a person: what was written, and the CT's summary.
    pub fn to_text(&self) -> String {
        let mut s = format!(
            "wrote {} ({} HU; read in {:.2} s, written in {:.2} s)\n",
            self.out.display(),
            self.datatype,
            self.read_seconds,
            self.write_seconds
        );
        s.push_str(&self.ct.to_text());
        s
    }
}
