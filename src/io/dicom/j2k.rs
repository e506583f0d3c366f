//! JPEG 2000 pixel data (DICOM PS3.5 A.4.4 and A.4.11: transfer syntaxes
//! 1.2.840.10008.1.2.4.90 and .91, and High-Throughput JPEG 2000 .4.201 to .4.203, which share
//! the codestream syntax) decoded to stored pixel values.
//!
//! Steps: join the frame's fragments into one codestream; read its SIZ marker segment ourselves
//! and check it against the DICOM header (one component, Columns x Rows, no subsampling,
//! precision within BitsAllocated) before the decoder allocates anything; decode with OpenJPEG
//! (`jpeg2k` over `openjpeg-sys`) in its default strict mode, so a truncated codestream is an
//! error rather than a partly blank image; check the decoded component again; apply
//! pydicom's sign correction when the codestream's signedness disagrees with
//! PixelRepresentation (a known export defect): the low `precision` bits are reinterpreted
//! with the header's sign.

/// SOC then SIZ: every JPEG 2000 codestream starts with these four bytes (ISO 15444-1 A.4.1).
const CODESTREAM_START: [u8; 4] = [0xFF, 0x4F, 0xFF, 0x51];

/// What a codestream's SIZ marker segment says about its one component (ISO 15444-1 A.5.1).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) struct Siz {
    /// Image width and height on the reference grid (Xsiz − XOsiz, Ysiz − YOsiz).
    pub width: u32,
    pub height: u32,
    /// Number of components (Csiz).
    pub components: u16,
    /// Bit depth of component 0 (Ssiz & 0x7F, plus 1).
    pub precision: u32,
    /// Component 0 holds signed values (Ssiz bit 7).
    pub signed: bool,
    /// Subsampling of component 0 (XRsiz, YRsiz).
    pub subsampling: [u8; 2],
}

/// Parse the SIZ marker segment at the start of `cs`; `Err` says what is wrong in words.
pub(crate) fn read_siz(cs: &[u8]) -> std::result::Result<Siz, String> {
    if cs.len() < 4 || cs[..4] != CODESTREAM_START {
        let what = if cs.get(4..8) == Some(b"jP  ") {
            "a JP2 file; DICOM requires a bare JPEG 2000 codestream".to_string()
        } else {
            format!(
                "does not start with a JPEG 2000 codestream (first bytes {:02X?})",
                &cs[..cs.len().min(4)]
            )
        };
        return Err(what);
    }
    // Fixed part of SIZ after the marker: Lsiz, Rsiz (u16), 8 x u32, Csiz (u16) = 38 bytes,
    // then 3 bytes per component.
    let seg = &cs[4..];
    let u16_at = |i: usize| seg.get(i..i + 2).map(|b| u16::from_be_bytes([b[0], b[1]]));
    let u32_at = |i: usize| {
        seg.get(i..i + 4)
            .map(|b| u32::from_be_bytes([b[0], b[1], b[2], b[3]]))
    };
    let short = || format!("SIZ marker segment cut short ({} bytes)", cs.len());
    let (xsiz, ysiz) = (u32_at(4).ok_or_else(short)?, u32_at(8).ok_or_else(short)?);
    let (xo, yo) = (u32_at(12).ok_or_else(short)?, u32_at(16).ok_or_else(short)?);
    let components = u16_at(36).ok_or_else(short)?;
    let lsiz = u16_at(0).ok_or_else(short)? as usize;
    if components == 0 || lsiz != 38 + 3 * components as usize {
        return Err(format!(
            "SIZ marker segment length {lsiz} does not match its {components} components"
        ));
    }
    let comp = seg.get(38..41).ok_or_else(short)?;
    if xsiz <= xo || ysiz <= yo {
        return Err(format!(
            "SIZ describes an empty image (Xsiz {xsiz}, XOsiz {xo}, Ysiz {ysiz}, YOsiz {yo})"
        ));
    }
    Ok(Siz {
        width: xsiz - xo,
        height: ysiz - yo,
        components,
        precision: (comp[0] & 0x7F) as u32 + 1,
        signed: comp[0] & 0x80 != 0,
        subsampling: [comp[1], comp[2]],
    })
}

/// The DICOM header values a JPEG 2000 frame must agree with.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Expected {
    /// Columns and Rows.
    pub cols: u32,
    pub rows: u32,
    /// BitsAllocated (8 or 16).
    pub bits_allocated: u16,
    /// PixelRepresentation is 1.
    pub signed: bool,
}

/// Decode one frame's codestream `cs` into `out` (Columns x Rows stored values, i fastest).
/// Errors are messages for a person; the caller adds the file name.
pub(crate) fn decode_frame(
    cs: &[u8],
    want: Expected,
    out: &mut [i32],
) -> std::result::Result<(), String> {
    let siz = read_siz(cs)?;
    if siz.components != 1 || siz.subsampling != [1, 1] {
        return Err(format!(
            "codestream has {} components with subsampling {}x{}; a CT slice has one full-resolution component",
            siz.components, siz.subsampling[0], siz.subsampling[1]
        ));
    }
    if (siz.width, siz.height) != (want.cols, want.rows) {
        return Err(format!(
            "codestream is {}x{} pixels but the header says Columns x Rows = {}x{}",
            siz.width, siz.height, want.cols, want.rows
        ));
    }
    if siz.precision > want.bits_allocated as u32 {
        return Err(format!(
            "codestream precision {} bits exceeds BitsAllocated {}",
            siz.precision, want.bits_allocated
        ));
    }
    debug_assert_eq!(out.len(), want.cols as usize * want.rows as usize);
    // A panic in the wrapper on a damaged codestream must become this file's error, not take
    // the whole series (and the process) down.
    let decoded = std::panic::catch_unwind(|| jpeg2k::Image::from_bytes(cs))
        .map_err(|_| "JPEG 2000 decoder failed on a damaged codestream".to_string())?
        .map_err(|e| match e {
            // What jpeg2k reports when OpenJPEG could not parse the main header.
            jpeg2k::error::Error::NullPointerError(_) => {
                "corrupt JPEG 2000 codestream (main header unreadable)".to_string()
            }
            e => format!("corrupt or truncated JPEG 2000 codestream ({e})"),
        })?;
    let comps = decoded.components();
    let [c] = comps else {
        return Err(format!("decoded {} components, expected 1", comps.len()));
    };
    if (c.width(), c.height()) != (want.cols, want.rows)
        || c.precision() != siz.precision
        || c.is_signed() != siz.signed
    {
        return Err(format!(
            "decoded component is {}x{}, {} bits {}, but SIZ says {}x{}, {} bits",
            c.width(),
            c.height(),
            c.precision(),
            if c.is_signed() { "signed" } else { "unsigned" },
            siz.width,
            siz.height,
            siz.precision
        ));
    }
    let data = c.data();
    if data.len() != out.len() {
        return Err(format!(
            "decoded {} samples, expected {}",
            data.len(),
            out.len()
        ));
    }
    let p = siz.precision;
    if siz.signed == want.signed {
        out.copy_from_slice(data);
    } else {
        // pydicom's correction: keep the low p bits, read them with the header's sign.
        let mask = if p >= 32 { u32::MAX } else { (1u32 << p) - 1 };
        for (o, &v) in out.iter_mut().zip(data) {
            let bits = (v as u32) & mask;
            *o = if want.signed && p < 32 && bits & (1 << (p - 1)) != 0 {
                (bits as i64 - (1i64 << p)) as i32
            } else {
                bits as i32
            };
        }
    }
    Ok(())
}
