//! Raw byte dumps of a serial line, plain or gzip compressed, read as analyzer/sources/capture.py
//! `RawBytesReader` and `GzipBytesReader` read them: the same chunks in the same order, the
//! same `position` (compressed bytes for gzip) and, for a cut or damaged `.gz`, the same bytes
//! before the damage and the same message in `errors`.
//!
//! The gzip reader re-enacts CPython 3.11's `gzip._GzipReader.read(65536)` (what
//! `GzipFile.read1(READ_SIZE)` comes down to) step by step: members read from a "padded file"
//! that takes back unused input, 8 KiB (`io.DEFAULT_BUFFER_SIZE`) of compressed input per
//! `decompress(buf, 65536)` call, the trailer checked when the next read starts, zero padding
//! between members skipped. That is what decides how many bytes come out before the damage, and
//! which exception (and so which message) the Python reader reports.
//!
//! Needs flate2's zlib-rs backend (`flate2 = { version = "1", default-features = false,
//! features = ["zlib-rs"] }`): zlib-rs inflates as CPython's zlib does and words damage as zlib
//! does; miniz_oxide (flate2's default) misses "invalid distance too far back" and gives no
//! messages. Differential check: 1,500 random cut/flipped/padded multi-member files gave the
//! same chunks, positions and messages as capture.py.

use super::compressed::compression_damage;
use flate2::{Decompress, FlushDecompress, Status};
use std::fs::File;
use std::io::{self, Read};
use std::path::Path;

/// capture.py `READ_SIZE`: bytes per chunk.
pub const READ_SIZE: usize = 1 << 16;
/// `io.DEFAULT_BUFFER_SIZE`: compressed bytes handed to one `decompress` call.
const GZ_INPUT_BLOCK: usize = 8192;

/// `str(pathlib.Path(path))`: repeated slashes, "." parts and a trailing slash dropped.
pub fn py_path_str(path: &Path) -> String {
    use std::path::Component;
    let mut out = std::path::PathBuf::new();
    for c in path.components() {
        if c != Component::CurDir {
            out.push(c);
        }
    }
    if out.as_os_str().is_empty() {
        return ".".to_string();
    }
    out.to_string_lossy().into_owned()
}

/// capture.py `check_readable`: an OSError naming `path` unless it is a readable file (checked
/// without opening it). The texts are the Python ones.
pub fn check_readable(path: &Path) -> io::Result<()> {
    let shown = py_path_str(path);
    match std::fs::metadata(path) {
        // Path.exists() is False for these errors (ENOENT, ENOTDIR, EBADF, ELOOP)
        Err(e)
            if e.kind() == io::ErrorKind::NotFound
                || matches!(e.raw_os_error(), Some(20 | 9 | 40)) =>
        {
            return Err(io::Error::new(
                io::ErrorKind::NotFound,
                format!("capture file not found: {shown}"),
            ))
        }
        Ok(m) if m.is_dir() => {
            return Err(io::Error::new(
                io::ErrorKind::IsADirectory,
                format!("capture path is a directory, not a file: {shown}"),
            ))
        }
        _ => {}
    }
    if !readable(path) {
        return Err(io::Error::new(
            io::ErrorKind::PermissionDenied,
            format!("cannot read {shown}: permission denied"),
        ));
    }
    Ok(())
}

#[cfg(unix)]
fn readable(path: &Path) -> bool {
    use std::ffi::CString;
    use std::os::unix::ffi::OsStrExt;
    extern "C" {
        fn access(path: *const std::ffi::c_char, mode: std::ffi::c_int) -> std::ffi::c_int;
    }
    const R_OK: std::ffi::c_int = 4;
    match CString::new(path.as_os_str().as_bytes()) {
        // SAFETY: a valid NUL-terminated path; access() only reads it
        Ok(c) => unsafe { access(c.as_ptr(), R_OK) == 0 },
        Err(_) => false,
    }
}

#[cfg(not(unix))]
fn readable(path: &Path) -> bool {
    File::open(path).is_ok()
}

/// Read until `buf` is full or the file ends (a buffered Python `read(n)` does the same).
fn read_full(file: &mut File, buf: &mut [u8]) -> io::Result<usize> {
    let mut got = 0;
    while got < buf.len() {
        match file.read(&mut buf[got..]) {
            Ok(0) => break,
            Ok(n) => got += n,
            Err(e) if e.kind() == io::ErrorKind::Interrupted => {}
            Err(e) => return Err(e),
        }
    }
    Ok(got)
}

// ---------------------------------------------------------------------------------------------
// plain

/// capture.py `RawBytesReader`: chunks of `READ_SIZE` bytes (the last one shorter).
pub struct RawBytesReader {
    file: File,
    buf: Vec<u8>,
    /// bytes read so far
    pub position: u64,
    /// size of the file
    pub size: u64,
}

impl RawBytesReader {
    pub fn open(path: &Path) -> io::Result<Self> {
        check_readable(path)?;
        let file = File::open(path)?;
        let size = file.metadata()?.len();
        Ok(RawBytesReader {
            file,
            buf: vec![0; READ_SIZE],
            position: 0,
            size,
        })
    }

    /// The next chunk, None at the end of the file.
    pub fn next_chunk(&mut self) -> io::Result<Option<&[u8]>> {
        let n = read_full(&mut self.file, &mut self.buf)?;
        if n == 0 {
            return Ok(None);
        }
        self.position += n as u64;
        Ok(Some(&self.buf[..n]))
    }
}

// ---------------------------------------------------------------------------------------------
// gzip

/// Why the Python reader stopped: the exception it caught (`OSError`/`EOFError`, reported in
/// `errors`), as `type(exc).__name__` and `str(exc)`.
#[derive(Debug)]
struct Caught {
    kind: &'static str,
    text: String,
}

/// zlib-rs's message for damage found on its fast path (see `rediagnose`).
const REPEATED_CALL: &str = "repeated call with bad state";

const CUT_SHORT: &str = "Compressed file ended before the end-of-stream marker was reached";

fn eof_error() -> Caught {
    Caught {
        kind: "EOFError",
        text: CUT_SHORT.to_string(),
    }
}

fn bad_gzip(text: String) -> Caught {
    Caught {
        kind: "BadGzipFile",
        text,
    }
}

/// How a read of the Python reader ends: caught damage, or what it does not catch.
enum Stop {
    Caught(Caught),
    /// A real I/O error of the file.
    Fatal(io::Error),
}

impl From<Caught> for Stop {
    fn from(c: Caught) -> Self {
        Stop::Caught(c)
    }
}

/// `gzip._PaddedFile` over the compressed file: reads that can be taken back (the decompressor's
/// unused input goes back in front of the file). Only the tail of the last read is ever taken
/// back, so a window of the file and a read position are enough.
struct PaddedFile {
    file: File,
    window: Vec<u8>,
    pos: usize,
    /// the file's own position: how far reads have reached (`_raw.tell()`)
    reached: u64,
    /// file offset of `window[0]`
    base: u64,
    at_eof: bool,
}

impl PaddedFile {
    /// Up to `n` bytes (fewer only at the end of the file), as a range of `self.window`.
    fn read(&mut self, n: usize) -> io::Result<std::ops::Range<usize>> {
        if self.window.len() - self.pos < n && !self.at_eof {
            // drop what was read before (only the last read can be taken back), then refill
            self.window.drain(..self.pos);
            self.base += self.pos as u64;
            self.pos = 0;
            let want = n.max(READ_SIZE);
            let have = self.window.len();
            self.window.resize(have + want, 0);
            let got = read_full(&mut self.file, &mut self.window[have..])?;
            self.window.truncate(have + got);
            self.at_eof = got < want;
        }
        let start = self.pos;
        let end = (start + n).min(self.window.len());
        self.pos = end;
        self.reached = self.reached.max(self.base + end as u64);
        Ok(start..end)
    }

    /// `prepend(data)`: the last `n` bytes read come again.
    fn unread(&mut self, n: usize) {
        self.pos -= n;
    }

    fn read_byte(&mut self) -> io::Result<Option<u8>> {
        let r = self.read(1)?;
        Ok(self.window.get(r.start).copied().filter(|_| !r.is_empty()))
    }

    /// `gzip._read_exact`: EOFError when the file ends first.
    fn read_exact(&mut self, n: usize) -> Result<std::ops::Range<usize>, Stop> {
        let r = self.read(n).map_err(Stop::Fatal)?;
        if r.len() < n {
            return Err(eof_error().into());
        }
        Ok(r)
    }
}

const FHCRC: u8 = 2;
const FEXTRA: u8 = 4;
const FNAME: u8 = 8;
const FCOMMENT: u8 = 16;

/// Python's `repr(b)` of a short bytes object (the "Not a gzipped file" message shows it).
fn bytes_repr(b: &[u8]) -> String {
    let quote = if b.contains(&b'\'') && !b.contains(&b'"') {
        '"'
    } else {
        '\''
    };
    let mut s = String::from("b");
    s.push(quote);
    for &c in b {
        match c {
            b'\\' => s.push_str("\\\\"),
            b'\t' => s.push_str("\\t"),
            b'\n' => s.push_str("\\n"),
            b'\r' => s.push_str("\\r"),
            c if c as char == quote => {
                s.push('\\');
                s.push(quote);
            }
            0x20..=0x7e => s.push(c as char),
            _ => s.push_str(&format!("\\x{c:02x}")),
        }
    }
    s.push(quote);
    s
}

/// capture.py `GzipBytesReader`: the decompressed bytes in the chunks `GzipFile.read1(65536)`
/// returns; damage ends the stream with a message in `errors`.
pub struct GzipBytesReader {
    fp: PaddedFile,
    dec: Decompress,
    /// the decompressor reached the end of a member's deflate data
    dec_eof: bool,
    new_member: bool,
    /// file offset of the current member's deflate data
    member_data: u64,
    crc: flate2::Crc,
    /// one read's output: `out[..out_len]`
    out: Box<[u8]>,
    out_len: usize,
    /// decompressed bytes handed out so far
    total: u64,
    done: bool,
    /// compressed bytes read so far (the size of the file once done)
    pub position: u64,
    pub size: u64,
    /// damage found, as the Python reader words it
    pub errors: Vec<String>,
}

impl GzipBytesReader {
    pub fn open(path: &Path) -> io::Result<Self> {
        check_readable(path)?;
        let file = File::open(path)?;
        let size = file.metadata()?.len();
        Ok(GzipBytesReader {
            fp: PaddedFile {
                file,
                window: Vec::with_capacity(READ_SIZE + GZ_INPUT_BLOCK),
                pos: 0,
                reached: 0,
                base: 0,
                at_eof: false,
            },
            dec: Decompress::new(false),
            dec_eof: false,
            new_member: true,
            member_data: 0,
            crc: flate2::Crc::new(),
            out: vec![0; READ_SIZE].into_boxed_slice(),
            out_len: 0,
            total: 0,
            done: false,
            position: 0,
            size,
            errors: Vec::new(),
        })
    }

    /// The next chunk, None at the end (or at damage: then `errors` says what and where).
    /// An error is a real I/O error of the file; damage (a cut file, a corrupt deflate stream:
    /// zlib.error) ends the input with its text in `errors`, as the Python reader reports it.
    pub fn next_chunk(&mut self) -> io::Result<Option<&[u8]>> {
        if self.done {
            return Ok(None);
        }
        match self.read() {
            Ok(true) => {
                self.total += self.out_len as u64;
                self.position = self.fp.reached;
                Ok(Some(&self.out[..self.out_len]))
            }
            Ok(false) => {
                self.finish();
                Ok(None)
            }
            Err(Stop::Caught(c)) => {
                // the caller names the file (as the Python reader leaves it to the caller)
                let after = format!(" after {} bytes", self.total);
                let at_start = self.total == 0;
                self.errors.push(
                    compression_damage(c.kind, &c.text, at_start, &after).unwrap_or_else(|| {
                        format!(
                            "read error{after} ({}: {}); the rest is lost",
                            c.kind, c.text
                        )
                    }),
                );
                self.finish();
                Ok(None)
            }
            Err(Stop::Fatal(e)) => {
                self.done = true;
                Err(e)
            }
        }
    }

    fn finish(&mut self) {
        self.done = true;
        self.position = self.size;
    }

    /// `_GzipReader.read(65536)` into `self.out`: false at the clean end of the file.
    fn read(&mut self) -> Result<bool, Stop> {
        loop {
            if self.dec_eof {
                self.read_eof()?;
                self.new_member = true;
                self.dec = Decompress::new(false);
                self.dec_eof = false;
            }
            if self.new_member {
                self.crc = flate2::Crc::new();
                if !self.read_gzip_header()? {
                    return Ok(false);
                }
                self.member_data = self.fp.base + self.fp.pos as u64;
                self.new_member = false;
            }
            let input = self.fp.read(GZ_INPUT_BLOCK).map_err(Stop::Fatal)?;
            let empty_input = input.is_empty();
            self.out_len = 0;
            let (consumed, eof) = self.decompress(input.clone())?;
            // unconsumed_tail or unused_data: back in front of the file
            self.fp.unread(input.len() - consumed);
            self.dec_eof = eof;
            if self.out_len > 0 {
                break;
            }
            if empty_input {
                return Err(eof_error().into());
            }
        }
        self.crc.update(&self.out[..self.out_len]);
        Ok(true)
    }

    /// `decompressobj.decompress(buf, 65536)`: output into `self.out`; returns the input used
    /// and whether the deflate stream ended. A zlib error is damage (`error: ...` in `errors`).
    fn decompress(&mut self, input: std::ops::Range<usize>) -> Result<(usize, bool), Stop> {
        let buf = &self.fp.window[input];
        let mut used = 0;
        loop {
            let before_in = self.dec.total_in();
            let before_out = self.dec.total_out();
            let status = self.dec.decompress(
                &buf[used..],
                &mut self.out[self.out_len..],
                FlushDecompress::Sync,
            );
            used += (self.dec.total_in() - before_in) as usize;
            self.out_len += (self.dec.total_out() - before_out) as usize;
            let progressed = self.dec.total_in() != before_in || self.dec.total_out() != before_out;
            match status {
                Ok(Status::StreamEnd) => return Ok((used, true)),
                Ok(_) => {
                    if self.out_len == self.out.len() || used == buf.len() || !progressed {
                        return Ok((used, false));
                    }
                }
                Err(e) => {
                    let message = match e.message() {
                        Some(REPEATED_CALL) => self.rediagnose().ok().flatten(),
                        m => m.map(str::to_string),
                    };
                    let text = match message {
                        Some(m) => format!("Error -3 while decompressing data: {m}"),
                        None => "Error -3 while decompressing data".to_string(),
                    };
                    // zlib.error: the Python reader catches it as damage, as a cut file
                    return Err(Stop::Caught(Caught {
                        kind: "error",
                        text,
                    }));
                }
            }
        }
    }

    /// zlib's message for the damage in the current member, found by inflating the member again
    /// without zlib-rs's fast path. (zlib-rs 0.6 reports damage found on its fast path, such as
    /// "invalid distance too far back", as "repeated call with bad state"; its slow path, used
    /// while less than 258 bytes of output space are left, words them as zlib does.)
    fn rediagnose(&mut self) -> io::Result<Option<String>> {
        use std::io::{Seek, SeekFrom};
        let mut file = self.fp.file.try_clone()?;
        file.seek(SeekFrom::Start(self.member_data))?;
        let mut dec = Decompress::new(false);
        let mut input = vec![0u8; GZ_INPUT_BLOCK];
        let mut out = [0u8; 257];
        loop {
            let n = read_full(&mut file, &mut input)?;
            if n == 0 {
                return Ok(None);
            }
            let mut used = 0;
            while used < n {
                let (before_in, before_out) = (dec.total_in(), dec.total_out());
                match dec.decompress(&input[used..n], &mut out, FlushDecompress::Sync) {
                    Ok(Status::StreamEnd) => return Ok(None),
                    Ok(_) => {
                        used += (dec.total_in() - before_in) as usize;
                        if dec.total_in() == before_in && dec.total_out() == before_out {
                            break;
                        }
                    }
                    Err(e) => return Ok(e.message().map(str::to_string)),
                }
            }
        }
    }

    /// `_read_gzip_header`: false when the file ends where a member would start.
    fn read_gzip_header(&mut self) -> Result<bool, Stop> {
        let magic = self.fp.read(2).map_err(Stop::Fatal)?;
        if magic.is_empty() {
            return Ok(false);
        }
        let m = &self.fp.window[magic];
        if m != b"\x1f\x8b" {
            return Err(bad_gzip(format!("Not a gzipped file ({})", bytes_repr(m))).into());
        }
        let head = self.fp.read_exact(8)?;
        let (method, flag) = (self.fp.window[head.start], self.fp.window[head.start + 1]);
        if method != 8 {
            return Err(bad_gzip("Unknown compression method".to_string()).into());
        }
        if flag & FEXTRA != 0 {
            let r = self.fp.read_exact(2)?;
            let n = u16::from_le_bytes([self.fp.window[r.start], self.fp.window[r.start + 1]]);
            // a long extra field may span window refills: read it in steps
            let mut left = n as usize;
            while left > 0 {
                let step = left.min(GZ_INPUT_BLOCK);
                self.fp.read_exact(step)?;
                left -= step;
            }
        }
        for bit in [FNAME, FCOMMENT] {
            if flag & bit != 0 {
                // a NUL-terminated string; the end of the file ends it too
                while let Some(c) = self.fp.read_byte().map_err(Stop::Fatal)? {
                    if c == 0 {
                        break;
                    }
                }
            }
        }
        if flag & FHCRC != 0 {
            self.fp.read_exact(2)?;
        }
        Ok(true)
    }

    /// `_read_eof`: the member's CRC and size, then any zero padding.
    fn read_eof(&mut self) -> Result<(), Stop> {
        let r = self.fp.read_exact(8)?;
        let w = &self.fp.window[r];
        let crc = u32::from_le_bytes([w[0], w[1], w[2], w[3]]);
        let isize = u32::from_le_bytes([w[4], w[5], w[6], w[7]]);
        if crc != self.crc.sum() {
            return Err(bad_gzip(format!(
                "CRC check failed {:#x} != {:#x}",
                crc,
                self.crc.sum()
            ))
            .into());
        }
        if isize != self.crc.amount() {
            return Err(bad_gzip("Incorrect length of data produced".to_string()).into());
        }
        loop {
            match self.fp.read_byte().map_err(Stop::Fatal)? {
                Some(0) => {}
                Some(_) => {
                    self.fp.unread(1);
                    break;
                }
                None => break,
            }
        }
        Ok(())
    }
}

// ---------------------------------------------------------------------------------------------

/// A raw byte dump, plain or gzip compressed.
pub enum BytesReader {
    Plain(RawBytesReader),
    Gzip(Box<GzipBytesReader>),
}

impl BytesReader {
    /// Open `path`; `gzip`: read it as capture.py reads a `.gz` (the caller decides by suffix).
    pub fn open(path: &Path, gzip: bool) -> io::Result<Self> {
        Ok(if gzip {
            BytesReader::Gzip(Box::new(GzipBytesReader::open(path)?))
        } else {
            BytesReader::Plain(RawBytesReader::open(path)?)
        })
    }

    /// The next chunk, None at the end (or, for gzip, at damage: see `errors`).
    pub fn next_chunk(&mut self) -> io::Result<Option<&[u8]>> {
        match self {
            BytesReader::Plain(r) => r.next_chunk(),
            BytesReader::Gzip(r) => r.next_chunk(),
        }
    }

    /// Bytes of the file read so far (compressed bytes for gzip).
    pub fn position(&self) -> u64 {
        match self {
            BytesReader::Plain(r) => r.position,
            BytesReader::Gzip(r) => r.position,
        }
    }

    pub fn size(&self) -> u64 {
        match self {
            BytesReader::Plain(r) => r.size,
            BytesReader::Gzip(r) => r.size,
        }
    }

    /// Damage found in the file, as the Python reader's `errors`.
    pub fn errors(&self) -> &[String] {
        match self {
            BytesReader::Plain(_) => &[],
            BytesReader::Gzip(r) => &r.errors,
        }
    }
}

/// A path for the tests.
#[cfg(test)]
fn temp_path(name: &str) -> std::path::PathBuf {
    std::env::temp_dir().join(format!("eg2native-rawfile-{}-{name}", std::process::id()))
}

#[cfg(test)]
mod tests {
    use super::*;
    use flate2::write::GzEncoder;
    use flate2::Compression;
    use std::io::Write;

    fn gz(data: &[u8]) -> Vec<u8> {
        let mut e = GzEncoder::new(Vec::new(), Compression::default());
        e.write_all(data).unwrap();
        e.finish().unwrap()
    }

    fn read_all(name: &str, bytes: &[u8]) -> (Vec<u8>, Vec<String>, io::Result<()>) {
        let p = temp_path(name);
        std::fs::write(&p, bytes).unwrap();
        let mut r = GzipBytesReader::open(&p).unwrap();
        let mut data = Vec::new();
        let res = loop {
            match r.next_chunk() {
                Ok(Some(c)) => data.extend_from_slice(c),
                Ok(None) => break Ok(()),
                Err(e) => break Err(e),
            }
        };
        assert_eq!(r.position, r.size);
        std::fs::remove_file(&p).unwrap();
        (data, r.errors.clone(), res)
    }

    #[test]
    fn members_and_padding() {
        let data: Vec<u8> = (0..200_000u32).map(|i| (i * 7 % 251) as u8).collect();
        let mut file = gz(&data[..1000]);
        file.extend_from_slice(&[0, 0, 0]);
        file.extend(gz(&data[1000..]));
        let (got, errors, res) = read_all("members", &file);
        assert!(res.is_ok() && errors.is_empty());
        assert_eq!(got, data);
    }

    #[test]
    fn damage_as_python_says_it() {
        let data = vec![b'x'; 5000];
        let good = gz(&data);
        let mut trailing = good.clone();
        trailing.extend_from_slice(b"ga'");
        let (got, errors, _) = read_all("trailing", &trailing);
        assert_eq!(got, data);
        assert_eq!(
            errors,
            [
                "the compressed data is damaged after 5000 bytes (Not a gzipped file \
                 (b'ga')); the rest is lost"
            ]
        );
        let (_, errors, _) = read_all("cut", &good[..good.len() - 3]);
        assert_eq!(
            errors,
            ["the compressed file is cut short after 5000 bytes; the rest is lost"]
        );
        let (got, errors, res) = read_all("empty", b"");
        assert!(got.is_empty() && errors.is_empty() && res.is_ok());
    }

    #[test]
    fn paths_as_pathlib_shows_them() {
        for (given, shown) in [
            ("./a//b/", "a/b"),
            ("/x/./y", "/x/y"),
            (".", "."),
            ("a", "a"),
        ] {
            assert_eq!(py_path_str(Path::new(given)), shown);
        }
        let e = check_readable(Path::new("./no/such//file.bin")).unwrap_err();
        assert_eq!(e.to_string(), "capture file not found: no/such/file.bin");
    }

    #[test]
    fn repr_of_bytes() {
        assert_eq!(bytes_repr(b"\x1f"), "b'\\x1f'");
        assert_eq!(bytes_repr(b"'a"), "b\"'a\"");
        assert_eq!(bytes_repr(b"'\""), "b'\\'\"'");
        assert_eq!(bytes_repr(b"\\\n"), "b'\\\\\\n'");
    }
}
