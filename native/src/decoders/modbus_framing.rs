//! Modbus RTU framing: finding frames in the bytes of an RS485 line (mirrors
//! `decoders/modbus_framing.py`).
//!
//! RTU marks frame boundaries with silence, which a capture without timing does not see, so a
//! frame is found from its bytes: the function code (and a byte count) give the candidate
//! lengths, the CRC-16/MODBUS confirms one. Candidates within `CLOSE` bytes of each other can
//! collide structurally; `_decide`/`_settle` pick one exactly as the Python does.

use crate::decoders::model::RESPONSE;

use crate::decoders::framing::Stream;
pub use crate::decoders::framing::NEED_MORE;
use crate::generated::messages as M;

pub use crate::generated::modbus::{
    function_text, READ_COILS, READ_DISCRETE, READ_HOLDING, READ_INPUT, WRITE_COIL, WRITE_COILS,
    WRITE_MULTIPLE, WRITE_SINGLE,
};

// what a function code byte announces: 0 nothing we frame, else one of these shapes
pub const KIND_READ: u8 = 1;
pub const KIND_SINGLE: u8 = 2;
pub const KIND_MULTI: u8 = 3;
pub const KIND_EXCEPTION: u8 = 4;

/// `KIND[fc]`: the frame shape a function code byte announces.
pub static KIND: [u8; 256] = {
    let mut k = [0u8; 256];
    let mut fc = 0;
    while fc < 0x80 {
        let kind = match fc as u8 {
            READ_COILS | READ_DISCRETE | READ_HOLDING | READ_INPUT => KIND_READ,
            WRITE_COIL | WRITE_SINGLE => KIND_SINGLE,
            WRITE_COILS | WRITE_MULTIPLE => KIND_MULTI,
            _ => 0,
        };
        if kind != 0 {
            k[fc] = kind;
            k[fc | 0x80] = KIND_EXCEPTION;
        }
        fc += 1;
    }
    k
};

/// never a slave address (the gripper takes 1-254, 0 is broadcast)
pub const NO_ADDRESS: u8 = 0xFF;
/// candidate lengths this near each other can collide structurally (`_decide`)
pub const CLOSE: i64 = 2;

/// (slave, function, first PDU word, second PDU word, its CRC held) of the request awaiting
/// its response (the Python `Pending` tuple).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct Pending {
    pub slave: u8,
    pub fc: u8,
    pub a: u16,
    pub b: u16,
    pub crc_ok: bool,
}

// -- CRC-16/MODBUS ----------------------------------------------------------------------------

/// Slicing-by-8 tables of the reflected polynomial 0xA001 (frames are short, but a 2-byte step
/// still halves the work of the plain table).
static CRC_TABLES: [[u16; 256]; 8] = {
    let mut t = [[0u16; 256]; 8];
    let mut i = 0;
    while i < 256 {
        let mut c = i as u16;
        let mut k = 0;
        while k < 8 {
            c = if c & 1 != 0 {
                (c >> 1) ^ 0xA001
            } else {
                c >> 1
            };
            k += 1;
        }
        t[0][i] = c;
        i += 1;
    }
    let mut i = 0;
    while i < 256 {
        let mut j = 1;
        while j < 8 {
            let prev = t[j - 1][i];
            t[j][i] = (prev >> 8) ^ t[0][(prev & 0xFF) as usize];
            j += 1;
        }
        i += 1;
    }
    t
};

/// CRC-16/MODBUS of `data` (init 0xFFFF), as crcmod's "modbus" function.
#[inline]
pub fn crc16(data: &[u8]) -> u16 {
    let t = &CRC_TABLES;
    let mut crc: u16 = 0xFFFF;
    let mut chunks = data.chunks_exact(8);
    for c in &mut chunks {
        let lo = crc ^ u16::from_le_bytes([c[0], c[1]]);
        crc = t[7][(lo & 0xFF) as usize]
            ^ t[6][(lo >> 8) as usize]
            ^ t[5][c[2] as usize]
            ^ t[4][c[3] as usize]
            ^ t[3][c[4] as usize]
            ^ t[2][c[5] as usize]
            ^ t[1][c[6] as usize]
            ^ t[0][c[7] as usize];
    }
    for &b in chunks.remainder() {
        crc = (crc >> 8) ^ t[0][((crc ^ b as u16) & 0xFF) as usize];
    }
    crc
}

pub const CRC_BAD: u8 = 0;
pub const CRC_OK: u8 = 1;
pub const CRC_SWAPPED_ORDER: u8 = 2;

/// CRC_OK, CRC_SWAPPED_ORDER or CRC_BAD for the frame buf[pos..end].
#[inline]
pub fn crc_state(buf: &[u8], pos: usize, end: usize) -> u8 {
    let c = crc16(&buf[pos..end - 2]);
    let got = buf[end - 2] as u16 | (buf[end - 1] as u16) << 8;
    if got == c {
        CRC_OK
    } else if got == c.swap_bytes() {
        CRC_SWAPPED_ORDER
    } else {
        CRC_BAD
    }
}

// -- candidate lengths ------------------------------------------------------------------------

/// Length of a read response with byte count bc, 0 if bc cannot be one.
#[inline]
pub fn read_response_len(fc: u8, bc: u8) -> i64 {
    if bc == 0 || (fc >= READ_HOLDING && bc & 1 != 0) {
        0
    } else {
        5 + bc as i64
    }
}

/// Length of a write-multiple request, 0 if count and byte count disagree.
#[inline]
pub fn write_request_len(fc: u8, count: u16, bc: u8) -> i64 {
    if count == 0 {
        return 0;
    }
    let bc = bc as i64;
    let count = count as i64;
    let agrees = if fc == WRITE_MULTIPLE {
        bc == 2 * count
    } else {
        bc == (count + 7) >> 3
    };
    if agrees {
        9 + bc
    } else {
        0
    }
}

/// Candidate frame lengths at pos, preferred first; -1 where the length is not known yet.
/// (At most two: returned as a small array and its length.)
pub fn candidates(
    buf: &[u8],
    pos: usize,
    n: usize,
    kind: u8,
    resp_first: bool,
) -> ([i64; 2], usize) {
    let fc = buf[pos + 1];
    if kind == KIND_READ {
        let resp = if pos + 2 < n {
            read_response_len(fc, buf[pos + 2])
        } else {
            -1
        };
        if resp == 0 || resp == 8 {
            return ([8, 0], 1);
        }
        return if resp_first {
            ([resp, 8], 2)
        } else {
            ([8, resp], 2)
        };
    }
    if kind == KIND_MULTI {
        let req = if pos + 6 < n {
            write_request_len(fc, word(buf, pos + 4), buf[pos + 6])
        } else {
            -1
        };
        if req == 0 {
            return ([8, 0], 1);
        }
        return if resp_first {
            ([8, req], 2)
        } else {
            ([req, 8], 2)
        };
    }
    if kind == KIND_SINGLE {
        return ([8, 0], 1);
    }
    ([5, 0], 1)
}

/// The 16-bit word (high byte first) at buf[i..i + 2].
#[inline]
pub fn word(buf: &[u8], i: usize) -> u16 {
    (buf[i] as u16) << 8 | buf[i + 1] as u16
}

// -- the framer -------------------------------------------------------------------------------

/// What the byte-stream base tells `frame_at` about the bytes held (framing.py's
/// `ByteStreamDecoder` attributes the Python framer reads).
pub trait FrameContext {
    /// stream offset of buffer index 0 (`_base`)
    fn base(&self) -> u64;
    /// the direction the source knows, if it does (`direction_hint`)
    fn direction_hint(&self) -> Option<&'static str>;
    /// a silence longer than gap_s preceded buffer index pos (`gap_at`)
    fn gap_at(&self, pos: usize) -> bool;
}

impl FrameContext for Stream {
    fn base(&self) -> u64 {
        self.base
    }
    fn direction_hint(&self) -> Option<&'static str> {
        self.direction_hint
    }
    fn gap_at(&self, pos: usize) -> bool {
        Stream::gap_at(self, pos)
    }
}

/// The framing half of the Modbus RTU decoder (`ModbusFramer`): `frame_at` and what it needs.
/// The decoder keeps `pending` (the request awaiting its response) up to date.
#[derive(Debug, Default)]
pub struct ModbusFramer {
    pub pending: Option<Pending>,
    /// (offset, length) of the last frame frame_at found valid with its CRC bytes swapped;
    /// a frame's CRC state is a property of its bytes, so this never goes stale
    pub swapped: Option<(u64, usize)>,
}

/// Up to two candidate lengths and their CRC states (None: not complete / unknown length).
type Cands = ([i64; 2], usize);

/// Does the close reading of length second hold its CRC too, beside the one ending at end?
/// None when that needs more bytes (`_close_reading_holds`).
#[inline(always)]
fn close_reading_holds(
    buf: &[u8],
    pos: usize,
    n: usize,
    fin: bool,
    end: usize,
    second: i64,
    exact: bool,
) -> Option<bool> {
    let d = pos as i64 + second - end as i64;
    if d > 0 && exact {
        // exact shortcut: this frame's CRC residue is 0, so a reading d bytes longer holds
        // exactly when the d bytes after it are 00
        if end + d as usize > n {
            return if fin { Some(false) } else { None };
        }
        return Some(buf[end] == 0 && (d == 1 || buf[end + 1] == 0));
    }
    if pos + second as usize > n {
        return if fin { Some(false) } else { None };
    }
    Some(crc_state(buf, pos, pos + second as usize) != CRC_BAD)
}

/// Index of the first reading whose CRC holds, Some(None) if none does; None while a reading
/// preferred to it is not complete yet (`_first_holding`).
fn first_holding(states: &[Option<u8>], fin: bool) -> Option<Option<usize>> {
    for (i, state) in states.iter().enumerate() {
        match state {
            None if !fin => return None,
            Some(s) if *s != CRC_BAD => return Some(Some(i)),
            _ => {}
        }
    }
    Some(None)
}

/// The holding reading cands[best] and the later readings close enough to rival it that hold
/// too; None while such a rival is not complete yet (`_contenders`).
fn contenders(
    cands: &[i64],
    states: &[Option<u8>],
    best: usize,
    rivals: bool,
    fin: bool,
) -> Option<Cands> {
    let length = cands[best];
    let mut contenders: Cands = ([length, 0], 1);
    for (&c, state) in cands[best + 1..].iter().zip(&states[best + 1..]) {
        if rivals && (c < 0 || (c - length).abs() <= CLOSE) {
            match state {
                None if !fin => return None,
                Some(s) if *s != CRC_BAD => {
                    contenders.0[contenders.1] = c;
                    contenders.1 += 1;
                }
                _ => {}
            }
        }
    }
    Some(contenders)
}

impl ModbusFramer {
    /// Length of a valid frame at pos (> 0); -length of a frame-shaped candidate whose CRC
    /// fails; 0 if no frame starts here; NEED_MORE if more bytes are needed.
    pub fn frame_at<C: FrameContext + ?Sized>(
        &mut self,
        ctx: &C,
        buf: &[u8],
        pos: usize,
        fin: bool,
    ) -> i64 {
        let n = buf.len();
        if buf[pos] == NO_ADDRESS {
            return 0;
        }
        if pos + 1 >= n {
            return NEED_MORE;
        }
        let kind = KIND[buf[pos + 1] as usize];
        if kind == KIND_SINGLE || kind == KIND_EXCEPTION {
            // one shape, either direction
            let length = if kind == KIND_SINGLE { 8 } else { 5 };
            return self.one_shape_at(ctx, buf, pos, n, fin, length);
        }
        if kind == 0 {
            return 0;
        }
        let hint = ctx.direction_hint();
        let (first, second) = self.two_readings(buf, pos, n, kind, hint);
        if let Some(length) = self.expected_reading(ctx, buf, pos, n, fin, first, second, hint) {
            return length;
        }
        let cands = if second == 0 {
            ([first, 0], 1)
        } else {
            ([first, second], 2)
        };
        self.decide(ctx, buf, pos, n, fin, cands, hint.is_none())
    }

    /// frame_at for a function with one frame length in either direction (`_one_shape_at`).
    #[inline(always)] // once per write-single or exception frame
    fn one_shape_at<C: FrameContext + ?Sized>(
        &mut self,
        ctx: &C,
        buf: &[u8],
        pos: usize,
        n: usize,
        fin: bool,
        length: usize,
    ) -> i64 {
        let end = pos + length;
        if end <= n {
            let c = crc16(&buf[pos..end - 2]);
            let got = buf[end - 2] as u16 | (buf[end - 1] as u16) << 8;
            if got == c {
                return length as i64;
            }
            if got == c.swap_bytes() {
                self.swapped = Some((ctx.base() + pos as u64, length));
                return length as i64;
            }
        }
        self.decide(ctx, buf, pos, n, fin, ([length as i64, 0], 1), false)
    }

    /// The two candidate lengths, preferred first, as candidates() orders them (inlined as
    /// the Python does); second == 0: none, -1: its length is not known yet (`_two_readings`).
    #[inline(always)] // once per frame: it was written inline in frame_at
    fn two_readings(
        &self,
        buf: &[u8],
        pos: usize,
        n: usize,
        kind: u8,
        hint: Option<&'static str>,
    ) -> (i64, i64) {
        let resp_first = match hint {
            None => matches!(self.pending, Some(p) if p.slave == buf[pos]),
            Some(h) => h == RESPONSE,
        };
        let fc = buf[pos + 1];
        if kind == KIND_READ {
            let other = if pos + 2 < n {
                let bc = buf[pos + 2];
                if bc == 0 || (fc >= READ_HOLDING && bc & 1 != 0) || bc == 3 {
                    0
                } else {
                    5 + bc as i64
                }
            } else {
                -1
            };
            return if resp_first && other != 0 {
                (other, 8)
            } else {
                (8, other)
            };
        }
        let other = if pos + 6 < n {
            write_request_len(fc, word(buf, pos + 4), buf[pos + 6])
        } else {
            -1
        };
        if resp_first || other == 0 {
            (8, other)
        } else {
            (other, 8)
        }
    }

    /// The common case: the expected shape checks, and no other reading is close enough to it
    /// to collide (see decide) or that reading fails its CRC; a known direction settles the
    /// reading by itself. None when this does not settle it (`_expected_reading`).
    #[allow(clippy::too_many_arguments)]
    #[inline(always)] // once per frame: it was written inline in frame_at
    fn expected_reading<C: FrameContext + ?Sized>(
        &mut self,
        ctx: &C,
        buf: &[u8],
        pos: usize,
        n: usize,
        fin: bool,
        first: i64,
        second: i64,
        hint: Option<&'static str>,
    ) -> Option<i64> {
        let end = pos as i64 + first;
        if first <= 0 || end as usize > n {
            return None;
        }
        let end = end as usize;
        let c = crc16(&buf[pos..end - 2]);
        let got = buf[end - 2] as u16 | (buf[end - 1] as u16) << 8;
        if got != c && got != c.swap_bytes() {
            return None;
        }
        let d = second - first;
        if second > 0 && hint.is_none() && (-CLOSE..=CLOSE).contains(&d) {
            match close_reading_holds(buf, pos, n, fin, end, second, got == c) {
                None => return Some(NEED_MORE),
                // then decide settles it
                Some(true) => {
                    return Some(self.decide(ctx, buf, pos, n, fin, ([first, second], 2), true))
                }
                Some(false) => {}
            }
        }
        if got != c {
            self.swapped = Some((ctx.base() + pos as u64, first as usize));
        }
        Some(first)
    }

    /// frame_at beyond the common case: every candidate, in the order the bus expects
    /// (`_decide`). The reading is the first candidate whose CRC holds; a close reading that
    /// holds too is settled by `settle`. Failing all, `damaged_reading`.
    #[allow(clippy::too_many_arguments)]
    fn decide<C: FrameContext + ?Sized>(
        &mut self,
        ctx: &C,
        buf: &[u8],
        pos: usize,
        n: usize,
        fin: bool,
        cands: Cands,
        rivals: bool,
    ) -> i64 {
        let (cv, cn) = cands;
        let cands = &cv[..cn];
        let mut states: [Option<u8>; 2] = [None; 2];
        for (i, &c) in cands.iter().enumerate() {
            states[i] = if c < 0 || pos + c as usize > n {
                None
            } else {
                Some(crc_state(buf, pos, pos + c as usize))
            };
        }
        let states = &states[..cn];
        let best = match first_holding(states, fin) {
            None => return NEED_MORE,
            Some(None) => return self.damaged_reading(ctx, buf, pos, n, fin, cands, states),
            Some(Some(best)) => best,
        };
        let Some(contenders) = contenders(cands, states, best, rivals, fin) else {
            return NEED_MORE;
        };
        let mut length = contenders.0[0];
        if contenders.1 > 1 {
            length = self.settle(
                ctx,
                buf,
                pos,
                n,
                fin,
                &contenders.0[..contenders.1],
                cands[0],
            );
            if length == NEED_MORE {
                return NEED_MORE;
            }
        }
        let idx = cands
            .iter()
            .position(|&c| c == length)
            .expect("length is a candidate");
        if states[idx] == Some(CRC_SWAPPED_ORDER) {
            self.swapped = Some((ctx.base() + pos as u64, length as usize));
        }
        length
    }

    /// Every candidate failed its CRC, or the stream ended: the first candidate cut off by the
    /// end makes a truncated frame (the base reports it on NEED_MORE when final); a bad CRC
    /// makes a frame only where one plausibly ends (`_damaged_reading`).
    #[allow(clippy::too_many_arguments)]
    fn damaged_reading<C: FrameContext + ?Sized>(
        &self,
        ctx: &C,
        buf: &[u8],
        pos: usize,
        n: usize,
        fin: bool,
        cands: &[i64],
        states: &[Option<u8>],
    ) -> i64 {
        for (&c, state) in cands.iter().zip(states) {
            if state.is_none() {
                return NEED_MORE;
            }
            let end = pos + c as usize;
            if end == n {
                return if fin { -c } else { NEED_MORE }; // not final: does the stream end here?
            }
            if ctx.gap_at(end) {
                return -c;
            }
            match self.valid_at(buf, end, n, fin) {
                None => return NEED_MORE,
                Some(true) => return -c,
                Some(false) => {}
            }
        }
        0
    }

    /// Several readings at pos hold their CRC: the one that makes sense wins (`_settle`):
    /// what the readings say, then what follows them, then the expected reading.
    #[allow(clippy::too_many_arguments)]
    fn settle<C: FrameContext + ?Sized>(
        &self,
        ctx: &C,
        buf: &[u8],
        pos: usize,
        n: usize,
        fin: bool,
        contenders: &[i64],
        expected: i64,
    ) -> i64 {
        let mut scores = [0i32; 2];
        for (i, &c) in contenders.iter().enumerate() {
            scores[i] = self.sense(buf, pos, c as usize) + (c == expected) as i32;
        }
        let scores = &scores[..contenders.len()];
        let top = *scores.iter().max().expect("contenders");
        let mut tied = [0i64; 2];
        let mut ntied = 0;
        for (&c, &score) in contenders.iter().zip(scores) {
            if score == top {
                tied[ntied] = c;
                ntied += 1;
            }
        }
        let tied = &tied[..ntied];
        if tied.len() == 1 {
            return tied[0];
        }
        for &c in tied {
            let end = pos + c as usize;
            if end >= n {
                if !fin {
                    return NEED_MORE;
                }
                return c;
            }
            if ctx.gap_at(end) {
                return c;
            }
            match self.valid_at(buf, end, n, fin) {
                None => return NEED_MORE,
                Some(true) => return c,
                Some(false) => {}
            }
        }
        tied[0]
    }

    /// 1 if the reading of buf[pos..pos + length] is content a real device would send.
    fn sense(&self, buf: &[u8], pos: usize, length: usize) -> i32 {
        let (slave, fc) = (buf[pos], buf[pos + 1]);
        let kind = KIND[fc as usize];
        let p = self.pending;
        let answers = matches!(p, Some(p) if p.slave == slave && p.fc == fc);
        if kind == KIND_READ && length == 8 {
            // a read request
            let count = word(buf, pos + 4);
            let limit = if fc >= READ_HOLDING { 125 } else { 2000 };
            return (1..=limit).contains(&count) as i32;
        }
        if kind == KIND_READ {
            // a read response
            let Some(p) = p.filter(|_| answers) else {
                return 1;
            };
            let bc = buf[pos + 2] as i64;
            let want = if fc >= READ_HOLDING {
                2 * p.b as i64
            } else {
                (p.b as i64 + 7) >> 3
            };
            return (bc == want) as i32;
        }
        if kind == KIND_MULTI && length == 8 {
            // a write-multiple response
            let (start, count) = (word(buf, pos + 2), word(buf, pos + 4));
            if let Some(p) = p.filter(|_| answers) {
                return (p.a == start && p.b == count) as i32;
            }
            let limit = if fc == WRITE_MULTIPLE { 123 } else { 1968 };
            return (1..=limit).contains(&count) as i32;
        }
        1
    }

    /// Does a frame with a good CRC start at pos? None: not known before more bytes.
    fn valid_at(&self, buf: &[u8], pos: usize, n: usize, fin: bool) -> Option<bool> {
        if pos >= n {
            return if fin { Some(false) } else { None };
        }
        if buf[pos] == NO_ADDRESS {
            return Some(false);
        }
        if pos + 1 >= n {
            return if fin { Some(false) } else { None };
        }
        let kind = KIND[buf[pos + 1] as usize];
        if kind == 0 {
            return Some(false);
        }
        let mut cut = false;
        let (cv, cn) = candidates(buf, pos, n, kind, false);
        for &length in &cv[..cn] {
            if length < 0 || pos + length as usize > n {
                cut = true;
            } else if crc_state(buf, pos, pos + length as usize) != CRC_BAD {
                return Some(true);
            }
        }
        if cut && !fin {
            None
        } else {
            Some(false)
        }
    }
}

/// The error text of a truncated frame (`ModbusFramer.truncated_reason`).
pub fn truncated_reason(raw: &[u8]) -> String {
    let n = raw.len();
    let got = format!("{n} byte{}", if n != 1 { "s" } else { "" });
    let kind = if n >= 2 { KIND[raw[1] as usize] } else { 0 };
    if kind == 0 {
        return M::modbus_truncated!(bytes = got).1;
    }
    let func = function_text(raw[1] & 0x7F).expect("a framed function");
    let what = if kind == KIND_EXCEPTION {
        format!("exception response to {func}")
    } else {
        func.to_string()
    };
    let (cv, cn) = candidates(raw, 0, n, kind, false);
    let mut lengths: Vec<i64> = cv[..cn].iter().copied().filter(|&c| c > n as i64).collect();
    lengths.sort_unstable();
    lengths.dedup();
    if lengths.is_empty() {
        return M::modbus_truncated_function!(bytes = got, what = what).1;
    }
    let joined: Vec<String> = lengths.iter().map(|l| l.to_string()).collect();
    M::modbus_truncated_lengths!(length = n, lengths = joined.join(" or "), what = what).1
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn crc_check_value() {
        assert_eq!(crc16(b"123456789"), 0x4B37);
        // every length through the 8-byte slices and the tail
        let data: Vec<u8> = (0..40u8)
            .map(|i| i.wrapping_mul(37).wrapping_add(11))
            .collect();
        for n in 0..data.len() {
            let mut c: u16 = 0xFFFF;
            for &b in &data[..n] {
                c ^= b as u16;
                for _ in 0..8 {
                    c = if c & 1 != 0 {
                        (c >> 1) ^ 0xA001
                    } else {
                        c >> 1
                    };
                }
            }
            assert_eq!(crc16(&data[..n]), c, "length {n}");
        }
    }

    #[test]
    fn kinds() {
        assert_eq!(KIND[0x03], KIND_READ);
        assert_eq!(KIND[0x83], KIND_EXCEPTION);
        assert_eq!(KIND[0x10], KIND_MULTI);
        assert_eq!(KIND[0x06], KIND_SINGLE);
        assert_eq!(KIND[0x07], 0);
        assert_eq!(KIND[0x87], 0);
    }

    #[test]
    fn truncated_texts() {
        assert_eq!(
            truncated_reason(&[1, 3, 10]),
            "truncated frame: the stream ended after 3 of 8 or 15 bytes (read holding registers)"
        );
        assert_eq!(
            truncated_reason(&[1]),
            "truncated frame: the stream ended after 1 byte"
        );
        assert_eq!(
            truncated_reason(&[1, 0x86, 2]),
            "truncated frame: the stream ended after 3 of 5 bytes (exception response to write single register)"
        );
    }
}
