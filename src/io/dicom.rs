//! Read a CT DICOM series (a folder of single-frame slices) into a [`Volume<f32>`] in Hounsfield
//! units, with its voxel index → world (RAS mm) affine.
//!
//! Steps: list the folder; read every slice's header in parallel, stopping before the pixel
//! data; check that the slices form one series on one grid; sort them by ImagePositionPatient
//! along the slice normal (never by file name or InstanceNumber); derive the slice step from the
//! positions (uniform within 1 %); decode each slice's pixels in parallel straight into the
//! volume, applying RescaleSlope/Intercept.
//!
//! Geometry (DICOM PS3.3 C.7.6.2.1.1): with row cosines r = IOP[0..3], column cosines
//! c = IOP[3..6], PixelSpacing = [Δrow, Δcol] and sorted positions P_k, voxel (i = column,
//! j = row, k = slice) lies at P_0 + i·Δcol·r + j·Δrow·c + k·s (LPS), where s is the mean step
//! between positions (s = step·(r × c) unless the gantry was tilted). RAS = diag(−1, −1, 1)·LPS.
//!
//! Policies:
//! - Every regular file in the folder except hidden files, `DICOMDIR` and the documents that
//!   travel with a series (named LICENSE, README..., or *.txt, *.md, *.pdf, ..., and without the
//!   DICOM marker; listed in [`DicomSeriesInfo::skipped_files`] and warned about) must be a
//!   DICOM slice of the series; anything else (a damaged slice, a 2-D localizer, a second
//!   series) is an error naming the file, so that a volume is never silently built from part
//!   of a folder.
//! - A single-slice series takes its slice spacing from SpacingBetweenSlices, else
//!   SliceThickness, else fails.
//! - A header whose Rows × Columns × BitsAllocated exceed what the file could hold (1024× its
//!   size for compressed and deflated syntaxes) is rejected before any pixel buffer is allocated.
//! - Pixel data in a transfer syntax this build cannot decode (JPEG-LS, 12-bit JPEG Extended,
//!   JPEG XL, ...) fails with a message giving the syntax's UID and name. JPEG 2000 (.4.90,
//!   .4.91), HTJ2K (.4.201-.4.203) and RLE go through our own adapters (`j2k.rs`, `pixels.rs`),
//!   which check the codestream against the header and return errors where dicom-pixeldata's
//!   would panic on damaged data.

mod geometry;
mod header;
mod j2k;
mod pixels;
mod scan;

use std::path::{Path, PathBuf};

use rayon::prelude::*;

use crate::volume::Volume;
use crate::{Error, Result};
use header::{SliceHeader, Source};

/// What a DICOM series says about itself, besides its voxels.
#[derive(Clone, Debug, PartialEq)]
pub struct DicomSeriesInfo {
    /// SeriesInstanceUID shared by all slices.
    pub series_instance_uid: String,
    /// SeriesDescription (may be empty).
    pub series_description: String,
    /// Modality, e.g. "CT" (may be empty).
    pub modality: String,
    /// Transfer syntax UID of the first slice, e.g. "1.2.840.10008.1.2.5".
    pub transfer_syntax_uid: String,
    /// Standard name of that transfer syntax, e.g. "RLE Lossless" (empty when not standard).
    pub transfer_syntax_name: String,
    /// The slice files in volume order (k = 0 first, ascending along the slice normal).
    pub files: Vec<PathBuf>,
    /// Distance between adjacent slices along the slice normal, mm.
    pub slice_step_mm: f64,
    /// Documents in the folder that are not slices (a licence, a read-me), left out.
    pub skipped_files: Vec<PathBuf>,
}

/// Read the CT series in folder `dir` as HU with its index → RAS mm affine.
///
/// See the module documentation for the sorting, geometry and error policies.
pub fn read_dicom_series(dir: &Path) -> Result<Volume<f32>> {
    read_dicom_series_with_info(dir).map(|(v, _)| v)
}

/// Like [`read_dicom_series`], also returning the series' [`DicomSeriesInfo`].
pub fn read_dicom_series_with_info(dir: &Path) -> Result<(Volume<f32>, DicomSeriesInfo)> {
    let (files, skipped) = list_series_files_skipping(dir)?;
    let sources: Vec<Source<'_>> = files.iter().map(|f| Source::File(f)).collect();
    let (volume, mut info) = read_sources(dir, &sources)?;
    info.skipped_files = skipped;
    Ok((volume, info))
}

/// Read a series from an explicit list of slice files (in any order); errors about the series
/// as a whole name the first file's folder.
pub fn read_dicom_series_from_files(files: &[PathBuf]) -> Result<(Volume<f32>, DicomSeriesInfo)> {
    let dir = files
        .first()
        .and_then(|f| f.parent())
        .unwrap_or(Path::new("."));
    let sources: Vec<Source<'_>> = files.iter().map(|f| Source::File(f)).collect();
    read_sources(dir, &sources)
}

/// Read a series from in-memory files `(name, bytes)`, each a complete DICOM file with its
/// 128-byte preamble; names only label error messages. Meant for fuzzing and tests.
pub fn read_dicom_series_from_memory(
    files: &[(PathBuf, Vec<u8>)],
) -> Result<(Volume<f32>, DicomSeriesInfo)> {
    let sources: Vec<Source<'_>> = files.iter().map(|(p, b)| Source::Memory(p, b)).collect();
    read_sources(Path::new("<memory>"), &sources)
}

/// The files of a series folder, sorted by name: every regular file except hidden ones,
/// `DICOMDIR`, and documents that travel with a series (see [`is_companion_document`]).
/// Fails when `dir` is missing, unreadable, or holds no such file.
pub fn list_series_files(dir: &Path) -> Result<Vec<PathBuf>> {
    list_series_files_skipping(dir).map(|(files, _)| files)
}

/// [`list_series_files`], also returning the companion documents it left out.
pub fn list_series_files_skipping(dir: &Path) -> Result<(Vec<PathBuf>, Vec<PathBuf>)> {
    if !dir.exists() {
        return Err(Error::missing(dir, "DICOM series folder"));
    }
    if !dir.is_dir() {
        return Err(Error::invalid(
            dir,
            "is not a folder; give the folder holding the DICOM series",
        ));
    }
    let (mut files, mut skipped) = (Vec::new(), Vec::new());
    for entry in std::fs::read_dir(dir).map_err(|e| Error::io(dir, e))? {
        let entry = entry.map_err(|e| Error::io(dir, e))?;
        let path = entry.path();
        let name = entry.file_name();
        let name = name.to_string_lossy();
        if name.starts_with('.') || name.eq_ignore_ascii_case("DICOMDIR") || !path.is_file() {
            continue;
        }
        if is_companion_document(&path) {
            skipped.push(path);
        } else {
            files.push(path);
        }
    }
    if files.is_empty() {
        return Err(Error::invalid(
            dir,
            "folder holds no files; expected a DICOM series",
        ));
    }
    files.sort();
    skipped.sort();
    Ok((files, skipped))
}

/// A licence, read-me or other document copied along with a series (LICENSE, README.md,
/// notes.txt, a screenshot): named like one and without the DICOM marker. Any other file
/// without the marker is still an error, so a damaged slice is never dropped silently.
fn is_companion_document(path: &Path) -> bool {
    const NAMES: [&str; 6] = [
        "license", "licence", "readme", "copying", "notice", "authors",
    ];
    const EXTENSIONS: [&str; 14] = [
        "txt", "md", "rst", "pdf", "html", "htm", "json", "xml", "csv", "png", "jpg", "jpeg",
        "log", "ini",
    ];
    let stem = path
        .file_stem()
        .map(|s| s.to_string_lossy().to_ascii_lowercase())
        .unwrap_or_default();
    let ext = path
        .extension()
        .map(|s| s.to_string_lossy().to_ascii_lowercase())
        .unwrap_or_default();
    let named = NAMES.iter().any(|n| stem.starts_with(n)) || EXTENSIONS.contains(&ext.as_str());
    named && !has_dicom_marker(path)
}

/// The file has the `DICM` marker at byte 128 (DICOM Part 10).
fn has_dicom_marker(path: &Path) -> bool {
    use std::io::Read;
    let mut head = [0u8; 132];
    std::fs::File::open(path)
        .and_then(|mut f| f.read_exact(&mut head))
        .is_ok()
        && &head[128..] == b"DICM"
}

fn read_sources(dir: &Path, sources: &[Source<'_>]) -> Result<(Volume<f32>, DicomSeriesInfo)> {
    if sources.is_empty() {
        return Err(Error::invalid(dir, "no DICOM files given"));
    }
    // Headers in parallel; on failure report the first failing file in name order so the
    // message does not depend on thread timing.
    let headers: Vec<Result<SliceHeader>> = sources
        .par_iter()
        .enumerate()
        .map(|(i, s)| SliceHeader::read(*s).map(|h| SliceHeader { source: i, ..h }))
        .collect();
    let headers = headers.into_iter().collect::<Result<Vec<_>>>()?;
    let geo = geometry::build(dir, headers)?;

    let first = &geo.slices[0];
    let (nx, ny, nz) = (first.cols as usize, first.rows as usize, geo.slices.len());
    let slice_len = nx * ny;
    let mut data = vec![0f32; slice_len * nz];
    let results: Vec<Result<()>> = data
        .par_chunks_mut(slice_len)
        .zip(geo.slices.par_iter())
        .map(|(out, h)| pixels::decode_slice(sources[h.source], h, out))
        .collect();
    results.into_iter().collect::<Result<Vec<()>>>()?;

    let info = DicomSeriesInfo {
        series_instance_uid: first.series_uid.clone(),
        series_description: first.series_description.clone(),
        modality: first.modality.clone(),
        transfer_syntax_uid: first.transfer_syntax.clone(),
        transfer_syntax_name: header::syntax_name(&first.transfer_syntax)
            .unwrap_or("")
            .to_string(),
        files: geo.slices.iter().map(|s| s.path.clone()).collect(),
        slice_step_mm: geo.slice_step,
        skipped_files: Vec::new(),
    };
    let volume = Volume::from_data([nx, ny, nz], geo.affine, data)
        .map_err(|e| Error::invalid(dir, e.to_string()))?;
    Ok((volume, info))
}
