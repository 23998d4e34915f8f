//! Modbus RTU on the EG2-4X2's RS485 line, from the bytes alone (mirrors
//! `decoders/modbus_rtu.py`, with `modbus_framing.py`, `modbus_pdu.py` and
//! `modbus_registers.py` as the submodules of the same names).
//!
//! `ModbusRtuDecoder` joins the two halves: `modbus_framing` finds the frames (candidate
//! lengths, CRC, collisions), `modbus_pdu` says what they mean. What ties them is the bus state
//! kept here: the request awaiting its response (which orders the framer's candidates and names
//! a read response's registers), how many identical copies of it a retrying host sent, and the
//! devices already said to use short register numbers.

use std::sync::Arc;

use super::{modbus_framing, modbus_pdu, modbus_registers};
use crate::decoders::flags::SHORT_REGISTER_NUMBERS;
use crate::decoders::framing::{ByteStreamDecoder, Framing, Stream};
use crate::decoders::model::{
    PairKey, Record, SharedFields, Str, Text, FRAME, MODBUS_RTU, REQUEST, RESPONSE,
};
use crate::generated::messages as M;
use crate::hash::FrameMemo;
use modbus_framing::{ModbusFramer, Pending, CRC_OK, CRC_SWAPPED_ORDER};
use modbus_pdu::decode;
use modbus_registers::Memo;

/// Memoised frame decodes per generation (crate::hash::FrameMemo: memory stays flat).
const FRAME_MEMO_GENERATION: usize = 4096;

/// `modbus_pdu::decode`'s result with the parts every record of it shares (fields, summary)
/// behind reference counts.
struct Decoded {
    direction: Option<&'static str>,
    name: Option<Str>,
    fields: SharedFields,
    summary: Text,
    errors: Vec<String>,
    warnings: Vec<String>,
    pair_key: Option<PairKey>,
    expects_response: bool,
    is_save: bool,
    next: Option<Pending>,
    flags: Vec<&'static str>,
}

impl From<modbus_pdu::Entry> for Decoded {
    fn from(e: modbus_pdu::Entry) -> Self {
        Decoded {
            direction: e.direction,
            name: e.name,
            fields: e.fields.into(),
            summary: e.summary.into(),
            errors: e.errors,
            warnings: e.warnings,
            pair_key: e.pair_key,
            expects_response: e.expects_response,
            is_save: e.is_save,
            next: e.next,
            flags: e.flags,
        }
    }
}

/// The memo key of a decode: everything `modbus_pdu::decode` reads besides its own caches (the
/// CRC state, the direction hint, the pending request) and the frame's bytes. None for a hint
/// the key has no code for (then the frame is decoded afresh).
fn memo_key(
    key: &mut Vec<u8>,
    raw: &[u8],
    pending: Option<Pending>,
    hint: Option<&'static str>,
    crc: Option<u8>,
) -> bool {
    key.clear();
    key.push(crc.map_or(0xFF, |c| {
        debug_assert!(c != 0xFF);
        c
    }));
    key.push(match hint {
        None => 0,
        Some(REQUEST) => 1,
        Some(RESPONSE) => 2,
        Some(_) => return false,
    });
    match pending {
        None => key.push(0),
        Some(p) => {
            key.extend_from_slice(&[1, p.slave, p.fc, p.crc_ok as u8]);
            key.extend_from_slice(&p.a.to_le_bytes());
            key.extend_from_slice(&p.b.to_le_bytes());
        }
    }
    key.extend_from_slice(raw);
    true
}

/// How the numbering warnings start (`MODBUS_SHORT_NUMBER` and `_NUMBERS`).
const SHORT: &str = "short register number";

/// The Modbus RTU protocol hooks of the byte-stream base, with the bus state they keep.
pub struct ModbusRtu {
    pub framer: ModbusFramer,
    /// identical requests sent and not yet answered
    outstanding: i64,
    /// an answer came since the pending request was first sent
    answered: bool,
    /// devices already said to use short numbers
    short_seen: [bool; 256],
    memo: Memo,
    /// whole-frame decodes by `memo_key` (a polling loop repeats the same frames)
    frames: FrameMemo<Decoded>,
    key: Vec<u8>,
}

/// Modbus RTU frames of one RS485 line, in stream order.
pub type ModbusRtuDecoder = ByteStreamDecoder<ModbusRtu>;

impl ByteStreamDecoder<ModbusRtu> {
    pub fn new(bus: Arc<str>) -> Self {
        ByteStreamDecoder::with_protocol(ModbusRtu::default(), bus, None)
    }

    /// (slave, function, start or address, count or value, CRC held) of the request awaiting
    /// its response, as on the wire.
    pub fn pending(&self) -> Option<Pending> {
        self.proto.framer.pending
    }

    /// How many identical copies of `pending` await an answer (a host's retries).
    pub fn outstanding(&self) -> i64 {
        self.proto.outstanding
    }
}

impl Default for ModbusRtu {
    fn default() -> Self {
        ModbusRtu {
            framer: ModbusFramer::default(),
            outstanding: 0,
            answered: false,
            short_seen: [false; 256],
            memo: Memo::default(),
            frames: FrameMemo::new(FRAME_MEMO_GENERATION),
            key: Vec::with_capacity(300),
        }
    }
}

impl ModbusRtu {
    /// Keep the outstanding requests up to date after a frame (`_follow`).
    fn follow(&mut self, direction: Option<&'static str>, request: Option<Pending>) {
        if direction == Some(RESPONSE) {
            // an answer: an identical request sent again before it waits for its own
            self.answered = true;
            self.outstanding -= 1;
            if self.outstanding <= 0 {
                self.outstanding = 0;
                self.framer.pending = None;
            }
        } else if request.is_some() && request == self.framer.pending && !self.answered {
            self.outstanding += 1; // the same request again before any answer: a retry
        } else {
            // a new request (or a broadcast, which nobody answers): earlier ones are given up
            self.framer.pending = request;
            self.outstanding = request.is_some() as i64;
            self.answered = false;
        }
    }

    /// A host that leaves out the 1000 offset does it on every frame: say so on its first
    /// frame per device; later frames keep `numbering: "short"` without the warning.
    fn short_numbering_once(
        &mut self,
        slave: u8,
        warnings: &mut Vec<String>,
        flags: &mut Vec<&'static str>,
    ) {
        if !self.short_seen[slave as usize] {
            self.short_seen[slave as usize] = true;
            for w in warnings.iter_mut() {
                if w.starts_with(SHORT) {
                    *w = M::modbus_host_short_numbers!(warning = w).1;
                }
            }
        } else {
            warnings.retain(|w| !w.starts_with(SHORT));
            flags.retain(|f| *f != SHORT_REGISTER_NUMBERS);
        }
    }
}

impl Framing for ModbusRtu {
    const PROTOCOL: &'static str = MODBUS_RTU;

    fn frame_at(&mut self, s: &Stream, pos: usize, final_: bool) -> i64 {
        self.framer.frame_at(s, &s.buf, pos, final_)
    }

    fn make_record(
        &mut self,
        s: &Stream,
        raw: &[u8],
        offset: u64,
        t: Option<f64>,
        valid: bool,
    ) -> Record {
        // frame_at checked the CRC of a valid frame already
        let crc = valid.then(|| {
            if self.framer.swapped == Some((offset, raw.len())) {
                CRC_SWAPPED_ORDER
            } else {
                CRC_OK
            }
        });
        let (pending, hint) = (self.framer.pending, s.direction_hint);
        let mut key = std::mem::take(&mut self.key);
        let fresh: Decoded;
        let e = if memo_key(&mut key, raw, pending, hint, crc) {
            let memo = &mut self.memo;
            self.frames
                .get_or_insert_with(&key, || decode(memo, raw, pending, hint, crc).into())
        } else {
            fresh = decode(&mut self.memo, raw, pending, hint, crc).into();
            &fresh
        };
        let (direction, next) = (e.direction, e.next);
        let mut rec = Record {
            t,
            bus: s.bus.clone(),
            protocol: MODBUS_RTU,
            kind: FRAME,
            length: raw.len(),
            raw: raw.to_vec(),
            offset: Some(offset),
            index: None,
            direction,
            device: Some(raw[0] as i64),
            code: Some(raw[1] as i64),
            name: e.name.clone(),
            fields: e.fields.clone(),
            errors: e.errors.clone(),
            warnings: e.warnings.clone(),
            summary: e.summary.clone(),
            seq: -1,
            pair: None,
            latency_ms: None,
            pair_key: e.pair_key,
            expects_response: e.expects_response,
            is_save: e.is_save,
            flags: e.flags.clone(),
        };
        self.key = key;
        self.follow(direction, next);
        if rec.flags.contains(&SHORT_REGISTER_NUMBERS) {
            self.short_numbering_once(raw[0], &mut rec.warnings, &mut rec.flags);
        }
        rec
    }

    fn truncated_reason(&self, raw: &[u8]) -> String {
        modbus_framing::truncated_reason(raw)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::decoders::framing::StreamDecoder;
    use crate::decoders::model::{Value, GARBAGE, REQUEST, TRUNCATED};
    use modbus_framing::crc16;

    fn with_crc(pdu: &[u8]) -> Vec<u8> {
        let mut f = pdu.to_vec();
        f.extend_from_slice(&crc16(pdu).to_le_bytes());
        f
    }

    fn read_request(slave: u8, start: u16, count: u16) -> Vec<u8> {
        let [a, b] = start.to_be_bytes();
        let [c, d] = count.to_be_bytes();
        with_crc(&[slave, 3, a, b, c, d])
    }

    fn read_response(slave: u8, values: &[u16]) -> Vec<u8> {
        let mut pdu = vec![slave, 3, 2 * values.len() as u8];
        for v in values {
            pdu.extend_from_slice(&v.to_be_bytes());
        }
        with_crc(&pdu)
    }

    fn decode_all(data: &[u8]) -> Vec<Record> {
        let mut dec = ModbusRtuDecoder::new(Arc::from("rs485"));
        let mut out = Vec::new();
        dec.feed(data, None, &mut out);
        dec.finish(&mut out);
        out
    }

    #[test]
    fn short_numbering_is_said_once_per_device() {
        let mut data = read_request(1, 61, 5);
        data.extend(read_response(1, &[500, 0xFFFE, 37, 0, 1]));
        data.extend(read_request(1, 61, 5));
        let recs = decode_all(&data);
        assert_eq!(recs.len(), 3);
        assert_eq!(
            recs[0].warnings,
            vec![
                "this host uses short register numbers: 61-65 mean 1061-1065 (the host leaves \
                  out the 1000 offset, as some clients do)"
            ]
        );
        assert_eq!(recs[0].flags, vec![SHORT_REGISTER_NUMBERS]);
        // later frames keep numbering: "short" without the warning
        assert!(recs[2].warnings.is_empty() && recs[2].flags.is_empty());
        assert!(recs[2]
            .fields
            .contains(&("numbering".into(), Value::from("short"))));
        assert_eq!(
            &*recs[1].summary,
            "-> measured_opening=500 (35.0 mm), current=-2, temperature_c=37 °C, \
             fault=0 (no fault), state=1 (fully open, idle)"
        );
    }

    #[test]
    fn retries_each_answer_is_decoded_against_its_request() {
        let poll = read_request(1, 1061, 2);
        let mut data = poll.clone();
        data.extend(&poll);
        data.extend(read_response(1, &[10, 20]));
        data.extend(read_response(1, &[11, 21]));
        let recs = decode_all(&data);
        let names: Vec<_> = recs.iter().map(|r| r.name.as_deref()).collect();
        assert_eq!(names, vec![Some("CMD_OPENLEN_ACT..CMD_CURRENT"); 4]);
        assert_eq!(
            &*recs[3].summary,
            "-> measured_opening=11 (0.77 mm), current=21"
        );
        assert!(recs.iter().all(|r| r.warnings.is_empty()));
    }

    #[test]
    fn stray_zero_after_a_request_is_garbage() {
        // 8-byte request + 00 collides with a 9-byte response reading: the request wins
        let mut data = read_request(1, 1061, 2);
        data.push(0);
        data.extend(read_response(1, &[10, 20]));
        let recs = decode_all(&data);
        let shape: Vec<_> = recs
            .iter()
            .map(|r| (r.kind, r.length, r.direction))
            .collect();
        assert_eq!(
            shape,
            vec![
                (FRAME, 8, Some(REQUEST)),
                (GARBAGE, 1, None),
                (FRAME, 9, Some(RESPONSE))
            ]
        );
    }

    #[test]
    fn manual_frames_swapped_crc_and_truncation() {
        let data: Vec<u8> = [
            "01 03 04 25 00 04 54 F2",
            "01 03 08 00 00 FF FE 00 25 00 00 C7 B9", // CRC high byte first, as printed
            "01 06 03",
        ]
        .iter()
        .flat_map(|h| h.split(' ').map(|b| u8::from_str_radix(b, 16).unwrap()))
        .collect();
        let recs = decode_all(&data);
        assert_eq!(recs.len(), 3);
        assert_eq!(
            recs[1].warnings,
            vec!["CRC byte order swapped (high byte first)"]
        );
        assert_eq!(recs[1].flags, vec![crate::decoders::flags::SWAPPED_CRC]);
        assert!(recs[1].errors.is_empty());
        assert_eq!(recs[2].kind, TRUNCATED);
        assert_eq!(
            recs[2].errors,
            vec!["truncated frame: the stream ended after 3 of 8 bytes (write single register)"]
        );
    }
}
