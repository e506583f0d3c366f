//! A cheap structural pre-scan of a DICOM file before dicom-object parses it.
//!
//! dicom-parser 0.10 trusts every declared value length: given a corrupt length it reserves and
//! zero-fills up to 4 GB before discovering that the file is shorter (seconds of work and a
//! memory spike per file). This scan walks the element headers exactly as the parser will
//! (file meta group by its group length, then the data set in its transfer syntax, into
//! sequences, items and encapsulated pixel fragments), seeking over values, and rejects any
//! length that runs past the end of the file, and sequences nested implausibly deep. Anything
//! else that is malformed (a truncated header, an unknown transfer syntax, an undecodable
//! deflate stream) is left for the parser to report in its own words.

use std::io::{BufReader, Cursor, Read};
use std::path::Path;

use flate2::{Decompress, FlushDecompress, Status};

use crate::{Error, Result};

/// Deepest nesting of sequences accepted; real CT headers use fewer than 10.
const MAX_DEPTH: usize = 32;
/// Value length meaning "undefined" (delimited by an item or sequence delimitation item).
const UNDEFINED: u32 = u32::MAX;
const ITEM: (u16, u16) = (0xFFFE, 0xE000);
const ITEM_END: (u16, u16) = (0xFFFE, 0xE00D);
const SEQ_END: (u16, u16) = (0xFFFE, 0xE0DD);
const PIXEL_DATA: (u16, u16) = (0x7FE0, 0x0010);

/// VRs whose explicit header carries a 16-bit length (PS3.5 7.1.2); every other code,
/// including unknown ones, has 2 reserved bytes and a 32-bit length, as in dicom-encoding.
const SHORT_VRS: [&[u8; 2]; 21] = [
    b"AE", b"AS", b"AT", b"CS", b"DA", b"DS", b"DT", b"FL", b"FD", b"IS", b"LO", b"LT", b"PN",
    b"SH", b"SL", b"SS", b"ST", b"TM", b"UI", b"UL", b"US",
];

#[derive(Clone, Copy)]
struct Encoding {
    explicit: bool,
    big_endian: bool,
}

const EXPLICIT_LE: Encoding = Encoding {
    explicit: true,
    big_endian: false,
};
const IMPLICIT_LE: Encoding = Encoding {
    explicit: false,
    big_endian: false,
};

/// Why a walk stopped early.
enum Stop {
    /// Out of bytes or not a structure this scan follows: left for the parser to report.
    Leave,
    /// A definite error.
    Bad(Error),
}

type Walk<T> = std::result::Result<T, Stop>;

/// One element header: tag, explicit VR (if any) and declared length.
struct Header {
    tag: (u16, u16),
    vr: Option<[u8; 2]>,
    len: u32,
}

/// A byte source the walk can skip forward in: by seeking when it can, else by reading.
pub(crate) trait Skip: Read {
    fn skip(&mut self, n: u64) -> std::io::Result<()>;
}

impl Skip for BufReader<std::fs::File> {
    fn skip(&mut self, n: u64) -> std::io::Result<()> {
        self.seek_relative(n as i64)
    }
}

impl Skip for Cursor<&[u8]> {
    fn skip(&mut self, n: u64) -> std::io::Result<()> {
        self.set_position(self.position().saturating_add(n));
        Ok(())
    }
}

/// A stream that can only be read (an inflating decoder): skipping reads and drops.
struct Stream<R>(R);

/// A raw-deflate reader that hands out every byte inflated before a corrupt spot, then ends,
/// so that the scan sees at least as much of a damaged stream as any parser can.
struct Inflate<'a> {
    d: Decompress,
    input: &'a [u8],
    done: bool,
}

impl<'a> Inflate<'a> {
    fn new(input: &'a [u8]) -> Self {
        Inflate {
            d: Decompress::new(false),
            input,
            done: false,
        }
    }
}

impl Read for Inflate<'_> {
    fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
        while !self.done && !buf.is_empty() {
            let (in0, out0) = (self.d.total_in(), self.d.total_out());
            let status = self.d.decompress(self.input, buf, FlushDecompress::None);
            let used = (self.d.total_in() - in0) as usize;
            let made = (self.d.total_out() - out0) as usize;
            self.input = &self.input[used..];
            // total_out counts what was written before an error too.
            self.done = !matches!(status, Ok(Status::Ok | Status::BufError)) || used + made == 0;
            if made > 0 {
                return Ok(made);
            }
        }
        Ok(0)
    }
}

impl<R: Read> Read for Stream<R> {
    fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
        self.0.read(buf)
    }
}

impl<R: Read> Skip for Stream<R> {
    fn skip(&mut self, n: u64) -> std::io::Result<()> {
        let got = std::io::copy(&mut (&mut self.0).take(n), &mut std::io::sink())?;
        if got < n {
            return Err(std::io::ErrorKind::UnexpectedEof.into());
        }
        Ok(())
    }
}

struct Walker<'p, R> {
    r: R,
    /// Four bytes read ahead and given back (a peeked tag), consumed before `r`.
    pending: Option<[u8; 4]>,
    pos: u64,
    len: u64,
    name: &'p Path,
    /// "file" or "inflated data set", for messages.
    what: &'static str,
}

/// Check the DICOM file `r` of `len` bytes (named `name` in errors), from its preamble on:
/// every declared value length must fit in the bytes that remain.
pub(crate) fn check_lengths<R: Skip>(r: R, len: u64, name: &Path) -> Result<()> {
    let mut w = Walker {
        r,
        pending: None,
        pos: 0,
        len,
        name,
        what: "file",
    };
    match w.file() {
        Ok(()) | Err(Stop::Leave) => Ok(()),
        Err(Stop::Bad(e)) => Err(e),
    }
}

impl<R: Skip> Walker<'_, R> {
    fn bytes<const N: usize>(&mut self) -> Walk<[u8; N]> {
        let mut b = [0u8; N];
        let mut from = 0;
        if let Some(p) = self.pending.take() {
            // Only a header read (4 bytes first) follows a peek.
            if N < 4 {
                return Err(Stop::Leave);
            }
            b[..4].copy_from_slice(&p);
            from = 4;
        }
        self.r.read_exact(&mut b[from..]).map_err(|_| Stop::Leave)?;
        self.pos += N as u64;
        Ok(b)
    }

    /// Give back four bytes just read by [`Walker::bytes`].
    fn unread(&mut self, b: [u8; 4]) {
        self.pending = Some(b);
        self.pos -= 4;
    }

    fn skip(&mut self, mut n: u64) -> Walk<()> {
        self.pos += n;
        if n > 0 && self.pending.take().is_some() {
            n -= 4.min(n);
        }
        self.r.skip(n).map_err(|_| Stop::Leave)
    }

    fn u16(b: [u8; 2], enc: Encoding) -> u16 {
        if enc.big_endian {
            u16::from_be_bytes(b)
        } else {
            u16::from_le_bytes(b)
        }
    }

    fn u32(b: [u8; 4], enc: Encoding) -> u32 {
        if enc.big_endian {
            u32::from_be_bytes(b)
        } else {
            u32::from_le_bytes(b)
        }
    }

    /// Read an element header as dicom-encoding decodes it.
    fn header(&mut self, enc: Encoding) -> Walk<Header> {
        let t = self.bytes::<4>()?;
        let tag = (Self::u16([t[0], t[1]], enc), Self::u16([t[2], t[3]], enc));
        if tag.0 == 0xFFFE || !enc.explicit {
            let len = Self::u32(self.bytes::<4>()?, enc);
            return Ok(Header { tag, vr: None, len });
        }
        let vr = self.bytes::<2>()?;
        let len = if SHORT_VRS.contains(&&vr) {
            Self::u16(self.bytes::<2>()?, enc) as u32
        } else {
            self.bytes::<2>()?;
            Self::u32(self.bytes::<4>()?, enc)
        };
        Ok(Header {
            tag,
            vr: Some(vr),
            len,
        })
    }

    /// Fail unless a value of `h.len` bytes fits in what remains.
    fn fits(&self, h: &Header) -> Walk<()> {
        let remaining = self.len.saturating_sub(self.pos);
        if h.len as u64 > remaining {
            let (g, e) = h.tag;
            return Err(Stop::Bad(Error::invalid(
                self.name,
                format!(
                    "corrupt DICOM element ({g:04X},{e:04X}) at byte {}: it declares {} bytes, but only {remaining} remain in the {}",
                    self.pos, h.len, self.what
                ),
            )));
        }
        Ok(())
    }

    /// Preamble, file meta group, then the data set in the transfer syntax the meta group names.
    fn file(&mut self) -> Walk<()> {
        self.bytes::<128>()?;
        if &self.bytes::<4>()? != b"DICM" {
            return Err(Stop::Leave);
        }
        // dicom-object reads (0002,0000) UL first, then explicit-LE elements until it has
        // consumed that many bytes.
        let h = self.header(EXPLICIT_LE)?;
        if h.tag != (0x0002, 0x0000) || h.len != 4 {
            return Err(Stop::Leave);
        }
        let group_len = u32::from_le_bytes(self.bytes::<4>()?) as u64;
        let meta_end = self.pos.saturating_add(group_len);
        let mut syntax = Vec::new();
        while self.pos < meta_end {
            let h = self.header(EXPLICIT_LE)?;
            if h.len == UNDEFINED {
                return Err(Stop::Leave);
            }
            self.fits(&h)?;
            if h.tag == (0x0002, 0x0010) && h.len <= 256 {
                syntax.resize(h.len as usize, 0);
                self.r.read_exact(&mut syntax).map_err(|_| Stop::Leave)?; // nothing pending here
                self.pos += h.len as u64;
            } else {
                self.skip(h.len as u64)?;
            }
        }
        let syntax = String::from_utf8_lossy(&syntax);
        let syntax = syntax.trim_end_matches(['\0', ' ']);
        match syntax {
            "1.2.840.10008.1.2" => self.dataset(IMPLICIT_LE, u64::MAX, false, 0),
            "1.2.840.10008.1.2.2" => self.dataset(
                Encoding {
                    explicit: true,
                    big_endian: true,
                },
                u64::MAX,
                false,
                0,
            ),
            "1.2.840.10008.1.2.1.99" | "1.2.840.10008.1.2.4.95" => self.deflated(),
            // Unknown syntaxes: the parser refuses them before reading the data set.
            s if super::header::syntax_name(s).is_some() => {
                self.dataset(EXPLICIT_LE, u64::MAX, false, 0)
            }
            _ => Err(Stop::Leave),
        }
    }

    /// Walk the rest of the file as it inflates (as the parser will read it), in a first pass
    /// that only measures the inflated size, then a second that checks lengths against it.
    /// Streaming: a deflate bomb costs time, not memory.
    fn deflated(&mut self) -> Walk<()> {
        let rest = self.len.saturating_sub(self.pos);
        let mut compressed = Vec::new();
        (&mut self.r)
            .take(rest)
            .read_to_end(&mut compressed)
            .map_err(|_| Stop::Leave)?;
        // On a corrupt stream, count every byte inflated before the error: a parser reading in
        // small pieces sees them all (flate2's reader drops a whole read's output on error).
        let mut counter = Inflate::new(&compressed);
        let mut len = 0u64;
        let mut buf = [0u8; 8192];
        while let Ok(n @ 1..) = counter.read(&mut buf) {
            len += n as u64;
        }
        let mut inner = Walker {
            r: Stream(Inflate::new(&compressed)),
            pending: None,
            pos: 0,
            len,
            name: self.name,
            what: "inflated data set",
        };
        inner.dataset(EXPLICIT_LE, u64::MAX, false, 0)
    }

    /// Elements up to byte `end`, or (when `delimited`) up to an item delimitation item.
    fn dataset(&mut self, enc: Encoding, end: u64, delimited: bool, depth: usize) -> Walk<()> {
        while self.pos < end.min(self.len) {
            let h = self.header(enc)?;
            if h.tag == ITEM_END || h.tag == SEQ_END {
                // dicom-parser reads a stray delimiter's declared length as a value (zero-filling
                // it first), while this walk would not skip it: both must see length 0.
                if h.len != 0 {
                    let (g, e) = h.tag;
                    return Err(Stop::Bad(Error::invalid(
                        self.name,
                        format!(
                            "corrupt DICOM element ({g:04X},{e:04X}) at byte {}: a delimitation item declares {} bytes instead of 0",
                            self.pos, h.len
                        ),
                    )));
                }
                if delimited {
                    return Ok(());
                }
                continue;
            }
            if h.len == UNDEFINED {
                if h.tag == PIXEL_DATA {
                    self.fragments(enc)?;
                } else {
                    // An undefined-length UN holds implicit VR little endian (PS3.5 6.2.2).
                    let inner = if h.vr == Some(*b"UN") {
                        IMPLICIT_LE
                    } else {
                        enc
                    };
                    self.items(inner, u64::MAX, depth + 1)?;
                }
                continue;
            }
            self.fits(&h)?;
            let value_end = self.pos + h.len as u64;
            let sequence = match h.vr {
                Some(vr) => &vr == b"SQ",
                // Implicit VR: the parser knows sequences from its dictionary; a value that
                // starts with an item tag is one.
                None if h.len >= 8 && h.tag.0 != 0xFFFE => {
                    let t = self.bytes::<4>()?;
                    self.unread(t);
                    (Self::u16([t[0], t[1]], enc), Self::u16([t[2], t[3]], enc)) == ITEM
                }
                None => false,
            };
            if sequence {
                self.items(enc, value_end, depth + 1)?;
                if self.pos > value_end {
                    return Err(Stop::Leave);
                }
                self.skip(value_end - self.pos)?;
            } else {
                self.skip(h.len as u64)?;
            }
        }
        Ok(())
    }

    /// The items of a sequence, up to byte `end` or a sequence delimitation item.
    fn items(&mut self, enc: Encoding, end: u64, depth: usize) -> Walk<()> {
        if depth > MAX_DEPTH {
            return Err(Stop::Bad(Error::invalid(
                self.name,
                format!("corrupt DICOM data set: sequences nested more than {MAX_DEPTH} deep at byte {}", self.pos),
            )));
        }
        while self.pos < end.min(self.len) {
            let h = self.header(Encoding {
                explicit: false,
                ..enc
            })?;
            match h.tag {
                SEQ_END => return Ok(()),
                ITEM if h.len == UNDEFINED => self.dataset(enc, end, true, depth)?,
                ITEM => {
                    self.fits(&h)?;
                    let item_end = self.pos + h.len as u64;
                    self.dataset(enc, item_end, false, depth)?;
                    if self.pos > item_end {
                        return Err(Stop::Leave);
                    }
                    self.skip(item_end - self.pos)?;
                }
                _ => return Err(Stop::Leave),
            }
        }
        Ok(())
    }

    /// Encapsulated pixel data: the offset table and fragments, each an item of known length,
    /// up to a sequence delimitation item.
    fn fragments(&mut self, enc: Encoding) -> Walk<()> {
        loop {
            let h = self.header(Encoding {
                explicit: false,
                ..enc
            })?;
            match h.tag {
                SEQ_END => return Ok(()),
                ITEM if h.len != UNDEFINED => {
                    self.fits(&h)?;
                    self.skip(h.len as u64)?;
                }
                _ => return Err(Stop::Leave),
            }
        }
    }
}
