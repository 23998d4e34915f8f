//! The offline decode path: analyzer/session/stage.py `Decoding` as `eg2scope decode FILE --jobs 1`
//! runs it (analyzer/session.py, analyzer/commands/decode.py and common.py), in one streaming
//! pass: reader -> decoders -> lint -> pairing -> `--device`/`--errors-only` filter -> writer.
//!
//! Nothing is held but what the stages themselves hold (undecided bytes, requests waiting for
//! their answer): memory stays flat at any input size. The output is pulled in batches of
//! bytes (`next_batch`), which the Python binding hands on without looking inside.

use crate::decoders::eg2_can::{CanMemos, Eg2CanDecoder};
use crate::decoders::lint::TimingLinter;
use crate::decoders::model::{CanFrame, Record, EG2_CAN};
use crate::decoders::pairing::Pairer;
use crate::session::byte_stage::ByteStream;
use crate::sinks::writers::{make_writer, Format, RecordWriter, TextOptions};
use crate::sources::candump::{BusNamer, CandumpReader};
use crate::sources::capture::{check_readable, BytesReader};
use std::io;
use std::path::Path;
use std::sync::Arc;

/// CAN frames decoded per step of `next_batch` (about 140 KB of JSONL).
const CAN_STEP: usize = 256;

/// Bytes of a raw dump's chunk handed to the decoder per step (about 100 KB of JSONL): a
/// batch ends at most this much output after its size.
const FEED_SLICE: usize = 2048;

/// The decode command's options the native path supports.
#[derive(Clone, Debug)]
pub struct DecodeOptions {
    /// Byte-stream protocol to force (`eg2-serial` / `modbus-rtu`), None: detect. `eg2-can`
    /// is accepted for CAN captures (and Unsupported for byte streams: Python's usage error).
    pub protocol: Option<&'static str>,
    /// `--bus`: bus name for every record.
    pub bus: Option<String>,
    /// `--device N`: only records of device N.
    pub device: Option<i64>,
    /// `--errors-only`: only records with errors or warnings.
    pub errors_only: bool,
    pub format: Format,
    pub text: TextOptions,
}

// -- which reader ----------------------------------------------------------------------------

/// The readers of analyzer/sources/capture.py `CAPTURE_READERS` the native path has.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ReaderKind {
    /// candump -L text, `.log` or `.log.gz` (`CanLogReader` over `CandumpReader`)
    Candump,
    /// any other suffix: raw bytes of a serial line (`RawBytesReader`)
    Raw,
    /// `.gz`: raw bytes, compressed (`GzipBytesReader`)
    GzipRaw,
}

/// Python's `PurePath.suffixes` (3.11), lower-cased as `reader_for` uses them.
fn suffixes(path: &Path) -> Vec<String> {
    let name = path
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    if name.ends_with('.') {
        return Vec::new();
    }
    let name = name.trim_start_matches('.');
    name.split('.')
        .skip(1)
        .map(|s| format!(".{}", s.to_lowercase()))
        .collect()
}

/// What analyzer/sources/capture.py `reader_for` picks for `path`: by what it holds
/// (sniff.rs), else by its longest registered suffix (`.log.gz` before `.gz`); an
/// `Unsupported` error for what only Python reads (PCAN traces, python-can's formats, MCAP)
/// or refuses (`.mcap.gz`, `.mf4.gz`: a usage error there).
pub fn reader_for(path: &Path) -> io::Result<ReaderKind> {
    match crate::sources::sniff::sniff(path) {
        Some("candump") => return Ok(ReaderKind::Candump),
        Some("bytes") => {
            let gz = suffixes(path).last().is_some_and(|s| s == ".gz");
            return Ok(if gz {
                ReaderKind::GzipRaw
            } else {
                ReaderKind::Raw
            });
        }
        Some(other) => {
            return Err(io::Error::new(
                io::ErrorKind::Unsupported,
                format!(
                    "{}: a {other} capture is read by the Python engine only",
                    path.display()
                ),
            ))
        }
        None => {}
    }
    reader_by_suffix(path)
}

/// `reader_for` by the suffix alone (a file whose content tells nothing).
fn reader_by_suffix(path: &Path) -> io::Result<ReaderKind> {
    const CAN_FORMATS: [&str; 6] = [".log", ".asc", ".blf", ".trc", ".csv", ".mf4"];
    const GZIP_READABLE: [&str; 5] = [".log", ".asc", ".blf", ".trc", ".csv"];
    let registered = |tail: &str| -> Option<&'static str> {
        if tail == ".log" || tail == ".log.gz" {
            return Some("candump");
        }
        if CAN_FORMATS.contains(&tail) {
            return Some("python-can");
        }
        if let Some(inner) = tail.strip_suffix(".gz") {
            if GZIP_READABLE.contains(&inner) {
                return Some("python-can");
            }
        }
        match tail {
            ".mcap" => Some("mcap"),
            ".gz" => Some("gzip"),
            _ => None,
        }
    };
    let unsupported = |what: &str| {
        io::Error::new(
            io::ErrorKind::Unsupported,
            format!(
                "{}: {what} is read by the Python engine only",
                path.display()
            ),
        )
    };
    let sfx = suffixes(path);
    let last_gz = sfx.last().is_some_and(|s| s == ".gz");
    for i in 0..sfx.len() {
        let tail = sfx[i..].concat();
        match registered(&tail) {
            Some("gzip") | None => {}
            Some("candump") => return Ok(ReaderKind::Candump),
            Some(other) => return Err(unsupported(&format!("a {other} capture ({tail})"))),
        }
        let inner = sfx[i..sfx.len() - 1].concat();
        if last_gz && registered(&inner).is_some() {
            return Err(unsupported(&format!("a compressed {inner} capture")));
        }
    }
    Ok(if last_gz {
        ReaderKind::GzipRaw
    } else {
        ReaderKind::Raw
    })
}

// -- the stages ------------------------------------------------------------------------------

/// What decodes: one byte stream (raw dumps), or CAN frames per bus.
enum Decoders {
    Bytes(ByteStream),
    Can(Box<CanBuses>),
}

/// One CAN decoder per bus name (`Decoding._can`), frames numbered across the file.
struct CanBuses {
    /// channel -> bus name, as `CanLogReader` names them (one `Arc` per name)
    names: BusNamer,
    /// by bus name: channels with one name ("0" and "can0") share a decoder, as in Python
    decoders: Vec<(Arc<str>, Eg2CanDecoder)>,
    /// one set of memos for all of them (memory bounded however many channels)
    memos: CanMemos,
    last: usize,
    index: u64,
}

impl CanBuses {
    fn new(fixed: Option<&str>) -> Self {
        CanBuses {
            names: BusNamer::new(fixed),
            decoders: Vec::new(),
            memos: CanMemos::default(),
            last: 0,
            index: 0,
        }
    }

    fn decode(&mut self, frame: &CanFrame) -> Record {
        let bus = self.names.bus(frame.channel.as_deref());
        let hit = self
            .decoders
            .get(self.last)
            .is_some_and(|(b, _)| Arc::ptr_eq(b, &bus));
        if !hit {
            self.last = match self.decoders.iter().position(|(b, _)| Arc::ptr_eq(b, &bus)) {
                Some(i) => i,
                None => {
                    self.decoders.push((bus.clone(), Eg2CanDecoder::new(bus)));
                    self.decoders.len() - 1
                }
            };
        }
        let index = self.index;
        self.index += 1;
        self.decoders[self.last]
            .1
            .decode_with(&mut self.memos, frame, index)
    }
}

/// Where the input comes from.
enum Input {
    Bytes(BytesReader),
    Can(Box<CandumpReader>),
}

/// What happens to decoded records: lint, pairing, the filter, the writer (`Decoding._post`
/// and the session's listeners).
struct Stages {
    linter: TimingLinter,
    pairer: Pairer,
    sink: Sink,
    /// records the pairer released at the end (reused)
    ready: Vec<Record>,
}

impl Stages {
    /// One record through lint and pairing, and out with whatever pairing released.
    #[inline]
    fn post(&mut self, mut rec: Record, out: &mut Vec<u8>) {
        self.linter.check(&mut rec);
        if self.pairer.admit(&mut rec) {
            // the common case: nothing held, nothing waiting: straight out, no copy
            self.sink.write(&rec, out);
        } else {
            // what pairing releases is written where it lies
            let (pairer, sink) = (&mut self.pairer, &mut self.sink);
            pairer.hold_with(rec, &mut |r| sink.write(r, out));
        }
    }

    fn post_all(&mut self, decoded: &mut Vec<Record>, out: &mut Vec<u8>) {
        for rec in decoded.drain(..) {
            self.post(rec, out);
        }
    }

    fn write_ready(&mut self, out: &mut Vec<u8>) {
        for rec in &self.ready {
            self.sink.write(rec, out);
        }
        self.ready.clear();
    }
}

/// The `--device` / `--errors-only` filter (`CaptureOptions.record_filter`) and the writer.
struct Sink {
    device: Option<i64>,
    errors_only: bool,
    writer: Box<dyn RecordWriter + Send>,
    written: u64,
}

impl Sink {
    #[inline]
    fn write(&mut self, rec: &Record, out: &mut Vec<u8>) {
        if let Some(d) = self.device {
            if rec.device != Some(d) {
                return;
            }
        }
        if self.errors_only && rec.errors.is_empty() && rec.warnings.is_empty() {
            return;
        }
        self.writer.write(rec, out);
        self.written += 1;
    }
}

/// One decode of one capture file, pulled in batches of output bytes.
pub struct DecodeRun {
    input: Input,
    decoders: Decoders,
    stages: Stages,
    size: u64,
    errors: Vec<String>,
    started: bool,
    done: bool,
    failure: Option<io::Error>,
    // reused between steps
    decoded: Vec<Record>,
    frame: CanFrame,
    /// the raw dump's chunk being decoded, and where its next slice starts
    chunk: Vec<u8>,
    chunk_at: usize,
}

impl DecodeRun {
    /// Open the capture (by its suffix, as analyzer/sources/capture.py `reader_for`: candump
    /// `.log`/`.log.gz`, anything else raw bytes, `.gz` raw bytes compressed).
    pub fn open(path: &Path, opts: DecodeOptions) -> io::Result<DecodeRun> {
        let writer = make_writer(opts.format, opts.text);
        Self::open_with_writer(path, opts, writer)
    }

    /// `open` with a writer of the caller's instead of `opts.format`'s (parquet/records.rs: columns for
    /// the Parquet output).
    pub fn open_with_writer(
        path: &Path,
        opts: DecodeOptions,
        writer: Box<dyn RecordWriter + Send>,
    ) -> io::Result<DecodeRun> {
        let kind = reader_for(path)?;
        if opts.protocol == Some(EG2_CAN) && kind != ReaderKind::Candump {
            // common.py `open_reader`: a usage error, worded by the Python engine
            return Err(io::Error::new(
                io::ErrorKind::Unsupported,
                format!(
                    "{}: CAN is chosen by the file, not by --protocol",
                    path.display()
                ),
            ));
        }
        check_readable(path)?;
        let size = std::fs::metadata(path)?.len();
        let (input, decoders) = match kind {
            ReaderKind::Candump => {
                let reader = CandumpReader::open(path)?;
                if reader.dated && cfg!(not(unix)) {
                    return Err(io::Error::new(
                        io::ErrorKind::Unsupported,
                        "candump -tA dates are read by the Python engine on this system",
                    ));
                }
                (
                    Input::Can(Box::new(reader)),
                    Decoders::Can(Box::new(CanBuses::new(opts.bus.as_deref()))),
                )
            }
            ReaderKind::Raw | ReaderKind::GzipRaw => {
                let reader = BytesReader::open(path, kind == ReaderKind::GzipRaw)?;
                let stream = ByteStream::new(
                    Arc::from(opts.bus.as_deref().unwrap_or("serial")),
                    opts.protocol.filter(|&p| p != EG2_CAN), // `byte_protocol`
                );
                (Input::Bytes(reader), Decoders::Bytes(stream))
            }
        };
        let stages = Stages {
            linter: TimingLinter::new(),
            // both readers are single-stream: seq is the place in the input
            pairer: Pairer::new(true),
            sink: Sink {
                device: opts.device,
                errors_only: opts.errors_only,
                writer,
                written: 0,
            },
            ready: Vec::new(),
        };
        Ok(DecodeRun {
            input,
            decoders,
            stages,
            size,
            errors: Vec::new(),
            started: false,
            done: false,
            failure: None,
            decoded: Vec::new(),
            frame: CanFrame::default(),
            chunk: Vec::new(),
            chunk_at: 0,
        })
    }

    /// Append the next output bytes to `out` (at least ~`max_bytes` unless the input ends).
    /// Returns false once everything has been written (the last call may append the tail).
    pub fn next_batch(&mut self, out: &mut Vec<u8>, max_bytes: usize) -> bool {
        if self.done {
            return false;
        }
        if !self.started {
            self.started = true;
            self.stages.sink.writer.begin(out);
        }
        let start = out.len();
        while out.len() - start < max_bytes.max(1) {
            if !self.step(out) {
                self.end(out);
                return false;
            }
        }
        true
    }

    /// `next_batch` for a writer that writes no bytes (parquet/records.rs): decode until at least
    /// `max_records` more records were written (unless the input ends). False once everything
    /// has been written.
    pub fn next_records(&mut self, out: &mut Vec<u8>, max_records: u64) -> bool {
        if self.done {
            return false;
        }
        if !self.started {
            self.started = true;
            self.stages.sink.writer.begin(out);
        }
        let start = self.stages.sink.written;
        while self.stages.sink.written - start < max_records.max(1) {
            if !self.step(out) {
                self.end(out);
                return false;
            }
        }
        true
    }

    /// Bytes of the input file read so far (compressed bytes for .gz), for a progress bar.
    pub fn position(&self) -> u64 {
        if self.done {
            return self.size;
        }
        match &self.input {
            Input::Bytes(r) => r.position(),
            Input::Can(r) => CandumpReader::position(r).min(self.size),
        }
    }

    /// Size of the input file in bytes.
    pub fn size(&self) -> u64 {
        self.size
    }

    /// Damage found in the input, as the Python readers' `errors` say it
    /// ("line 12: cannot parse: ...", "compressed data damaged ..."), in order.
    pub fn errors(&self) -> &[String] {
        &self.errors
    }

    /// Records written so far (after the filter).
    pub fn records_written(&self) -> u64 {
        self.stages.sink.written
    }

    /// A read error that ended the input early (the Python would have raised it: the command
    /// fails), if any.
    pub fn failure(&self) -> Option<&io::Error> {
        self.failure.as_ref()
    }

    // -- internals -------------------------------------------------------------------------

    /// Decode one step of input (a slice of a chunk, or up to `CAN_STEP` frames) and write
    /// what is ready. False at the end of the input.
    fn step(&mut self, out: &mut Vec<u8>) -> bool {
        let decoded = &mut self.decoded;
        let stages = &mut self.stages;
        match (&mut self.input, &mut self.decoders) {
            (Input::Bytes(reader), Decoders::Bytes(stream)) => {
                if self.chunk_at >= self.chunk.len() {
                    match reader.next_chunk() {
                        Ok(Some(chunk)) if stream.dec.is_none() => {
                            // held until the protocol is chosen, then decoded as read
                            if let Some(held) = stream.detect(chunk) {
                                self.chunk = held;
                                self.chunk_at = 0;
                            }
                            return true;
                        }
                        Ok(Some(chunk)) => {
                            self.chunk.clear();
                            self.chunk.extend_from_slice(chunk);
                            self.chunk_at = 0;
                        }
                        Ok(None) => return false,
                        Err(e) => {
                            self.failure = Some(e);
                            return false;
                        }
                    }
                }
                // one slice per step: its records are written while still in cache, and a
                // batch ends within a slice's output of its size (a chunk's records would
                // make megabytes of JSON). The decoders give the same records in any
                // chunking (their tests say so).
                let end = self.chunk.len().min(self.chunk_at + FEED_SLICE);
                stream.feed(&self.chunk[self.chunk_at..end], decoded);
                self.chunk_at = end;
                stages.post_all(decoded, out);
                true
            }
            (Input::Can(reader), Decoders::Can(buses)) => {
                for _ in 0..CAN_STEP {
                    if !reader.next_into(&mut self.frame) {
                        return false;
                    }
                    // one frame at a time through lint and pairing (`feed_can`)
                    stages.post(buses.decode(&self.frame), out);
                }
                true
            }
            _ => unreachable!("the reader and the decoders are made together"),
        }
    }

    /// The end of the input: `Decoding.finish`, the reader's errors, the writer's tail.
    fn end(&mut self, out: &mut Vec<u8>) {
        if let Decoders::Bytes(stream) = &mut self.decoders {
            stream.finish(&mut self.decoded);
        }
        self.stages.post_all(&mut self.decoded, out);
        self.stages.pairer.flush(&mut self.stages.ready);
        self.stages.write_ready(out);
        self.stages.sink.writer.end(out);
        match &self.input {
            Input::Bytes(r) => self.errors.extend(r.errors().iter().cloned()),
            Input::Can(r) => self.errors.extend(r.errors.iter().cloned()),
        }
        self.done = true;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn kind(p: &str) -> Result<ReaderKind, io::ErrorKind> {
        reader_for(Path::new(p)).map_err(|e| e.kind())
    }

    #[test]
    fn readers_by_suffix() {
        use ReaderKind::*;
        assert_eq!(kind("a.log"), Ok(Candump));
        assert_eq!(kind("dir.x/A.LOG.GZ"), Ok(Candump));
        assert_eq!(kind("a.b.log"), Ok(Candump));
        assert_eq!(kind("a.bin"), Ok(Raw));
        assert_eq!(kind("a.log.bin"), Ok(Raw));
        assert_eq!(kind("a"), Ok(Raw));
        assert_eq!(kind(".log"), Ok(Raw));
        assert_eq!(kind("a.log."), Ok(Raw));
        assert_eq!(kind("a.bin.gz"), Ok(GzipRaw));
        assert_eq!(kind("a.gz"), Ok(GzipRaw));
        assert_eq!(kind("a.asc"), Err(io::ErrorKind::Unsupported));
        assert_eq!(kind("a.asc.gz"), Err(io::ErrorKind::Unsupported));
        assert_eq!(kind("a.mcap"), Err(io::ErrorKind::Unsupported));
        assert_eq!(kind("a.mcap.gz"), Err(io::ErrorKind::Unsupported));
        assert_eq!(kind("a.mf4.gz"), Err(io::ErrorKind::Unsupported));
        assert_eq!(kind("a.x.mcap.gz"), Err(io::ErrorKind::Unsupported));
    }
}
