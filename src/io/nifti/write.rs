//! Writing a volume as NIfTI-1 (.nii or .nii.gz, chosen by the name), atomically, with its
//! affine in both sform and qform so that every reader places it identically.

use super::is_gz;
use crate::io::atomic::write_atomic;
use crate::math::Matrix3;
use crate::volume::Volume;
use crate::Result;
use std::io::Write;
use std::path::Path;

/// Voxel types bronchosim writes to NIfTI.
pub trait NiftiVoxel: Copy + Send + Sync {
    /// NIfTI datatype code.
    const CODE: i16;
    /// Little-endian bytes of one voxel.
    fn le_bytes(self, out: &mut Vec<u8>);
}

impl NiftiVoxel for u8 {
    const CODE: i16 = 2;
    fn le_bytes(self, out: &mut Vec<u8>) {
        out.push(self);
    }
}

impl NiftiVoxel for i16 {
    const CODE: i16 = 4;
    fn le_bytes(self, out: &mut Vec<u8>) {
        out.extend_from_slice(&self.to_le_bytes());
    }
}

impl NiftiVoxel for f32 {
    const CODE: i16 = 16;
    fn le_bytes(self, out: &mut Vec<u8>) {
        out.extend_from_slice(&self.to_le_bytes());
    }
}

/// Write `vol` as NIfTI-1 (gzip-compressed when `path` ends in .gz), atomically.
/// The affine goes into the sform (code 2, aligned) and, as nibabel does, the qform too
/// (code 1, scanner) when it is a rotation times scaling.
pub fn write_nifti<T: NiftiVoxel>(path: &Path, vol: &Volume<T>) -> Result<()> {
    let header = header_bytes::<T>(vol);
    let gz = is_gz(path);
    write_atomic(path, |w| {
        if gz {
            let mut enc = flate2::write::GzEncoder::new(w, flate2::Compression::new(3));
            write_payload(&mut enc, &header, vol)?;
            enc.finish()?;
            Ok(())
        } else {
            write_payload(w, &header, vol)
        }
    })
}

fn write_payload<T: NiftiVoxel, W: Write + ?Sized>(
    w: &mut W,
    header: &[u8],
    vol: &Volume<T>,
) -> std::io::Result<()> {
    w.write_all(header)?;
    w.write_all(&[0u8; 4])?; // no extensions; data starts at 352
    let mut buf = Vec::with_capacity(1 << 20);
    for chunk in vol.data.chunks(1 << 18) {
        buf.clear();
        for &v in chunk {
            v.le_bytes(&mut buf);
        }
        w.write_all(&buf)?;
    }
    Ok(())
}

/// The 348-byte little-endian NIfTI-1 header for `vol`.
fn header_bytes<T: NiftiVoxel>(vol: &Volume<T>) -> Vec<u8> {
    let mut h = vec![0u8; 348];
    let put_i16 =
        |h: &mut Vec<u8>, at: usize, v: i16| h[at..at + 2].copy_from_slice(&v.to_le_bytes());
    let put_f32 =
        |h: &mut Vec<u8>, at: usize, v: f32| h[at..at + 4].copy_from_slice(&v.to_le_bytes());
    h[0..4].copy_from_slice(&348i32.to_le_bytes());
    put_i16(&mut h, 40, 3);
    for a in 0..3 {
        put_i16(&mut h, 42 + 2 * a, vol.dims[a] as i16);
    }
    for a in 3..7 {
        put_i16(&mut h, 42 + 2 * a, 1);
    }
    put_i16(&mut h, 70, T::CODE);
    put_i16(&mut h, 72, (std::mem::size_of::<T>() * 8) as i16);
    let sp = vol.spacing();
    let lin = vol.affine.fixed_view::<3, 3>(0, 0).into_owned();
    let det = lin.determinant();
    let qfac = if det < 0.0 { -1.0 } else { 1.0 };
    put_f32(&mut h, 76, qfac as f32);
    for (a, s) in sp.iter().enumerate() {
        put_f32(&mut h, 80 + 4 * a, *s as f32);
    }
    put_f32(&mut h, 108, 352.0); // vox_offset
    put_f32(&mut h, 112, 1.0); // scl_slope
    h[123] = 2 | 8; // xyzt_units: mm, s
    let descrip = b"bronchosim";
    h[148..148 + descrip.len()].copy_from_slice(descrip);
    // qform from the rotation part (polar decomposition of the direction cosines).
    let mut rot = lin;
    for c in 0..3 {
        let s = if c == 2 { sp[c] * qfac } else { sp[c] };
        for r in 0..3 {
            rot[(r, c)] /= s;
        }
    }
    let is_rotation = (rot.transpose() * rot - Matrix3::identity()).norm() < 1e-4;
    if is_rotation {
        let q = nalgebra::UnitQuaternion::from_matrix(&rot);
        // NIfTI stores (b, c, d) with a >= 0 implied.
        let sign = if q.w < 0.0 { -1.0 } else { 1.0 };
        let (qb, qc, qd) = (sign * q.i, sign * q.j, sign * q.k);
        put_i16(&mut h, 252, 1);
        put_f32(&mut h, 256, qb as f32);
        put_f32(&mut h, 260, qc as f32);
        put_f32(&mut h, 264, qd as f32);
    }
    put_f32(&mut h, 268, vol.affine[(0, 3)] as f32);
    put_f32(&mut h, 272, vol.affine[(1, 3)] as f32);
    put_f32(&mut h, 276, vol.affine[(2, 3)] as f32);
    put_i16(&mut h, 254, 2); // sform_code: aligned
    for r in 0..3 {
        for c in 0..4 {
            put_f32(&mut h, 280 + 16 * r + 4 * c, vol.affine[(r, c)] as f32);
        }
    }
    h[344..348].copy_from_slice(b"n+1\0");
    h
}
