//! The JSONL, CSV and text writers: analyzer/sinks/jsonl.py, csv.py and text.py.
//!
//! Pure formatting of one Record into a byte buffer, byte for byte as the Python sinks write it:
//! - JSONL: `orjson.dumps(Record.to_dict())` + `\n` (key order of decoders/model.py `to_dict`);
//! - CSV: Python's `csv.writer` (excel dialect: `QUOTE_MINIMAL`, `""` inside quotes, `\r\n`),
//!   `fields` as orjson text, errors/warnings/flags joined with `"; "`, None as an empty cell,
//!   floats as `str(x)`;
//! - text: `TextFormatter.format`: time column, padded bus/device/name columns, arrows,
//!   latency suffix, errors and warnings (coloured with `--colour`).
//!
//! Each writer formats into a scratch `String` of its own (json.rs and pyfloat.rs write to a
//! `String`) and appends its bytes to `out`: no allocation per record once the scratch has grown.

use crate::decoders::flags::ESTIMATED_TIME;
use crate::decoders::model::{Record, Segment, FRAME, REQUEST, RESPONSE};
use crate::json::{push_ascii, push_int as push_i64, push_map, push_str, push_u64};
use crate::pyfloat::{push_json_float, push_py_repr};
use std::fmt::Write;
use std::ops::Range;
use std::sync::Arc;

/// The output formats of `eg2scope decode --format`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Format {
    Jsonl,
    Csv,
    Text,
}

/// Options of the text format (`--colour`, `--absolute-time`).
#[derive(Clone, Copy, Debug, Default)]
pub struct TextOptions {
    pub colour: bool,
    pub absolute_time: bool,
}

/// Formats records, in output order, into `out` (the caller flushes `out` in batches). The
/// writers append UTF-8 text only, and may rely on `out` holding nothing else (the callers
/// hand them buffers holding what writers wrote, or empty ones).
pub trait RecordWriter {
    /// What comes before the first record (the CSV header), if anything.
    fn begin(&mut self, _out: &mut Vec<u8>) {}
    fn write(&mut self, rec: &Record, out: &mut Vec<u8>);
    /// What comes after the last record, if anything.
    fn end(&mut self, _out: &mut Vec<u8>) {}
}

/// The writer of a format.
pub fn make_writer(format: Format, text: TextOptions) -> Box<dyn RecordWriter + Send> {
    match format {
        Format::Jsonl => Box::new(JsonlWriter::default()),
        Format::Csv => Box::new(CsvWriter::default()),
        Format::Text => Box::new(TextWriter::new(text)),
    }
}

// ---------------------------------------------------------------------------------------------
// small formatting helpers

const HEX: &[u8; 16] = b"0123456789ABCDEF";

/// `raw.hex(" ").upper()`: "AA 0B 01" (formatted 32 bytes at a time on the stack).
fn push_hex(out: &mut String, raw: &[u8]) {
    out.reserve(raw.len() * 3);
    let mut buf = [b' '; 96];
    for (n, chunk) in raw.chunks(32).enumerate() {
        for (i, &b) in chunk.iter().enumerate() {
            buf[i * 3] = HEX[(b >> 4) as usize];
            buf[i * 3 + 1] = HEX[(b & 15) as usize];
        }
        if n > 0 {
            out.push(' ');
        }
        push_ascii(out, &buf[..chunk.len() * 3 - 1]);
    }
}

/// An orjson list of strings.
fn push_str_list(out: &mut String, items: &[impl AsRef<str>]) {
    out.push('[');
    for (i, s) in items.iter().enumerate() {
        if i > 0 {
            out.push(',');
        }
        push_str(out, s.as_ref());
    }
    out.push(']');
}

fn push_opt_i64(out: &mut String, v: Option<i64>) {
    match v {
        Some(v) => push_i64(out, v),
        None => out.push_str("null"),
    }
}

fn push_opt_u64(out: &mut String, v: Option<u64>) {
    match v {
        Some(v) => push_u64(out, v),
        None => out.push_str("null"),
    }
}

fn push_opt_json_float(out: &mut String, v: Option<f64>) {
    match v {
        Some(v) => push_json_float(out, v),
        None => out.push_str("null"),
    }
}

fn push_opt_json_str(out: &mut String, v: Option<&str>) {
    match v {
        Some(v) => push_str(out, v),
        None => out.push_str("null"),
    }
}

// ---------------------------------------------------------------------------------------------
// JSONL (analyzer/sinks/jsonl.py)

/// `orjson.dumps(rec.to_dict())`: every key of the JSONL contract in `to_dict`'s order.
pub fn push_record_json(out: &mut String, rec: &Record) {
    out.push_str("{\"t\":");
    push_opt_json_float(out, rec.t);
    push_json_head(out, rec);
    push_json_rest(out, rec);
}

/// `,"bus":…,"protocol":…,"kind":…`: the same for most records of a capture.
fn push_json_head(out: &mut String, rec: &Record) {
    out.push_str(",\"bus\":");
    push_str(out, &rec.bus);
    out.push_str(",\"protocol\":");
    push_str(out, rec.protocol);
    out.push_str(",\"kind\":");
    push_str(out, rec.kind);
}

/// The keys after `kind`.
fn push_json_rest(out: &mut String, rec: &Record) {
    push_json_ids(out, rec);
    push_json_segment(out, rec);
    push_json_tail(out, rec);
}

/// `,"offset":…,"index":…,"length":…`
fn push_json_ids(out: &mut String, rec: &Record) {
    out.push_str(",\"offset\":");
    push_opt_u64(out, rec.offset);
    out.push_str(",\"index\":");
    push_opt_u64(out, rec.index);
    out.push_str(",\"length\":");
    push_u64(out, rec.length as u64);
}

/// `,"direction":…` through `,"raw":"…"`: what a memoised decode fixes (with the raw bytes).
fn push_json_segment(out: &mut String, rec: &Record) {
    out.push_str(",\"direction\":");
    push_opt_json_str(out, rec.direction);
    out.push_str(",\"device\":");
    push_opt_i64(out, rec.device);
    out.push_str(",\"code\":");
    push_opt_i64(out, rec.code);
    out.push_str(",\"name\":");
    push_opt_json_str(out, rec.name.as_deref());
    out.push_str(",\"fields\":");
    push_map(out, &rec.fields);
    out.push_str(",\"raw\":\"");
    push_hex(out, &rec.raw); // hex digits and spaces: nothing to escape
    out.push('"');
}

/// The keys after `raw`.
fn push_json_tail(out: &mut String, rec: &Record) {
    push_json_notes(out, rec);
    push_json_links(out, rec);
}

/// `,"errors":…,"warnings":…,"flags":…,"summary":…`
fn push_json_notes(out: &mut String, rec: &Record) {
    out.push_str(",\"errors\":");
    push_str_list(out, &rec.errors);
    out.push_str(",\"warnings\":");
    push_str_list(out, &rec.warnings);
    out.push_str(",\"flags\":");
    push_str_list(out, &rec.flags);
    out.push_str(",\"summary\":");
    push_str(out, &rec.summary);
}

/// `,"seq":…,"pair":…,"latency_ms":…}`
fn push_json_links(out: &mut String, rec: &Record) {
    out.push_str(",\"seq\":");
    push_i64(out, rec.seq);
    out.push_str(",\"pair\":");
    push_opt_i64(out, rec.pair);
    out.push_str(",\"latency_ms\":");
    push_opt_json_float(out, rec.latency_ms);
    out.push('}');
}

/// `push_json_links` and the end of the line, seq copied from `seq_text` (where the same
/// number was written already) if given.
fn push_json_links_after(out: &mut String, rec: &Record, seq_text: Option<Range<usize>>) {
    match seq_text {
        Some(span) => {
            out.push_str(",\"seq\":");
            // SAFETY: the span holds ASCII digits written by push_u64, so `out` stays UTF-8
            unsafe { out.as_mut_vec() }.extend_from_within(span);
            out.push_str(",\"pair\":");
            push_opt_i64(out, rec.pair);
            out.push_str(",\"latency_ms\":");
            push_opt_json_float(out, rec.latency_ms);
            out.push('}');
        }
        None => push_json_links(out, rec),
    }
    out.push('\n');
}

/// One JSON object per record and line, formatted straight into the output buffer.
#[derive(Default)]
pub struct JsonlWriter {
    /// `push_json_head` of the last record, and what it was made of: the same bus (the Arc is
    /// held, so its address cannot be reused) and the same static protocol and kind strings
    /// give the same text, copied at once instead of escaped again.
    head: String,
    head_of: Option<(Arc<str>, &'static str, &'static str)>,
}

impl JsonlWriter {
    fn push_head(&mut self, out: &mut String, rec: &Record) {
        let same = matches!(&self.head_of, Some((bus, protocol, kind))
            if Arc::ptr_eq(bus, &rec.bus)
                && std::ptr::eq(*protocol, rec.protocol)
                && std::ptr::eq(*kind, rec.kind));
        if !same {
            self.head.clear();
            push_json_head(&mut self.head, rec);
            self.head_of = Some((rec.bus.clone(), rec.protocol, rec.kind));
        }
        out.push_str(&self.head);
    }

    /// The line of `rec`, appended to `out`.
    fn line(&mut self, out: &mut String, rec: &Record) {
        out.push_str("{\"t\":");
        push_opt_json_float(out, rec.t);
        self.push_head(out, rec);
        // offset or index: the same number as seq in a single-stream decode (kept to copy)
        out.push_str(",\"offset\":");
        let offset_at = out.len();
        push_opt_u64(out, rec.offset);
        let offset_span = offset_at..out.len();
        out.push_str(",\"index\":");
        let index_at = out.len();
        push_opt_u64(out, rec.index);
        let index_span = index_at..out.len();
        out.push_str(",\"length\":");
        push_u64(out, rec.length as u64);
        let seq = u64::try_from(rec.seq).ok();
        let seq_text = if seq.is_some() && seq == rec.offset {
            Some(offset_span)
        } else if seq.is_some() && seq == rec.index {
            Some(index_span)
        } else {
            None
        };
        // the segments of records that share their decode: formatted once, then copied
        let fields = &rec.fields;
        let quiet = match fields.segment() {
            Some(seg) if seg.matches(rec) => {
                out.push_str(&seg.text);
                seg.quiet_text(rec)
            }
            Some(_) => {
                push_json_segment(out, rec);
                None
            }
            None => {
                let start = out.len();
                push_json_segment(out, rec);
                if fields.is_shared() {
                    let end = out.len();
                    push_json_notes(out, rec);
                    let quiet =
                        (rec.errors.is_empty() && rec.warnings.is_empty() && rec.flags.is_empty())
                            .then(|| (rec.summary.clone(), out[end..].into()));
                    fields.set_segment(|| Segment {
                        direction: rec.direction,
                        device: rec.device,
                        code: rec.code,
                        name: rec.name.clone(),
                        raw: rec.raw.as_slice().into(),
                        text: out[start..end].into(),
                        quiet,
                    });
                    push_json_links_after(out, rec, seq_text);
                    return;
                }
                None
            }
        };
        match quiet {
            Some(text) => out.push_str(text),
            None => push_json_notes(out, rec),
        }
        push_json_links_after(out, rec, seq_text);
    }
}

impl RecordWriter for JsonlWriter {
    fn write(&mut self, rec: &Record, out: &mut Vec<u8>) {
        // no scratch line copied over: `out` itself, as a String for the call (it holds the
        // writers' text only: UTF-8, see `RecordWriter`) and handed back
        // SAFETY: the bytes are UTF-8 (the trait's contract) and only text is appended
        let mut text = unsafe { String::from_utf8_unchecked(std::mem::take(out)) };
        self.line(&mut text, rec);
        *out = text.into_bytes();
    }
}

// ---------------------------------------------------------------------------------------------
// CSV (analyzer/sinks/csv.py)

pub use crate::generated::csv::CSV_COLUMNS;

/// One cell as `csv.writer` (excel dialect, QUOTE_MINIMAL) writes it: quoted when it holds the
/// delimiter, the quote character or a character of the line terminator (`\r`, `\n`), with
/// quotes doubled inside.
fn push_csv_cell(out: &mut String, cell: &str) {
    if !cell
        .bytes()
        .any(|b| matches!(b, b',' | b'"' | b'\r' | b'\n'))
    {
        out.push_str(cell);
        return;
    }
    out.push('"');
    let mut start = 0;
    for (i, b) in cell.bytes().enumerate() {
        if b == b'"' {
            out.push_str(&cell[start..=i]);
            out.push('"');
            start = i + 1;
        }
    }
    out.push_str(&cell[start..]);
    out.push('"');
}

/// A cell whose text needs no quoting (numbers).
fn push_csv_opt_i64(out: &mut String, v: Option<i64>) {
    if let Some(v) = v {
        push_i64(out, v);
    }
}

fn push_csv_opt_u64(out: &mut String, v: Option<u64>) {
    if let Some(v) = v {
        push_u64(out, v);
    }
}

/// `str(x)` of a float cell (repr digits: "inf", "nan", "1e-05" need no quoting either).
fn push_csv_opt_float(out: &mut String, v: Option<f64>) {
    if let Some(v) = v {
        push_py_repr(out, v);
    }
}

fn push_csv_opt_str(out: &mut String, v: Option<&str>) {
    if let Some(v) = v {
        push_csv_cell(out, v);
    }
}

/// `"; ".join(items)` as one cell.
fn push_csv_joined(out: &mut String, scratch: &mut String, items: &[impl AsRef<str>]) {
    match items {
        [] => {}
        [one] => push_csv_cell(out, one.as_ref()),
        _ => {
            scratch.clear();
            for (i, s) in items.iter().enumerate() {
                if i > 0 {
                    scratch.push_str("; ");
                }
                scratch.push_str(s.as_ref());
            }
            push_csv_cell(out, scratch);
        }
    }
}

/// A header row, then one row per record.
#[derive(Default)]
pub struct CsvWriter {
    buf: String,
    cell: String,
}

impl CsvWriter {
    fn row(&mut self, rec: &Record) {
        let out = &mut self.buf;
        let cell = &mut self.cell;
        push_i64(out, rec.seq);
        out.push(',');
        push_csv_opt_float(out, rec.t);
        out.push(',');
        push_csv_cell(out, &rec.bus);
        out.push(',');
        push_csv_cell(out, rec.protocol);
        out.push(',');
        push_csv_cell(out, rec.kind);
        out.push(',');
        push_csv_opt_u64(out, rec.offset);
        out.push(',');
        push_csv_opt_u64(out, rec.index);
        out.push(',');
        push_u64(out, rec.length as u64);
        out.push(',');
        push_csv_opt_str(out, rec.direction);
        out.push(',');
        push_csv_opt_i64(out, rec.device);
        out.push(',');
        push_csv_opt_i64(out, rec.code);
        out.push(',');
        push_csv_opt_str(out, rec.name.as_deref());
        out.push(',');
        push_csv_cell(out, &rec.summary);
        out.push(',');
        cell.clear();
        push_map(cell, &rec.fields);
        push_csv_cell(out, cell);
        out.push(',');
        push_hex(out, &rec.raw); // hex digits and spaces: never quoted
        out.push(',');
        push_csv_joined(out, cell, &rec.errors);
        out.push(',');
        push_csv_joined(out, cell, &rec.warnings);
        out.push(',');
        push_csv_joined(out, cell, &rec.flags);
        out.push(',');
        push_csv_opt_i64(out, rec.pair);
        out.push(',');
        push_csv_opt_float(out, rec.latency_ms);
        out.push_str("\r\n");
    }
}

impl RecordWriter for CsvWriter {
    fn begin(&mut self, out: &mut Vec<u8>) {
        out.extend_from_slice(CSV_COLUMNS.join(",").as_bytes());
        out.extend_from_slice(b"\r\n");
    }

    fn write(&mut self, rec: &Record, out: &mut Vec<u8>) {
        self.buf.clear();
        self.row(rec);
        out.extend_from_slice(self.buf.as_bytes());
    }
}

// ---------------------------------------------------------------------------------------------
// text (analyzer/sinks/text.py)

const RED: &str = "\x1b[31m";
const YELLOW: &str = "\x1b[33m";
const RESET: &str = "\x1b[0m";

/// `s` and spaces up to `width` characters (Python's `f"{s:width}"` counts code points).
fn push_ljust(out: &mut String, s: &str, width: usize) {
    out.push_str(s);
    let n = if s.is_ascii() {
        s.len()
    } else {
        s.chars().count()
    };
    for _ in n..width {
        out.push(' ');
    }
}

/// Spaces, then the `len` characters at `out[from..]`, right-aligned to `width`.
fn rjust_from(out: &mut String, from: usize, width: usize) {
    let n = out[from..].chars().count();
    if n < width {
        out.insert_str(from, &" ".repeat(width - n));
    }
}

/// Python's `f"{x:.{prec}f}"` (also for nan and the infinities, which Rust spells otherwise).
fn push_fixed(out: &mut String, x: f64, prec: usize) {
    if x.is_nan() {
        out.push_str("nan");
    } else if x.is_infinite() {
        out.push_str(if x > 0.0 { "inf" } else { "-inf" });
    } else {
        let _ = write!(out, "{x:.prec$}");
    }
}

/// text.py `TextFormatter`: one line per record, times relative to the first record's (or
/// absolute with `--absolute-time`).
pub struct TextWriter {
    opts: TextOptions,
    t0: Option<f64>,
    buf: String,
}

impl TextWriter {
    pub fn new(opts: TextOptions) -> Self {
        TextWriter {
            opts,
            t0: None,
            buf: String::new(),
        }
    }

    /// `t0`: the time shown as 0 (default: the first record's).
    pub fn with_t0(opts: TextOptions, t0: Option<f64>) -> Self {
        TextWriter {
            opts,
            t0,
            buf: String::new(),
        }
    }

    fn time_column(&mut self, rec: &Record) {
        let out = &mut self.buf;
        let from = out.len();
        match rec.t {
            None => {
                // f"@{where}".rjust(11), where = offset if not None else index (maybe None)
                out.push('@');
                match rec.offset.or(rec.index) {
                    Some(w) => push_u64(out, w),
                    None => out.push_str("None"),
                }
                rjust_from(out, from, 11);
            }
            Some(t) if self.opts.absolute_time => {
                push_fixed(out, t, 6);
                rjust_from(out, from, 17);
            }
            Some(t) => {
                let t0 = *self.t0.get_or_insert(t);
                push_fixed(out, t - t0, 6);
                rjust_from(out, from, 11);
            }
        }
    }

    /// `TextFormatter.format(rec)` (without the line end).
    pub fn format(&mut self, rec: &Record) {
        self.time_column(rec);
        let out = &mut self.buf;
        out.push(' ');
        push_ljust(out, &rec.bus, 6);
        out.push(' ');
        out.push_str(match rec.direction {
            Some(d) if d == REQUEST => "→",
            Some(d) if d == RESPONSE => "←",
            _ => "·",
        });
        out.push(' ');
        match rec.device {
            Some(d) => {
                let from = out.len();
                out.push_str("ID ");
                push_i64(out, d);
                for _ in (out.len() - from)..8 {
                    out.push(' ');
                }
            }
            None => out.push_str("-       "),
        }
        out.push(' ');
        if rec.kind == FRAME {
            let name = match rec.name.as_deref() {
                Some(n) if !n.is_empty() => n,
                _ => rec.protocol,
            };
            push_ljust(out, name, 26);
        } else {
            push_ljust(out, &rec.kind.to_uppercase(), 26);
        }
        out.push(' ');
        out.push_str(&rec.summary);
        if let (Some(ms), Some(RESPONSE)) = (rec.latency_ms, rec.direction) {
            out.push_str(" (");
            if rec.flags.contains(&ESTIMATED_TIME) {
                out.push('~');
            }
            push_fixed(out, ms, 2);
            out.push_str(" ms)");
        }
        if !rec.errors.is_empty() {
            if self.opts.colour {
                out.push_str(RED);
            }
            out.push_str("  !! ");
            push_joined(out, &rec.errors);
            if self.opts.colour {
                out.push_str(RESET);
            }
        }
        if !rec.warnings.is_empty() {
            if self.opts.colour {
                out.push_str(YELLOW);
            }
            out.push_str("  ⚠ ");
            push_joined(out, &rec.warnings);
            if self.opts.colour {
                out.push_str(RESET);
            }
        }
    }
}

fn push_joined(out: &mut String, items: &[String]) {
    for (i, s) in items.iter().enumerate() {
        if i > 0 {
            out.push_str("; ");
        }
        out.push_str(s);
    }
}

impl RecordWriter for TextWriter {
    fn write(&mut self, rec: &Record, out: &mut Vec<u8>) {
        self.buf.clear();
        self.format(rec);
        self.buf.push('\n');
        out.extend_from_slice(self.buf.as_bytes());
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::decoders::model::{Value, EG2_SERIAL, GARBAGE};
    use std::borrow::Cow;
    use std::sync::Arc;

    fn rec() -> Record {
        let mut r = Record::new(
            Some(1.5),
            Arc::from("serial"),
            EG2_SERIAL,
            FRAME,
            vec![0xEB, 0x90, 0x01],
        );
        r.offset = Some(3);
        r.direction = Some(RESPONSE);
        r.device = Some(1);
        r.code = Some(0x10);
        r.name = Some(Cow::Borrowed("CMD_MC_MOVE_CATCH_XG"));
        r.fields = vec![
            (Cow::Borrowed("speed"), Value::Int(500)),
            (Cow::Borrowed("x"), Value::Float(0.5)),
            (Cow::Borrowed("s"), Value::Str(Cow::Borrowed("a,\"b\""))),
        ]
        .into();
        r.summary = "catch speed=500".into();
        r.seq = 7;
        r.pair = Some(6);
        r.latency_ms = Some(0.405);
        r
    }

    fn write_all(format: Format, opts: TextOptions, recs: &[Record]) -> String {
        let mut w = make_writer(format, opts);
        let mut out = Vec::new();
        w.begin(&mut out);
        for r in recs {
            w.write(r, &mut out);
        }
        w.end(&mut out);
        String::from_utf8(out).unwrap()
    }

    #[test]
    fn jsonl_in_to_dict_order() {
        let s = write_all(Format::Jsonl, TextOptions::default(), &[rec()]);
        assert_eq!(
            s,
            "{\"t\":1.5,\"bus\":\"serial\",\"protocol\":\"eg2-serial\",\"kind\":\"frame\",\
             \"offset\":3,\"index\":null,\"length\":3,\"direction\":\"response\",\"device\":1,\
             \"code\":16,\"name\":\"CMD_MC_MOVE_CATCH_XG\",\"fields\":{\"speed\":500,\"x\":0.5,\
             \"s\":\"a,\\\"b\\\"\"},\"raw\":\"EB 90 01\",\"errors\":[],\"warnings\":[],\
             \"flags\":[],\"summary\":\"catch speed=500\",\"seq\":7,\"pair\":6,\
             \"latency_ms\":0.405}\n"
        );
    }

    /// Records sharing one decode (the same `fields` and summary) reuse its JSON text only
    /// where they agree with the record it was made from: every line as the uncached path
    /// writes it.
    #[test]
    fn shared_decodes_write_as_unshared() {
        let first = rec();
        let mut recs = vec![first.clone(), first.clone()];
        let mut r = first.clone();
        r.raw = vec![0xEB, 0x90, 0x02]; // other bytes
        recs.push(r);
        let mut r = first.clone();
        r.warnings.push("late".into()); // a note added after decoding
        r.flags.push("x");
        recs.push(r);
        let mut r = first.clone();
        r.summary = "catch speed=500".into(); // equal text, another Arc
        recs.push(r);
        let mut r = first.clone();
        r.name = None;
        r.direction = Some(REQUEST);
        recs.push(r);
        let mut r = first.clone();
        r.fields.make_mut().push((Cow::Borrowed("y"), Value::Null)); // copied, then changed
        recs.push(r);
        recs.push(first.clone());
        let mut expected = String::new();
        for r in &recs {
            push_record_json(&mut expected, r);
            expected.push('\n');
        }
        assert_eq!(
            write_all(Format::Jsonl, TextOptions::default(), &recs),
            expected
        );
        assert!(first.fields.segment().is_some());
    }

    #[test]
    fn csv_quotes_as_the_csv_module() {
        let mut r = rec();
        r.errors = vec!["a".into(), "b\nc".into()];
        r.t = None;
        let s = write_all(Format::Csv, TextOptions::default(), &[r]);
        let mut lines = s.split("\r\n");
        assert_eq!(lines.next().unwrap(), CSV_COLUMNS.join(","));
        assert_eq!(
            lines.next().unwrap(),
            "7,,serial,eg2-serial,frame,3,,3,response,1,16,CMD_MC_MOVE_CATCH_XG,catch speed=500,\
             \"{\"\"speed\"\":500,\"\"x\"\":0.5,\"\"s\"\":\"\"a,\\\"\"b\\\"\"\"\"}\",EB 90 01,\
             \"a; b\nc\",,,6,0.405"
        );
    }

    #[test]
    fn text_columns() {
        let mut g = Record::new(None, Arc::from("rs485-bus"), EG2_SERIAL, GARBAGE, vec![1]);
        g.offset = Some(12);
        g.errors = vec!["junk".into()];
        let mut r = rec();
        r.t = Some(2.0);
        let mut first = rec();
        first.latency_ms = None;
        let s = write_all(Format::Text, TextOptions::default(), &[first, r, g]);
        let lines: Vec<&str> = s.lines().collect();
        assert_eq!(
            lines[0],
            "   0.000000 serial ← ID 1     CMD_MC_MOVE_CATCH_XG       catch speed=500"
        );
        assert_eq!(
            lines[1],
            "   0.500000 serial ← ID 1     CMD_MC_MOVE_CATCH_XG       catch speed=500 (0.41 ms)"
        );
        assert_eq!(
            lines[2],
            "        @12 rs485-bus · -        GARBAGE                      !! junk"
        );
    }

    #[test]
    fn nan_as_python_writes_it() {
        let mut r = rec();
        r.t = Some(f64::NAN);
        r.latency_ms = Some(f64::INFINITY);
        let j = write_all(
            Format::Jsonl,
            TextOptions::default(),
            std::slice::from_ref(&r),
        );
        assert!(j.starts_with("{\"t\":null,") && j.ends_with("\"latency_ms\":null}\n"));
        let c = write_all(
            Format::Csv,
            TextOptions::default(),
            std::slice::from_ref(&r),
        );
        assert!(c.contains("\r\n7,nan,serial,") && c.ends_with(",6,inf\r\n"));
        let t = write_all(Format::Text, TextOptions::default(), &[r]);
        assert!(t.starts_with("        nan serial") && t.ends_with(" (inf ms)\n"));
    }

    #[test]
    fn fixed_like_python() {
        let mut s = String::new();
        push_fixed(&mut s, f64::NAN, 6);
        push_fixed(&mut s, f64::NEG_INFINITY, 2);
        push_fixed(&mut s, -0.0000001, 6);
        assert_eq!(s, "nan-inf-0.000000");
    }
}
