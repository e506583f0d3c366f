//! One slice's header: the attributes needed to place and decode it, read without its pixels.

use std::io::{Cursor, Read};
use std::path::{Path, PathBuf};

use dicom_dictionary_std::tags;
use dicom_object::file::ReadPreamble;
use dicom_object::{DefaultDicomObject, FileMetaTable, OpenFileOptions};

use crate::{Error, Result};

/// Where a slice's bytes come from: a file, or memory (for fuzzing and tests).
#[derive(Clone, Copy, Debug)]
pub(crate) enum Source<'a> {
    File(&'a Path),
    Memory(&'a Path, &'a [u8]),
}

impl<'a> Source<'a> {
    /// The name used in error messages.
    pub(crate) fn name(&self) -> &'a Path {
        match *self {
            Source::File(p) | Source::Memory(p, _) => p,
        }
    }

    /// Size in bytes of the whole file.
    fn len(&self) -> Result<u64> {
        match *self {
            Source::File(p) => std::fs::metadata(p)
                .map(|m| m.len())
                .map_err(|e| Error::io(p, e)),
            Source::Memory(_, b) => Ok(b.len() as u64),
        }
    }

    /// Walk the element headers of the whole file (not decoding values) and fail when a
    /// declared length runs past its end: dicom-parser would zero-fill up to 4 GB first.
    pub(crate) fn check_lengths(&self) -> Result<()> {
        match *self {
            Source::File(p) => {
                let file = std::fs::File::open(p).map_err(|e| Error::io(p, e))?;
                let len = file.metadata().map_err(|e| Error::io(p, e))?.len();
                super::scan::check_lengths(std::io::BufReader::new(file), len, p)
            }
            Source::Memory(p, b) => super::scan::check_lengths(Cursor::new(b), b.len() as u64, p),
        }
    }

    /// A reader positioned at the `DICM` marker, after checking that the marker is at byte 128.
    fn open_after_preamble(&self) -> Result<Box<dyn Read + 'a>> {
        let mut reader: Box<dyn Read + 'a> = match *self {
            Source::File(p) => Box::new(std::fs::File::open(p).map_err(|e| Error::io(p, e))?),
            Source::Memory(_, b) => Box::new(b),
        };
        let mut head = [0u8; 132];
        let mut got = 0;
        while got < head.len() {
            match reader.read(&mut head[got..]) {
                Ok(0) => break,
                Ok(n) => got += n,
                Err(e) if e.kind() == std::io::ErrorKind::Interrupted => {}
                Err(e) => return Err(Error::io(self.name(), e)),
            }
        }
        if got < head.len() || &head[128..132] != b"DICM" {
            return Err(Error::invalid(
                self.name(),
                "not a DICOM file (no 'DICM' marker at byte 128); a series folder holds DICOM slices and may hold documents named as such (LICENSE, README.md, *.txt)",
            ));
        }
        Ok(Box::new(Cursor::new(*b"DICM").chain(reader)))
    }

    /// Parse the file meta group and data set, stopping before the pixel data when `header_only`.
    pub(crate) fn open(&self, header_only: bool) -> Result<DefaultDicomObject> {
        let reader = self.open_after_preamble()?;
        let mut options = OpenFileOptions::new().read_preamble(ReadPreamble::Never);
        if header_only {
            options = options.read_until(tags::PIXEL_DATA);
        }
        options.from_reader(reader).map_err(|e| {
            // Name the transfer syntax when the meta group itself could be read: most failures
            // here are syntaxes the parser does not know.
            let ts = self
                .open_after_preamble()
                .ok()
                .and_then(|r| FileMetaTable::from_reader(r).ok())
                .map(|m| {
                    format!(
                        " (transfer syntax {})",
                        describe_syntax(m.transfer_syntax())
                    )
                })
                .unwrap_or_default();
            Error::invalid(self.name(), format!("cannot read DICOM data set{ts}: {e}"))
        })
    }
}

/// The attributes of one slice that the series reader uses.
#[derive(Clone, Debug)]
pub(crate) struct SliceHeader {
    /// Index of this slice's [`Source`] in the reader's list.
    pub source: usize,
    pub path: PathBuf,
    pub transfer_syntax: String,
    pub series_uid: String,
    pub series_description: String,
    pub modality: String,
    pub rows: u32,
    pub cols: u32,
    pub bits_allocated: u16,
    pub bits_stored: u16,
    pub high_bit: u16,
    pub signed: bool,
    /// Pixel data is encapsulated (compressed): it must go through a decoder.
    pub encapsulated: bool,
    /// ImagePositionPatient, LPS mm.
    pub position: [f64; 3],
    /// ImageOrientationPatient: row direction cosines then column direction cosines (LPS).
    pub orientation: [f64; 6],
    /// PixelSpacing: [row spacing (between rows, along j), column spacing (along i)] in mm.
    pub pixel_spacing: [f64; 2],
    pub slice_thickness: Option<f64>,
    pub spacing_between_slices: Option<f64>,
    pub slope: f64,
    pub intercept: f64,
}

/// Transfer syntaxes whose pixel data this build decodes: dicom-pixeldata's `native` feature
/// (uncompressed, deflate, JPEG baseline/extended/lossless), our RLE decoder and our JPEG 2000
/// adapter (`j2k.rs`).
const DECODABLE_SYNTAXES: &[&str] = &[
    "1.2.840.10008.1.2",
    "1.2.840.10008.1.2.1",
    "1.2.840.10008.1.2.1.98",
    "1.2.840.10008.1.2.1.99",
    "1.2.840.10008.1.2.2",
    "1.2.840.10008.1.2.4.50",
    "1.2.840.10008.1.2.4.51",
    "1.2.840.10008.1.2.4.57",
    "1.2.840.10008.1.2.4.70",
    "1.2.840.10008.1.2.4.90",
    "1.2.840.10008.1.2.4.91",
    "1.2.840.10008.1.2.4.201",
    "1.2.840.10008.1.2.4.202",
    "1.2.840.10008.1.2.4.203",
    "1.2.840.10008.1.2.5",
];

/// Names of the standard transfer syntaxes (DICOM PS3.6 Annex A), for error messages.
const SYNTAX_NAMES: &[(&str, &str)] = &[
    ("1.2.840.10008.1.2", "Implicit VR Little Endian"),
    ("1.2.840.10008.1.2.1", "Explicit VR Little Endian"),
    (
        "1.2.840.10008.1.2.1.98",
        "Encapsulated Uncompressed Explicit VR Little Endian",
    ),
    (
        "1.2.840.10008.1.2.1.99",
        "Deflated Explicit VR Little Endian",
    ),
    ("1.2.840.10008.1.2.2", "Explicit VR Big Endian"),
    ("1.2.840.10008.1.2.4.50", "JPEG Baseline (Process 1)"),
    ("1.2.840.10008.1.2.4.51", "JPEG Extended (Process 2 & 4)"),
    (
        "1.2.840.10008.1.2.4.57",
        "JPEG Lossless, Non-Hierarchical (Process 14)",
    ),
    (
        "1.2.840.10008.1.2.4.70",
        "JPEG Lossless, Non-Hierarchical, First-Order Prediction",
    ),
    ("1.2.840.10008.1.2.4.80", "JPEG-LS Lossless"),
    ("1.2.840.10008.1.2.4.81", "JPEG-LS Near-Lossless"),
    (
        "1.2.840.10008.1.2.4.90",
        "JPEG 2000 Image Compression (Lossless Only)",
    ),
    ("1.2.840.10008.1.2.4.91", "JPEG 2000 Image Compression"),
    (
        "1.2.840.10008.1.2.4.92",
        "JPEG 2000 Part 2 Multi-component (Lossless Only)",
    ),
    ("1.2.840.10008.1.2.4.93", "JPEG 2000 Part 2 Multi-component"),
    ("1.2.840.10008.1.2.4.94", "JPIP Referenced"),
    ("1.2.840.10008.1.2.4.95", "JPIP Referenced Deflate"),
    ("1.2.840.10008.1.2.4.100", "MPEG2 Main Profile / Main Level"),
    ("1.2.840.10008.1.2.4.101", "MPEG2 Main Profile / High Level"),
    ("1.2.840.10008.1.2.4.102", "MPEG-4 AVC/H.264 High Profile"),
    (
        "1.2.840.10008.1.2.4.103",
        "MPEG-4 AVC/H.264 BD-compatible High Profile",
    ),
    ("1.2.840.10008.1.2.4.110", "JPEG XL Lossless"),
    ("1.2.840.10008.1.2.4.111", "JPEG XL JPEG Recompression"),
    ("1.2.840.10008.1.2.4.112", "JPEG XL"),
    (
        "1.2.840.10008.1.2.4.201",
        "High-Throughput JPEG 2000 (Lossless Only)",
    ),
    (
        "1.2.840.10008.1.2.4.202",
        "High-Throughput JPEG 2000 with RPCL Options (Lossless Only)",
    ),
    ("1.2.840.10008.1.2.4.203", "High-Throughput JPEG 2000"),
    ("1.2.840.10008.1.2.5", "RLE Lossless"),
];

/// The standard name of a transfer syntax UID, if it has one.
pub(crate) fn syntax_name(uid: &str) -> Option<&'static str> {
    SYNTAX_NAMES
        .iter()
        .find(|(u, _)| *u == uid)
        .map(|(_, n)| *n)
}

/// "UID (name)" or "UID (not a standard transfer syntax)".
pub(crate) fn describe_syntax(uid: &str) -> String {
    let uid = uid.trim_end_matches(['\0', ' ']);
    match syntax_name(uid) {
        Some(n) => format!("{uid} ({n})"),
        None => format!("{uid} (not a standard transfer syntax)"),
    }
}

/// Largest decoded/encoded size ratio accepted for compressed pixel data before decoding:
/// RLE reaches 64:1 on constant rows, JPEG a few hundred to one on flat images and deflate at
/// most 1032:1; anything beyond this is a header lying about the image size.
const MAX_COMPRESSION_RATIO: u64 = 1024;

fn text(obj: &DefaultDicomObject, tag: dicom_object::Tag) -> String {
    obj.get(tag)
        .and_then(|e| e.to_str().ok())
        .map(|s| s.trim_matches(['\0', ' ']).to_string())
        .unwrap_or_default()
}

/// The attributes of one parsed data set, read with errors that name its file.
struct Attributes<'a> {
    name: &'a Path,
    obj: &'a DefaultDicomObject,
}

impl Attributes<'_> {
    fn missing(&self, what: &str) -> Error {
        Error::invalid(self.name, format!("missing or malformed {what}"))
    }

    /// An unsigned integer attribute.
    fn uint(&self, tag: dicom_object::Tag, what: &str) -> Result<u32> {
        self.obj
            .get(tag)
            .and_then(|e| e.to_int::<u32>().ok())
            .ok_or_else(|| self.missing(what))
    }

    /// Exactly `n` finite numbers.
    fn floats(&self, tag: dicom_object::Tag, what: &str, n: usize) -> Result<Vec<f64>> {
        let v = self
            .obj
            .get(tag)
            .and_then(|e| e.to_multi_float64().ok())
            .ok_or_else(|| self.missing(what))?;
        if v.len() != n || !v.iter().all(|x| x.is_finite()) {
            return Err(Error::invalid(
                self.name,
                format!("{what} must hold {n} finite numbers, found {v:?}"),
            ));
        }
        Ok(v)
    }

    /// An optional finite number (absent, malformed and non-finite values read as `None`).
    fn opt_float(&self, tag: dicom_object::Tag) -> Option<f64> {
        self.obj
            .get(tag)
            .and_then(|e| e.to_float64().ok())
            .filter(|v| v.is_finite())
    }

    /// Fail unless the data set is one slice of a volume: not a localizer, one frame.
    fn check_one_slice(&self) -> Result<()> {
        let image_type = text(self.obj, tags::IMAGE_TYPE);
        if image_type.to_ascii_uppercase().contains("LOCALIZER") {
            return Err(Error::invalid(
                self.name,
                format!("is a 2-D localizer (ImageType {image_type}), not a slice of the CT volume; move it out of the series folder"),
            ));
        }
        let frames = match self.obj.get(tags::NUMBER_OF_FRAMES) {
            None => 1,
            Some(e) => e
                .to_int::<i64>()
                .map_err(|_| self.missing("NumberOfFrames"))?,
        };
        if frames != 1 {
            return Err(Error::unsupported(
                self.name,
                format!("multi-frame image (NumberOfFrames {frames}); only one slice per file is supported"),
            ));
        }
        Ok(())
    }

    /// ImagePositionPatient, ImageOrientationPatient and PixelSpacing (which must be positive).
    fn placement(&self) -> Result<([f64; 3], [f64; 6], [f64; 2])> {
        let position = self.floats(tags::IMAGE_POSITION_PATIENT, "ImagePositionPatient", 3)?;
        let orientation = self.floats(
            tags::IMAGE_ORIENTATION_PATIENT,
            "ImageOrientationPatient",
            6,
        )?;
        let spacing = self.floats(tags::PIXEL_SPACING, "PixelSpacing", 2)?;
        if !(spacing[0] > 0.0 && spacing[1] > 0.0) {
            return Err(Error::invalid(
                self.name,
                format!("PixelSpacing {spacing:?} must be positive"),
            ));
        }
        Ok((
            [position[0], position[1], position[2]],
            std::array::from_fn(|a| orientation[a]),
            [spacing[0], spacing[1]],
        ))
    }
}

impl SliceHeader {
    /// Read the header of `src` (not its pixel data) and check that its pixel data can be held
    /// by a file of its size and decoded by this build.
    pub(crate) fn read(src: Source<'_>) -> Result<Self> {
        let name = src.name();
        let file_len = src.len()?;
        // Also covers the pixel data, which decode_slice parses later without checking again.
        src.check_lengths()?;
        let obj = src.open(true)?;
        let transfer_syntax = obj
            .meta()
            .transfer_syntax()
            .trim_end_matches(['\0', ' '])
            .to_string();
        let at = Attributes { name, obj: &obj };
        at.check_one_slice()?;
        let rows = at.uint(tags::ROWS, "Rows")?;
        let cols = at.uint(tags::COLUMNS, "Columns")?;
        if rows == 0 || cols == 0 {
            return Err(Error::invalid(
                name,
                format!("image is {cols}x{rows} pixels (Columns x Rows)"),
            ));
        }
        let spp = at
            .uint(tags::SAMPLES_PER_PIXEL, "SamplesPerPixel")
            .unwrap_or(1);
        let photometric = text(&obj, tags::PHOTOMETRIC_INTERPRETATION);
        if spp != 1 || !(photometric == "MONOCHROME2" || photometric == "MONOCHROME1") {
            return Err(Error::unsupported(
                name,
                format!("PhotometricInterpretation '{photometric}' with {spp} samples per pixel; a CT slice must be MONOCHROME1/2 with 1 sample"),
            ));
        }
        let bits_allocated = at.uint(tags::BITS_ALLOCATED, "BitsAllocated")? as u16;
        let bits_stored = at
            .uint(tags::BITS_STORED, "BitsStored")
            .unwrap_or(bits_allocated as u32) as u16;
        let high_bit = at
            .uint(tags::HIGH_BIT, "HighBit")
            .unwrap_or((bits_stored as u32).saturating_sub(1)) as u16;
        check_bits(name, bits_allocated, bits_stored, high_bit)?;
        let signed = at
            .uint(tags::PIXEL_REPRESENTATION, "PixelRepresentation")
            .unwrap_or(0)
            == 1;

        // Before any pixel buffer exists: a corrupt or hostile header must not make us
        // allocate gigabytes, nor reach a decoder this build lacks.
        let encapsulated = check_pixel_budget(
            name,
            &transfer_syntax,
            [cols, rows],
            bits_allocated,
            file_len,
        )?;
        check_decodable(name, &transfer_syntax, bits_stored)?;
        let (position, orientation, pixel_spacing) = at.placement()?;
        Ok(SliceHeader {
            source: 0,
            path: name.to_path_buf(),
            transfer_syntax,
            series_uid: text(&obj, tags::SERIES_INSTANCE_UID),
            series_description: text(&obj, tags::SERIES_DESCRIPTION),
            modality: text(&obj, tags::MODALITY),
            rows,
            cols,
            bits_allocated,
            bits_stored,
            high_bit,
            signed,
            encapsulated,
            position,
            orientation,
            pixel_spacing,
            slice_thickness: at.opt_float(tags::SLICE_THICKNESS).filter(|v| *v > 0.0),
            spacing_between_slices: at
                .opt_float(tags::SPACING_BETWEEN_SLICES)
                .filter(|v| *v > 0.0),
            slope: at.opt_float(tags::RESCALE_SLOPE).unwrap_or(1.0),
            intercept: at.opt_float(tags::RESCALE_INTERCEPT).unwrap_or(0.0),
        })
    }
}

/// Fail when Rows x Columns x BitsAllocated exceed what a `file_len`-byte file in `ts` can hold
/// (saturating: a malformed file may store Rows/Columns as 32-bit). Returns whether the pixel
/// data is encapsulated (compressed) and must go through a decoder.
fn check_pixel_budget(
    name: &Path,
    ts: &str,
    [cols, rows]: [u32; 2],
    bits_allocated: u16,
    file_len: u64,
) -> Result<bool> {
    let needed = (rows as u64)
        .saturating_mul(cols as u64)
        .saturating_mul(bits_allocated as u64 / 8);
    let deflated = ts == "1.2.840.10008.1.2.1.99";
    let encapsulated = !deflated
        && !matches!(
            ts,
            "1.2.840.10008.1.2" | "1.2.840.10008.1.2.1" | "1.2.840.10008.1.2.2"
        );
    // A deflated data set holds native pixels, but compressed with the rest of the file.
    let limit = if encapsulated || deflated {
        file_len.saturating_mul(MAX_COMPRESSION_RATIO)
    } else {
        file_len
    };
    if needed > limit {
        return Err(Error::invalid(
            name,
            format!(
                "header claims {cols}x{rows} pixels of {bits_allocated} bits ({needed} bytes), more than a {file_len}-byte file can hold"
            ),
        ));
    }
    Ok(encapsulated)
}

/// Fail, naming the syntax, when this build has no decoder for pixel data in `ts`.
fn check_decodable(name: &Path, ts: &str, bits_stored: u16) -> Result<()> {
    if !DECODABLE_SYNTAXES.contains(&ts) {
        return Err(Error::unsupported(
            name,
            format!(
                "pixel data in transfer syntax {} cannot be decoded by this build (supported: uncompressed, deflate, RLE, JPEG baseline/extended 8-bit/lossless, JPEG 2000, HTJ2K)",
                describe_syntax(ts)
            ),
        ));
    }
    if ts == "1.2.840.10008.1.2.4.51" && bits_stored > 8 {
        // Process 4: jpeg-decoder 0.3 decodes 8-bit DCT (process 2) only.
        return Err(Error::unsupported(
            name,
            format!(
                "pixel data in transfer syntax {} with {bits_stored} bits stored (12-bit DCT) cannot be decoded by this build; 8-bit JPEG Extended can",
                describe_syntax(ts)
            ),
        ));
    }
    Ok(())
}

/// Fail unless BitsAllocated is 8 or 16 and BitsStored / HighBit fit inside it.
fn check_bits(name: &Path, bits_allocated: u16, bits_stored: u16, high_bit: u16) -> Result<()> {
    if bits_allocated != 8 && bits_allocated != 16 {
        return Err(Error::unsupported(
            name,
            format!("BitsAllocated {bits_allocated}; only 8 and 16 are supported"),
        ));
    }
    if bits_stored == 0
        || bits_stored > bits_allocated
        || high_bit >= bits_allocated
        || high_bit + 1 < bits_stored
    {
        return Err(Error::invalid(
            name,
            format!("inconsistent BitsAllocated {bits_allocated}, BitsStored {bits_stored}, HighBit {high_bit}"),
        ));
    }
    Ok(())
}
