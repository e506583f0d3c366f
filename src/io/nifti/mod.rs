//! NIfTI-1 volumes (`.nii`, `.nii.gz`): read into `Volume<f32>` with the index→world affine,
//! write masks and CT volumes that 3D Slicer, ITK-SNAP and nibabel open.
//!
//! The header is parsed by the `nifti` crate (both byte orders); the voxel data is streamed
//! by this module straight into the output array, chunk by chunk, so a 200 MB int16 CT is never
//! held twice in memory.

mod voxels;
mod write;

use voxels::read_voxels;

pub use write::{write_nifti, NiftiVoxel};

use crate::math::{Affine, Matrix3};
use crate::volume::Volume;
use crate::{Error, Result};
use flate2::read::MultiGzDecoder;
use nifti::{Endianness, NiftiHeader};
use std::fs::File;
use std::io::{BufReader, Read};
use std::path::Path;

/// Largest expansion deflate can achieve (a run of identical bytes compresses ~1032:1);
/// a .nii.gz whose header promises more voxel bytes than this allows is refused before
/// any allocation.
const MAX_DEFLATE_RATIO: u64 = 1032;

/// Where a volume's index→world affine came from.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "lowercase")]
pub enum AffineSource {
    /// The sform (`srow_x/y/z`), used when `sform_code > 0`.
    Sform,
    /// The qform (quaternion + offsets + pixdim), used when `sform_code == 0 < qform_code`.
    Qform,
    /// Only `pixdim` scaling (both codes 0): orientation and origin are unknown.
    Pixdim,
}

/// Header facts of a NIfTI file that a person may want to see.
#[derive(Clone, Debug, serde::Serialize)]
pub struct NiftiInfo {
    /// NIfTI datatype name (e.g. "int16").
    pub datatype: &'static str,
    /// Where the affine came from.
    pub affine_source: AffineSource,
    /// scl_slope as applied (1 when the header says 0 or non-finite).
    pub scl_slope: f64,
    /// scl_inter as applied.
    pub scl_inter: f64,
    /// Things worth a warning (e.g. no orientation in the header).
    pub warnings: Vec<String>,
}

/// The voxel types bronchosim reads, with their NIfTI codes and sizes in bytes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum VoxelType {
    U8,
    I8,
    I16,
    U16,
    I32,
    U32,
    F32,
    F64,
}

impl VoxelType {
    fn from_code(code: i16) -> Option<Self> {
        Some(match code {
            2 => VoxelType::U8,
            256 => VoxelType::I8,
            4 => VoxelType::I16,
            512 => VoxelType::U16,
            8 => VoxelType::I32,
            768 => VoxelType::U32,
            16 => VoxelType::F32,
            64 => VoxelType::F64,
            _ => return None,
        })
    }

    fn size(self) -> usize {
        match self {
            VoxelType::U8 | VoxelType::I8 => 1,
            VoxelType::I16 | VoxelType::U16 => 2,
            VoxelType::I32 | VoxelType::U32 | VoxelType::F32 => 4,
            VoxelType::F64 => 8,
        }
    }

    fn name(self) -> &'static str {
        match self {
            VoxelType::U8 => "uint8",
            VoxelType::I8 => "int8",
            VoxelType::I16 => "int16",
            VoxelType::U16 => "uint16",
            VoxelType::I32 => "int32",
            VoxelType::U32 => "uint32",
            VoxelType::F32 => "float32",
            VoxelType::F64 => "float64",
        }
    }
}

/// Names of NIfTI datatypes bronchosim does not read, for error messages.
fn datatype_name(code: i16) -> String {
    match code {
        0 => "unknown (0)".into(),
        1 => "binary (1)".into(),
        32 => "complex64 (32)".into(),
        128 => "rgb24 (128)".into(),
        1024 => "int64 (1024)".into(),
        1280 => "uint64 (1280)".into(),
        1536 => "float128 (1536)".into(),
        1792 => "complex128 (1792)".into(),
        2048 => "complex256 (2048)".into(),
        2304 => "rgba32 (2304)".into(),
        c => format!("code {c}"),
    }
}

/// True when `path` names a gzip-compressed NIfTI by its extension.
pub(super) fn is_gz(path: &Path) -> bool {
    path.extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("gz"))
}

/// The file name is a single-file NIfTI's: it ends in `.nii` or `.nii.gz` (any case).
pub fn is_nifti_name(path: &Path) -> bool {
    let name = path
        .file_name()
        .map(|n| n.to_string_lossy().to_ascii_lowercase())
        .unwrap_or_default();
    name.ends_with(".nii") || name.ends_with(".nii.gz")
}

/// Read a NIfTI-1 volume as `f32` (scl_slope/scl_inter applied), with its affine.
pub fn read_nifti(path: &Path) -> Result<Volume<f32>> {
    read_nifti_with_info(path).map(|(v, _)| v)
}

/// Read a NIfTI-1 volume and the header facts worth reporting.
pub fn read_nifti_with_info(path: &Path) -> Result<(Volume<f32>, NiftiInfo)> {
    let file = File::open(path).map_err(|e| match e.kind() {
        std::io::ErrorKind::NotFound => Error::missing(path, "NIfTI file"),
        _ => Error::io(path, e),
    })?;
    let file_len = file.metadata().map_err(|e| Error::io(path, e))?.len();
    let reader = BufReader::with_capacity(1 << 20, file);
    if is_gz(path) {
        read_nifti_stream(MultiGzDecoder::new(reader), file_len, true, path)
    } else {
        read_nifti_stream(reader, file_len, false, path)
    }
}

/// Read a NIfTI-1 image held in memory (`gz`: gzip-compressed); `path` only names it in errors.
pub fn read_nifti_bytes(bytes: &[u8], gz: bool, path: &Path) -> Result<(Volume<f32>, NiftiInfo)> {
    if gz {
        read_nifti_stream(MultiGzDecoder::new(bytes), bytes.len() as u64, true, path)
    } else {
        read_nifti_stream(bytes, bytes.len() as u64, false, path)
    }
}

/// Read a NIfTI-1 stream. `file_len` is the size of the file on disk (compressed when
/// `compressed`), used to refuse headers that promise more data than the file can hold.
/// `path` only names the source in errors.
pub fn read_nifti_stream<R: Read>(
    mut input: R,
    file_len: u64,
    compressed: bool,
    path: &Path,
) -> Result<(Volume<f32>, NiftiInfo)> {
    let mut head = [0u8; 348];
    read_full(&mut input, &mut head, path, "the 348-byte NIfTI header")?;
    let hdr = NiftiHeader::from_reader(&head[..])
        .map_err(|e| Error::invalid(path, format!("not a NIfTI-1 header: {e}")))?;
    if hdr.sizeof_hdr != 348 {
        return Err(Error::invalid(
            path,
            format!(
                "not a NIfTI-1 file (sizeof_hdr is {}, expected 348)",
                hdr.sizeof_hdr
            ),
        ));
    }
    if &head[344..347] != b"n+1" && &head[344..347] != b"ni1" {
        return Err(Error::invalid(
            path,
            "not a NIfTI-1 file (magic is not \"n+1\")",
        ));
    }
    if &head[344..347] == b"ni1" {
        return Err(Error::unsupported(
            path,
            "a NIfTI header/image pair (.hdr/.img); convert to a single .nii or .nii.gz",
        ));
    }
    let dims = spatial_dims(&hdr, path)?;
    let vtype = VoxelType::from_code(hdr.datatype).ok_or_else(|| {
        Error::unsupported(
            path,
            format!(
                "NIfTI datatype {}; bronchosim reads uint8, int8, int16, uint16, int32, uint32, float32, float64",
                datatype_name(hdr.datatype)
            ),
        )
    })?;
    let nvox = dims[0] * dims[1] * dims[2];
    let data_bytes = (nvox as u64) * vtype.size() as u64;
    let vox_offset = hdr.vox_offset;
    if !(348.0..1e9).contains(&vox_offset) {
        return Err(Error::invalid(
            path,
            format!("vox_offset {vox_offset} is not a valid data offset"),
        ));
    }
    let vox_offset = vox_offset as u64;
    // Refuse before allocating: the file cannot hold the data its header promises.
    let max_payload = if compressed {
        file_len.saturating_mul(MAX_DEFLATE_RATIO)
    } else {
        file_len
    };
    if vox_offset + data_bytes > max_payload {
        return Err(Error::invalid(
            path,
            format!(
                "header promises {}x{}x{} {} voxels ({} bytes) but the file is only {} bytes{}: truncated or corrupt",
                dims[0],
                dims[1],
                dims[2],
                vtype.name(),
                data_bytes,
                file_len,
                if compressed { " compressed" } else { "" }
            ),
        ));
    }
    let affine_and_source = header_affine(&hdr, dims, path)?;
    let (slope, inter) = scaling(&hdr);
    // Skip extensions up to vox_offset.
    let mut skip = vox_offset - 348;
    let mut scratch = [0u8; 4096];
    while skip > 0 {
        let n = skip.min(scratch.len() as u64) as usize;
        read_full(&mut input, &mut scratch[..n], path, "the header extensions")?;
        skip -= n as u64;
    }
    let swap = hdr.endianness != Endianness::native();
    let data = read_voxels(&mut input, nvox, vtype, swap, slope, inter, path)?;
    let (affine, source) = affine_and_source;
    let mut warnings = Vec::new();
    if source == AffineSource::Pixdim {
        warnings.push(format!(
            "{}: sform_code and qform_code are both 0: orientation unknown, using pixdim scaling only",
            path.display()
        ));
    }
    let info = NiftiInfo {
        datatype: vtype.name(),
        affine_source: source,
        scl_slope: slope as f64,
        scl_inter: inter as f64,
        warnings,
    };
    let vol =
        Volume::from_data(dims, affine, data).map_err(|e| Error::invalid(path, e.to_string()))?;
    Ok((vol, info))
}

/// Fill `buf` from `input`, turning a short read into a "truncated" error naming `what`.
pub(super) fn read_full<R: Read>(
    input: &mut R,
    buf: &mut [u8],
    path: &Path,
    what: &str,
) -> Result<()> {
    let mut got = 0;
    while got < buf.len() {
        match input.read(&mut buf[got..]) {
            Ok(0) => {
                return Err(Error::invalid(
                    path,
                    format!(
                        "truncated: file ends {} bytes into {what} ({} expected)",
                        got,
                        buf.len()
                    ),
                ))
            }
            Ok(n) => got += n,
            Err(e) if e.kind() == std::io::ErrorKind::Interrupted => {}
            Err(e) => {
                return Err(Error::invalid(
                    path,
                    format!("corrupt data while reading {what}: {e}"),
                ))
            }
        }
    }
    Ok(())
}

/// The three spatial dimensions; refuses 2-D images and 4-D+ series.
fn spatial_dims(hdr: &NiftiHeader, path: &Path) -> Result<[usize; 3]> {
    let ndim = hdr.dim[0] as usize;
    if !(1..=7).contains(&ndim) {
        return Err(Error::invalid(
            path,
            format!("dim[0] = {} is not in 1..7", hdr.dim[0]),
        ));
    }
    let d: Vec<usize> = (1..=7)
        .map(|i| if i <= ndim { hdr.dim[i] as usize } else { 1 })
        .collect();
    if d[..ndim].iter().any(|&n| n == 0 || n > 32767) {
        return Err(Error::invalid(
            path,
            format!("invalid dimensions {:?}", &d[..ndim]),
        ));
    }
    if d[3..].iter().any(|&n| n > 1) {
        return Err(Error::unsupported(
            path,
            format!(
                "a {ndim}-D image with dimensions {:?}; a CT must be one 3-D volume",
                &d[..ndim]
            ),
        ));
    }
    if d[..3].iter().filter(|&&n| n > 1).count() < 3 {
        return Err(Error::unsupported(
            path,
            format!(
                "a {}-D image ({}x{}x{}); a CT must be a 3-D volume with every dimension > 1",
                d[..3].iter().filter(|&&n| n > 1).count(),
                d[0],
                d[1],
                d[2]
            ),
        ));
    }
    Ok([d[0], d[1], d[2]])
}

/// scl_slope / scl_inter as NIfTI defines them: a slope of 0 (or non-finite) means no scaling.
fn scaling(hdr: &NiftiHeader) -> (f32, f32) {
    if hdr.scl_slope == 0.0 || !hdr.scl_slope.is_finite() {
        (1.0, 0.0)
    } else {
        let inter = if hdr.scl_inter.is_finite() {
            hdr.scl_inter
        } else {
            0.0
        };
        (hdr.scl_slope, inter)
    }
}

/// The index→world affine: sform when sform_code > 0, else qform when qform_code > 0,
/// else pixdim scaling (the NIfTI-1 "method 1", as nibabel does).
fn header_affine(
    hdr: &NiftiHeader,
    dims: [usize; 3],
    path: &Path,
) -> Result<(Affine, AffineSource)> {
    let pix = [
        hdr.pixdim[1] as f64,
        hdr.pixdim[2] as f64,
        hdr.pixdim[3] as f64,
    ];
    let (affine, source) = if hdr.sform_code > 0 {
        let mut m = Affine::identity();
        for (r, row) in [hdr.srow_x, hdr.srow_y, hdr.srow_z].iter().enumerate() {
            for c in 0..4 {
                m[(r, c)] = row[c] as f64;
            }
        }
        (m, AffineSource::Sform)
    } else if hdr.qform_code > 0 {
        (qform_affine(hdr), AffineSource::Qform)
    } else {
        let mut m = Affine::identity();
        for a in 0..3 {
            m[(a, a)] = if pix[a] > 0.0 && pix[a].is_finite() {
                pix[a]
            } else {
                1.0
            };
        }
        (m, AffineSource::Pixdim)
    };
    let lin = affine.fixed_view::<3, 3>(0, 0);
    if !affine.iter().all(|v| v.is_finite()) || lin.determinant().abs() < 1e-9 {
        return Err(Error::invalid(
            path,
            format!(
                "{:?} affine is singular or non-finite (grid {}x{}x{}, pixdim {:?})",
                source, dims[0], dims[1], dims[2], pix
            ),
        ));
    }
    Ok((affine, source))
}

/// The qform affine from the quaternion (b, c, d), offsets and pixdim, with qfac = pixdim[0].
fn qform_affine(hdr: &NiftiHeader) -> Affine {
    let (b, c, d) = (
        hdr.quatern_b as f64,
        hdr.quatern_c as f64,
        hdr.quatern_d as f64,
    );
    let mut a2 = 1.0 - (b * b + c * c + d * d);
    let (mut b, mut c, mut d) = (b, c, d);
    if a2 < 1e-7 {
        // Rounding put (b, c, d) on or just outside the unit sphere: a 180° rotation.
        let n = (b * b + c * c + d * d).sqrt();
        b /= n;
        c /= n;
        d /= n;
        a2 = 0.0;
    }
    let a = a2.sqrt();
    let r = Matrix3::new(
        a * a + b * b - c * c - d * d,
        2.0 * (b * c - a * d),
        2.0 * (b * d + a * c),
        2.0 * (b * c + a * d),
        a * a + c * c - b * b - d * d,
        2.0 * (c * d - a * b),
        2.0 * (b * d - a * c),
        2.0 * (c * d + a * b),
        a * a + d * d - c * c - b * b,
    );
    let qfac = if hdr.pixdim[0] < 0.0 { -1.0 } else { 1.0 };
    let pix = [
        hdr.pixdim[1] as f64,
        hdr.pixdim[2] as f64,
        qfac * hdr.pixdim[3] as f64,
    ];
    let mut m = Affine::identity();
    for row in 0..3 {
        for col in 0..3 {
            m[(row, col)] = r[(row, col)] * pix[col];
        }
    }
    m[(0, 3)] = hdr.quatern_x as f64;
    m[(1, 3)] = hdr.quatern_y as f64;
    m[(2, 3)] = hdr.quatern_z as f64;
    m
}
