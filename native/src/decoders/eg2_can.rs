//! The EG2-4X0 CAN register protocol (reference section 3): CanFrame -> Record.
//!
//! Mirrors `decoders/eg2_can.py` (`Eg2CanDecoder`); read that module's docstring for the
//! rules. The 29-bit identifier packs `reserved(1) | operation(2) | start address(12) |
//! device(14)`. Direction comes from the frame's shape and a table of pending requests per
//! identifier (`Directions`, the Python `_Directions`), so decoding is stateful and in order.
//!
//! The Python memoises decoded parts (per frame, per identifier layout, per register value);
//! the caches here are the same idea and, as there, never change the output: every cached
//! part is a pure function of its key.

use std::borrow::Cow;
use std::collections::HashSet;
use std::fmt::Write;
use std::sync::{Arc, Mutex, OnceLock};

use crate::decoders::flags as F;
use crate::decoders::model::{
    CanFrame, Fields, Notes, PairKey, Record, SharedFields, Str, Text, Value, EG2_CAN, FOREIGN_CAN,
    FRAME,
};
use crate::decoders::model::{REQUEST, RESPONSE};
use crate::decoders::registers::{self, by_can_address, fault_text, state_text, RegRef, Register};
use crate::generated::messages as M;

pub use crate::generated::can::{
    BROADCAST, CAN_ERR_CLASSES, MAP_FIRST, MAP_LAST, MAX_ID, MEMO_LIMIT, OPERATIONS, OP_READ,
    OP_WRITE, PENDING_LIMIT, PENDING_TIMEOUT_S, RESERVED_BIT,
};

/// Memo sizes: the Python's MEMO_LIMIT (reaching it only empties a cache, the output is the
/// same), but here the memos of decodes are smaller than the Python's (each decode keeps its JSON text
/// too): at most two generations of this many (crate::hash::FrameMemo), and this many layouts;
/// benchmark traffic hits as often, and hostile input (every frame new) stays in a few MB.
const MEMO_GENERATION: usize = 2048;
const LAYOUT_LIMIT: usize = 4096;
const VALUE_CACHE_LIMIT: usize = 1 << 14;

// direction tags
const TAG_REQUEST: u32 = 0;
const TAG_RESPONSE: u32 = 1;
const TAG_NONE: u32 = 2;
/// a response whose length does not match the pending request: TAG_MISMATCH + expected length
const TAG_MISMATCH: u32 = 16;

use crate::hash::{FastMap, FrameMemo};

/// (operation, start address, device) of an EG2 identifier.
pub fn unpack_id(aid: u32) -> (u32, u32, u32) {
    ((aid >> 26) & 3, (aid >> 14) & 0xFFF, aid & 0x3FFF)
}

/// An error frame's identifier (SocketCAN error class bits) in words.
pub fn can_error_text(error_class: u32) -> String {
    let words: Vec<&str> = CAN_ERR_CLASSES
        .iter()
        .filter(|(bit, _)| error_class & bit != 0)
        .map(|(_, text)| *text)
        .collect();
    if words.is_empty() {
        return M::CAN_ERROR_FRAME.1.to_string();
    }
    M::can_error_frame_classes!(classes = words.join(", "), error_class = error_class).1
}

/// A read request's or write response's shape: one count byte 1-8, or 8 bytes zero padded.
fn count_shaped(data: &[u8]) -> bool {
    let n = data.len();
    (n == 1 || (n == 8 && data[1..].iter().all(|&b| b == 0))) && (1..=8).contains(&data[0])
}

/// A pending request on one identifier (Python `_Pending`).
#[derive(Clone, Copy, Debug)]
struct Pending {
    /// length asked for (read) or written (write)
    n: usize,
    data: [u8; 8],
    len: u8,
    t: Option<f64>,
    /// unanswered copies (a host's retransmissions)
    copies: u32,
    /// whether a copy has been answered
    answered: bool,
}

impl Pending {
    fn data(&self) -> &[u8] {
        &self.data[..self.len as usize]
    }
}

/// Which way an EG2 read or write frame goes (Python `_Directions`): its shape, then the
/// request pending on its identifier. Broadcasts are never pending.
#[derive(Default)]
struct Directions {
    pending: FastMap<u32, Pending>,
}

impl Directions {
    /// The direction tag of a read (op 0) or write (op 1) frame (of at most 8 bytes), from its
    /// shape and the request pending on its identifier; `note` keeps the pending table.
    fn tag(&mut self, aid: u32, op: u32, data: &[u8], t: Option<f64>) -> u32 {
        let mut pend = self.pending.get(&aid).copied();
        if let (Some(p), Some(t)) = (pend, t) {
            if let Some(pt) = p.t {
                if t - pt > PENDING_TIMEOUT_S {
                    pend = None; // too old to be answered (the entry stays, as in Python)
                }
            }
        }
        let mut n = data.len();
        let shaped = count_shaped(data);
        let tag;
        if op == OP_READ {
            if pend.is_some_and(|p| p.n == n) {
                tag = TAG_RESPONSE;
            } else if shaped {
                tag = TAG_REQUEST;
                n = data[0] as usize;
            } else if n == 0 {
                return TAG_NONE;
            } else if let Some(p) = pend {
                tag = TAG_MISMATCH + p.n as u32;
            } else {
                return TAG_RESPONSE; // nothing pending: the pairing stage says so
            }
        } else if pend.is_some_and(|p| shaped && data[0] as usize == p.n) {
            tag = TAG_RESPONSE;
        } else if n != 0 {
            tag = TAG_REQUEST;
        } else {
            return TAG_NONE;
        }
        self.note(aid, tag, n, data, t, pend);
        tag
    }

    /// A request joins the pending table (nobody answers a broadcast); an answer takes one
    /// waiting copy off it (`_note`).
    fn note(
        &mut self,
        aid: u32,
        tag: u32,
        n: usize,
        data: &[u8],
        t: Option<f64>,
        pend: Option<Pending>,
    ) {
        if tag == TAG_REQUEST {
            if aid & 0x3FFF != BROADCAST {
                let mut buf = [0u8; 8];
                buf[..data.len()].copy_from_slice(data);
                let mut copies = 1;
                match pend {
                    // the same request again before any answer: a retransmission
                    Some(p) if p.data() == data && !p.answered => copies = p.copies + 1,
                    _ => {
                        if self.pending.len() >= PENDING_LIMIT {
                            self.pending.clear();
                        }
                    }
                }
                let entry = Pending {
                    n,
                    data: buf,
                    len: data.len() as u8,
                    t,
                    copies,
                    answered: false,
                };
                self.pending.insert(aid, entry);
            }
        } else if let Some(p) = pend {
            // an answer: one copy fewer is waiting
            if p.copies > 1 {
                self.pending.insert(
                    aid,
                    Pending {
                        copies: p.copies - 1,
                        answered: true,
                        ..p
                    },
                );
            } else {
                self.pending.remove(&aid);
            }
        }
    }
}

/// Strings kept for the life of the process at most (a bound on what interning may keep).
const INTERN_LIMIT: usize = 100_000;

/// A string built once and kept for the life of the process, so that the records that carry
/// it copy a pointer: placeholder register names, span names and identifiers. Only built when
/// a layout or memo entry is made, never per record; past INTERN_LIMIT strings (hostile
/// traffic with ever new identifiers) it stops keeping and hands out owned copies.
fn intern(s: String) -> Str {
    static NAMES: OnceLock<Mutex<HashSet<&'static str>>> = OnceLock::new();
    let mut names = NAMES
        .get_or_init(Default::default)
        .lock()
        .unwrap_or_else(|e| e.into_inner());
    if let Some(&name) = names.get(s.as_str()) {
        return Cow::Borrowed(name);
    }
    if names.len() >= INTERN_LIMIT {
        return Cow::Owned(s);
    }
    let name: &'static str = Box::leak(s.into_boxed_str());
    names.insert(name);
    Cow::Borrowed(name)
}

/// The register at an even CAN address; a flagged placeholder outside the manual's map.
fn register_at(address: i64) -> RegRef {
    if let Some(reg) = by_can_address(address) {
        return match reg {
            Cow::Owned(mut reg) => {
                reg.name = intern(reg.name.into_owned());
                Cow::Owned(reg)
            }
            borrowed => borrowed,
        };
    }
    let number = 1000 + (address - 1000).div_euclid(2);
    Cow::Owned(Register {
        number,
        name: intern(format!("ADDR_{address}")),
        key: Cow::Owned(format!("addr_{address}")),
        access: "?",
        lo: None,
        hi: None,
        unit: "",
        signed: false,
        meaning: Cow::Owned(format!("CAN address {address}, outside the register map")),
        documented: false,
    })
}

fn plural(n: usize) -> String {
    if n == 1 {
        "1 byte".to_string()
    } else {
        format!("{n} bytes")
    }
}

/// `data.hex(" ").upper()`
pub fn push_hex(out: &mut String, data: &[u8]) {
    const DIGITS: &[u8; 16] = b"0123456789ABCDEF";
    for (i, &b) in data.iter().enumerate() {
        if i > 0 {
            out.push(' ');
        }
        out.push(DIGITS[(b >> 4) as usize] as char);
        out.push(DIGITS[(b & 15) as usize] as char);
    }
}

pub fn hex_upper(data: &[u8]) -> String {
    let mut s = String::with_capacity(data.len() * 3);
    push_hex(&mut s, data);
    s
}

/// Every register that a span of n bytes from address touches, in order.
fn span_registers(address: i64, n: i64) -> Vec<RegRef> {
    if n <= 0 {
        return Vec::new();
    }
    let first = address & !1;
    let last = (address + n - 1) & !1;
    (first..=last).step_by(2).map(register_at).collect()
}

fn span_name(regs: &[RegRef]) -> Option<Str> {
    match regs {
        [] => None,
        [one] => Some(one.name.clone()),
        [first, .., last] => Some(intern(format!("{}..{}", first.name, last.name))),
    }
}

fn span_keys(regs: &[RegRef]) -> String {
    match regs {
        [one] => one.key.to_string(),
        [first, .., last] => format!("{}..{}", first.key, last.key),
        [] => unreachable!("a span of at least one byte"),
    }
}

fn register_names(regs: &[RegRef]) -> Value {
    Value::List(regs.iter().map(|r| Value::Str(r.name.clone())).collect())
}

/// Flag how a span is laid out: odd address or length, unknown or read-only registers.
fn span_warnings(address: i64, n: i64, regs: &[RegRef], write: bool, notes: &mut Notes) {
    if address & 1 != 0 {
        let reg = register_at(address - 1);
        notes.warn_of(M::can_odd_start!(
            address = address,
            register = reg.name,
            register_address = address - 1
        ));
    }
    if (address + n) & 1 != 0 && n > 0 {
        let reg = register_at(address + n - 1);
        notes.warn_of(M::can_odd_end!(
            bytes = plural(n as usize),
            address = address,
            register = reg.name,
            register_address = address + n - 1
        ));
    } else if n & 1 != 0 {
        notes.warn_of(M::can_odd_length!(length = n));
    }
    for reg in regs {
        if !reg.documented {
            let a = reg.can_address();
            if (MAP_FIRST..=MAP_LAST).contains(&a) {
                notes.warn_of(M::can_undocumented_address!(
                    address = a,
                    number = reg.number
                ));
            } else {
                notes.warn_of(M::can_outside_map!(
                    address = a,
                    first = MAP_FIRST,
                    last = MAP_LAST
                ));
            }
        } else if write && reg.access == "ro" {
            notes.warn_of(M::can_read_only_write!(name = reg.name, key = reg.key));
        }
    }
}

/// The decoded part of a record (all but time, bus, raw and index): built once per distinct
/// frame and copied into each Record (Python `_Template`).
#[derive(Clone, Debug)]
struct Template {
    protocol: &'static str,
    direction: Option<&'static str>,
    device: Option<i64>,
    code: Option<i64>,
    name: Option<Str>,
    fields: SharedFields,
    errors: Vec<String>,
    warnings: Vec<String>,
    summary: Text,
    pair_key: Option<PairKey>,
    expects: bool,
    is_save: bool,
    flags: Vec<&'static str>,
}

/// One register value, decoded once per (register, raw value): the value, its summary text,
/// and what is special about it (range warning, extra field, save).
#[derive(Clone, Debug)]
struct ValueEntry {
    value: i64,
    text: String,
    problem: Option<String>,
    extra: Option<(&'static str, Value)>,
    save: bool,
}

fn value_entry(reg: &Register, raw: u16) -> ValueEntry {
    let value = reg.value(raw as i64);
    let extra = if reg.key == "state" {
        Some(("state_text", Value::Str(state_text(value))))
    } else if reg.key == "fault" {
        let words = fault_text(value)
            .into_iter()
            .map(|w| Value::Str(Cow::Borrowed(w)));
        Some(("fault_text", Value::List(words.collect())))
    } else {
        None
    };
    ValueEntry {
        value,
        text: reg.describe(value),
        problem: reg.range_warning(value),
        extra,
        save: value == 1 && registers::is_save_register(reg.number),
    }
}

/// Everything about a value-carrying frame (read response, write request) that its
/// identifier, length and direction fix; only the register values vary (Python `_Layout`).
#[derive(Debug)]
struct Layout {
    direction: &'static str,
    device: i64,
    code: i64,
    name: Option<Str>,
    fields: Fields,
    warnings: Vec<String>,
    flags: Vec<&'static str>,
    /// of the summary
    prefix: String,
    pair_key: PairKey,
    expects: bool,
    /// the frame may also fit the other direction's shape: true for a read response
    read: bool,
    /// odd start address: the first byte is the high byte of this register (its address + 1)
    head: Option<(i64, Str)>,
    /// offset of the first whole register
    start: usize,
    /// name, CAN address and register of each whole register
    slots: Vec<(Str, u32, RegRef)>,
    /// the span ends inside this register: the last byte is its low byte (address, name)
    tail: Option<(i64, Str)>,
}

/// The fields and notes every EG2 frame of this identifier and length has.
fn id_fields(aid: u32, n: usize) -> (Fields, Notes) {
    let (op, address, device) = unpack_id(aid);
    let mut fields: Fields = vec![
        (Cow::Borrowed("op"), Value::from(OPERATIONS[op as usize])),
        (Cow::Borrowed("address"), Value::Int(address as i64)),
        (
            Cow::Borrowed("id"),
            Value::Str(intern(format!("0x{aid:08X}"))),
        ),
        (Cow::Borrowed("dlc"), Value::Int(n as i64)),
    ];
    let mut notes = Notes::default();
    if device == 0 {
        notes.warn_of(M::CAN_DEVICE_ZERO);
    }
    if device == BROADCAST {
        fields.push((Cow::Borrowed("broadcast"), Value::Bool(true)));
    }
    (fields, notes)
}

/// The fixed part of a read response or write request of n bytes.
fn make_layout(aid: u32, n: usize, tag: u32) -> Layout {
    let (op, address, device) = unpack_id(aid);
    let address = address as i64;
    let (mut fields, mut notes) = id_fields(aid, n);
    let regs = span_registers(address, n as i64);
    fields.push((Cow::Borrowed("length"), Value::Int(n as i64)));
    fields.push((Cow::Borrowed("registers"), register_names(&regs)));
    let write = op == OP_WRITE;
    if tag >= TAG_MISMATCH {
        let asked = (tag - TAG_MISMATCH) as usize;
        notes.warn_of(M::can_length_mismatch!(asked = plural(asked), length = n));
    }
    span_warnings(address, n as i64, &regs, write, &mut notes);
    let head = if address & 1 != 0 {
        let reg = register_at(address - 1);
        Some((reg.can_address() + 1, reg.name.clone()))
    } else {
        None
    };
    let start = usize::from(head.is_some());
    let whole = (n - start) / 2;
    let slots = (0..whole)
        .map(|k| {
            let reg = register_at(address + start as i64 + 2 * k as i64);
            (reg.name.clone(), reg.can_address() as u32, reg)
        })
        .collect();
    let tail = if (n - start) & 1 != 0 {
        let reg = register_at(address + n as i64 - 1);
        Some((reg.can_address(), reg.name.clone()))
    } else {
        None
    };
    Layout {
        direction: if write { REQUEST } else { RESPONSE },
        device: device as i64,
        code: op as i64,
        name: span_name(&regs),
        fields,
        warnings: notes.warnings,
        flags: notes.flags,
        prefix: if write {
            format!("write {} at {address}: ", plural(n))
        } else {
            "-> ".into()
        },
        pair_key: [aid as i64, 0],
        expects: write && device != BROADCAST,
        read: !write,
        head,
        start,
        slots,
        tail,
    }
}

/// Frames that carry no register values: read requests, write responses, frames without
/// data, and operations 2 and 3.
fn build_other(aid: u32, data: &[u8], tag: u32) -> Template {
    let (op, address, device) = unpack_id(aid);
    let n = data.len();
    let (mut fields, mut notes) = id_fields(aid, n);
    let mut direction = None;
    let mut name = None;
    let summary;
    if op == OP_READ && tag == TAG_REQUEST {
        direction = Some(REQUEST);
        (name, summary) = read_request(address as i64, data, &mut fields, &mut notes);
    } else if op == OP_WRITE && tag == TAG_RESPONSE {
        direction = Some(RESPONSE);
        (name, summary) = write_response(address as i64, data, &mut fields);
    } else if op == OP_READ || op == OP_WRITE {
        // no data at all
        let what = if op == OP_READ { "read" } else { "write" };
        notes.error_of(M::can_no_data!(what = what));
        summary = format!("{what} at {address}: no data");
    } else {
        (name, summary) = raw_operation(op, address, data, &mut fields, &mut notes);
    }
    Template {
        protocol: EG2_CAN,
        direction,
        device: Some(device as i64),
        code: Some(op as i64),
        name,
        fields: fields.into(),
        errors: notes.errors,
        warnings: notes.warnings,
        summary: summary.into(),
        pair_key: direction.map(|_| [aid as i64, 0]),
        expects: direction == Some(REQUEST) && device != BROADCAST,
        is_save: false,
        flags: notes.flags,
    }
}

/// Name and summary of a read request; its span goes into fields (`_read_request`).
fn read_request(
    address: i64,
    data: &[u8],
    fields: &mut Fields,
    notes: &mut Notes,
) -> (Option<Str>, String) {
    let count = data[0] as usize;
    let regs = span_registers(address, count as i64);
    fields.push((Cow::Borrowed("length"), Value::Int(count as i64)));
    fields.push((Cow::Borrowed("registers"), register_names(&regs)));
    if data.len() == 8 {
        fields.push((Cow::Borrowed("padded"), Value::Bool(true)));
    }
    span_warnings(address, count as i64, &regs, false, notes);
    let summary = format!("read {} at {address} ({})", plural(count), span_keys(&regs));
    (span_name(&regs), summary)
}

/// Name and summary of a write response; its span goes into fields (`_write_response`).
fn write_response(address: i64, data: &[u8], fields: &mut Fields) -> (Option<Str>, String) {
    let count = data[0] as usize;
    let regs = span_registers(address, count as i64);
    fields.push((Cow::Borrowed("written_bytes"), Value::Int(count as i64)));
    fields.push((Cow::Borrowed("registers"), register_names(&regs)));
    if data.len() == 8 {
        fields.push((Cow::Borrowed("padded"), Value::Bool(true)));
    }
    (span_name(&regs), format!("-> wrote {}", plural(count)))
}

/// Name and summary of operations 2 and 3, whose payload the manual does not lay out
/// (`_raw_operation`).
fn raw_operation(
    op: u32,
    address: u32,
    data: &[u8],
    fields: &mut Fields,
    notes: &mut Notes,
) -> (Option<Str>, String) {
    let opname = OPERATIONS[op as usize];
    fields.push((Cow::Borrowed("data"), Value::from(hex_upper(data))));
    notes.warn_of(M::can_raw_operation!(op = op, name = opname));
    let mut s = format!("{opname} at {address} [{}] ", data.len());
    push_hex(&mut s, data);
    (Some(Cow::Borrowed(opname)), s.trim_end().to_string())
}

/// Python's `str.rstrip()` of an ASCII summary.
fn rstrip(mut s: String) -> String {
    let keep = s.trim_end().len();
    s.truncate(keep);
    s
}

/// A frame no EG2 sent (or one the device filter leaves out), shown as it is
/// (`_build_foreign`).
fn build_foreign(frame: &CanFrame, length: usize, filtered: bool) -> Template {
    let aid = frame.arbitration_id;
    let data = &frame.data[..];
    let mut notes = Notes::default();
    notes.flag(F::FOREIGN);
    let extended = frame.is_extended;
    let ident = if extended {
        format!("0x{aid:08X}")
    } else {
        format!("0x{aid:03X}")
    };
    let mut fields: Fields = vec![
        (Cow::Borrowed("id"), Value::from(ident.clone())),
        (Cow::Borrowed("dlc"), Value::Int(length as i64)),
        (Cow::Borrowed("extended"), Value::Bool(extended)),
    ];
    let kind = if extended { "extended" } else { "standard" };
    let summary;
    if frame.is_error {
        summary = error_frame(aid, data, &mut fields, &mut notes);
    } else {
        let limit = if extended { MAX_ID } else { 0x7FF };
        if aid > limit {
            let bits = if extended { 29 } else { 11 };
            notes.warn_of(M::can_id_too_wide!(id = aid, bits = bits));
        }
        if frame.is_remote {
            // not EG2 (it sends data frames only): the code is the record's own foreign
            notes.warn_of(M::CAN_REMOTE_FRAME);
            summary = format!("remote {kind} {ident} [{length}]");
        } else {
            let title = format!("{kind} {ident}");
            summary = data_frame(frame, title, filtered, &mut fields, &mut notes);
        }
        fields.push((Cow::Borrowed("data"), Value::from(hex_upper(data))));
    }
    Template {
        protocol: FOREIGN_CAN,
        direction: None,
        device: None,
        code: None,
        name: None,
        fields: fields.into(),
        errors: notes.errors,
        warnings: notes.warnings,
        summary: summary.into(),
        pair_key: None,
        expects: false,
        is_save: false,
        flags: notes.flags,
    }
}

/// Summary of a CAN error frame (aid: its error class); its problem is noted (`_error_frame`).
fn error_frame(aid: u32, data: &[u8], fields: &mut Fields, notes: &mut Notes) -> String {
    let text = can_error_text(aid);
    notes.error(F::CAN_ERROR_FRAME, text.clone()); // can_error_text: the catalogue's words
    fields.push((Cow::Borrowed("error_class"), Value::Int(aid as i64)));
    fields.push((Cow::Borrowed("data"), Value::from(hex_upper(data))));
    let mut s = format!("{text} [{}] ", data.len());
    push_hex(&mut s, data);
    rstrip(s)
}

/// Summary of a foreign data frame (title: its kind and identifier); what does not fit
/// classic CAN is noted (`_data_frame`).
fn data_frame(
    frame: &CanFrame,
    mut title: String,
    filtered: bool,
    fields: &mut Fields,
    notes: &mut Notes,
) -> String {
    let aid = frame.arbitration_id;
    let data = &frame.data[..];
    if frame.is_fd {
        fields.push((Cow::Borrowed("fd"), Value::Bool(true)));
        title.insert_str(0, "FD ");
    } else if data.len() > 8 {
        notes.warn_of(M::can_too_long!(length = data.len()));
    } else if frame.dlc.is_some_and(|d| d != data.len()) {
        let dlc = frame.dlc.unwrap_or(0);
        notes.warn_of(M::can_dlc_mismatch!(dlc = dlc, length = data.len()));
    } else if frame.is_extended && filtered && aid < RESERVED_BIT {
        // left out by the decoder's device filter
        fields.push((
            Cow::Borrowed("eg2_device"),
            Value::Int((aid & 0x3FFF) as i64),
        ));
    }
    let mut s = format!("{title} [{}] ", data.len());
    push_hex(&mut s, data);
    rstrip(s)
}

/// The last read response or write request per identifier, length and direction: its data,
/// its decode, and the layout the three fix.
struct Last {
    data: [u8; 8],
    template: Arc<Template>,
    layout: Layout,
}

/// Decode CAN frames of EG2-4X0 grippers: one Record per frame, in order.
///
/// `devices`, when given, limits EG2 decoding to those device IDs (plus broadcast); frames for
/// any other device are shown as foreign `can` records.
pub struct Eg2CanDecoder {
    pub bus: Arc<str>,
    devices: Option<Vec<u32>>,
    directions: Directions,
    /// the memos of `decode` (`decode_with` takes the caller's)
    memos: CanMemos,
}

/// The memoised decodes. A decode does not depend on the bus, so the decoders of all the buses
/// of a capture can share one set (offline_run.rs does): memory stays bounded however many
/// channels a log names. Caches: what they drop changes no output.
#[derive(Default)]
pub struct CanMemos {
    /// frames without register values: (aid, length, tag, data) -> decode
    memo: Option<FrameMemo<Template>>,
    /// (aid << 10 | length << 6 | tag) -> the last value-carrying frame
    last: FastMap<u64, Last>,
    /// value-carrying frames: (that key, data) -> decode (values come back: a gripper
    /// moving to and fro, a poll of a few registers)
    filled: Option<FrameMemo<Arc<Template>>>,
    /// (CAN address << 16 | raw value) -> the decoded value
    values: FastMap<u64, ValueEntry>,
}

impl Eg2CanDecoder {
    pub fn new(bus: Arc<str>) -> Self {
        Eg2CanDecoder {
            bus,
            devices: None,
            directions: Directions::default(),
            memos: CanMemos::default(),
        }
    }

    /// A decoder for only these device IDs (the Python `devices=` argument).
    pub fn with_devices(bus: Arc<str>, devices: &[i64]) -> Self {
        let mut dec = Eg2CanDecoder::new(bus);
        // an ID no 14-bit device field can equal is simply never matched
        dec.devices = Some(
            devices
                .iter()
                .filter_map(|&d| u32::try_from(d).ok())
                .collect(),
        );
        dec
    }

    /// Forget pending requests (a new capture, or a gap in the stream).
    pub fn reset(&mut self) {
        self.directions.pending.clear();
    }

    /// Pending requests (Python `len(self._directions)`).
    pub fn pending(&self) -> usize {
        self.directions.pending.len()
    }

    /// The Record of one frame. Never panics on any frame.
    pub fn decode(&mut self, frame: &CanFrame, index: u64) -> Record {
        let mut memos = std::mem::take(&mut self.memos);
        let rec = self.decode_with(&mut memos, frame, index);
        self.memos = memos;
        rec
    }

    /// `decode` with memos shared with other decoders.
    pub fn decode_with(&mut self, memos: &mut CanMemos, frame: &CanFrame, index: u64) -> Record {
        let memo = memos
            .memo
            .get_or_insert_with(|| FrameMemo::new(MEMO_GENERATION));
        let filled = memos
            .filled
            .get_or_insert_with(|| FrameMemo::new(MEMO_GENERATION));
        let (last_of, values) = (&mut memos.last, &mut memos.values);
        let data = &frame.data[..];
        let aid = frame.arbitration_id;
        let n = data.len();
        let device = aid & 0x3FFF;
        if !frame.is_extended
            || frame.is_remote
            || frame.is_error
            || frame.is_fd
            || n > 8
            || frame.dlc.is_some_and(|d| d != n)
            || aid >= RESERVED_BIT // bit 28 set: not EG2 (J1939 and others)
            || self
                .devices
                .as_ref()
                .is_some_and(|ds| !ds.contains(&device) && device != BROADCAST)
        {
            let length = frame.length();
            let tpl = build_foreign(frame, length, self.devices.is_some());
            return self.record(&tpl, frame.t, length, data, index);
        }
        let op = aid >> 26;
        let tag = if op <= OP_WRITE {
            self.directions.tag(aid, op, data, frame.t)
        } else {
            TAG_NONE
        };
        // register values ride on read responses and write requests
        if tag != TAG_NONE && (tag == TAG_REQUEST) == (op == OP_WRITE) {
            let lkey = (aid as u64) << 10 | (n as u64) << 6 | tag as u64;
            let mut buf = [0u8; 8];
            buf[..n].copy_from_slice(data);
            // the memo key: that key, then the data
            let mut fkey = [0u8; 16];
            fkey[..8].copy_from_slice(&lkey.to_le_bytes());
            fkey[8..8 + n].copy_from_slice(data);
            let fkey = &fkey[..8 + n];
            if let Some(last) = last_of.get_mut(&lkey) {
                if last.data != buf {
                    // same identifier, length and direction, new values: the layout holds
                    let layout = &last.layout;
                    last.template = filled
                        .get_or_insert_with(fkey, || Arc::new(fill(values, layout, data)))
                        .clone();
                    last.data = buf;
                }
                return record_from(&last.template, &self.bus, frame.t, n, data, index);
            }
            if last_of.len() >= LAYOUT_LIMIT {
                last_of.clear(); // a cache: emptying it changes no output
            }
            let layout = make_layout(aid, n, tag);
            let template = filled
                .get_or_insert_with(fkey, || Arc::new(fill(values, &layout, data)))
                .clone();
            let rec = record_from(&template, &self.bus, frame.t, n, data, index);
            last_of.insert(
                lkey,
                Last {
                    data: buf,
                    template,
                    layout,
                },
            );
            rec
        } else {
            // the memo key: identifier, length, tag, data
            let mut key = [0u8; 16];
            key[..4].copy_from_slice(&aid.to_le_bytes());
            key[4] = n as u8;
            key[5] = tag as u8; // at most TAG_MISMATCH
            key[6..6 + n].copy_from_slice(data);
            let tpl = memo.get_or_insert_with(&key[..6 + n], || build_other(aid, data, tag));
            record_from(tpl, &self.bus, frame.t, n, data, index)
        }
    }

    fn record(
        &self,
        tpl: &Template,
        t: Option<f64>,
        length: usize,
        data: &[u8],
        index: u64,
    ) -> Record {
        record_from(tpl, &self.bus, t, length, data, index)
    }
}

/// A layout with the register values of one frame (Python `_fill`); `values` memoises the
/// decoded value per (CAN address, raw value).
fn fill(values_cache: &mut FastMap<u64, ValueEntry>, layout: &Layout, data: &[u8]) -> Template {
    // room for the extra fields, values and partial bytes: no regrowth per frame
    let mut fields = Vec::with_capacity(layout.fields.len() + 4);
    fields.extend(layout.fields.iter().cloned());
    let mut notes = Notes {
        errors: Vec::new(),
        warnings: layout.warnings.clone(),
        flags: layout.flags.clone(),
    };
    if count_shaped(data) {
        note_ambiguity(layout, data[0] as usize, &mut notes);
    }
    let mut summary = Parts::new(&layout.prefix, 24 * layout.slots.len());
    let mut partial: Vec<Value> = Vec::new();
    if let Some((address, name)) = &layout.head {
        half_byte(*address, data[0], name, "high", &mut summary, &mut partial);
    }
    let (values, is_save) = fill_values(
        values_cache,
        layout,
        data,
        &mut fields,
        &mut summary,
        &mut notes,
    );
    if let Some((address, name)) = &layout.tail {
        let last = data[data.len() - 1];
        half_byte(*address, last, name, "low", &mut summary, &mut partial);
    }
    fields.push((Cow::Borrowed("values"), Value::Map(values)));
    if !partial.is_empty() {
        fields.push((Cow::Borrowed("partial"), Value::List(partial)));
    }
    Template {
        protocol: EG2_CAN,
        direction: Some(layout.direction),
        device: Some(layout.device),
        code: Some(layout.code),
        name: layout.name.clone(),
        fields: fields.into(),
        errors: Vec::new(),
        warnings: notes.warnings,
        summary: summary.text.into(),
        pair_key: Some(layout.pair_key),
        expects: layout.expects,
        is_save,
        flags: notes.flags,
    }
}

/// A summary being built: a prefix, then parts joined by ", " (Python's `", ".join(parts)`).
struct Parts {
    text: String,
    empty: bool,
}

impl Parts {
    fn new(prefix: &str, room: usize) -> Self {
        let mut text = String::with_capacity(prefix.len() + room);
        text.push_str(prefix);
        Parts { text, empty: true }
    }

    /// The text, ready for the next part.
    fn next(&mut self) -> &mut String {
        if !std::mem::take(&mut self.empty) {
            self.text.push_str(", ");
        }
        &mut self.text
    }
}

/// A value-carrying frame shaped like a count could also be the other direction
/// (`_note_ambiguity`).
fn note_ambiguity(layout: &Layout, count: usize, notes: &mut Notes) {
    if layout.read {
        notes.warn_of(M::can_maybe_read_request!(bytes = plural(count)));
    } else {
        notes.warn_of(M::can_maybe_write_response!(bytes = plural(count)));
    }
}

/// One byte of a register whose other half lies outside the frame (`_half_byte`).
fn half_byte(
    address: i64,
    byte: u8,
    register: &Str,
    half: &'static str,
    summary: &mut Parts,
    partial: &mut Vec<Value>,
) {
    partial.push(partial_entry(address, byte, register, half));
    let _ = write!(summary.next(), "byte {address}=0x{byte:02X}");
}

/// The register values of the frame (and whether one is a parameter save); their texts go to
/// the summary, their extra fields to fields (`_fill_values`). `values_cache` memoises the
/// decoded value per (CAN address, raw value).
fn fill_values(
    values_cache: &mut FastMap<u64, ValueEntry>,
    layout: &Layout,
    data: &[u8],
    fields: &mut Fields,
    summary: &mut Parts,
    notes: &mut Notes,
) -> (Fields, bool) {
    let mut values: Fields = Vec::with_capacity(layout.slots.len());
    let mut is_save = false;
    if values_cache.len() >= VALUE_CACHE_LIMIT {
        values_cache.clear();
    }
    for (k, (name, address, reg)) in layout.slots.iter().enumerate() {
        let i = layout.start + 2 * k;
        let raw = u16::from_le_bytes([data[i], data[i + 1]]);
        let entry = values_cache
            .entry((*address as u64) << 16 | raw as u64)
            .or_insert_with(|| value_entry(reg, raw));
        values.push((name.clone(), Value::Int(entry.value)));
        summary.next().push_str(&entry.text);
        if let Some(problem) = &entry.problem {
            notes.warn(F::OUT_OF_RANGE, problem.clone());
        }
        if let Some((key, value)) = &entry.extra {
            // a dict assignment: a key already there keeps its place
            match fields.iter_mut().find(|(k, _)| k == key) {
                Some(slot) => slot.1 = value.clone(),
                None => fields.push((Cow::Borrowed(key), value.clone())),
            }
        }
        is_save |= entry.save;
    }
    (values, is_save)
}

fn partial_entry(address: i64, byte: u8, register: &Str, half: &'static str) -> Value {
    Value::Map(vec![
        (Cow::Borrowed("address"), Value::Int(address)),
        (Cow::Borrowed("byte"), Value::from(format!("{byte:02X}"))),
        (Cow::Borrowed("register"), Value::Str(register.clone())),
        (Cow::Borrowed("half"), Value::from(half)),
    ])
}

/// A Record from a decode (Python `_from_template`), with its own copies of everything.
fn record_from(
    tpl: &Template,
    bus: &Arc<str>,
    t: Option<f64>,
    length: usize,
    data: &[u8],
    index: u64,
) -> Record {
    Record {
        t,
        bus: bus.clone(),
        protocol: tpl.protocol,
        kind: FRAME,
        length,
        raw: data.to_vec(),
        offset: None,
        index: Some(index),
        direction: tpl.direction,
        device: tpl.device,
        code: tpl.code,
        name: tpl.name.clone(),
        fields: tpl.fields.clone(),
        errors: tpl.errors.clone(),
        warnings: tpl.warnings.clone(),
        summary: tpl.summary.clone(),
        seq: -1,
        pair: None,
        latency_ms: None,
        pair_key: tpl.pair_key,
        expects_response: tpl.expects,
        is_save: tpl.is_save,
        flags: tpl.flags.clone(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn frame(t: Option<f64>, aid: u32, data: &[u8]) -> CanFrame {
        CanFrame {
            t,
            arbitration_id: aid,
            data: data.to_vec(),
            is_extended: true,
            ..Default::default()
        }
    }

    fn id(op: u32, address: u32, device: u32) -> u32 {
        op << 26 | address << 14 | device
    }

    #[test]
    fn read_request_then_response() {
        let mut dec = Eg2CanDecoder::new("can0".into());
        let aid = id(0, 1120, 1);
        let req = dec.decode(&frame(Some(1.0), aid, &[4]), 0);
        assert_eq!(req.direction, Some(REQUEST));
        assert_eq!(
            &*req.summary,
            "read 4 bytes at 1120 (measured_force..measured_opening)"
        );
        let resp = dec.decode(&frame(Some(1.01), aid, &[0xF4, 0x01, 0xFF, 0xFF]), 1);
        assert_eq!(resp.direction, Some(RESPONSE));
        assert_eq!(
            &*resp.summary,
            "-> measured_force=500, measured_opening=65535 (4587.45 mm)"
        );
        assert_eq!(dec.pending(), 0);
    }

    #[test]
    fn odd_span_and_error_text() {
        let mut dec = Eg2CanDecoder::new("can0".into());
        let rec = dec.decode(&frame(None, id(1, 1021, 1), &[1, 2, 3]), 0);
        assert_eq!(
            &*rec.summary,
            "write 3 bytes at 1021: byte 1021=0x01, speed=770"
        );
        assert_eq!(rec.flags, vec![F::ODD_SPAN]);
        assert_eq!(can_error_text(0), "CAN error frame");
        assert_eq!(
            can_error_text(0x41),
            "CAN error frame: TX timeout, bus off (class 0x041)"
        );
    }

    #[test]
    fn retransmission_timeout_and_mismatch() {
        let mut dec = Eg2CanDecoder::new("can0".into());
        let aid = id(0, 1120, 1);
        // a host's retransmission: two requests pending, both answers are responses
        dec.decode(&frame(Some(0.0), aid, &[4]), 0);
        dec.decode(&frame(Some(0.01), aid, &[4]), 1);
        assert_eq!(dec.pending(), 1);
        let r = dec.decode(&frame(Some(0.02), aid, &[1, 0, 2, 0]), 2);
        assert_eq!(r.direction, Some(RESPONSE));
        let r = dec.decode(&frame(Some(0.03), aid, &[1, 0, 2, 0]), 3);
        assert_eq!(r.direction, Some(RESPONSE));
        assert_eq!(dec.pending(), 0);
        // an answer after PENDING_TIMEOUT_S: still a response, the stale entry stays
        dec.decode(&frame(Some(1.0), aid, &[4]), 4);
        dec.decode(&frame(Some(3.5), aid, &[1, 0, 2, 0]), 5);
        assert_eq!(dec.pending(), 1);
        // a response of another length than asked for
        dec.decode(&frame(Some(4.0), aid, &[4]), 6);
        let r = dec.decode(&frame(Some(4.01), aid, &[1, 0]), 7);
        assert_eq!(r.flags, vec![F::LENGTH_MISMATCH]);
        assert_eq!(dec.pending(), 0);
    }

    #[test]
    fn broadcast_and_foreign() {
        let mut dec = Eg2CanDecoder::new("can0".into());
        let r = dec.decode(&frame(None, id(1, 1020, BROADCAST), &[0, 0]), 0);
        assert!(!r.expects_response && dec.pending() == 0);
        let mut remote = frame(None, 0x123, &[]);
        remote.is_extended = false;
        remote.is_remote = true;
        remote.dlc = Some(5);
        let r = dec.decode(&remote, 1);
        assert_eq!((r.protocol, r.length), (FOREIGN_CAN, 5));
        assert_eq!(&*r.summary, "remote standard 0x123 [5]");
        assert_eq!(r.warnings, vec!["remote frame".to_string()]);
    }
}
