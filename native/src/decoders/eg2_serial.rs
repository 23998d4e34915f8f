//! The EG2-4X1 regular serial protocol (RS232), reference section 1. Mirrors
//! `decoders/eg2_serial.py` (`Eg2SerialDecoder`).
//!
//! Frame: `EB 90 | ID | LEN | CMD | DATA (LEN-1) | SUM` from the host, `EE 16 ...` from the
//! gripper; the whole frame is LEN + 5 bytes and SUM = (ID + LEN + CMD + DATA) & 0xFF. Values
//! are u16 little endian.
//!
//! As in the Python, [`COMMANDS`] is a table of messages keyed by CMD, each with its manual
//! name, a summary verb and its request and response layouts (lists of fields, or one of the
//! few payload decoders a flat list cannot describe). A CMD in no table still decodes, as
//! `UNKNOWN_0xNN`. Every error and warning is written with its flag code.
//!
//! Speed: decoding is a pure function of the frame bytes and the same few frames repeat all
//! day, so (as the Python) the decode of a frame is memoised by its bytes; a hit costs a hash
//! lookup and clones.

use crate::decoders::framing::{ByteStreamDecoder, Framing, Stream, NEED_MORE};
use crate::decoders::model::{
    Fields, Notes, Record, SharedFields, Str, Text, Value, EG2_SERIAL, FRAME, REQUEST, RESPONSE,
};
use crate::decoders::registers::{self, opening_mm};
use crate::generated::messages as M;
use crate::hash::FrameMemo;
use crate::pyfloat::py_repr;
use std::borrow::Cow;
use std::fmt::Write;
use std::sync::{Arc, OnceLock};

pub use crate::generated::serial::{
    cmd, BROADCAST, COMMANDS, ID_RANGE, RUN_STATE, RUN_STATE_SIZE, STATUS_FAILED, STATUS_OK,
};

// -- the texts shared with the other protocols (registers.py) ---------------------------------

/// Tables for the values that repeat (Python's `_MM`, `_MM_TEXT`, `_STATE_TEXT`,
/// `_FAULT_SUMMARY`): float formatting is the slow part of a summary.
struct Tables {
    mm: Vec<f64>,
    mm_text: Vec<String>,
    state_text: Vec<String>,
    fault_summary: Vec<String>,
}

fn tables() -> &'static Tables {
    static T: OnceLock<Tables> = OnceLock::new();
    T.get_or_init(|| {
        let mm: Vec<f64> = (0..=1000).map(opening_mm).collect();
        let mm_text = mm.iter().map(|&x| py_repr(x)).collect();
        let state_text = (0..256)
            .map(|s| registers::state_text(s).into_owned())
            .collect();
        let fault_summary = (0..256).map(registers::fault_words).collect();
        Tables {
            mm,
            mm_text,
            state_text,
            fault_summary,
        }
    })
}

fn mm(value: i64) -> f64 {
    if (0..=1000).contains(&value) {
        tables().mm[value as usize]
    } else {
        opening_mm(value)
    }
}

fn push_mm_text(out: &mut String, value: i64) {
    if (0..=1000).contains(&value) {
        out.push_str(&tables().mm_text[value as usize]);
    } else {
        out.push_str(&py_repr(opening_mm(value)));
    }
}

// -- the declarative part --------------------------------------------------------------------

/// Width of one value: struct "B" (u8) or "H" (u16 little endian).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Fmt {
    U8,
    U16,
}

/// One value in a payload. unit "mm" marks a 0-1000 opening, also shown in millimetres.
#[derive(Debug)]
pub struct Field {
    /// name in Record.fields
    pub key: &'static str,
    /// `key + "_mm"` for an opening
    pub mm_key: Option<&'static str>,
    pub fmt: Fmt,
    /// name in the summary line and in range warnings
    pub label: &'static str,
    pub unit: &'static str,
    /// documented range
    pub lo: i64,
    pub hi: i64,
}

/// A payload layout: a list of fields, or a decoder for a payload a flat list cannot describe.
#[derive(Debug)]
pub enum Layout {
    Fields(&'static [Field]),
    /// the one status byte of a write/action response
    Status,
    SetId,
    RunState,
    EgState,
    HandValues,
    HandWriteReply,
}

#[derive(Debug)]
pub struct Command {
    pub code: u8,
    /// the manual's identifier (`CMD_MC_MOVE_CATCH_XG`)
    pub name: &'static str,
    /// request summary ("catch", "read limits")
    pub verb: &'static str,
    pub request: Layout,
    pub response: Layout,
    /// the hand's name for the same code (section 1.2)
    pub alias: Option<&'static str>,
}

/// One value of the 0x41 reply (Python `RunStateValue`): its place, and the state field it
/// reports (an index into `tracker::VALUE_KEYS`).
#[derive(Clone, Copy, Debug)]
pub struct RunStateValue {
    /// name in Record.fields
    pub key: &'static str,
    pub offset: usize,
    /// 1 (u8) or 2 (u16 little endian)
    pub width: usize,
    pub state: usize,
    /// name in range warnings
    pub label: &'static str,
    /// documented range, None where the manual gives none
    pub lo: Option<i64>,
    pub hi: Option<i64>,
}

impl RunStateValue {
    /// The value in a reply of `RUN_STATE_SIZE` bytes.
    pub fn read(&self, data: &[u8]) -> i64 {
        if self.width == 1 {
            i64::from(data[self.offset])
        } else {
            u16_at(data, self.offset)
        }
    }
}

/// CMD -> index in COMMANDS + 1 (0: no command), built at compile time.
static BY_CODE: [u8; 256] = {
    let mut t = [0u8; 256];
    let mut i = 0;
    while i < COMMANDS.len() {
        t[COMMANDS[i].code as usize] = i as u8 + 1;
        i += 1;
    }
    t
};

/// The command of a CMD byte, if either table lists it.
pub fn command_of(code: u8) -> Option<&'static Command> {
    match BY_CODE[code as usize] {
        0 => None,
        i => Some(&COMMANDS[i as usize - 1]),
    }
}

/// SUM over ID + LEN + CMD + DATA (everything between the header and SUM).
pub fn checksum(body: &[u8]) -> u8 {
    body.iter().fold(0u8, |a, &b| a.wrapping_add(b))
}

// -- the decode of one payload ----------------------------------------------------------------

/// `bytes.hex(" ").upper()`
fn push_hex(out: &mut String, data: &[u8]) {
    const HEX: &[u8; 16] = b"0123456789ABCDEF";
    for (i, &b) in data.iter().enumerate() {
        if i > 0 {
            out.push(' ');
        }
        out.push(HEX[(b >> 4) as usize] as char);
        out.push(HEX[(b & 15) as usize] as char);
    }
}

fn hex(data: &[u8]) -> String {
    let mut s = String::with_capacity(data.len() * 3);
    push_hex(&mut s, data);
    s
}

fn words(n: usize) -> String {
    format!("{n} data byte{}", if n == 1 { "" } else { "s" })
}

fn u16_at(data: &[u8], i: usize) -> i64 {
    (data[i] as i64) | (data[i + 1] as i64) << 8
}

/// `_u16_list`: the u16 values of data and the odd byte left over.
fn u16_list(data: &[u8]) -> (Value, &[u8]) {
    let even = data.len() & !1;
    let values = data[..even]
        .chunks_exact(2)
        .map(|p| Value::Int(u16_at(p, 0)))
        .collect();
    (Value::List(values), &data[even..])
}

fn key(k: &'static str) -> Str {
    Cow::Borrowed(k)
}

/// One payload's decode: the body fields go to `fields` (after `id`), the summary to
/// `summary`, errors and warnings to `notes`.
struct Payload<'a> {
    cmd: &'a Command,
    direction: &'static str,
    device: u8,
    fields: &'a mut Fields,
    summary: &'a mut String,
    notes: &'a mut Notes,
}

impl Payload<'_> {
    fn head(&self) -> &'static str {
        if self.direction == REQUEST {
            self.cmd.verb
        } else {
            "->"
        }
    }

    fn decode(&mut self, layout: &Layout, data: &[u8]) {
        match layout {
            Layout::Fields(fl) => self.fields_layout(fl, data),
            Layout::Status => self.status(data),
            Layout::SetId => self.set_id(data),
            Layout::RunState => self.run_state(data),
            Layout::EgState => self.eg_state(data),
            Layout::HandValues => self.hand_values(data),
            Layout::HandWriteReply => {
                // a hand-compatible write is answered like any write, if it is short
                if data.len() == 1 {
                    self.status(data)
                } else {
                    self.hand_values(data)
                }
            }
        }
    }

    /// A payload that does not fit the documented layout: show it raw, never guess.
    fn mismatch(&mut self, expected: &str, data: &[u8]) {
        let h = hex(data);
        self.fields
            .push((key("data"), Value::Str(Cow::Owned(h.clone()))));
        if self.cmd.alias.is_some() && data.len() >= 2 {
            // the hand's form of this code carries a list of u16 (section 1.2)
            self.fields.push((key("values"), u16_list(data).0));
        }
        self.notes.error_of(M::serial_layout!(
            name = self.cmd.name,
            direction = self.direction,
            expected = expected,
            length = data.len()
        ));
        let head = self.head();
        let s = &mut *self.summary;
        s.push_str(head);
        s.push_str(" unexpected data ");
        s.push_str(if h.is_empty() { "(none)" } else { &h });
    }

    /// A flat list of fields (Python `_compile`'s decode).
    fn fields_layout(&mut self, layout: &'static [Field], data: &[u8]) {
        let size: usize = layout
            .iter()
            .map(|f| if f.fmt == Fmt::U8 { 1 } else { 2 })
            .sum();
        if data.len() != size {
            return self.mismatch(&words(size), data);
        }
        let head = self.head();
        let s = &mut *self.summary;
        s.push_str(head);
        let mut i = 0;
        for f in layout {
            let v = match f.fmt {
                Fmt::U8 => data[i] as i64,
                Fmt::U16 => u16_at(data, i),
            };
            i += if f.fmt == Fmt::U8 { 1 } else { 2 };
            self.fields.push((key(f.key), Value::Int(v)));
            s.push(' ');
            s.push_str(f.label);
            s.push('=');
            let _ = write!(s, "{v}");
            match f.mm_key {
                None => {
                    if !f.unit.is_empty() {
                        s.push(' ');
                        s.push_str(f.unit);
                    }
                }
                Some(mm_key) => {
                    self.fields.push((key(mm_key), Value::Float(mm(v))));
                    s.push_str(" (");
                    push_mm_text(s, v);
                    s.push_str(" mm)");
                }
            }
            if !(f.lo <= v && v <= f.hi) {
                self.notes.warn_of(M::value_out_of_range!(
                    label = f.label,
                    lo = f.lo,
                    hi = f.hi,
                    value = v
                ));
            }
        }
    }

    /// The one status byte of a write/action response: 0x01 ok, 0x55 failure.
    fn status(&mut self, data: &[u8]) {
        if data.len() != 1 {
            return self.mismatch("1 data byte (status)", data);
        }
        let b = data[0];
        if b == STATUS_OK {
            self.fields.push((key("status"), Value::from("ok")));
            self.summary.push_str("-> ok");
        } else if b == STATUS_FAILED {
            self.notes.warn_of(M::SERIAL_WRITE_FAILED);
            self.fields.push((key("status"), Value::from("failure")));
            self.summary.push_str("-> FAILED (0x55)");
        } else {
            // a status the manual does not list: not said to have failed, not said to be ok
            self.notes.warn_of(M::serial_unknown_status!(status = b));
            self.fields
                .push((key("status"), Value::from(format!("unknown 0x{b:02X}"))));
            let _ = write!(self.summary, "-> unknown status 0x{b:02X}");
        }
    }

    /// New ID: one byte per the manual, a u16 LE in one client's code (section 4).
    fn set_id(&mut self, data: &[u8]) {
        let (new_id, width) = match data.len() {
            1 => (data[0] as i64, 1),
            2 => (u16_at(data, 0), 2),
            _ => return self.mismatch("1 or 2 data bytes", data),
        };
        let (lo, hi) = ID_RANGE;
        if !(lo <= new_id && new_id <= hi) {
            self.notes.warn_of(M::value_out_of_range!(
                label = "new_id",
                lo = lo,
                hi = hi,
                value = new_id
            ));
        }
        if self.device == BROADCAST {
            self.notes.warn_of(M::SERIAL_SET_ID_BROADCAST);
        }
        let _ = write!(self.summary, "set ID {} -> {new_id}", self.device);
        if width == 2 {
            self.summary.push_str(" (2-byte value)");
        }
        self.fields.push((key("new_id"), Value::Int(new_id)));
        self.fields.push((key("id_width"), Value::Int(width)));
    }

    /// 0x41 reply: state u8, fault u8, temperature u8, position u16, force setting u16.
    fn run_state(&mut self, data: &[u8]) {
        if data.len() != RUN_STATE_SIZE {
            return self.mismatch(&words(RUN_STATE_SIZE), data);
        }
        let values = RUN_STATE.map(|v| v.read(data));
        let [state, fault, temp, pos, force] = values;
        let tb = tables();
        let text: &'static str = &tb.state_text[state as usize];
        let faults: &'static str = &tb.fault_summary[fault as usize];
        let f = &mut *self.fields;
        f.push((key("state"), Value::Int(state)));
        f.push((key("state_text"), Value::Str(Cow::Borrowed(text))));
        f.push((key("fault"), Value::Int(fault)));
        f.push((
            key("fault_text"),
            Value::List(
                registers::fault_text(fault)
                    .into_iter()
                    .map(|w| Value::Str(Cow::Borrowed(w)))
                    .collect(),
            ),
        ));
        f.push((key("temperature_c"), Value::Int(temp)));
        f.push((key("position"), Value::Int(pos)));
        f.push((key("position_mm"), Value::Float(mm(pos))));
        f.push((key("force_setting_g"), Value::Int(force)));
        let s = &mut *self.summary;
        let _ = write!(
            s,
            "-> state={state} {text}, {faults}, {temp} °C, position={pos} ("
        );
        push_mm_text(s, pos);
        let _ = write!(s, " mm), force setting={force} g");
        for (spec, value) in RUN_STATE.iter().zip(values) {
            if spec.key == "fault" {
                // fault bits, not a range
                if value != 0 {
                    self.notes.warn_of(M::serial_device_fault!(faults = faults));
                }
            } else if let (Some(lo), Some(hi)) = (spec.lo, spec.hi) {
                if !(lo..=hi).contains(&value) {
                    self.notes.warn_of(M::value_out_of_range!(
                        label = spec.label,
                        lo = lo,
                        hi = hi,
                        value = value
                    ));
                }
            }
        }
    }

    /// 0x14 reply: not documented. One client reads opening, force, threshold (section 4).
    fn eg_state(&mut self, data: &[u8]) {
        let h = hex(data);
        self.fields
            .push((key("data"), Value::Str(Cow::Owned(h.clone()))));
        let s = &mut *self.summary;
        if data.len() != 6 {
            let _ = write!(s, "-> {} {h} (layout not documented)", words(data.len()));
            return;
        }
        let (opening, force, threshold) = (u16_at(data, 0), u16_at(data, 2), u16_at(data, 4));
        self.fields.push((
            key("probable"),
            Value::Map(vec![
                (key("opening"), Value::Int(opening)),
                (key("force"), Value::Int(force)),
                (key("force_threshold"), Value::Int(threshold)),
            ]),
        ));
        let _ = write!(
            s,
            "-> {h}, probable layout (unverified): opening={opening} ("
        );
        push_mm_text(s, opening);
        let _ = write!(s, " mm) force={force} force threshold={threshold}");
    }

    /// Hand-compatible codes: the gripper's payload lengths are unknown, so u16 values by LEN.
    fn hand_values(&mut self, data: &[u8]) {
        let head = self.head();
        let s = &mut *self.summary;
        s.push_str(head);
        if data.is_empty() {
            return;
        }
        let (values, rest) = u16_list(data);
        s.push_str(" values=");
        if let Value::List(items) = &values {
            for (i, v) in items.iter().enumerate() {
                if i > 0 {
                    s.push(',');
                }
                if let Value::Int(v) = v {
                    let _ = write!(s, "{v}");
                }
            }
        }
        self.fields.push((key("values"), values));
        if !rest.is_empty() {
            // an odd byte left over
            let h = hex(rest);
            s.push_str(" extra=");
            s.push_str(&h);
            self.fields.push((key("extra"), Value::Str(Cow::Owned(h))));
        }
    }
}

/// Everything about a frame that depends only on its bytes (Python's `_Entry`).
#[derive(Clone, Debug)]
struct Entry {
    direction: Option<&'static str>,
    device: Option<i64>,
    code: Option<i64>,
    name: Option<Str>,
    fields: SharedFields,
    summary: Text,
    errors: Vec<String>,
    warnings: Vec<String>,
    pair_key: Option<[i64; 2]>,
    expects: bool,
    save: bool,
    flags: Vec<&'static str>,
}

impl Entry {
    /// A record of these bytes (fresh lists: the pairing and lint stages append to them).
    /// (One struct literal: built in place, not built empty and then copied.)
    #[inline]
    fn record(&self, s: &Stream, raw: &[u8], offset: u64, t: Option<f64>) -> Record {
        Record {
            t,
            bus: s.bus.clone(),
            protocol: EG2_SERIAL,
            kind: FRAME,
            length: raw.len(),
            raw: raw.to_vec(),
            offset: Some(offset),
            index: None,
            direction: self.direction,
            device: self.device,
            code: self.code,
            name: self.name.clone(),
            fields: self.fields.clone(),
            errors: self.errors.clone(),
            warnings: self.warnings.clone(),
            summary: self.summary.clone(),
            seq: -1,
            pair: None,
            latency_ms: None,
            pair_key: self.pair_key,
            expects_response: self.expects,
            is_save: self.save,
            flags: self.flags.clone(),
        }
    }
}

/// Everything about a frame that depends only on its bytes (`_decode`).
fn decode(raw: &[u8]) -> Entry {
    let n = raw.len();
    if n < 6 || raw[3] as usize + 5 != n || !matches!((raw[0], raw[1]), (0xEB, 0x90) | (0xEE, 0x16))
    {
        return malformed(raw); // the framer only hands over well-framed bytes
    }
    let direction = if raw[0] == 0xEB { REQUEST } else { RESPONSE };
    let (device, code, data) = (raw[2], raw[4], &raw[5..n - 1]);
    let mut notes = Notes::default();
    note_header(raw, direction, &mut notes); // the header's problems come first
                                             // room for the largest layout (run state: id + 8 values), so nothing grows
    let mut fields: Fields = Vec::with_capacity(9);
    fields.push((key("id"), Value::Int(device as i64)));
    let mut summary = String::with_capacity(128);
    let name: Str = match command_of(code) {
        None => {
            unknown(code, data, &mut fields, &mut summary, &mut notes);
            Cow::Owned(format!("UNKNOWN_0x{code:02X}"))
        }
        Some(c) => {
            let layout = if direction == REQUEST {
                &c.request
            } else {
                &c.response
            };
            Payload {
                cmd: c,
                direction,
                device,
                fields: &mut fields,
                summary: &mut summary,
                notes: &mut notes,
            }
            .decode(layout, data);
            if let Some(alias) = c.alias {
                fields.push((key("alias"), Value::from(alias)));
            }
            Cow::Borrowed(c.name)
        }
    };
    Entry {
        direction: Some(direction),
        device: Some(device as i64),
        code: Some(code as i64),
        name: Some(name),
        fields: fields.into(),
        summary: summary.into(),
        errors: notes.errors,
        warnings: notes.warnings,
        pair_key: Some([device as i64, code as i64]),
        expects: direction == REQUEST && device != BROADCAST,
        save: direction == REQUEST && code == cmd::PARA_SAVE,
        flags: notes.flags,
    }
}

/// The entry of bytes that do not fit a header and its length byte (`_malformed`).
fn malformed(raw: &[u8]) -> Entry {
    let (flag, error) = M::serial_frame_shape!(length = raw.len());
    Entry {
        direction: None,
        device: None,
        code: None,
        name: None,
        fields: vec![(key("data"), Value::Str(Cow::Owned(hex(raw))))].into(),
        summary: Text::from("malformed frame"),
        errors: vec![error],
        warnings: Vec::new(),
        pair_key: None,
        expects: false,
        save: false,
        flags: vec![flag],
    }
}

/// The header's problems: a checksum that fails, an invalid or broadcast ID (`_note_header`).
fn note_header(raw: &[u8], direction: &str, notes: &mut Notes) {
    let n = raw.len();
    let device = raw[2];
    let (expected, got) = (checksum(&raw[2..n - 1]), raw[n - 1]);
    if expected != got {
        notes.error_of(M::serial_checksum!(expected = expected, got = got));
    }
    if device == 0 {
        notes.warn_of(M::SERIAL_ID_ZERO);
    } else if device == BROADCAST && direction == RESPONSE {
        notes.warn_of(M::SERIAL_BROADCAST_RESPONSE);
    }
}

/// A CMD in neither table: still a frame when SUM checks; its bytes are shown (`_unknown`).
fn unknown(code: u8, data: &[u8], fields: &mut Fields, summary: &mut String, notes: &mut Notes) {
    let _ = write!(summary, "unknown command 0x{code:02X}");
    if !data.is_empty() {
        summary.push_str(": ");
        push_hex(summary, data);
    }
    notes.warn_of(M::serial_unknown_command!(code = code));
    fields.push((key("data"), Value::Str(Cow::Owned(hex(data)))));
}

/// frame_at for fewer than 4 bytes: 0 as soon as the header is wrong, else wait.
fn short_candidate(buf: &[u8], pos: usize) -> i64 {
    let head = &buf[pos..buf.len().min(pos + 2)];
    match head {
        [0xEB, 0x90] | [0xEE, 0x16] | [0xEB] | [0xEE] => NEED_MORE,
        _ => 0,
    }
}

/// Memoised decodes per generation (crate::hash::FrameMemo: at most two generations held): a
/// live bus repeats few frames, memory stays flat. (The Python keeps 50,000; the memo never
/// changes the output, and here fewer are as fast on benchmark traffic while all-distinct
/// frames stay in a few MB.)
const CACHE_GENERATION: usize = 4096;

/// The protocol hooks of the regular serial protocol (the Python `Eg2SerialDecoder`'s
/// overrides); [`Eg2SerialDecoder`] is the framer driving them.
pub struct Eg2Serial {
    cache: FrameMemo<Entry>,
}

impl std::fmt::Debug for Eg2Serial {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("Eg2Serial")
    }
}

impl Default for Eg2Serial {
    fn default() -> Self {
        Eg2Serial {
            cache: FrameMemo::new(CACHE_GENERATION),
        }
    }
}

impl Framing for Eg2Serial {
    const PROTOCOL: &'static str = EG2_SERIAL;
    const SKIPS: bool = true;

    fn frame_at(&mut self, s: &Stream, pos: usize, _final: bool) -> i64 {
        let buf = &s.buf;
        if pos + 3 >= buf.len() {
            // fewer than 4 bytes: the length is not known yet
            return short_candidate(buf, pos);
        }
        let (b0, b1, size) = (buf[pos], buf[pos + 1], buf[pos + 3] as usize + 5);
        if !((b0 == 0xEB && b1 == 0x90) || (b0 == 0xEE && b1 == 0x16)) {
            return 0;
        }
        if size == 5 {
            return 0; // LEN 0: no CMD, not a frame
        }
        let end = pos + size - 1; // index of SUM
        if end >= buf.len() {
            return NEED_MORE;
        }
        if checksum(&buf[pos + 2..end]) == buf[end] {
            size as i64
        } else {
            -(size as i64)
        }
    }

    fn next_start(&mut self, buf: &[u8], pos: usize) -> usize {
        // a header, or its first byte as the last byte held (the second may be on its way)
        let n = buf.len();
        let mut p = pos;
        while p < n {
            match buf[p] {
                0xEB if p + 1 == n || buf[p + 1] == 0x90 => return p,
                0xEE if p + 1 == n || buf[p + 1] == 0x16 => return p,
                _ => p += 1,
            }
        }
        n
    }

    fn make_record(
        &mut self,
        s: &Stream,
        raw: &[u8],
        offset: u64,
        t: Option<f64>,
        _valid: bool,
    ) -> Record {
        // valid is implied by raw (the checksum is part of it), so the cache key is raw alone
        self.cache
            .get_or_insert_with(raw, || decode(raw))
            .record(s, raw, offset, t)
    }

    fn truncated_reason(&self, raw: &[u8]) -> String {
        if raw.len() < 4 {
            return M::serial_truncated_header!(length = raw.len()).1;
        }
        let needed = raw[3] as usize + 5;
        M::serial_truncated_body!(len_byte = raw[3], needed = needed, length = raw.len()).1
    }
}

/// Feed chunks of an RS232 tap (either or both directions interleaved), get Records.
pub type Eg2SerialDecoder = ByteStreamDecoder<Eg2Serial>;

impl ByteStreamDecoder<Eg2Serial> {
    pub fn new(bus: Arc<str>) -> Self {
        Self::with_protocol(Eg2Serial::default(), bus, None)
    }

    /// With the line's byte time (10 bits / baud): records' times are counted back from the
    /// chunk times at line speed.
    pub fn with_byte_time(bus: Arc<str>, byte_time_s: Option<f64>) -> Self {
        Self::with_protocol(Eg2Serial::default(), bus, byte_time_s)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::decoders::framing::StreamDecoder;

    fn frame(header: [u8; 2], id: u8, code: u8, data: &[u8]) -> Vec<u8> {
        let mut f = vec![header[0], header[1], id, data.len() as u8 + 1, code];
        f.extend_from_slice(data);
        f.push(checksum(&f[2..]));
        f
    }

    fn decode_all(data: &[u8]) -> Vec<Record> {
        let mut d = Eg2SerialDecoder::new(Arc::from("serial"));
        let mut out = Vec::new();
        d.feed(data, None, &mut out);
        d.finish(&mut out);
        out
    }

    #[test]
    fn catch_request() {
        let f = frame(
            [0xEB, 0x90],
            1,
            cmd::MOVE_CATCH_XG,
            &[0xF4, 0x01, 0x64, 0x00],
        );
        let r = &decode_all(&f)[0];
        assert_eq!(&*r.summary, "catch speed=500 force=100 g");
        assert_eq!(r.name.as_deref(), Some("CMD_MC_MOVE_CATCH_XG"));
        assert!(r.expects_response);
    }

    #[test]
    fn run_state_with_fault() {
        let f = frame(
            [0xEE, 0x16],
            1,
            cmd::READ_EG_RUNSTATE,
            &[4, 0x21, 37, 0xF4, 1, 100, 0],
        );
        let r = &decode_all(&f)[0];
        assert_eq!(
            &*r.summary,
            "-> state=4 closing, stall, reserved bit 5, 37 °C, position=500 (35.0 mm), \
             force setting=100 g"
        );
        assert_eq!(
            r.warnings,
            vec!["gripper reports fault: stall, reserved bit 5"]
        );
    }

    #[test]
    fn hand_values_odd_byte() {
        let f = frame([0xEB, 0x90], 1, cmd::READ_DRVALL_SPEED, &[7]);
        assert_eq!(
            &*decode_all(&f)[0].summary,
            "read speed (hand-compatible) values= extra=07"
        );
    }

    #[test]
    fn truncated_reasons() {
        let out = decode_all(&[0xEB, 0x90, 0x01]);
        assert_eq!(
            out[0].errors,
            vec!["truncated frame: stream ended 3 bytes in, before the length byte"]
        );
        let out = decode_all(&[0xEE, 0x16, 0x01, 0x05, 0x10]);
        assert_eq!(
            out[0].errors,
            vec!["truncated frame: LEN 5 needs 10 bytes, stream ended after 5"]
        );
    }

    #[test]
    fn bad_checksum_keeps_the_decode() {
        let out = decode_all(&[0xEE, 0x16, 0x01, 0x03, 0xD9, 0xE8, 0x03, 0x74]);
        assert_eq!(
            out[0].errors,
            vec!["checksum error: expected 0xC8, got 0x74"]
        );
        assert_eq!(out[0].fields[2], (key("position_mm"), Value::Float(70.0)));
    }

    #[test]
    fn idle_line_decides_what_is_held() {
        let mut d = Eg2SerialDecoder::new(Arc::from("serial"));
        let mut out = Vec::new();
        d.feed(&[0xEB, 0x90, 0x01, 0x05, 0x10], Some(10.0), &mut out);
        d.idle(10.05, &mut out);
        assert!(out.is_empty()); // not quiet long enough
        d.idle(10.2, &mut out);
        assert_eq!(out.len(), 1);
        assert_eq!(out[0].kind, crate::decoders::model::TRUNCATED);
        assert_eq!(out[0].t, Some(10.0));
    }
}
