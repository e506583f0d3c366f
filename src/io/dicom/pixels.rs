//! Decode one slice's pixel data into Hounsfield units.

use dicom_dictionary_std::tags;
use dicom_pixeldata::PixelDecoder;

use super::header::{describe_syntax, SliceHeader, Source};
use super::j2k;
use crate::{Error, Result};

const RLE_LOSSLESS: &str = "1.2.840.10008.1.2.5";
/// JPEG 2000 Image Compression (Lossless Only), JPEG 2000 Image Compression, and High-Throughput
/// JPEG 2000 (Lossless Only, with RPCL Options, lossy): one codestream syntax, one decoder.
pub(crate) const JPEG_2000: [&str; 5] = [
    "1.2.840.10008.1.2.4.90",
    "1.2.840.10008.1.2.4.91",
    "1.2.840.10008.1.2.4.201",
    "1.2.840.10008.1.2.4.202",
    "1.2.840.10008.1.2.4.203",
];

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
    if JPEG_2000.contains(&h.transfer_syntax.as_str()) {
        return decode_jpeg2000(&obj, name, h, out);
    }
    // Native (unencapsulated) pixel data is used in place: decode_pixel_data would copy it.
    let native;
    let decoded;
    let rle;
    let bytes: &[u8] = if h.transfer_syntax == RLE_LOSSLESS {
        // Our own decoder: dicom-transfer-syntax-registry 0.10's panics on a short fragment
        // or a segment that decodes to fewer bytes than the image (found by cargo-fuzz).
        let element = obj
            .get(tags::PIXEL_DATA)
            .ok_or_else(|| Error::invalid(name, "missing PixelData"))?;
        let fragments = element.value().fragments().unwrap_or(&[]);
        let [fragment] = fragments else {
            return Err(Error::invalid(
                name,
                format!(
                    "RLE Lossless pixel data must be one fragment for one frame, found {}",
                    fragments.len()
                ),
            ));
        };
        rle = decode_rle(fragment, out.len(), (h.bits_allocated / 8) as usize)
            .map_err(|m| Error::invalid(name, format!("corrupt RLE Lossless pixel data: {m}")))?;
        &rle
    } else if h.encapsulated {
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

/// Decode a JPEG 2000 slice with our own adapter (see [`j2k`]) and rescale it to HU.
fn decode_jpeg2000(
    obj: &dicom_object::DefaultDicomObject,
    name: &std::path::Path,
    h: &SliceHeader,
    out: &mut [f32],
) -> Result<()> {
    let element = obj
        .get(tags::PIXEL_DATA)
        .ok_or_else(|| Error::invalid(name, "missing PixelData"))?;
    let fragments = element.value().fragments().unwrap_or(&[]);
    if fragments.is_empty() {
        return Err(Error::invalid(
            name,
            "JPEG 2000 pixel data holds no fragments (is it encapsulated?)",
        ));
    }
    // A single-frame image may split its codestream over several fragments (PS3.5 A.4).
    let joined;
    let cs: &[u8] = if let [one] = fragments {
        one
    } else {
        joined = fragments.concat();
        &joined
    };
    let want = j2k::Expected {
        cols: h.cols,
        rows: h.rows,
        bits_allocated: h.bits_allocated,
        signed: h.signed,
    };
    let mut stored = vec![0i32; out.len()];
    j2k::decode_frame(cs, want, &mut stored).map_err(|m| {
        Error::invalid(
            name,
            format!(
                "cannot decode pixel data in transfer syntax {}: {m}",
                describe_syntax(&h.transfer_syntax)
            ),
        )
    })?;
    let (slope, intercept) = (h.slope, h.intercept);
    for (o, &v) in out.iter_mut().zip(&stored) {
        *o = (v as f64 * slope + intercept) as f32;
    }
    Ok(())
}

/// Decode one RLE Lossless frame (DICOM PS3.5 Annex G) of `pixels` single-sample pixels of
/// `bytes_per` bytes into little-endian pixel bytes. Segment k holds byte k of every pixel,
/// most significant first; each is PackBits-coded. Every malformation is an error message.
fn decode_rle(
    fragment: &[u8],
    pixels: usize,
    bytes_per: usize,
) -> std::result::Result<Vec<u8>, String> {
    if fragment.len() < 64 {
        return Err(format!(
            "fragment of {} bytes is shorter than the 64-byte header",
            fragment.len()
        ));
    }
    let word = |i: usize| {
        u32::from_le_bytes(fragment[4 * i..4 * i + 4].try_into().expect("4 bytes")) as usize
    };
    let segments = word(0);
    if segments != bytes_per {
        return Err(format!(
            "{segments} segments for {} bits per pixel, expected {bytes_per}",
            bytes_per * 8
        ));
    }
    let mut out = vec![0u8; pixels * bytes_per];
    for k in 0..segments {
        let start = word(1 + k);
        let end = if k + 1 < segments {
            word(2 + k)
        } else {
            fragment.len()
        };
        let segment = fragment
            .get(start..end)
            .filter(|_| start >= 64)
            .ok_or_else(|| {
                format!(
                    "segment {k} spans bytes {start}..{end} of a {}-byte fragment",
                    fragment.len()
                )
            })?;
        // Byte k of the big-endian sample goes to little-endian position bytes_per - 1 - k.
        let lane = bytes_per - 1 - k;
        let mut n = 0; // pixels decoded
        let mut i = 0;
        let mut put = |b: u8, n: &mut usize| {
            if *n < pixels {
                out[*n * bytes_per + lane] = b;
                *n += 1;
            }
        };
        while i < segment.len() && n < pixels {
            let control = segment[i] as i8;
            i += 1;
            if control >= 0 {
                let count = control as usize + 1;
                let literal = segment
                    .get(i..i + count)
                    .ok_or_else(|| format!("segment {k} ends inside a literal run"))?;
                for &b in literal {
                    put(b, &mut n);
                }
                i += count;
            } else if control != -128 {
                let b = *segment
                    .get(i)
                    .ok_or_else(|| format!("segment {k} ends inside a repeat run"))?;
                i += 1;
                for _ in 0..(1 - control as isize) {
                    put(b, &mut n);
                }
            }
        }
        if n < pixels {
            return Err(format!("segment {k} decodes to {n} of {pixels} pixels"));
        }
    }
    Ok(out)
}
