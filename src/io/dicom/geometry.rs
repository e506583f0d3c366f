//! Series geometry: one series, one grid; slices sorted along the normal; index→world affine.

use std::path::Path;

use super::header::SliceHeader;
use crate::math::{Affine, Vector3};
use crate::{Error, Result};

/// Largest relative deviation of one slice step from the mean step (the 1 %).
const MAX_STEP_DEVIATION: f64 = 0.01;
/// Largest difference between two slices' direction cosines still taken as the same orientation.
const ORIENTATION_TOL: f64 = 1e-4;
/// Largest relative difference between two slices' pixel spacings.
const SPACING_TOL: f64 = 1e-4;

/// The sorted slices and the grid they span.
pub(crate) struct SeriesGeometry {
    /// Slice headers sorted by position along the slice normal, ascending.
    pub slices: Vec<SliceHeader>,
    /// Voxel index (i = column, j = row, k = sorted slice) → RAS mm.
    pub affine: Affine,
    /// Mean distance between adjacent slices along the normal, mm (SliceThickness for one slice).
    pub slice_step: f64,
}

fn rel_diff(a: f64, b: f64) -> f64 {
    (a - b).abs() / a.abs().max(b.abs()).max(1e-12)
}

/// Check that all slices belong to one series on one grid, then sort and place them.
/// `dir` names the folder in errors that concern the series as a whole.
pub(crate) fn build(dir: &Path, mut slices: Vec<SliceHeader>) -> Result<SeriesGeometry> {
    let Some(first) = slices.first().cloned() else {
        return Err(Error::invalid(dir, "no DICOM slices"));
    };
    check_one_grid(dir, &first, &slices[1..])?;
    let (row, col) = in_plane_axes(&first)?;
    let normal = row.cross(&col);
    let along = |s: &SliceHeader| Vector3::from(s.position).dot(&normal);
    slices.sort_by(|a, b| along(a).total_cmp(&along(b)));
    let (slice_step, k_axis) = if slices.len() == 1 {
        // One slice has no neighbour to measure spacing from: use its nominal spacing, which
        // matters only for the thickness of the single voxel layer.
        let step = first.spacing_between_slices.or(first.slice_thickness).ok_or_else(|| {
            Error::invalid(
                &first.path,
                "single-slice series without SliceThickness or SpacingBetweenSlices: slice spacing unknown",
            )
        })?;
        (step, normal * step)
    } else {
        slice_axis(dir, &slices, normal)?
    };

    // LPS columns: i steps along the row direction by the column spacing, j along the column
    // direction by the row spacing (PixelSpacing = [row spacing, column spacing]).
    let [dr, dc] = first.pixel_spacing;
    let i_axis = row * dc;
    let j_axis = col * dr;
    let origin = Vector3::from(slices[0].position);
    let mut affine = Affine::identity();
    for (c, v) in [i_axis, j_axis, k_axis, origin].iter().enumerate() {
        // LPS → RAS: negate x and y.
        affine[(0, c)] = -v.x;
        affine[(1, c)] = -v.y;
        affine[(2, c)] = v.z;
    }
    Ok(SeriesGeometry {
        slices,
        affine,
        slice_step,
    })
}

/// A slice's file name, for error messages.
fn fname(s: &SliceHeader) -> String {
    s.path.display().to_string()
}

/// Fail unless every slice of `rest` has the series UID, size, orientation and pixel spacing
/// of `first`.
fn check_one_grid(dir: &Path, first: &SliceHeader, rest: &[SliceHeader]) -> Result<()> {
    for s in rest {
        if s.series_uid != first.series_uid {
            return Err(Error::invalid(
                dir,
                format!(
                    "folder mixes series: {} has SeriesInstanceUID {}, {} has {}",
                    fname(first),
                    first.series_uid,
                    fname(s),
                    s.series_uid
                ),
            ));
        }
        if (s.rows, s.cols) != (first.rows, first.cols) {
            return Err(Error::invalid(
                dir,
                format!(
                    "slices differ in size: {} is {}x{} (Columns x Rows), {} is {}x{}",
                    fname(first),
                    first.cols,
                    first.rows,
                    fname(s),
                    s.cols,
                    s.rows
                ),
            ));
        }
        if (0..6).any(|a| (s.orientation[a] - first.orientation[a]).abs() > ORIENTATION_TOL) {
            return Err(Error::invalid(
                dir,
                format!(
                    "slices differ in orientation: {} has ImageOrientationPatient {:?}, {} has {:?}",
                    fname(first),
                    first.orientation,
                    fname(s),
                    s.orientation
                ),
            ));
        }
        if (0..2).any(|a| rel_diff(s.pixel_spacing[a], first.pixel_spacing[a]) > SPACING_TOL) {
            return Err(Error::invalid(
                dir,
                format!(
                    "slices differ in PixelSpacing: {} has {:?}, {} has {:?}",
                    fname(first),
                    first.pixel_spacing,
                    fname(s),
                    s.pixel_spacing
                ),
            ));
        }
    }
    Ok(())
}

/// The row and column directions (LPS unit vectors) of `first`'s ImageOrientationPatient,
/// the column made exactly orthogonal to the row.
fn in_plane_axes(first: &SliceHeader) -> Result<(Vector3<f64>, Vector3<f64>)> {
    let o = &first.orientation;
    let row = Vector3::new(o[0], o[1], o[2]);
    let col = Vector3::new(o[3], o[4], o[5]);
    if (row.norm() - 1.0).abs() > 1e-3
        || (col.norm() - 1.0).abs() > 1e-3
        || row.dot(&col).abs() > 1e-3
    {
        return Err(Error::invalid(
            &first.path,
            format!("ImageOrientationPatient {o:?} is not two orthogonal unit vectors"),
        ));
    }
    let row = row.normalize();
    // Re-orthogonalise so that rounding in the stored cosines does not shear the grid.
    let col = (col - row * row.dot(&col)).normalize();
    Ok((row, col))
}

/// The mean slice step (mm) and the k axis (LPS mm per slice) of two or more `slices` sorted
/// along `normal`: fails on two slices at one position, a missing slice, a step off the mean
/// by more than 1 %, or positions off a straight line.
fn slice_axis(
    dir: &Path,
    slices: &[SliceHeader],
    normal: Vector3<f64>,
) -> Result<(f64, Vector3<f64>)> {
    let along = |s: &SliceHeader| Vector3::from(s.position).dot(&normal);
    let n = slices.len();
    let d: Vec<f64> = slices
        .windows(2)
        .map(|w| along(&w[1]) - along(&w[0]))
        .collect();
    for (w, dk) in slices.windows(2).zip(&d) {
        if *dk < 1e-6 {
            return Err(Error::invalid(
                dir,
                format!(
                    "two slices at the same position along the slice normal ({:.4} mm): {} and {}",
                    along(&w[0]),
                    fname(&w[0]),
                    fname(&w[1])
                ),
            ));
        }
    }
    let mean = (along(&slices[n - 1]) - along(&slices[0])) / (n - 1) as f64;
    let mut sorted = d.clone();
    sorted.sort_by(f64::total_cmp);
    let median = sorted[sorted.len() / 2];
    let deviates = |dk: f64| (dk - mean).abs() > MAX_STEP_DEVIATION * mean;
    // A gap of a whole number of usual steps is a missing slice; report that before the
    // general non-uniformity it also causes in the mean.
    for (w, dk) in slices.windows(2).zip(&d) {
        let ratio = dk / median;
        if deviates(*dk) && ratio > 1.5 && (ratio - ratio.round()).abs() < 0.1 {
            return Err(Error::invalid(
                dir,
                format!(
                    "missing slice(s): gap of {dk:.4} mm between {} and {}, where the usual step is {median:.4} mm",
                    fname(&w[0]),
                    fname(&w[1])
                ),
            ));
        }
    }
    if let Some((w, dk)) = slices.windows(2).zip(&d).find(|(_, dk)| deviates(**dk)) {
        return Err(Error::invalid(
            dir,
            format!(
                "non-uniform slice spacing: {dk:.4} mm between {} and {}, mean step {mean:.4} mm (tolerance 1%)",
                fname(&w[0]),
                fname(&w[1])
            ),
        ));
    }
    // The k axis is the mean step between positions, not step * normal: for a tilted
    // gantry the positions drift sideways and this keeps every slice where it was acquired.
    let p0 = Vector3::from(slices[0].position);
    let pn = Vector3::from(slices[n - 1].position);
    let k_axis = (pn - p0) / (n - 1) as f64;
    for (k, s) in slices.iter().enumerate() {
        let off = (Vector3::from(s.position) - (p0 + k_axis * k as f64)).norm();
        if off > MAX_STEP_DEVIATION * mean {
            return Err(Error::invalid(
                dir,
                format!(
                    "slice positions do not lie on a line: {} is {off:.4} mm off the line through the first and last slice",
                    fname(s)
                ),
            ));
        }
    }
    Ok((mean, k_axis))
}
