//! The case's CT: `ct.nii.gz` / `ct.nii` or a DICOM series in `ct/`, read into HU with its affine.

use crate::io::{dicom, nifti};
use crate::volume::Volume;
use crate::{Error, Result};
use std::path::{Path, PathBuf};

/// Where a case's CT lives.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum CtSource {
    /// A NIfTI-1 file (`ct.nii.gz` or `ct.nii`).
    Nifti(PathBuf),
    /// A folder of DICOM slices (`ct/`).
    Dicom(PathBuf),
}

impl CtSource {
    /// The file or folder.
    pub fn path(&self) -> &Path {
        match self {
            CtSource::Nifti(p) | CtSource::Dicom(p) => p,
        }
    }
}

/// What the reader found out about the CT beyond its voxels.
#[derive(Clone, Debug, serde::Serialize)]
pub struct CtInfo {
    /// "nifti" or "dicom".
    pub format: &'static str,
    /// How the affine was obtained (NIfTI: sform / qform / pixdim; DICOM: "ImagePositionPatient").
    pub affine_source: String,
    /// Warnings a person should see (e.g. a NIfTI without orientation).
    pub warnings: Vec<String>,
    /// What a DICOM series says about itself (None for NIfTI).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub dicom: Option<DicomCtInfo>,
}

/// The parts of a DICOM series' headers a person checks after reading it.
#[derive(Clone, Debug, serde::Serialize)]
pub struct DicomCtInfo {
    /// Transfer syntax of the first slice as "UID (name)".
    pub transfer_syntax: String,
    /// Number of slice files read.
    pub slices: usize,
    /// Distance between adjacent slices along the slice normal (mm).
    pub slice_step_mm: f64,
    /// Modality, e.g. "CT" (may be empty).
    pub modality: String,
    /// SeriesDescription (may be empty).
    pub series_description: String,
}

/// The note that documents in a series folder were left out, naming them.
fn skipped_warning(dir: &Path, skipped: &[std::path::PathBuf]) -> Option<String> {
    if skipped.is_empty() {
        return None;
    }
    let names: Vec<String> = skipped
        .iter()
        .filter_map(|p| p.file_name().map(|n| n.to_string_lossy().into_owned()))
        .collect();
    Some(format!(
        "{}: left out {} file(s) that are not DICOM slices: {}",
        dir.display(),
        names.len(),
        names.join(", ")
    ))
}

/// The CT in a folder that is not a case: its one NIfTI file when that is all it holds besides
/// the documents a series may travel with ([`dicom::list_series_files`]), else the DICOM series.
pub fn ct_folder_source(dir: &Path) -> Result<CtSource> {
    let files = dicom::list_series_files(dir)?;
    let nifti = files.iter().filter(|p| nifti::is_nifti_name(p)).count();
    match (nifti, files.len()) {
        (1, 1) => Ok(CtSource::Nifti(files[0].clone())),
        (n, m) if n > 1 && n == m => Err(Error::invalid(
            dir,
            format!("holds {n} NIfTI files and no DICOM series; give the one to read"),
        )),
        _ => Ok(CtSource::Dicom(dir.to_path_buf())),
    }
}

/// Find the CT of the case in `case_dir`: exactly one of ct.nii.gz, ct.nii or ct/.
pub fn find_ct(case_dir: &Path) -> Result<CtSource> {
    let candidates = [("ct.nii.gz", false), ("ct.nii", false), ("ct", true)];
    let found: Vec<CtSource> = candidates
        .iter()
        .filter_map(|&(name, is_dir)| {
            let p = case_dir.join(name);
            match (is_dir, p.is_dir(), p.is_file()) {
                (true, true, _) => Some(CtSource::Dicom(p)),
                (false, _, true) => Some(CtSource::Nifti(p)),
                _ => None,
            }
        })
        .collect();
    match found.len() {
        0 => Err(Error::missing(
            case_dir,
            "no CT: expected ct.nii.gz, ct.nii or a DICOM folder ct/",
        )),
        1 => Ok(found.into_iter().next().expect("one CT")),
        _ => Err(Error::invalid(
            case_dir,
            format!(
                "more than one CT ({}): keep exactly one",
                found
                    .iter()
                    .map(|s| s
                        .path()
                        .file_name()
                        .unwrap_or_default()
                        .to_string_lossy()
                        .into_owned())
                    .collect::<Vec<_>>()
                    .join(", ")
            ),
        )),
    }
}

/// Read the CT in Hounsfield units, with its index→world affine (RAS mm).
pub fn read_ct(source: &CtSource) -> Result<(Volume<f32>, CtInfo)> {
    match source {
        CtSource::Nifti(p) => {
            let (vol, info) = nifti::read_nifti_with_info(p)?;
            let source = serde_json::to_value(info.affine_source)
                .ok()
                .and_then(|v| v.as_str().map(str::to_owned))
                .unwrap_or_default();
            Ok((
                vol,
                CtInfo {
                    format: "nifti",
                    affine_source: source,
                    warnings: info.warnings,
                    dicom: None,
                },
            ))
        }
        CtSource::Dicom(dir) => {
            let (vol, s) = dicom::read_dicom_series_with_info(dir)?;
            let transfer_syntax = if s.transfer_syntax_name.is_empty() {
                s.transfer_syntax_uid.clone()
            } else {
                format!("{} ({})", s.transfer_syntax_uid, s.transfer_syntax_name)
            };
            Ok((
                vol,
                CtInfo {
                    format: "dicom",
                    affine_source: "ImagePositionPatient/ImageOrientationPatient (LPS→RAS)".into(),
                    warnings: skipped_warning(dir, &s.skipped_files).into_iter().collect(),
                    dicom: Some(DicomCtInfo {
                        transfer_syntax,
                        slices: s.files.len(),
                        slice_step_mm: s.slice_step_mm,
                        modality: s.modality,
                        series_description: s.series_description,
                    }),
                },
            ))
        }
    }
}
