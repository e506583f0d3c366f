//! Decode one slice's pixel data into Hounsfield units.

use dicom_dictionary_std::tags;
use dicom_pixeldata::PixelDecoder;

use super::header::{describe_syntax, SliceHeader, Source};
use crate::{Error, Result};

/// Decode the pixels of `src` (whose header is `h`) into `out` (one slice, i fastest), applying
/// BitsStored/HighBit masking, sign extension and RescaleSlope/Intercept.
pub(crate) fn decode_slice(src: Source<'_>, h: &SliceHeader, out: &mut [f32]) -> Result<()> {
    let name = src.name();
    // SliceHeader::read has checked every element length (pixel data included) against the
    // file size, so this full parse cannot be made to allocate gigabytes.
    let obj = src.open(false)?;
    let decode_error = |e: &dyn std::fmt::Display| {
        Error::invalid(
            name,
            format!(
                "cannot decode pixel data in transfer syntax {}: {e}",
                describe_syntax(&h.transfer_syntax)
            ),
        )
    };
    // Native (unencapsulated) pixel data is used in place: decode_pixel_data would copy it.
    let native;
    let decoded;
    let bytes: &[u8] = if h.encapsulated {
        decoded = obj.decode_pixel_data().map_err(|e| decode_error(&e))?;
        decoded.data()
    } else {
        let element = obj
            .get(tags::PIXEL_DATA)
            .ok_or_else(|| Error::invalid(name, "missing PixelData"))?;
        native = element.to_bytes().map_err(|e| decode_error(&e))?;
        &native
    };
    let n = out.len();
    let bytes_per = (h.bits_allocated / 8) as usize;
    if bytes.len() < n * bytes_per {
        return Err(Error::invalid(
            name,
            format!(
                "pixel data holds {} bytes, but {}x{} pixels of {} bits need {}",
                bytes.len(),
                h.cols,
                h.rows,
                h.bits_allocated,
                n * bytes_per
            ),
        ));
    }
    // Stored bits sit at [high_bit + 1 - bits_stored, high_bit]; the rest may hold overlays.
    let shift = (h.high_bit + 1 - h.bits_stored) as u32;
    let bits = h.bits_stored as u32;
    let mask: u32 = if bits >= 32 {
        u32::MAX
    } else {
        (1u32 << bits) - 1
    };
    let sign_bit = 1u32 << (bits - 1);
    let signed = h.signed;
    let (slope, intercept) = (h.slope, h.intercept);
    let value = move |raw: u32| -> f32 {
        let v = (raw >> shift) & mask;
        let v = if signed && v & sign_bit != 0 {
            v as i64 - (1i64 << bits)
        } else {
            v as i64
        };
        (v as f64 * slope + intercept) as f32
    };
    if bytes_per == 2 {
        for (o, b) in out.iter_mut().zip(bytes.chunks_exact(2)) {
            *o = value(u16::from_le_bytes([b[0], b[1]]) as u32);
        }
    } else {
        for (o, &b) in out.iter_mut().zip(bytes.iter()) {
            *o = value(b as u32);
        }
    }
    Ok(())
}
