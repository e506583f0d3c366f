//! Streaming a NIfTI file's voxel data, chunk by chunk, into `f32` with its byte order and
//! scaling applied (every NIfTI datatype bronchosim reads).

use super::{read_full, VoxelType};
use crate::{Error, Result};
use std::io::Read;
use std::path::Path;

/// Stream `nvox` voxels of `vtype` into an f32 vector, converting and scaling chunk by chunk.
pub(super) fn read_voxels<R: Read>(
    input: &mut R,
    nvox: usize,
    vtype: VoxelType,
    swap: bool,
    slope: f32,
    inter: f32,
    path: &Path,
) -> Result<Vec<f32>> {
    let size = vtype.size();
    let mut out = vec![0f32; nvox];
    const CHUNK_VOXELS: usize = 1 << 20;
    let mut buf = vec![0u8; CHUNK_VOXELS * size];
    let mut done = 0;
    while done < nvox {
        let n = (nvox - done).min(CHUNK_VOXELS);
        let bytes = &mut buf[..n * size];
        read_full(input, bytes, path, "the voxel data").map_err(|e| match e {
            Error::Invalid { message, .. } if message.starts_with("truncated") => Error::invalid(
                path,
                format!("truncated: voxel data ends after {done}+ of {nvox} voxels"),
            ),
            other => other,
        })?;
        convert_chunk(bytes, &mut out[done..done + n], vtype, swap, slope, inter);
        done += n;
    }
    Ok(out)
}

/// Decode one chunk of raw voxels (any byte order) into scaled f32.
fn convert_chunk(
    bytes: &[u8],
    out: &mut [f32],
    vtype: VoxelType,
    swap: bool,
    slope: f32,
    inter: f32,
) {
    macro_rules! conv {
        ($t:ty, $n:expr) => {
            for (o, b) in out.iter_mut().zip(bytes.chunks_exact($n)) {
                let mut a = [0u8; $n];
                a.copy_from_slice(b);
                if swap {
                    a.reverse();
                }
                *o = <$t>::from_ne_bytes(a) as f32 * slope + inter;
            }
        };
    }
    match vtype {
        VoxelType::U8 => out
            .iter_mut()
            .zip(bytes)
            .for_each(|(o, &b)| *o = b as f32 * slope + inter),
        VoxelType::I8 => out
            .iter_mut()
            .zip(bytes)
            .for_each(|(o, &b)| *o = b as i8 as f32 * slope + inter),
        VoxelType::I16 => conv!(i16, 2),
        VoxelType::U16 => conv!(u16, 2),
        VoxelType::I32 => conv!(i32, 4),
        VoxelType::U32 => conv!(u32, 4),
        VoxelType::F32 => conv!(f32, 4),
        VoxelType::F64 => {
            for (o, b) in out.iter_mut().zip(bytes.chunks_exact(8)) {
                let mut a = [0u8; 8];
                a.copy_from_slice(b);
                if swap {
                    a.reverse();
                }
                *o = (f64::from_ne_bytes(a) * slope as f64 + inter as f64) as f32;
            }
        }
    }
}
