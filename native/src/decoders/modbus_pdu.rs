//! Modbus RTU PDUs: what a frame of the EG2-4X2's RS485 line means (mirrors
//! `decoders/modbus_pdu.py`).
//!
//! Direction: the shape decides for reads, write multiple and exceptions; a write single
//! (request and response identical) is the response of the pending request it echoes, else a
//! request; a direction the source knows (`hint`) wins where the shape cannot decide.
//! Registers are named by `modbus_registers`; a read response is named from its pending
//! request. Every error and warning carries its flag code.

use std::borrow::Cow;
use std::fmt::Write;

use crate::decoders::flags as F;
use crate::decoders::modbus_framing::{
    candidates, crc16, crc_state, function_text, read_response_len, word, Pending, CRC_BAD,
    CRC_SWAPPED_ORDER, KIND, KIND_EXCEPTION, KIND_MULTI, KIND_READ, KIND_SINGLE, READ_COILS,
    READ_DISCRETE, READ_HOLDING, WRITE_COIL, WRITE_COILS, WRITE_MULTIPLE, WRITE_SINGLE,
};
use crate::decoders::modbus_registers::{words, Memo};
use crate::decoders::model::{Fields, Notes, PairKey, Str, Value, REQUEST, RESPONSE};
use crate::decoders::registers::is_save_register;
use crate::generated::messages as M;

use crate::generated::modbus::{exception_text, BROADCAST};

/// `FUNCTION_NAME`: the record name of the functions that address no EG2 register.
fn function_name(fc: u8) -> &'static str {
    crate::generated::modbus::function_name(fc)
        .unwrap_or_else(|| unreachable!("function_name of function {fc}"))
}

fn is_eg2_function(fc: u8) -> bool {
    matches!(fc, READ_HOLDING | WRITE_SINGLE | WRITE_MULTIPLE)
}

/// Enough for the summary of a 5-register poll response: one allocation, no regrowth.
const SUMMARY_CAPACITY: usize = 160;

/// One frame's meaning (the Python `Entry` tuple).
#[derive(Clone, Debug, Default)]
pub struct Entry {
    pub direction: Option<&'static str>,
    pub name: Option<Str>,
    pub fields: Fields,
    pub summary: String,
    pub errors: Vec<String>,
    pub warnings: Vec<String>,
    pub pair_key: Option<PairKey>,
    pub expects_response: bool,
    pub is_save: bool,
    /// the pending request after this frame
    pub next: Option<Pending>,
    pub flags: Vec<&'static str>,
}

/// request or response, from the shape where it decides, else from the hint or the bus.
pub fn direction(
    raw: &[u8],
    pending: Option<Pending>,
    hint: Option<&'static str>,
) -> Option<&'static str> {
    let n = raw.len();
    let fc = raw[1];
    let kind = KIND[fc as usize];
    if kind == KIND_EXCEPTION {
        return Some(RESPONSE);
    }
    if kind == KIND_READ {
        let is_req = n == 8;
        let is_resp = read_response_len(fc, raw[2]) == n as i64;
        if is_req != is_resp {
            return Some(if is_req { REQUEST } else { RESPONSE });
        }
    } else if kind == KIND_MULTI {
        return Some(if n == 8 { RESPONSE } else { REQUEST });
    } else if kind != KIND_SINGLE {
        return None;
    }
    // the same bytes either way (a write single, or a coil read of 3 bytes)
    if hint.is_some() {
        return hint;
    }
    if let Some(p) = pending {
        if p.slave == raw[0] && p.fc == fc && (kind != KIND_SINGLE || p.a == word(raw, 2)) {
            return Some(RESPONSE);
        }
    }
    Some(REQUEST)
}

fn int(v: impl Into<i64>) -> Value {
    Value::Int(v.into())
}

fn key(k: &'static str) -> Str {
    Cow::Borrowed(k)
}

/// The entry of bytes no framer would hand over (`_shapeless`), else None.
fn shapeless(raw: &[u8]) -> Option<Entry> {
    let n = raw.len();
    let (fields, error): (Fields, String) = if n < 4 {
        let slave = raw.first().map_or(Value::Null, |&s| int(s));
        (
            vec![(key("slave"), slave)],
            M::modbus_too_short!(length = n).1,
        )
    } else {
        let kind = KIND[raw[1] as usize];
        if kind != 0 {
            let (cv, cn) = candidates(raw, 0, n, kind, false);
            if cv[..cn].contains(&(n as i64)) {
                return None;
            }
        }
        let what = if kind != 0 {
            match function_text(raw[1] & 0x7F) {
                Some(t) => t.to_string(),
                None => format!("function 0x{:02X}", raw[1]),
            }
        } else {
            format!("code 0x{:02X}", raw[1])
        };
        (
            vec![
                (key("slave"), int(raw[0])),
                (key("function"), int(raw[1] & 0x7F)),
            ],
            M::modbus_no_shape!(length = n, what = what).1,
        )
    };
    Some(Entry {
        fields,
        errors: vec![error],
        flags: vec![F::MALFORMED],
        ..Entry::default()
    })
}

/// The meaning of one frame (raw bytes with their CRC), given the pending request and the
/// direction the source knows (if it does). `crc`: the CRC state if already known.
///
/// (The Python's fast path for the answer to the read just seen gives the same result as the
/// general path; here the general path is fast enough, so there is one.)
pub fn decode(
    memo: &mut Memo,
    raw: &[u8],
    pending: Option<Pending>,
    hint: Option<&'static str>,
    crc: Option<u8>,
) -> Entry {
    if let Some(e) = shapeless(raw) {
        return e;
    }
    let mut notes = Notes::default();
    let (slave, fc) = (raw[0], raw[1]);
    let func = fc & 0x7F;
    let kind = KIND[fc as usize];
    let crc = crc.unwrap_or_else(|| crc_state(raw, 0, raw.len()));
    note_crc(raw, crc, &mut notes);
    let direction = direction(raw, pending, hint);
    note_unexpected(raw, kind, direction, &mut notes);
    // a response is checked against the request it answers
    let answers = matches!(pending, Some(p) if p.slave == slave && p.fc == func);
    let req = if direction == Some(RESPONSE) && answers {
        pending
    } else {
        None
    };
    let mut fields: Fields = Vec::with_capacity(8);
    fields.push((key("slave"), int(slave)));
    fields.push((key("function"), int(func)));
    let mut summary = String::with_capacity(SUMMARY_CAPACITY);
    let (name, is_save) = body(
        memo,
        raw,
        kind,
        direction,
        req,
        &mut fields,
        &mut summary,
        &mut notes,
    );
    let (pair_key, expects, next) = pairing(raw, direction, crc);
    Entry {
        direction,
        name,
        fields,
        summary,
        errors: notes.errors,
        warnings: notes.warnings,
        pair_key,
        expects_response: expects,
        is_save: is_save && direction == Some(REQUEST),
        next,
        flags: notes.flags,
    }
}

/// A CRC that fails, or holds with its two bytes swapped, is noted (`_note_crc`).
fn note_crc(raw: &[u8], crc: u8, notes: &mut Notes) {
    let n = raw.len();
    if crc == CRC_SWAPPED_ORDER {
        notes.warn_of(M::MODBUS_CRC_SWAPPED);
    } else if crc == CRC_BAD {
        let c = crc16(&raw[..n - 2]);
        notes.error_of(M::modbus_crc!(
            expected_lo = c & 0xFF,
            expected_hi = c >> 8,
            got_lo = raw[n - 2],
            got_hi = raw[n - 1]
        ));
    }
}

/// A function the EG2 does not document, or a response from the broadcast address
/// (`_note_unexpected`).
fn note_unexpected(raw: &[u8], kind: u8, direction: Option<&'static str>, notes: &mut Notes) {
    let (slave, fc) = (raw[0], raw[1]);
    if kind != KIND_EXCEPTION && !is_eg2_function(fc) {
        let name = function_text(fc).expect("a framed function");
        notes.warn_of(M::modbus_undocumented_function!(code = fc, name = name));
    }
    if direction == Some(RESPONSE) && slave == BROADCAST {
        notes.warn_of(M::MODBUS_BROADCAST_RESPONSE);
    }
}

/// (pair key, expects a response, the request now pending) of a frame (`_pairing`).
fn pairing(
    raw: &[u8],
    direction: Option<&'static str>,
    crc: u8,
) -> (Option<[i64; 2]>, bool, Option<Pending>) {
    let (slave, fc) = (raw[0], raw[1]);
    if direction != Some(REQUEST) {
        let key = (direction == Some(RESPONSE)).then_some([slave as i64, (fc & 0x7F) as i64]);
        return (key, false, None);
    }
    let key = Some([slave as i64, fc as i64]);
    if slave == BROADCAST {
        return (key, false, None);
    }
    let next = Pending {
        slave,
        fc,
        a: word(raw, 2),
        b: word(raw, 4),
        crc_ok: crc != CRC_BAD,
    };
    (key, true, Some(next))
}

/// Name and is_save of a well-shaped frame; its values go into fields, its summary into
/// `summary` (`_body`).
#[allow(clippy::too_many_arguments)]
fn body(
    memo: &mut Memo,
    raw: &[u8],
    kind: u8,
    direction: Option<&'static str>,
    req: Option<Pending>,
    fields: &mut Fields,
    summary: &mut String,
    notes: &mut Notes,
) -> (Option<Str>, bool) {
    let fc = raw[1];
    if kind == KIND_EXCEPTION {
        return exception(raw, fields, summary, notes);
    }
    if kind == KIND_READ && direction == Some(REQUEST) {
        let (start, count) = (word(raw, 2), word(raw, 4));
        return (
            read_request(memo, fc, start, count, fields, summary, notes),
            false,
        );
    }
    if kind == KIND_READ {
        return (
            read_response(memo, raw, fc, req, fields, summary, notes),
            false,
        );
    }
    if kind == KIND_SINGLE {
        return write_single(memo, raw, direction, req, fields, summary, notes);
    }
    if direction == Some(REQUEST) {
        return write_multiple(memo, raw, fc, fields, summary, notes);
    }
    let (start, count) = (word(raw, 2), word(raw, 4));
    (
        write_multiple_response(memo, fc, start, count, req, fields, summary, notes),
        false,
    )
}

fn exception(
    raw: &[u8],
    fields: &mut Fields,
    summary: &mut String,
    notes: &mut Notes,
) -> (Option<Str>, bool) {
    let code = raw[2];
    notes.flag(F::EXCEPTION_RESPONSE); // the summary says it in words
    let text: Str = match exception_text(code) {
        Some(t) => Cow::Borrowed(t),
        None => {
            notes.warn_of(M::modbus_unknown_exception!(code = code));
            Cow::Owned(format!("unknown exception code {code}"))
        }
    };
    let _ = write!(summary, "exception {code}: {text}");
    fields.push((key("exception_code"), int(code)));
    fields.push((key("exception_text"), Value::Str(text)));
    (Some(key("EXCEPTION")), false)
}

fn coil_words(fc: u8) -> &'static str {
    if fc == READ_COILS {
        "coils"
    } else {
        "discrete inputs"
    }
}

fn read_request(
    memo: &mut Memo,
    fc: u8,
    start: u16,
    count: u16,
    fields: &mut Fields,
    summary: &mut String,
    notes: &mut Notes,
) -> Option<Str> {
    if fc <= READ_DISCRETE {
        // coils and discrete inputs: bits, not EG2 registers
        let what = coil_words(fc);
        fields.push((key("start"), int(start)));
        fields.push((key("count"), int(count)));
        if !(1..=2000).contains(&count) {
            notes.warn_of(M::modbus_count!(count = count, limit = 2000, what = what));
        }
        let _ = write!(summary, "read {count} {what} from {start}");
        return Some(key(function_name(fc)));
    }
    let p = memo.plan(start, count);
    fields.extend(p.extra.iter().cloned());
    fields.push((key("registers"), p.names.clone()));
    p.note(notes);
    if !(1..=125).contains(&count) {
        notes.warn_of(M::modbus_count!(
            count = count,
            limit = 125,
            what = "registers"
        ));
    }
    summary.push_str(&p.read_summary);
    p.name.clone()
}

/// The bits of coil data, as many as asked for and present (LSB first in each byte).
fn bits_of(data: &[u8], count: i64) -> Vec<u8> {
    let k = count.min(8 * data.len() as i64).max(0) as usize;
    (0..k).map(|i| (data[i >> 3] >> (i & 7)) & 1).collect()
}

fn bits_value(bits: &[u8]) -> Value {
    Value::List(bits.iter().map(|&b| int(b)).collect())
}

fn push_bits(summary: &mut String, bits: &[u8]) {
    summary.extend(bits.iter().map(|&b| if b != 0 { '1' } else { '0' }));
}

fn read_response(
    memo: &mut Memo,
    raw: &[u8],
    fc: u8,
    req: Option<Pending>,
    fields: &mut Fields,
    summary: &mut String,
    notes: &mut Notes,
) -> Option<Str> {
    let bc = raw[2];
    fields.push((key("byte_count"), int(bc)));
    let data_end = (3 + bc as usize).min(raw.len() - 2);
    if fc <= READ_DISCRETE {
        let data = &raw[3..data_end.max(3)];
        let what = coil_words(fc);
        if let Some(req) = req {
            let count = req.b;
            let bits = bits_of(data, count as i64);
            fields.push((key("start"), int(req.a)));
            fields.push((key("count"), int(count)));
            fields.push((key("bits"), bits_value(&bits)));
            let _ = write!(summary, "-> {what} ");
            push_bits(summary, &bits);
            return Some(key(function_name(fc)));
        }
        fields.push((
            key("values_raw"),
            Value::List(data.iter().map(|&b| int(b)).collect()),
        ));
        let _ = write!(summary, "-> {bc} bytes of {what}: ");
        for (i, b) in data.iter().enumerate() {
            if i > 0 {
                summary.push(' ');
            }
            let _ = write!(summary, "{b:02X}");
        }
        return Some(key(function_name(fc)));
    }
    let req = match req {
        Some(r) if 2 * r.b as i64 == bc as i64 => r,
        _ => {
            let values_raw = words(raw, 3, data_end);
            let n = values_raw.len();
            if let Some(r) = req {
                notes.warn_of(M::modbus_read_length!(count = n, asked = r.b));
            } else {
                notes.warn_of(M::MODBUS_NO_REQUEST);
            }
            let noun = if n == 1 { "value" } else { "values" };
            let _ = write!(summary, "-> {n} {noun} (registers unknown): ");
            for (i, v) in values_raw.iter().enumerate() {
                if i > 0 {
                    summary.push_str(", ");
                }
                let _ = write!(summary, "{v}");
            }
            fields.push((
                key("values_raw"),
                Value::List(values_raw.into_iter().map(int).collect()),
            ));
            return None;
        }
    };
    let p = memo.plan(req.a, req.b);
    fields.extend(p.extra.iter().cloned());
    p.note(notes);
    if !req.crc_ok {
        notes.warn_of(M::MODBUS_UNTRUSTED);
    }
    summary.push_str("-> ");
    let mut range_warnings = Vec::new();
    let values = memo.values(&p, raw, 3, data_end, summary, &mut range_warnings);
    for text in range_warnings {
        notes.warn(F::OUT_OF_RANGE, text);
    }
    fields.push((key("values"), Value::Map(values)));
    p.name.clone()
}

fn write_single(
    memo: &mut Memo,
    raw: &[u8],
    direction: Option<&'static str>,
    req: Option<Pending>,
    fields: &mut Fields,
    summary: &mut String,
    notes: &mut Notes,
) -> (Option<Str>, bool) {
    let fc = raw[1];
    let (addr, w) = (word(raw, 2), word(raw, 4));
    let response = direction == Some(RESPONSE);
    if fc == WRITE_COIL {
        fields.push((key("coil"), int(addr)));
        fields.push((key("value"), int(w)));
        let state: Cow<'static, str> = match w {
            0xFF00 => Cow::Borrowed("on"),
            0x0000 => Cow::Borrowed("off"),
            _ => {
                notes.warn_of(M::modbus_coil_value!(value = w));
                Cow::Owned(format!("0x{w:04X}"))
            }
        };
        let text = format!("coil {addr} {state}");
        if response {
            echo(req, addr, w, &text, summary, notes);
        } else {
            let _ = write!(summary, "write {text}");
        }
        return (Some(key(function_name(fc))), false);
    }
    let p = memo.plan(addr, 1);
    let reg = &p.regs[0];
    let cell = memo.value_of(reg, w);
    let (value, text, warning) = (cell.value, &*cell.text, cell.warning.as_deref());
    fields.push((key("register"), int(p.start)));
    fields.push((key("name"), Value::Str(reg.name.clone())));
    fields.push((key("value"), int(value)));
    if p.short {
        fields.push((key("numbering"), Value::Str(key("short"))));
        fields.push((key("address"), int(addr)));
    }
    p.note(notes);
    if response {
        echo(req, addr, w, text, summary, notes);
        return (Some(reg.name.clone()), false);
    }
    if let Some(warn) = warning {
        notes.warn(F::OUT_OF_RANGE, warn.to_string());
    }
    if let Some(ro) = &p.read_only {
        notes.warn(F::READ_ONLY_WRITE, ro.clone());
    }
    summary.push_str("write ");
    summary.push_str(text);
    (
        Some(reg.name.clone()),
        is_save_register(reg.number) && w == 1,
    )
}

fn echo(
    req: Option<Pending>,
    addr: u16,
    w: u16,
    text: &str,
    summary: &mut String,
    notes: &mut Notes,
) {
    match req {
        None => {
            notes.warn_of(M::MODBUS_WRITE_NO_REQUEST);
            let _ = write!(summary, "-> echo {text}");
        }
        Some(r) if r.a != addr || r.b != w => {
            notes.warn_of(M::modbus_echo_differs!(
                address = r.a,
                value = r.b,
                echo_address = addr,
                echo_value = w
            ));
            let _ = write!(summary, "-> echo differs: {text}");
        }
        Some(_) => summary.push_str("-> ok (echo)"),
    }
}

fn write_multiple(
    memo: &mut Memo,
    raw: &[u8],
    fc: u8,
    fields: &mut Fields,
    summary: &mut String,
    notes: &mut Notes,
) -> (Option<Str>, bool) {
    let (start, count, bc) = (word(raw, 2), word(raw, 4), raw[6]);
    let data_end = (7 + bc as usize).min(raw.len() - 2);
    fields.push((key("byte_count"), int(bc)));
    if fc == WRITE_COILS {
        let data = &raw[7..data_end.max(7)];
        let bits = bits_of(data, count as i64);
        fields.push((key("start"), int(start)));
        fields.push((key("count"), int(count)));
        fields.push((key("bits"), bits_value(&bits)));
        let _ = write!(summary, "write {count} coils from {start}: ");
        push_bits(summary, &bits);
        return (Some(key(function_name(fc))), false);
    }
    let p = memo.plan(start, count);
    fields.extend(p.extra.iter().cloned());
    p.note(notes);
    if !(1..=123).contains(&count) {
        notes.warn_of(M::modbus_count!(
            count = count,
            limit = 123,
            what = "registers"
        ));
    }
    let noun = if count == 1 { "register" } else { "registers" };
    let _ = write!(summary, "write {count} {noun} from {}: ", p.start);
    let mut range_warnings = Vec::new();
    let values = memo.values(&p, raw, 7, data_end, summary, &mut range_warnings);
    for text in range_warnings {
        notes.warn(F::OUT_OF_RANGE, text);
    }
    if let Some(ro) = &p.read_only {
        notes.warn(F::READ_ONLY_WRITE, ro.clone());
    }
    // values.get(name) == 1 for a save register's name (values holds the registers with data)
    let save = p
        .save_idx
        .iter()
        .any(|&i| matches!(values.get(i), Some((_, Value::Int(1)))));
    fields.push((key("values"), Value::Map(values)));
    (p.name.clone(), save)
}

#[allow(clippy::too_many_arguments)]
fn write_multiple_response(
    memo: &mut Memo,
    fc: u8,
    start: u16,
    count: u16,
    req: Option<Pending>,
    fields: &mut Fields,
    summary: &mut String,
    notes: &mut Notes,
) -> Option<Str> {
    match req {
        None => notes.warn_of(M::MODBUS_WRITE_NO_REQUEST),
        Some(r) if r.a != start || r.b != count => notes.warn_of(M::modbus_write_differs!(
            start = start,
            count = count,
            asked_start = r.a,
            asked_count = r.b
        )),
        Some(_) => {}
    }
    if fc == WRITE_COILS {
        fields.push((key("start"), int(start)));
        fields.push((key("count"), int(count)));
        let _ = write!(summary, "-> wrote {count} coils from {start}");
        return Some(key(function_name(fc)));
    }
    let p = memo.plan(start, count);
    fields.extend(p.extra.iter().cloned());
    p.note(notes);
    let noun = if count == 1 { "register" } else { "registers" };
    let _ = write!(summary, "-> wrote {count} {noun} from {}", p.start);
    p.name.clone()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// decode() is public: any bytes, of any length, give an entry (never a panic).
    #[test]
    fn decode_takes_any_bytes() {
        let mut memo = Memo::default();
        let mut x: u32 = 12345;
        let mut next = || {
            x ^= x << 13;
            x ^= x >> 17;
            x ^= x << 5;
            x
        };
        for _ in 0..20_000 {
            let n = (next() % 40) as usize;
            let mut raw: Vec<u8> = (0..n).map(|_| next() as u8).collect();
            if n > 1 && next() % 2 == 0 {
                raw[1] = [1, 2, 3, 4, 5, 6, 15, 16, 0x83, 0x90][(next() % 10) as usize];
            }
            let pending = (next() % 3 == 0).then(|| Pending {
                slave: raw.first().copied().unwrap_or(1),
                fc: raw.get(1).copied().unwrap_or(3) & 0x7F,
                a: next() as u16,
                b: (next() % 130) as u16,
                crc_ok: next() % 2 == 0,
            });
            let hint = [None, Some(REQUEST), Some(RESPONSE)][(next() % 3) as usize];
            let e = decode(&mut memo, &raw, pending, hint, None);
            assert_eq!(
                e.errors.is_empty() && e.warnings.is_empty(),
                e.flags.is_empty() || e.flags == [F::EXCEPTION_RESPONSE]
            );
        }
    }

    #[test]
    fn shapeless_bytes() {
        let mut memo = Memo::default();
        let e = decode(&mut memo, &[1, 3], None, None, None);
        assert_eq!(e.errors, vec!["frame too short (2 bytes)"]);
        let e = decode(&mut memo, &[1, 0x41, 0, 0, 0], None, None, None);
        assert_eq!(
            e.errors,
            vec!["5 bytes are no Modbus frame shape (code 0x41)"]
        );
        let e = decode(&mut memo, &[1, 3, 0, 0, 0, 0], None, None, None);
        assert_eq!(
            e.errors,
            vec!["6 bytes are no Modbus frame shape (read holding registers)"]
        );
    }
}
