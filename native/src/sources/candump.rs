//! candump logs as CanFrames, in every layout candump writes: `-l`/`-L` lines
//! (`(1600000000.123456) can0 04FF0001#0000F401F401`), the default columns
//! (`can0  0C8   [8]  F0 00 ...`) with or without `-ta`/`-tz`/`-td`/`-tA` stamps, ERROR lines.
//!
//! Mirrors analyzer/sources/candump.py (the line grammar, `ByteLines`, `Clock`,
//! `holds_deltas`, `local_time`, `is_complete`, `quote`, `reason`), can_files.py
//! `CandumpReader` and `_TextLogReader` (the fast path, the give-up after GIVE_UP bad lines,
//! `_FileReaderBase._error`) and the channel naming of analyzer/sources/capture.py
//! (`can_bus_name`, `CanLogReader`). Everything the Python does is copied, including its
//! quirks:
//!
//! - a line is first tried by the Python's fast path, whose `int(ident, 16)` accepts a `0x`
//!   prefix, a sign and underscores (`0x123456#..` is an extended frame there), then by the
//!   general parser, whose error texts (`float()`/`int()`/`unhexlify` messages included,
//!   cut at 100 characters) end up in `errors`;
//! - lines end at LF; a file whose first 64 KiB hold CRs but no LF is split at CRs;
//! - a cut or damaged .gz yields what Python's gzip module yields before raising: every whole
//!   line before the damage (LF files), whole 1 MiB blocks (CR files), nothing at all when the
//!   damage is inside the line that crosses the first 64 KiB, and the whole head when the
//!   damage is inside the first 64 KiB (but the line the damage cuts: it is part of it);
//!   then one error in words (compressed.rs), or `line N: read error: Type: message`;
//! - -tA dates go through the C library's `mktime`, as Python's `time.mktime` does (on Unix;
//!   elsewhere `DecodeRun::open` leaves such logs to the Python engine).
//!
//! The gzip container is read here (header, CRC and size checks, members, zero padding, in
//! Python's order and words); the deflate data through flate2. A corrupt deflate stream
//! (zlib.error) is damage like a cut file: `line N: the compressed data is damaged (Error -3
//! ...); the rest is lost`.

use std::borrow::Cow;
use std::fs::File;
use std::io::{self, Read, Seek, SeekFrom};
use std::path::{Path, PathBuf};

use flate2::{Crc, Decompress, FlushDecompress, Status};

use super::compressed::compression_damage;
use crate::decoders::model::CanFrame;

/// errors listed per file; `bad_lines` counts them all
pub const MAX_ERRORS: usize = 100;
pub const READ_BUFFER: usize = 1 << 20;
/// bytes looked at for a byte order mark and the line ends
pub const HEAD_SIZE: usize = 1 << 16;
pub const BOM: &[u8] = b"\xef\xbb\xbf";

/// SocketCAN: error frame; the identifier carries the error class
pub const CAN_ERR_FLAG: u64 = 0x2000_0000;
/// SocketCAN: remote frame; never printed by candump (it writes "#R")
pub const CAN_RTR_FLAG: u64 = 0x4000_0000;
pub const CAN_EFF_MASK: u64 = 0x1FFF_FFFF;

const GZIP_EOF: &str =
    "EOFError: Compressed file ended before the end-of-stream marker was reached";

// -- Python's text conversions ------------------------------------------------------------

/// Python's whitespace for bytes (`bytes.split()`, `int()`, `float()`).
fn is_space(b: u8) -> bool {
    matches!(b, b' ' | b'\t' | b'\n' | b'\r' | 0x0b | 0x0c)
}

/// `repr(bytes)`
pub fn bytes_repr(s: &[u8]) -> String {
    let quote = if s.contains(&b'\'') && !s.contains(&b'"') {
        '"'
    } else {
        '\''
    };
    let mut out = String::with_capacity(s.len() + 3);
    out.push('b');
    out.push(quote);
    for &c in s {
        match c {
            b'\\' => out.push_str("\\\\"),
            b'\t' => out.push_str("\\t"),
            b'\n' => out.push_str("\\n"),
            b'\r' => out.push_str("\\r"),
            _ if c as char == quote => {
                out.push('\\');
                out.push(quote);
            }
            0x20..=0x7e => out.push(c as char),
            _ => out.push_str(&format!("\\x{c:02x}")),
        }
    }
    out.push(quote);
    out
}

/// What a Python string literal does with a character past ASCII.
#[derive(Clone, Copy, PartialEq)]
enum NonAscii {
    /// As it is: `repr(str)`.
    Keep,
    /// As `\xNN`: `ascii(str)` (the strings here are latin-1, so two digits do).
    Escape,
}

/// `repr(str)` or `ascii(str)` of a string that holds ASCII and either U+FFFD only
/// (`bytes.decode("ascii", "replace")`, kept) or latin-1 (escaped): printable ASCII as it
/// is, control characters escaped.
fn str_literal(s: &str, non_ascii: NonAscii) -> String {
    let quote = if s.contains('\'') && !s.contains('"') {
        '"'
    } else {
        '\''
    };
    let mut out = String::with_capacity(s.len() + 2);
    out.push(quote);
    for c in s.chars() {
        match c {
            '\\' => out.push_str("\\\\"),
            '\t' => out.push_str("\\t"),
            '\n' => out.push_str("\\n"),
            '\r' => out.push_str("\\r"),
            _ if c == quote => {
                out.push('\\');
                out.push(quote);
            }
            ' '..='~' => out.push(c),
            _ if c.is_ascii() || non_ascii == NonAscii::Escape => {
                out.push_str(&format!("\\x{:02x}", c as u32))
            }
            _ => out.push(c),
        }
    }
    out.push(quote);
    out
}

/// `bytes.decode("ascii", "replace")`
fn ascii_replace(s: &[u8]) -> String {
    s.iter()
        .map(|&b| if b < 0x80 { b as char } else { '\u{FFFD}' })
        .collect()
}

/// Digits with single underscores between them (Python's rule for int and float literals).
fn digits_ok(s: &[u8], radix: u32) -> bool {
    !s.is_empty()
        && s[0] != b'_'
        && s[s.len() - 1] != b'_'
        && !s.windows(2).any(|w| w == b"__")
        && s.iter().all(|&c| c == b'_' || (c as char).is_digit(radix))
}

/// `float(b"...")`: Python's grammar (sign, digits with underscores, a point, an exponent,
/// inf/infinity/nan in any case, surrounding whitespace), else its ValueError text.
pub fn py_float(s: &[u8]) -> Result<f64, String> {
    let err = || format!("could not convert string to float: {}", bytes_repr(s));
    let mut lo = 0;
    let mut hi = s.len();
    while lo < hi && is_space(s[lo]) {
        lo += 1;
    }
    while hi > lo && is_space(s[hi - 1]) {
        hi -= 1;
    }
    let t = &s[lo..hi];
    let (neg, body) = match t.first() {
        Some(b'-') => (true, &t[1..]),
        Some(b'+') => (false, &t[1..]),
        _ => (false, t),
    };
    let lower = body.to_ascii_lowercase();
    let special = match &lower[..] {
        b"inf" | b"infinity" => Some(f64::INFINITY),
        b"nan" => Some(f64::NAN),
        _ => None,
    };
    if let Some(v) = special {
        return Ok(if neg { -v } else { v });
    }
    // mantissa [e exponent]
    let (mant, exp) = match body.iter().position(|&c| c == b'e' || c == b'E') {
        Some(i) => (&body[..i], Some(&body[i + 1..])),
        None => (body, None),
    };
    let (int_part, frac) = match mant.iter().position(|&c| c == b'.') {
        Some(i) => (&mant[..i], Some(&mant[i + 1..])),
        None => (mant, None),
    };
    let int_ok = int_part.is_empty() || digits_ok(int_part, 10);
    let frac_ok = match frac {
        None => true,
        Some(f) => f.is_empty() || digits_ok(f, 10),
    };
    let has_digits = !int_part.is_empty() || frac.is_some_and(|f| !f.is_empty());
    let exp_ok = match exp {
        None => true,
        Some(e) => {
            let e = match e.first() {
                Some(b'-') | Some(b'+') => &e[1..],
                _ => e,
            };
            digits_ok(e, 10)
        }
    };
    if !(int_ok && frac_ok && has_digits && exp_ok) {
        return Err(err());
    }
    let clean: String = t
        .iter()
        .filter(|&&c| c != b'_')
        .map(|&c| c as char)
        .collect();
    clean.parse::<f64>().map_err(|_| err())
}

/// `int(b"...", 16)`: sign, optional 0x prefix (an underscore may follow it), hex digits with
/// single underscores, surrounding whitespace; else its ValueError text (the first 200 bytes,
/// the repr cut at 200 characters, as CPython's `%.200R`). None: a value beyond i64 (only
/// compared against small bounds by the callers, so it is reported as too large).
pub fn py_int16(s: &[u8]) -> Result<Option<i64>, String> {
    let err = || {
        let repr = bytes_repr(&s[..s.len().min(200)]);
        let repr: String = repr.chars().take(200).collect();
        format!("invalid literal for int() with base 16: {repr}")
    };
    let mut lo = 0;
    let mut hi = s.len();
    while lo < hi && is_space(s[lo]) {
        lo += 1;
    }
    while hi > lo && is_space(s[hi - 1]) {
        hi -= 1;
    }
    let t = &s[lo..hi];
    let (neg, mut body) = match t.first() {
        Some(b'-') => (true, &t[1..]),
        Some(b'+') => (false, &t[1..]),
        _ => (false, t),
    };
    if body.len() >= 2 && body[0] == b'0' && (body[1] == b'x' || body[1] == b'X') {
        body = &body[2..];
        if body.first() == Some(&b'_') {
            body = &body[1..];
        }
    }
    if !digits_ok(body, 16) {
        return Err(err());
    }
    let mut v: i64 = 0;
    for &c in body {
        if c == b'_' {
            continue;
        }
        let d = (c as char).to_digit(16).unwrap_or(0) as i64;
        v = match v.checked_mul(16).and_then(|v| v.checked_add(d)) {
            Some(v) => v,
            None => return Ok(None),
        };
    }
    Ok(Some(if neg { -v } else { v }))
}

fn hex_val(c: u8) -> Option<u8> {
    match c {
        b'0'..=b'9' => Some(c - b'0'),
        b'a'..=b'f' => Some(c - b'a' + 10),
        b'A'..=b'F' => Some(c - b'A' + 10),
        _ => None,
    }
}

/// `binascii.unhexlify` into `out` (cleared), else its error text.
pub fn unhexlify(s: &[u8], out: &mut Vec<u8>) -> Result<(), &'static str> {
    out.clear();
    if !s.len().is_multiple_of(2) {
        return Err("Odd-length string");
    }
    for pair in s.chunks_exact(2) {
        match (hex_val(pair[0]), hex_val(pair[1])) {
            (Some(h), Some(l)) => out.push(h << 4 | l),
            _ => return Err("Non-hexadecimal digit found"),
        }
    }
    Ok(())
}

/// `bytes.decode("ascii")`, else the UnicodeDecodeError text.
fn decode_ascii(s: &[u8]) -> Result<&str, String> {
    match s.iter().position(|&b| b >= 0x80) {
        None => Ok(std::str::from_utf8(s).unwrap_or_default()),
        Some(i) => Err(format!(
            "'ascii' codec can't decode byte 0x{:02x} in position {i}: ordinal not in range(128)",
            s[i]
        )),
    }
}

/// `line.split()`: ASCII-whitespace separated fields, at most `N` (None: more than N).
fn split_fields<const N: usize>(line: &[u8]) -> Option<([&[u8]; N], usize)> {
    let mut parts: [&[u8]; N] = [&[]; N];
    let mut n = 0;
    let mut i = 0;
    let len = line.len();
    while i < len {
        while i < len && is_space(line[i]) {
            i += 1;
        }
        if i == len {
            break;
        }
        let s = i;
        while i < len && !is_space(line[i]) {
            i += 1;
        }
        if n == N {
            return None;
        }
        parts[n] = &line[s..i];
        n += 1;
    }
    Some((parts, n))
}

fn is_direction(p: &[u8]) -> bool {
    matches!(p, b"R" | b"T" | b"r" | b"t")
}

fn all_hex(s: &[u8]) -> bool {
    s.iter().all(|&c| c.is_ascii_hexdigit())
}

/// candump.py `quote(line, limit)`: the line for an error text, stripped, cut at `limit`
/// characters, repr'd.
fn quote(line: &[u8], limit: usize) -> String {
    let text: String = line.iter().map(|&b| b as char).collect(); // latin-1
                                                                  // candump.py `STRIPPED`: what str.strip takes of ASCII
    let text = text.trim_matches(|c: char| matches!(c, '\t'..='\r' | '\x1c'..='\x1f' | ' '));
    str_literal(&cut_chars(text, limit), NonAscii::Escape)
}

/// `text` cut at `limit` characters, the last three of them "..." (as the Python cuts).
fn cut_chars(text: &str, limit: usize) -> String {
    if text.chars().count() <= limit {
        return text.to_string();
    }
    text.chars().take(limit - 3).collect::<String>() + "..."
}

/// candump.py `MAX_QUOTED`, `MAX_REASON`: characters of a bad line, and of why it is bad.
const MAX_QUOTED: usize = 80;
const MAX_REASON: usize = 100;

/// `can_bus_name`: python-can channels are often numbers: name them the SocketCAN way.
pub fn can_bus_name(channel: Option<&str>) -> Cow<'_, str> {
    match channel {
        None | Some("") => Cow::Borrowed("can0"),
        Some(c) if c.bytes().all(|b| b.is_ascii_digit()) => Cow::Owned(format!("can{c}")),
        Some(c) => Cow::Borrowed(c),
    }
}

/// The channel -> bus naming of `CanLogReader`: the fixed `--bus`, else `can_bus_name` of the
/// frame's channel (remembered per channel).
pub struct BusNamer {
    fixed: Option<std::sync::Arc<str>>,
    last: Option<(Option<String>, std::sync::Arc<str>)>,
    names: Vec<(Option<String>, std::sync::Arc<str>)>,
}

impl BusNamer {
    pub fn new(fixed: Option<&str>) -> Self {
        BusNamer {
            fixed: fixed.map(Into::into),
            last: None,
            names: Vec::new(),
        }
    }

    /// The bus of a frame from this channel (the same `Arc` for the same name).
    pub fn bus(&mut self, channel: Option<&str>) -> std::sync::Arc<str> {
        if let Some(f) = &self.fixed {
            return f.clone();
        }
        if let Some((c, name)) = &self.last {
            if c.as_deref() == channel {
                return name.clone();
            }
        }
        let name = match self.names.iter().find(|(c, _)| c.as_deref() == channel) {
            Some((_, name)) => name.clone(),
            None => {
                let bus = can_bus_name(channel);
                // one Arc per distinct bus name, as the Python decoders are keyed by name
                let arc = match self.names.iter().find(|(_, n)| **n == *bus) {
                    Some((_, n)) => n.clone(),
                    None => std::sync::Arc::from(&*bus),
                };
                self.names.push((channel.map(str::to_string), arc.clone()));
                arc
            }
        };
        self.last = Some((channel.map(str::to_string), name.clone()));
        name
    }
}

// -- the gzip container, as Python's gzip module reads it ---------------------------------

/// A read error as Python's readers raise it: `text` is `"TypeName: message"`.
#[derive(Clone, Debug)]
pub struct ReadError {
    pub text: String,
}

impl ReadError {
    fn os(text: impl Into<String>) -> Self {
        ReadError { text: text.into() }
    }
}

impl From<io::Error> for ReadError {
    fn from(e: io::Error) -> Self {
        ReadError::os(format!("OSError: {e}"))
    }
}

/// A file read through a counter (the position for progress bars).
struct Counted<R> {
    inner: R,
    count: u64,
}

impl<R: Read> Read for Counted<R> {
    fn read(&mut self, buf: &mut [u8]) -> io::Result<usize> {
        let n = self.inner.read(buf)?;
        self.count += n as u64;
        Ok(n)
    }
}

#[derive(PartialEq, Eq)]
enum GzState {
    Header,
    Body,
    Done,
}

/// Python's `gzip.GzipFile` reading: members one after another, zero padding between them,
/// its errors in its words.
struct GzReader<R> {
    file: Counted<R>,
    inbuf: Box<[u8]>,
    in_pos: usize,
    in_len: usize,
    state: GzState,
    dec: Decompress,
    crc: Crc,
    /// an error found right after the bytes last handed out (reported on the next read)
    pending: Option<ReadError>,
}

impl<R: Read> GzReader<R> {
    fn new(inner: R) -> Self {
        GzReader {
            file: Counted { inner, count: 0 },
            inbuf: vec![0u8; 1 << 16].into_boxed_slice(),
            in_pos: 0,
            in_len: 0,
            state: GzState::Header,
            dec: Decompress::new(false),
            crc: Crc::new(),
            pending: None,
        }
    }

    /// More compressed input; false at the end of the file.
    fn fill(&mut self) -> Result<bool, ReadError> {
        if self.in_pos < self.in_len {
            return Ok(true);
        }
        self.in_pos = 0;
        self.in_len = loop {
            match self.file.read(&mut self.inbuf) {
                Ok(n) => break n,
                Err(e) if e.kind() == io::ErrorKind::Interrupted => continue,
                Err(e) => return Err(e.into()),
            }
        };
        Ok(self.in_len > 0)
    }

    /// `fp.read(n)` of the padded file: up to n bytes (fewer at its end).
    fn raw_read(&mut self, n: usize) -> Result<Vec<u8>, ReadError> {
        let mut out = Vec::with_capacity(n);
        while out.len() < n && self.fill()? {
            let take = (n - out.len()).min(self.in_len - self.in_pos);
            out.extend_from_slice(&self.inbuf[self.in_pos..self.in_pos + take]);
            self.in_pos += take;
        }
        Ok(out)
    }

    /// `_read_exact`
    fn read_exact(&mut self, n: usize) -> Result<Vec<u8>, ReadError> {
        let out = self.raw_read(n)?;
        if out.len() < n {
            return Err(ReadError::os(GZIP_EOF));
        }
        Ok(out)
    }

    /// `_read_gzip_header`: false at the end of the file.
    fn header(&mut self) -> Result<bool, ReadError> {
        let magic = self.raw_read(2)?;
        if magic.is_empty() {
            return Ok(false);
        }
        if magic != b"\x1f\x8b" {
            return Err(ReadError::os(format!(
                "BadGzipFile: Not a gzipped file ({})",
                bytes_repr(&magic)
            )));
        }
        let head = self.read_exact(8)?;
        let (method, flag) = (head[0], head[1]);
        if method != 8 {
            return Err(ReadError::os("BadGzipFile: Unknown compression method"));
        }
        if flag & 4 != 0 {
            let x = self.read_exact(2)?;
            self.read_exact(u16::from_le_bytes([x[0], x[1]]) as usize)?;
        }
        for bit in [8u8, 16] {
            if flag & bit != 0 {
                loop {
                    let s = self.raw_read(1)?;
                    if s.is_empty() || s[0] == 0 {
                        break;
                    }
                }
            }
        }
        if flag & 2 != 0 {
            self.read_exact(2)?;
        }
        Ok(true)
    }

    /// `_read_eof`: the member's CRC and size, then the zero padding.
    fn trailer(&mut self) -> Result<(), ReadError> {
        let t = self.read_exact(8)?;
        let crc32 = u32::from_le_bytes([t[0], t[1], t[2], t[3]]);
        let isize = u32::from_le_bytes([t[4], t[5], t[6], t[7]]);
        if crc32 != self.crc.sum() {
            return Err(ReadError::os(format!(
                "BadGzipFile: CRC check failed {crc32:#x} != {:#x}",
                self.crc.sum()
            )));
        }
        if isize != self.crc.amount() {
            return Err(ReadError::os(
                "BadGzipFile: Incorrect length of data produced",
            ));
        }
        loop {
            if !self.fill()? {
                break;
            }
            if self.inbuf[self.in_pos] != 0 {
                break;
            }
            self.in_pos += 1;
        }
        Ok(())
    }

    /// Decompressed bytes into `out`; 0 at the end.
    fn read(&mut self, out: &mut [u8]) -> Result<usize, ReadError> {
        if let Some(e) = self.pending.take() {
            return Err(e);
        }
        loop {
            match self.state {
                GzState::Done => return Ok(0),
                GzState::Header => {
                    if !self.header()? {
                        self.state = GzState::Done;
                        return Ok(0);
                    }
                    self.dec.reset(false);
                    self.crc.reset();
                    self.state = GzState::Body;
                }
                GzState::Body => {
                    let more = self.fill()?;
                    let input = &self.inbuf[self.in_pos..self.in_len];
                    let (in0, out0) = (self.dec.total_in(), self.dec.total_out());
                    let status = self.dec.decompress(input, out, FlushDecompress::None);
                    let consumed = (self.dec.total_in() - in0) as usize;
                    let produced = (self.dec.total_out() - out0) as usize;
                    self.in_pos += consumed;
                    // zlib.error: caught as damage, worded as `type(exc).__name__: str(exc)`
                    let status = status.map_err(|e| {
                        let text = match e.message() {
                            Some(m) => format!("error: Error -3 while decompressing data: {m}"),
                            None => "error: Error -3 while decompressing data".to_string(),
                        };
                        ReadError { text }
                    })?;
                    self.crc.update(&out[..produced]);
                    if status == Status::StreamEnd {
                        // Python checks the trailer on the next read, after handing out these
                        // bytes: the same order for everything after them
                        self.state = GzState::Header;
                        if produced > 0 {
                            // check now but report after the data: keep the error for later
                            if let Err(e) = self.trailer() {
                                self.pending = Some(e);
                            }
                            return Ok(produced);
                        }
                        self.trailer()?;
                        continue;
                    }
                    if produced > 0 {
                        return Ok(produced);
                    }
                    if !more {
                        return Err(ReadError::os(GZIP_EOF));
                    }
                }
            }
        }
    }
}

// -- lines, as byte_lines / _cr_lines give them --------------------------------------------

enum Source {
    Plain(Counted<Box<dyn Read + Send>>),
    Gz(Box<GzReader<File>>),
}

impl Source {
    fn read(&mut self, out: &mut [u8]) -> Result<usize, ReadError> {
        match self {
            Source::Plain(f) => loop {
                match f.read(out) {
                    Ok(n) => return Ok(n),
                    Err(e) if e.kind() == io::ErrorKind::Interrupted => continue,
                    Err(e) => return Err(e.into()),
                }
            },
            Source::Gz(g) => g.read(out),
        }
    }

    fn position(&self) -> u64 {
        match self {
            Source::Plain(f) => f.count,
            Source::Gz(g) => g.file.count,
        }
    }
}

/// The lines of the file (`byte_lines`): each ends in `\n` but a cut last one; without the
/// byte order mark; split at lone CRs when the first 64 KiB hold CRs and no LF.
struct Lines {
    src: Source,
    buf: Vec<u8>,
    start: usize,
    end: usize,
    /// split at CR (each line gets a `\n`, as `_cr_lines` appends one)
    cr: bool,
    /// nothing more to read
    exhausted: bool,
    /// at the end, yield the bytes after the last line end as a (cut) line
    yield_partial: bool,
    /// raised after the lines
    error: Option<ReadError>,
    /// CR mode: the line with its `\n`
    scratch: Vec<u8>,
    /// the first 64 KiB, without the byte order mark (`ByteLines.head`)
    head: Vec<u8>,
}

/// Read into `buf` (grown by up to `want` bytes) until `want` bytes or the end; the bytes read
/// and the error that stopped it, if any.
fn read_more(src: &mut Source, buf: &mut Vec<u8>, want: usize) -> (usize, Option<ReadError>) {
    let base = buf.len();
    buf.resize(base + want, 0);
    let mut got = 0;
    let mut error = None;
    while got < want {
        match src.read(&mut buf[base + got..]) {
            Ok(0) => break,
            Ok(n) => got += n,
            Err(e) => {
                error = Some(e);
                break;
            }
        }
    }
    buf.truncate(base + got);
    (got, error)
}

impl Lines {
    fn new(mut src: Source) -> Lines {
        let mut buf = Vec::with_capacity(READ_BUFFER + HEAD_SIZE);
        let (_, head_error) = read_more(&mut src, &mut buf, HEAD_SIZE);
        let start = if buf.starts_with(BOM) { BOM.len() } else { 0 };
        let head = &buf[start..];
        let head_copy = head.to_vec();
        let mut lines = Lines {
            head: head_copy,
            cr: !head.contains(&b'\n') && head.contains(&b'\r'),
            exhausted: false,
            yield_partial: true,
            end: buf.len(),
            start,
            error: None,
            src,
            buf,
            scratch: Vec::new(),
        };
        if lines.cr {
            if head_error.is_some() {
                // a head cut by an error: its lines and its rest, then the error
                lines.exhausted = true;
                lines.error = head_error;
            } else {
                // `_cr_lines` reads its first block before it splits the head: an error there
                // loses the head too
                let (got, err) = read_more(&mut lines.src, &mut lines.buf, READ_BUFFER);
                lines.end = lines.buf.len();
                if let Some(e) = err {
                    lines.start = lines.end;
                    lines.exhausted = true;
                    lines.yield_partial = false;
                    lines.error = Some(e);
                } else if got == 0 {
                    lines.exhausted = true;
                }
            }
        } else if head_error.is_some() || lines.start == lines.end {
            // the line the damage cut is part of it: said once, with it
            lines.yield_partial = head_error.is_none();
            lines.exhausted = true;
            lines.error = head_error;
        } else if lines.buf[lines.end - 1] != b'\n' {
            // `head += f.readline()`: an error in that line loses the whole head
            loop {
                let from = lines.buf.len();
                let (got, err) = read_more(&mut lines.src, &mut lines.buf, HEAD_SIZE);
                lines.end = lines.buf.len();
                let found = lines.buf[from..].contains(&b'\n');
                if let Some(e) = err {
                    if !found {
                        lines.start = lines.end;
                    }
                    // else: the line was read; the damage comes later, after the whole lines
                    lines.exhausted = true;
                    lines.yield_partial = false;
                    lines.error = Some(e);
                    break;
                }
                if got == 0 || found {
                    break;
                }
            }
        }
        lines
    }

    /// The next line; Err once, after the last line, when reading failed.
    fn next_line(&mut self) -> Result<Option<&[u8]>, ReadError> {
        loop {
            let sep = if self.cr { b'\r' } else { b'\n' };
            if let Some(i) = self.buf[self.start..self.end]
                .iter()
                .position(|&b| b == sep)
            {
                let s = self.start;
                self.start = s + i + 1;
                if self.cr {
                    self.scratch.clear();
                    self.scratch.extend_from_slice(&self.buf[s..s + i]);
                    self.scratch.push(b'\n');
                    return Ok(Some(&self.scratch));
                }
                return Ok(Some(&self.buf[s..s + i + 1]));
            }
            if self.exhausted {
                if self.start < self.end && self.yield_partial {
                    let s = self.start;
                    self.start = self.end;
                    return Ok(Some(&self.buf[s..self.end]));
                }
                self.start = self.end;
                return match self.error.take() {
                    Some(e) => Err(e),
                    None => Ok(None),
                };
            }
            // keep the unfinished line, read the next block
            self.buf.copy_within(self.start..self.end, 0);
            self.end -= self.start;
            self.start = 0;
            self.buf.truncate(self.end);
            let (got, err) = read_more(&mut self.src, &mut self.buf, READ_BUFFER);
            if let Some(e) = err {
                // Python loses the unfinished line (LF: its complete lines before the damage
                // are handed out) or the whole block being read (CR: `f.read(READ_BUFFER)`)
                if self.cr {
                    self.buf.truncate(self.end);
                }
                self.end = self.buf.len();
                self.exhausted = true;
                self.yield_partial = false;
                self.error = Some(e);
                continue;
            }
            self.end = self.buf.len();
            if got == 0 {
                self.exhausted = true;
            }
        }
    }
}

// -- the reader -------------------------------------------------------------------------------

/// can_files.py `GIVE_UP`: bad lines before the first frame that make a file no candump log.
pub const GIVE_UP: usize = 5;
/// can_files.py `TRUNCATED`
const TRUNCATED: &str = "truncated: the file ends in the middle of this line";

/// candump logs in every layout candump writes, as CanFrames (Python `CandumpReader` over
/// candump.py): -l/-L lines, the default columns with or without `-t` stamps, ERROR lines.
/// Blank lines, `#` comments and candump -e's explanation lines after an error frame are
/// skipped; any other line that does not parse is counted in `bad_lines`, listed in `errors`
/// and skipped; a file whose first GIVE_UP bad lines come before any frame is no candump log:
/// one error says so and reading stops.
pub struct CandumpReader {
    pub path: PathBuf,
    lines: Option<Lines>,
    /// the damage found, in the Python's words (at most MAX_ERRORS, then one more line)
    pub errors: Vec<String>,
    /// frames yielded
    pub frames: u64,
    pub bad_lines: u64,
    /// errors listed (MAX_ERRORS; a test may raise it to compare every error)
    pub max_errors: usize,
    lineno: u64,
    clock: Clock,
    /// the last frame was an error frame: TAB-indented lines after it explain it (-e)
    after_error: bool,
    /// errors before the first frame (None once a frame was read)
    held: Option<Vec<String>>,
    first_bad: Vec<u8>,
    /// the head holds a -tA date stamp (the native core reads them on Unix only)
    pub dated: bool,
}

/// `is_gzip`: by the suffix, as the Python chooses (not by the magic bytes).
pub fn is_gzip(path: &Path) -> bool {
    path.extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("gz"))
}

impl CandumpReader {
    /// Open a candump log (`.gz`: gzip compressed); a missing file fails at once.
    pub fn open(path: &Path) -> io::Result<CandumpReader> {
        let file = File::open(path)?;
        let src = if is_gzip(path) {
            Source::Gz(Box::new(GzReader::new(file)))
        } else {
            Source::Plain(Counted {
                inner: Box::new(file),
                count: 0,
            })
        };
        Ok(CandumpReader::with_source(path, src))
    }

    /// Only the lines in [lo, hi) of an uncompressed file (the bounds must fall on line
    /// starts): the parallel decoder's parts (Python `byte_range`).
    pub fn open_range(path: &Path, lo: u64, hi: u64) -> io::Result<CandumpReader> {
        if is_gzip(path) {
            return Err(io::Error::new(
                io::ErrorKind::InvalidInput,
                "a byte range of a compressed candump log cannot be read",
            ));
        }
        let mut file = File::open(path)?;
        file.seek(SeekFrom::Start(lo))?;
        let part: Box<dyn Read + Send> = Box::new(file.take(hi.saturating_sub(lo)));
        Ok(CandumpReader::with_source(
            path,
            Source::Plain(Counted {
                inner: part,
                count: 0,
            }),
        ))
    }

    fn with_source(path: &Path, src: Source) -> CandumpReader {
        let lines = Lines::new(src);
        let (deltas, dated) = holds_deltas(&lines.head, lines.cr);
        CandumpReader {
            path: path.to_path_buf(),
            lines: Some(lines),
            errors: Vec::new(),
            frames: 0,
            bad_lines: 0,
            max_errors: MAX_ERRORS,
            lineno: 0,
            clock: Clock::new(deltas),
            after_error: false,
            held: Some(Vec::new()),
            first_bad: Vec::new(),
            dated,
        }
    }

    /// Bytes read so far (of the compressed file for .gz), for progress bars.
    pub fn position(&self) -> u64 {
        self.lines.as_ref().map_or(0, |l| l.src.position())
    }

    /// `_FileReaderBase._error`
    fn error(&mut self, text: String) {
        push_error(&mut self.errors, text, self.max_errors);
    }

    /// `_TextLogReader._framed`: a frame was read: the errors held before it are damage.
    fn framed(&mut self) {
        if let Some(held) = self.held.take() {
            for text in held {
                self.error(text);
            }
        }
    }

    /// `_TextLogReader._bad`: report a line that is no frame; true when the file is no log.
    fn bad(&mut self, line: &[u8], why: &str) -> bool {
        self.bad_lines += 1;
        let why = if line.last() == Some(&b'\n') {
            cut_chars(why, MAX_REASON)
        } else {
            TRUNCATED.to_string()
        };
        let text = format!(
            "line {}: cannot parse: {} ({why})",
            self.lineno,
            quote(line, MAX_QUOTED)
        );
        let Some(held) = self.held.as_mut() else {
            self.error(text);
            return false;
        };
        if held.is_empty() {
            self.first_bad = line.to_vec();
        }
        held.push(text);
        if held.len() < GIVE_UP {
            return false;
        }
        let text = format!(
            "does not look like a candump log: no CAN frame in its first {GIVE_UP} lines (the \
             first is {}); nothing read",
            quote(&self.first_bad, 40)
        );
        self.errors.push(text);
        true
    }

    /// The next frame into `frame` (its buffers reused); false at the end.
    pub fn next_into(&mut self, frame: &mut CanFrame) -> bool {
        loop {
            let Some(lines) = self.lines.as_mut() else {
                return false;
            };
            let line = match lines.next_line() {
                Ok(Some(line)) => line,
                Ok(None) => {
                    self.lines = None;
                    self.framed();
                    return false;
                }
                Err(e) => {
                    self.framed();
                    let (kind, message) = e.text.split_once(": ").unwrap_or((&e.text, ""));
                    let at_start = self.lineno == 0;
                    let text = match compression_damage(kind, message, at_start, "") {
                        Some(words) => format!("line {}: {words}", self.lineno + 1),
                        None => format!("line {}: read error: {}", self.lineno + 1, e.text),
                    };
                    push_error(&mut self.errors, text, self.max_errors);
                    self.lines = None;
                    return false;
                }
            };
            self.lineno += 1;
            if fast_parse(line, frame) {
                self.framed();
                self.after_error = false;
                self.frames += 1;
                return true;
            }
            if self.after_error && line.first() == Some(&b'\t') {
                continue;
            }
            let parsed = match parse_line(line, frame, &mut self.clock) {
                Ok(Some((layout, _))) if line.last() != Some(&b'\n') => {
                    if is_complete(line, layout) {
                        Ok(true)
                    } else {
                        Err(TRUNCATED.to_string())
                    }
                }
                Ok(found) => Ok(found.is_some()),
                Err(why) => Err(why),
            };
            match parsed {
                Ok(true) => {
                    self.framed();
                    self.after_error = frame.is_error;
                    self.frames += 1;
                    return true;
                }
                Ok(false) => {}
                Err(why) => {
                    // the line is borrowed from `lines`: copy it for the error text
                    let line = line.to_vec();
                    if self.bad(&line, &why) {
                        self.lines = None;
                        return false;
                    }
                }
            }
        }
    }
}

fn push_error(errors: &mut Vec<String>, text: String, max: usize) {
    if errors.len() < max {
        errors.push(text);
    } else if errors.len() == max {
        errors.push("further errors not listed".to_string());
    }
}

impl Iterator for CandumpReader {
    type Item = CanFrame;

    fn next(&mut self) -> Option<CanFrame> {
        let mut frame = CanFrame::default();
        self.next_into(&mut frame).then_some(frame)
    }
}

fn set_channel(frame: &mut CanFrame, chan: &str) {
    if frame.channel.as_deref() != Some(chan) {
        frame.channel = Some(chan.to_string());
    }
}

/// sniff.py `head`: the first HEAD_SIZE bytes (decompressed for a `.gz` name; what a damaged
/// one gives before the damage); empty when the file cannot be read or is no regular file.
pub fn first_bytes(path: &Path) -> Vec<u8> {
    // a FIFO must not be read twice (nor a device): its name decides
    if !std::fs::metadata(path).is_ok_and(|m| m.is_file()) {
        return Vec::new();
    }
    let Ok(file) = File::open(path) else {
        return Vec::new();
    };
    let mut src = if is_gzip(path) {
        Source::Gz(Box::new(GzReader::new(file)))
    } else {
        Source::Plain(Counted {
            inner: Box::new(file),
            count: 0,
        })
    };
    let mut buf = Vec::new();
    read_more(&mut src, &mut buf, HEAD_SIZE);
    buf
}

/// Whether a stripped line parses as a candump frame (sniff.py `_frame_line`).
pub fn parses_as_candump(text: &[u8]) -> bool {
    let mut line = text.to_vec();
    line.push(b'\n');
    matches!(
        parse_line(&line, &mut CanFrame::default(), &mut Clock::new(false)),
        Ok(Some(_))
    )
}

// -- time ---------------------------------------------------------------------------------------

/// candump.py `RELATIVE_LIMIT`: a smaller stamp is relative (-tz, -td), not Unix time.
pub const RELATIVE_LIMIT: f64 = 662688000.0;

/// candump.py `Clock`: a line's stamp as `t`, summed when the log holds -td deltas.
pub struct Clock {
    deltas: bool,
    total: f64,
}

impl Clock {
    pub fn new(deltas: bool) -> Clock {
        Clock { deltas, total: 0.0 }
    }

    /// A numeric stamp of a default-layout or ERROR line.
    fn relative(&mut self, stamp: f64) -> f64 {
        if !self.deltas || stamp >= RELATIVE_LIMIT {
            return stamp;
        }
        self.total += stamp;
        self.total
    }
}

/// candump.py `holds_deltas`: whether the relative stamps of the head's default-layout lines
/// go back (candump -td); and whether a line of it has a -tA date (for non-Unix builds).
fn holds_deltas(head: &[u8], cr: bool) -> (bool, bool) {
    let sep = if cr { b'\r' } else { b'\n' };
    let mut lines: Vec<&[u8]> = head.split(|&b| b == sep).collect();
    lines.pop(); // the last one may be cut
    let mut clock = Clock::new(false);
    let mut frame = CanFrame::default();
    let mut line = Vec::new();
    let mut last = -1.0;
    let mut dated = false;
    for text in lines {
        line.clear();
        line.extend_from_slice(text);
        line.push(b'\n');
        let Ok(Some((layout, is_dated))) = parse_line(&line, &mut frame, &mut clock) else {
            continue;
        };
        dated |= is_dated;
        let Some(t) = frame.t else { continue };
        if layout != Layout::Columns || t >= RELATIVE_LIMIT || is_dated {
            continue;
        }
        if t < last {
            return (true, dated);
        }
        last = t;
    }
    (false, dated)
}

/// candump.py `local_time`: `2020-12-19` and `12:04:45.485261` (candump -tA) as Unix time in
/// this machine's time zone, through the C library's `mktime` as Python's `time.mktime`.
fn local_time(date: &[u8], clock: &[u8]) -> Result<f64, String> {
    let bad = || "bad date and time".to_string();
    let (hms, frac) = match clock.iter().position(|&c| c == b'.') {
        Some(i) => (&clock[..i], &clock[i + 1..]),
        None => (clock, &clock[clock.len()..]),
    };
    let fields: Vec<&[u8]> = date
        .split(|&c| c == b'-')
        .chain(hms.split(|&c| c == b':'))
        .collect();
    let widths = [(4, 4), (1, 2), (1, 2), (1, 2), (1, 2), (1, 2)];
    let isdigit = |x: &[u8]| !x.is_empty() && x.iter().all(u8::is_ascii_digit);
    if fields.len() != 6
        || !fields
            .iter()
            .zip(widths)
            .all(|(x, (lo, hi))| (lo..=hi).contains(&x.len()) && isdigit(x))
    {
        return Err(bad());
    }
    if !(frac.is_empty() || isdigit(frac) && frac.len() <= 9) {
        return Err(bad());
    }
    let num = |x: &[u8]| x.iter().fold(0i64, |v, &c| v * 10 + (c - b'0') as i64);
    let v: Vec<i64> = fields.iter().map(|x| num(x)).collect();
    let (y, mo, d, h, mi, sec) = (v[0], v[1], v[2], v[3], v[4], v[5]);
    if !((1..=12).contains(&mo) && (1..=31).contains(&d) && h <= 23 && mi <= 59 && sec <= 60) {
        return Err(bad());
    }
    let seconds = mktime(y, mo, d, h, mi, sec).ok_or_else(bad)?;
    Ok(if frac.is_empty() {
        seconds
    } else {
        seconds + num(frac) as f64 / 10f64.powi(frac.len() as i32)
    })
}

/// `time.mktime((y, mo, d, h, mi, s, 0, 0, -1))`: None where Python raises OverflowError.
#[cfg(unix)]
fn mktime(y: i64, mo: i64, d: i64, h: i64, mi: i64, s: i64) -> Option<f64> {
    use std::ffi::{c_char, c_int, c_long};
    #[repr(C)]
    struct Tm {
        tm_sec: c_int,
        tm_min: c_int,
        tm_hour: c_int,
        tm_mday: c_int,
        tm_mon: c_int,
        tm_year: c_int,
        tm_wday: c_int,
        tm_yday: c_int,
        tm_isdst: c_int,
        tm_gmtoff: c_long,
        tm_zone: *const c_char,
    }
    extern "C" {
        fn mktime(tm: *mut Tm) -> i64;
    }
    let mut tm = Tm {
        tm_sec: s as c_int,
        tm_min: mi as c_int,
        tm_hour: h as c_int,
        tm_mday: d as c_int,
        tm_mon: (mo - 1) as c_int,
        tm_year: (y - 1900) as c_int,
        tm_wday: -1, // Python's sentinel: still -1 after a failed call
        tm_yday: -1,
        tm_isdst: -1,
        tm_gmtoff: 0,
        tm_zone: std::ptr::null(),
    };
    // SAFETY: a valid struct tm for the duration of the call; mktime only reads and writes it
    let tt = unsafe { mktime(&mut tm) };
    if tt == -1 && tm.tm_wday == -1 {
        return None;
    }
    Some(tt as f64)
}

/// Elsewhere the Python engine reads -tA stamps (`DecodeRun::open` says Unsupported).
#[cfg(not(unix))]
fn mktime(_y: i64, _mo: i64, _d: i64, _h: i64, _mi: i64, _s: i64) -> Option<f64> {
    None
}

// -- one line ---------------------------------------------------------------------------------

/// candump.py's layouts: an -l/-L line, or the default columns (and ERROR lines).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Layout {
    Log,
    Columns,
}

/// candump.py `is_complete`: whether a line that parsed, but has no line end, cannot be the
/// start of a longer one.
fn is_complete(line: &[u8], layout: Layout) -> bool {
    let parts: Vec<&[u8]> = line
        .split(|&b| is_space(b))
        .filter(|p| !p.is_empty())
        .collect();
    let last = parts[parts.len() - 1];
    if layout != Layout::Log || is_direction(last) {
        return true;
    }
    let payload = match last.iter().position(|&c| c == b'#') {
        Some(i) => &last[i + 1..],
        None => &last[last.len()..],
    };
    match payload.first() {
        Some(b'#') => payload.len() == 2 + 2 * CANFD_MAX_LEN,
        Some(b'R') | Some(b'r') => payload.len() == 2,
        _ => payload.contains(&b'_') || payload.len() == 16,
    }
}

/// candump.py `CANFD_MAX_LEN`
const CANFD_MAX_LEN: usize = 64;

/// candump.py `_channel`
fn channel_of(chan: &[u8]) -> Result<&str, String> {
    decode_ascii(chan).map_err(|_| "the channel name is not ASCII".to_string())
}

/// candump.py `_identifier`: (identifier, extended, error frame) of 1-8 hex digits.
fn identifier(ident: &[u8]) -> Result<(u64, bool, bool), String> {
    if ident.is_empty() || !all_hex(ident) || ident.len() > 8 {
        return Err(format!(
            "bad identifier {}",
            str_literal(&ascii_replace(ident), NonAscii::Keep)
        ));
    }
    let mut aid = ident
        .iter()
        .fold(0u64, |v, &c| v << 4 | hex_val(c).unwrap_or(0) as u64);
    let extended = ident.len() > 3;
    let mut error = false;
    if extended {
        if aid & CAN_RTR_FLAG != 0 {
            let text = std::str::from_utf8(ident).unwrap_or_default();
            return Err(format!("identifier {text} does not fit in 29 bits"));
        }
        error = aid & CAN_ERR_FLAG != 0;
        aid &= CAN_EFF_MASK;
    } else if aid > 0x7FF {
        return Err("standard identifier above 0x7FF".into());
    }
    Ok((aid, extended, error))
}

/// candump.py `parse_line`: any candump line into `frame`: Ok(Some((layout, dated))), Ok(None)
/// for a blank or `#` comment line, else the ValueError text saying what is wrong.
fn parse_line(
    line: &[u8],
    frame: &mut CanFrame,
    clock: &mut Clock,
) -> Result<Option<(Layout, bool)>, String> {
    let parts: Vec<&[u8]> = line
        .split(|&b| is_space(b))
        .filter(|p| !p.is_empty())
        .collect();
    if parts.is_empty() || parts[0][0] == b'#' {
        return Ok(None);
    }
    let mut t = None;
    let mut dated = false;
    let mut rest = &parts[..];
    let first = parts[0];
    if first[0] == b'(' {
        if first.len() > 1 && first[first.len() - 1] == b')' {
            t = Some(py_float(&first[1..first.len() - 1])?);
            rest = &parts[1..];
        } else if parts.len() > 1 && parts[1].last() == Some(&b')') {
            let clock_part = parts[1];
            t = Some(local_time(
                &first[1..],
                &clock_part[..clock_part.len() - 1],
            )?);
            dated = true;
            rest = &parts[2..];
        } else {
            return Err("no (timestamp)".into());
        }
    }
    if rest.len() < 2 {
        return Err("expected a channel and a frame".into());
    }
    let (chan, body) = (rest[0], &rest[1..]);
    let layout;
    if body.len() == 1 && body[0] == b"ERROR" {
        let chan = channel_of(chan)?;
        frame.arbitration_id = 0;
        frame.data.clear();
        frame.is_extended = true;
        frame.is_remote = false;
        frame.is_error = true;
        frame.is_fd = false;
        frame.dlc = Some(0);
        set_channel(frame, chan);
        layout = Layout::Columns;
    } else if body[0].contains(&b'#')
        && (body.len() == 1 || (body.len() == 2 && is_direction(body[1])))
    {
        let chan = channel_of(chan)?;
        log_frame(body[0], frame)?;
        set_channel(frame, chan);
        layout = Layout::Log;
    } else if body.len() >= 2 && body[1].first() == Some(&b'[') {
        let chan = channel_of(chan)?;
        columns_frame(body, frame)?;
        set_channel(frame, chan);
        layout = Layout::Columns;
    } else {
        return Err("not a candump frame".into());
    }
    if let Some(stamp) = t {
        if layout == Layout::Columns && !dated {
            t = Some(clock.relative(stamp));
        }
    }
    frame.t = t;
    Ok(Some((layout, dated)))
}

/// candump.py `_log_frame`: `ID#DATA` and its variants (-l/-L).
fn log_frame(body: &[u8], frame: &mut CanFrame) -> Result<(), String> {
    let hash = body.iter().position(|&c| c == b'#').unwrap_or(body.len());
    let (ident, payload) = (&body[..hash], &body[(hash + 1).min(body.len())..]);
    let (aid, extended, error) = identifier(ident)?;
    let (mut remote, mut fd) = (false, false);
    let data = &mut frame.data;
    let dlc;
    if payload.first() == Some(&b'#') {
        // CAN FD: "##", one flags digit (BRS, ESI: not kept), the data
        if payload.len() < 2 || !payload[1].is_ascii_hexdigit() {
            return Err("CAN FD frame without its flags digit".into());
        }
        fd = true;
        unhexlify(&payload[2..], data)?;
        dlc = data.len();
    } else if matches!(payload.first(), Some(b'R') | Some(b'r')) {
        // remote frame, optional DLC digit
        data.clear();
        let d = if payload.len() > 1 {
            py_int16(&payload[1..])?
        } else {
            Some(0)
        };
        match d {
            Some(d) if (0..=15).contains(&d) => dlc = d as usize,
            _ => return Err("bad remote DLC".into()),
        }
        remote = true;
    } else if let Some(us) = payload.iter().position(|&c| c == b'_') {
        // classic frame with a DLC of 9-15: 8 data bytes and "_<dlc>"
        unhexlify(&payload[..us], data)?;
        match py_int16(&payload[us + 1..])? {
            Some(d) if data.len() == 8 && (9..=15).contains(&d) => dlc = d as usize,
            _ => return Err("bad DLC suffix".into()),
        }
    } else {
        unhexlify(payload, data).map_err(|e| format!("bad data: {e}"))?;
        dlc = data.len();
        fd = dlc > 8; // more than a classic frame holds: CAN FD written without its "##"
    }
    if data.len() > CANFD_MAX_LEN {
        return Err(format!(
            "{} data bytes: more than a CAN FD frame holds",
            data.len()
        ));
    }
    frame.arbitration_id = aid as u32;
    frame.is_extended = extended;
    frame.is_remote = remote;
    frame.is_error = error;
    frame.is_fd = fd;
    frame.dlc = Some(dlc);
    Ok(())
}

/// candump.py `_columns_frame`: `ID  [n]  AA BB ...` (the default layout).
fn columns_frame(body: &[&[u8]], frame: &mut CanFrame) -> Result<(), String> {
    let (aid, extended, error) = identifier(body[0])?;
    let length = body[1];
    let digits: &[u8] = if length.len() >= 2 {
        &length[1..length.len() - 1]
    } else {
        &[]
    };
    let isdigit = !digits.is_empty() && digits.iter().all(u8::is_ascii_digit);
    if length.last() != Some(&b']') || !isdigit || digits.len() > 2 {
        return Err(format!(
            "bad length {}",
            str_literal(&ascii_replace(length), NonAscii::Keep)
        ));
    }
    let n = digits
        .iter()
        .fold(0usize, |v, &c| v * 10 + (c - b'0') as usize);
    let fd = digits.len() == 2; // candump prints a CAN FD length with two digits: [08], [12]
    if n > CANFD_MAX_LEN {
        return Err(format!("length {n}: more than a CAN FD frame holds"));
    }
    let values = &body[2..];
    frame.arbitration_id = aid as u32;
    frame.is_extended = extended;
    frame.is_error = error;
    frame.dlc = Some(n);
    frame.data.clear();
    if values.len() == 2 && values[0] == b"remote" && values[1] == b"request" && !fd {
        frame.is_remote = true;
        frame.is_fd = false;
        return Ok(());
    }
    let tokens = &values[..n.min(values.len())];
    let tail = &values[tokens.len()..];
    if tokens.len() < n || !tokens.iter().all(|x| x.len() == 2 && all_hex(x)) {
        return Err(format!("expected {n} data bytes"));
    }
    let tail_ok =
        tail.is_empty() || (tail.len() == 1 && tail[0] == b"ERRORFRAME") || tail[0][0] == b'\'';
    if !tail_ok {
        return Err(format!("more than {n} data bytes"));
    }
    for x in tokens {
        frame
            .data
            .push(hex_val(x[0]).unwrap_or(0) << 4 | hex_val(x[1]).unwrap_or(0));
    }
    frame.is_remote = false;
    frame.is_fd = fd || n > 8;
    Ok(())
}

/// `float()` of a time stamp. The usual `seconds.micros` with at most 2^53 as its digits
/// takes Clinger's fast path: the digits and the power of ten are exact doubles, so one
/// division is correctly rounded, as Python's `float()` is. Anything else: `py_float`.
fn stamp_float(s: &[u8]) -> Result<f64, String> {
    const POW10: [f64; 23] = [
        1e0, 1e1, 1e2, 1e3, 1e4, 1e5, 1e6, 1e7, 1e8, 1e9, 1e10, 1e11, 1e12, 1e13, 1e14, 1e15, 1e16,
        1e17, 1e18, 1e19, 1e20, 1e21, 1e22,
    ];
    let mut mant: u64 = 0;
    let mut digits = 0;
    let mut frac: Option<usize> = None;
    for &c in s {
        match c {
            b'0'..=b'9' => {
                mant = mant.wrapping_mul(10).wrapping_add((c - b'0') as u64);
                digits += 1;
                if let Some(f) = frac.as_mut() {
                    *f += 1;
                }
            }
            b'.' if frac.is_none() => frac = Some(0),
            _ => return py_float(s),
        }
    }
    let k = frac.unwrap_or(0);
    if digits == 0 || digits > 19 || mant > 1 << 53 || k > 22 {
        return py_float(s);
    }
    Ok(mant as f64 / POW10[k])
}

/// The Python's fast path: `(stamp) channel ID#HEXDATA` with a 3- or 8-character identifier
/// as `int(ident, 16)` reads it; false: let the general parser decide.
fn fast_parse(line: &[u8], frame: &mut CanFrame) -> bool {
    if line.last() != Some(&b'\n') {
        return false;
    }
    let Some((parts, n)) = split_fields::<4>(line) else {
        return false;
    };
    if !(n == 3 || (n == 4 && is_direction(parts[3]))) {
        return false;
    }
    let [stamp, chan, body, _] = parts;
    let Some(hash) = body.iter().position(|&c| c == b'#') else {
        return false;
    };
    let (ident, hexdata) = (&body[..hash], &body[hash + 1..]);
    if hexdata.contains(&b'#') || stamp[0] != b'(' || stamp[stamp.len() - 1] != b')' {
        return false;
    }
    let k = ident.len();
    if k != 3 && k != 8 {
        return false;
    }
    let Ok(t) = stamp_float(&stamp[1..stamp.len() - 1]) else {
        return false;
    };
    let aid = if all_hex(ident) {
        ident
            .iter()
            .fold(0u64, |v, &c| v << 4 | hex_val(c).unwrap_or(0) as u64)
    } else {
        match py_int16(ident) {
            Ok(Some(aid)) if aid >= 0 => aid as u64,
            _ => return false,
        }
    };
    if hexdata.len() > 16 || unhexlify(hexdata, &mut frame.data).is_err() {
        return false;
    }
    let Ok(chan) = decode_ascii(chan) else {
        return false;
    };
    let extended = if k == 8 && aid <= CAN_EFF_MASK {
        true
    } else if k == 3 && aid <= 0x7FF {
        false
    } else {
        return false;
    };
    frame.t = Some(t);
    frame.arbitration_id = aid as u32;
    frame.is_extended = extended;
    frame.is_remote = false;
    frame.is_error = false;
    frame.is_fd = false;
    frame.dlc = Some(frame.data.len());
    set_channel(frame, chan);
    true
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn python_literals() {
        assert_eq!(py_float(b"1_0.5e1").unwrap(), 105.0);
        assert!(py_float(b"-InFinity").unwrap().is_infinite());
        assert_eq!(
            py_float(b"1_").unwrap_err(),
            "could not convert string to float: b'1_'"
        );
        assert_eq!(
            py_float(b"a'b").unwrap_err(),
            "could not convert string to float: b\"a'b\""
        );
        assert_eq!(py_int16(b"+0x_1_f").unwrap(), Some(31));
        assert!(py_int16(b"0_x1").is_err());
        assert_eq!(py_int16(b"-0").unwrap(), Some(0));
        assert_eq!(bytes_repr(b"\xff\x00\\"), "b'\\xff\\x00\\\\'");
        assert_eq!(quote(b"  ab\x1c\n", MAX_QUOTED), "'ab'");
        assert_eq!(quote(b"abcdef", 5), "'ab...'");
        assert_eq!(
            quote(b"\xff\x80 a'b\xc3(\n", 80),
            "\"\\xff\\x80 a'b\\xc3(\""
        );
        // repr() keeps U+FFFD, ascii() escapes past ASCII; both escape controls
        assert_eq!(
            str_literal("a\x7f\x01\u{FFFD}'", NonAscii::Keep),
            "\"a\\x7f\\x01\u{FFFD}'\""
        );
        assert_eq!(
            str_literal("\t\x7f\u{e9}", NonAscii::Escape),
            "'\\t\\x7f\\xe9'"
        );
        assert_eq!(can_bus_name(Some("1")), "can1");
        assert_eq!(can_bus_name(Some("")), "can0");
    }

    #[test]
    fn stamps_as_python_reads_them() {
        for s in [
            "1763700000.000120",
            "0.1",
            "5.",
            ".5",
            "123",
            "1.7976931348623157",
            "9007199254740993.0",
        ] {
            let want: f64 = s.parse().unwrap();
            assert_eq!(
                stamp_float(s.as_bytes()).unwrap().to_bits(),
                want.to_bits(),
                "{s}"
            );
        }
        assert!(stamp_float(b".").is_err());
        assert!(stamp_float(b"").is_err());
        assert!(stamp_float(b"1.2.3").is_err());
    }

    #[test]
    fn quirky_fast_path() {
        let mut f = CanFrame::default();
        assert!(fast_parse(b"(1.5) can0 0x123456#00\n", &mut f));
        assert_eq!((f.arbitration_id, f.is_extended), (0x123456, true));
        assert!(!fast_parse(b"(1.5) can0 0x12#00\n", &mut f));
        assert_eq!(
            parse_line(b"(1.5) can0 0x12#00\n", &mut f, &mut Clock::new(false)).unwrap_err(),
            "bad identifier '0x12'"
        );
    }

    #[test]
    fn every_layout() {
        let mut f = CanFrame::default();
        let mut clock = Clock::new(false);
        let mut parse = |line: &[u8]| parse_line(line, &mut f, &mut clock).map(|p| p.map(|x| x.0));
        assert_eq!(
            parse(b"  can0  0C8   [8]  F0 00 00 00 00 00 00 00\n"),
            Ok(Some(Layout::Columns))
        );
        assert_eq!(
            parse(b"(1.5) vcan0 123   [12]  00 01 02 03 04 05 06 07 08 09 0A 0B\n"),
            Ok(Some(Layout::Columns))
        );
        assert_eq!(
            parse(b"can0  123   [3]  00 01\n"),
            Err("expected 3 data bytes".into())
        );
        assert_eq!(
            parse(b"can0  123   [1]  00 01\n"),
            Err("more than 1 data bytes".into())
        );
        assert_eq!(
            parse(b"can0  20000004   [8]  00 00 00 00 00 00 00 00   ERRORFRAME\n"),
            Ok(Some(Layout::Columns))
        );
        assert_eq!(parse(b"can0 ERROR\n"), Ok(Some(Layout::Columns)));
        assert_eq!(
            parse(b"(1.0) can0 064#F001FFFFFFFFFFFFFFFF\n"),
            Ok(Some(Layout::Log))
        );
        assert_eq!(parse(b"# comment\n"), Ok(None));
        assert_eq!(
            parse(b"(2020-13-19 12:04:45.485261) can0 ERROR\n"),
            Err("bad date and time".into())
        );
    }

    #[test]
    fn deltas_and_complete_lines() {
        let td = b"(000.000000) can0 123 [1] 11\n(000.500000) can0 123 [1] 11\n(000.100000) can0 123 [1] 11\n";
        assert_eq!(holds_deltas(td, false), (true, false));
        let tz = b"(000.000000) can0 123 [1] 11\n(000.500000) can0 123 [1] 11\n(000.600000) can0 123 [1] 11\n";
        assert_eq!(holds_deltas(tz, false), (false, false));
        assert!(!is_complete(b"(1.0) can0 123#1122", Layout::Log));
        assert!(is_complete(b"(1.0) can0 123#1122 R", Layout::Log));
        assert!(is_complete(b"(1.0) can0 123#1122334455667788", Layout::Log));
        assert!(is_complete(b"(1.0) can0 123#R5", Layout::Log));
        assert!(!is_complete(b"(1.0) can0 123#R", Layout::Log));
    }

    fn read_all(name: &str, bytes: &[u8]) -> (usize, Vec<String>) {
        let path =
            std::env::temp_dir().join(format!("eg2native-candump-{}-{name}", std::process::id()));
        std::fs::write(&path, bytes).unwrap();
        let mut reader = CandumpReader::open(&path).unwrap();
        let n = reader.by_ref().count();
        std::fs::remove_file(&path).unwrap();
        (n, reader.errors)
    }

    fn gzip(data: &[u8]) -> Vec<u8> {
        use std::io::Write;
        let mut enc = flate2::write::GzEncoder::new(Vec::new(), flate2::Compression::default());
        enc.write_all(data).unwrap();
        enc.finish().unwrap()
    }

    #[test]
    fn line_ends_and_cut_files() {
        let lines = b"(1.0) can0 123#11\r(2.0) can0 123#22\r(3.0) can0 12";
        let (n, errors) = read_all("cr.log", lines);
        assert_eq!(n, 2);
        assert_eq!(
            errors,
            ["line 3: cannot parse: '(3.0) can0 12' (truncated: the file ends in the middle of this line)"]
        );
        let (n, errors) = read_all("bom.log", b"\xef\xbb\xbf(1.0) can0 123#11\r\n");
        assert_eq!((n, errors.len()), (1, 0));
    }

    #[test]
    fn damaged_gzip() {
        let data: Vec<u8> = (0..2000)
            .flat_map(|i| format!("({i}.5) can0 123#{:02X}\n", i % 256).into_bytes())
            .collect();
        let gz = gzip(&data);
        assert_eq!(read_all("ok.log.gz", &gz), (2000, vec![]));
        let (n, errors) = read_all("cut.log.gz", &gz[..gz.len() - 9]);
        assert_eq!(n, 2000);
        assert_eq!(
            errors,
            ["line 2001: the compressed file is cut short; the rest is lost"]
        );
        let mut bad = gz.clone();
        let k = bad.len() - 8;
        bad[k] ^= 1;
        let (_, errors) = read_all("crc.log.gz", &bad);
        assert!(
            errors[0].starts_with("line 2001: the compressed data is damaged (CRC check failed 0x")
        );
        let (n, errors) = read_all("not.log.gz", b"(1.0) can0 123#11\n");
        assert_eq!(n, 0);
        assert_eq!(
            errors,
            ["line 1: not gzip data, though its name ends in .gz"]
        );
    }
}
