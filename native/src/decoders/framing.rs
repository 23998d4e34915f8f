//! Splitting a byte stream into frames, shared by the serial and Modbus RTU decoders.
//!
//! Mirrors `decoders/framing.py` (`ByteStreamDecoder`). A protocol supplies the hooks of
//! [`Framing`] (`frame_at`, `next_start`, `make_record`, `truncated_reason`, with the Python
//! meanings and return conventions: `> 0` a valid frame's length, `-length` a frame-shaped
//! candidate whose checksum fails, `0` no frame here, [`NEED_MORE`]); the generic
//! [`ByteStreamDecoder`] does the rest the same way for every protocol:
//!
//! - bytes are kept only until they are decided, so memory stays flat;
//! - a run of bytes that belongs to no frame becomes `garbage` records of at most
//!   [`MAX_GARBAGE`] bytes each;
//! - a candidate whose checksum fails is a frame with an error unless a valid frame starts inside
//!   it (then its first bytes are garbage, resynchronising one byte on);
//! - at the end of the stream a frame that lacks bytes becomes a `truncated` record;
//! - every input byte ends up in exactly one record.
//!
//! The hooks see the base's state through [`Stream`] (the buffer, its stream offset, the
//! direction hint, `gap_at`), as the Python subclasses see `self._buf`, `self._base`,
//! `self.direction_hint` and `self.gap_at`. The hooks must be called in the same order as the
//! Python calls them, since a protocol may keep state in them (Modbus remembers a swapped CRC).

use crate::decoders::flags;
use crate::decoders::model::{Record, CUT_OFF, GARBAGE, TRUNCATED};
use crate::generated::messages as M;
use std::collections::VecDeque;
use std::sync::Arc;

/// `frame_at`: cannot decide before more bytes arrive.
pub const NEED_MORE: i64 = -0x7FFF_FFFF;
/// A garbage run is cut into records of at most this many bytes.
pub const MAX_GARBAGE: usize = 4096;

/// A byte-stream decoder (serial or Modbus RTU): bytes in, Records out in stream order.
pub trait StreamDecoder {
    /// Bytes as they arrived; `t`: arrival time of the chunk (None for raw dumps).
    fn feed(&mut self, data: &[u8], t: Option<f64>, out: &mut Vec<Record>);
    /// End of input: decide everything held (truncated frames, garbage).
    fn finish(&mut self, out: &mut Vec<Record>);
    /// The capture was stopped, not the stream ended: as `finish`, but a frame begun is a
    /// `cut_off` record (no error: the stop cut it, not the bus).
    fn stop(&mut self, out: &mut Vec<Record>);
    /// The stream's first byte is at `offset` of a larger capture (parallel parts).
    fn start_at(&mut self, offset: u64);
    /// Stream offset of the first byte not decided yet (None: nothing held).
    fn held_from(&self) -> Option<u64>;
}

/// One chunk's place and time (Python's `_ChunkSpan`).
#[derive(Clone, Copy, Debug)]
struct ChunkSpan {
    /// stream offset of its first byte
    start: u64,
    /// stream offset after its last byte
    end: u64,
    /// its arrival time
    t: Option<f64>,
    /// a silence longer than `gap_s` came before it
    gap: bool,
}

/// The base's state that a protocol's hooks may read (the Python subclasses read these
/// attributes of `self`).
#[derive(Debug)]
pub struct Stream {
    pub bus: Arc<str>,
    /// seconds per byte on the line (10 bits / baud), when known
    pub byte_time_s: Option<f64>,
    /// the bytes held (Python `_buf`)
    pub buf: Vec<u8>,
    /// stream offset of `buf[0]` (Python `_base`)
    pub base: u64,
    /// direction of the newest chunk, if the source knows it
    pub direction_hint: Option<&'static str>,
    times: VecDeque<ChunkSpan>,
    last_t: Option<f64>,
    /// with a byte time: when the last stamped record's bytes had all arrived
    stamped_until: f64,
}

impl Stream {
    /// True if a silence longer than `gap_s` preceded buffer index `pos` (a boundary hint).
    pub fn gap_at(&self, pos: usize) -> bool {
        let offset = self.base + pos as u64;
        self.times.iter().any(|s| s.start == offset && s.gap)
    }

    /// The chunk holding `offset`, dropping entries wholly before it.
    fn chunk_of(&mut self, offset: u64) -> Option<ChunkSpan> {
        let times = &mut self.times;
        while times.len() > 1 && times[1].start <= offset {
            times.pop_front();
        }
        times.front().copied()
    }

    fn time_of(&mut self, offset: u64) -> Option<f64> {
        self.chunk_of(offset).and_then(|s| s.t)
    }

    /// Give a record its time, estimated from its place in its chunk when the byte time is
    /// known (Python `_stamp`).
    fn stamp(&mut self, rec: &mut Record) {
        let offset = rec.offset.expect("a framed record has an offset");
        let Some(span) = self.chunk_of(offset) else {
            return;
        };
        let (Some(t), Some(bt)) = (span.t, self.byte_time_s) else {
            rec.t = span.t;
            return;
        };
        let est = t - (span.end - offset) as f64 * bt;
        // Python max(est, stamped_until): the first unless the second is greater
        let rt = if self.stamped_until > est {
            self.stamped_until
        } else {
            est
        };
        rec.t = Some(rt);
        self.stamped_until = rt + rec.length as f64 * bt;
        if span.start < offset || span.end > offset + rec.length as u64 {
            rec.flags.push(flags::ESTIMATED_TIME);
        }
    }
}

/// What a protocol supplies (the methods a Python `ByteStreamDecoder` subclass overrides).
pub trait Framing {
    /// `Record.protocol` of garbage and truncated records.
    const PROTOCOL: &'static str;
    /// True when `next_start` is overridden (the Python base checks
    /// `type(self).next_start is not ByteStreamDecoder.next_start`).
    const SKIPS: bool = false;
    /// Silence that hints at a frame boundary.
    const GAP_S: f64 = 0.00175;
    /// A live line quiet this long will not finish the frame it started.
    const IDLE_S: f64 = 0.1;

    /// Length of a valid frame at `pos` (> 0); -length of a frame-shaped candidate whose
    /// checksum fails; 0 if no frame starts here; [`NEED_MORE`] if more bytes are needed.
    /// The bytes are `s.buf`.
    fn frame_at(&mut self, s: &Stream, pos: usize, final_: bool) -> i64;

    /// The first index >= pos where a frame could start (buf.len() if none). Only called
    /// when [`Framing::SKIPS`] is true or from the resynchronisation search.
    fn next_start(&mut self, buf: &[u8], pos: usize) -> usize {
        let _ = buf;
        pos
    }

    /// The record of the frame `raw` at stream `offset` (`valid`: frame_at said its checksum
    /// holds).
    fn make_record(
        &mut self,
        s: &Stream,
        raw: &[u8],
        offset: u64,
        t: Option<f64>,
        valid: bool,
    ) -> Record;

    fn truncated_reason(&self, raw: &[u8]) -> String {
        M::framing_truncated!(length = raw.len()).1
    }
}

/// The shared machinery of the byte-stream decoders, generic over the protocol's hooks.
#[derive(Debug)]
pub struct ByteStreamDecoder<P: Framing> {
    pub proto: P,
    pub stream: Stream,
    /// buffer index where the open garbage run starts
    garbage_at: Option<usize>,
    /// buffer index of the first byte not decided yet (after an open run)
    resume: usize,
    garbage_why: &'static str,
    /// set by valid_start: a candidate needs bytes not yet received
    undecided: bool,
    /// deciding the held bytes because the capture was stopped (`stop`)
    stopping: bool,
}

impl<P: Framing> ByteStreamDecoder<P> {
    /// `byte_time_s`: seconds per byte on the line, when known; chunk times are then arrival
    /// times of their last byte.
    pub fn with_protocol(proto: P, bus: Arc<str>, byte_time_s: Option<f64>) -> Self {
        if let Some(bt) = byte_time_s {
            assert!(bt > 0.0, "byte_time_s must be positive, not {bt}");
        }
        ByteStreamDecoder {
            proto,
            stream: Stream {
                bus,
                byte_time_s,
                buf: Vec::new(),
                base: 0,
                direction_hint: None,
                times: VecDeque::new(),
                last_t: None,
                stamped_until: f64::NEG_INFINITY,
            },
            garbage_at: None,
            resume: 0,
            garbage_why: M::GARBAGE_NO_HEADER,
            undecided: false,
            stopping: false,
        }
    }

    /// Python `feed(Chunk(data, t, direction))`.
    pub fn feed_chunk(
        &mut self,
        data: &[u8],
        t: Option<f64>,
        direction: Option<&'static str>,
        out: &mut Vec<Record>,
    ) {
        let s = &mut self.stream;
        if direction.is_some() {
            s.direction_hint = direction;
        }
        if !data.is_empty() {
            let mut gap = false;
            if let (Some(t), Some(last)) = (t, s.last_t) {
                let first_byte_t = match s.byte_time_s {
                    None => t,
                    Some(bt) => t - data.len() as f64 * bt,
                };
                gap = first_byte_t - last > P::GAP_S;
            }
            let start = s.base + s.buf.len() as u64;
            s.times.push_back(ChunkSpan {
                start,
                end: start + data.len() as u64,
                t,
                gap,
            });
            s.buf.extend_from_slice(data);
        }
        if t.is_some() {
            s.last_t = t;
        }
        self.scan(false, out);
    }

    /// Live streams: when the line has been quiet for `IDLE_S`, decide the bytes held as if
    /// the stream had ended.
    pub fn idle(&mut self, now: f64, out: &mut Vec<Record>) {
        if let Some(last) = self.stream.last_t {
            if !self.stream.buf.is_empty() && now - last > P::IDLE_S {
                self.scan(true, out);
            }
        }
    }

    /// Decide what can be decided in the bytes held; keep the rest.
    fn scan(&mut self, final_: bool, out: &mut Vec<Record>) {
        let n = self.stream.buf.len();
        let mut pos = self.resume; // the bytes of an open garbage run are decided: not again
        let plain_times = self.stream.byte_time_s.is_none();
        while pos < n {
            if P::SKIPS {
                let start = self.proto.next_start(&self.stream.buf, pos);
                if start > pos {
                    self.garbage(out, pos, start, None);
                    pos = start;
                    if pos >= n {
                        break;
                    }
                }
            }
            let r = self.proto.frame_at(&self.stream, pos, final_);
            if r > 0 {
                // the common case: a valid frame
                let r = r as usize;
                if self.garbage_at.is_some() {
                    self.flush_garbage(out, pos);
                }
                if plain_times {
                    let s = &mut self.stream;
                    let offset = s.base + pos as u64;
                    let t = if s.times.len() == 1 {
                        s.times[0].t
                    } else {
                        s.time_of(offset)
                    };
                    let rec = self
                        .proto
                        .make_record(s, &s.buf[pos..pos + r], offset, t, true);
                    out.push(rec);
                } else {
                    let rec = self.frame(pos, r, true);
                    out.push(rec);
                }
                pos += r;
            } else if r == 0 {
                self.garbage(out, pos, pos + 1, None);
                pos += 1;
            } else if r == NEED_MORE {
                if !final_ {
                    break;
                }
                pos = self.cut_off(out, pos);
            } else {
                match self.failed(out, pos, (-r) as usize, final_) {
                    Some(nxt) => pos = nxt,
                    None => break,
                }
            }
        }
        if final_ {
            self.flush_garbage(out, pos);
        }
        self.keep_from(pos);
    }

    /// The stream ended inside a candidate at pos: a frame may still start after it, else it
    /// is a truncated frame. Returns where to go on.
    fn cut_off(&mut self, out: &mut Vec<Record>, pos: usize) -> usize {
        let n = self.stream.buf.len();
        let Some(q) = self.valid_start(pos + 1, n, true) else {
            self.flush_garbage(out, pos);
            let rec = self.truncated(pos);
            out.push(rec);
            return n;
        };
        let q = self.damaged_start(pos + 1, q, true);
        self.garbage(out, pos, q, Some(M::GARBAGE_INCOMPLETE));
        q
    }

    /// A candidate at pos whose checksum fails: a frame with an error, or garbage up to a
    /// frame that starts inside it. Returns where to go on, None to wait for more bytes.
    fn failed(
        &mut self,
        out: &mut Vec<Record>,
        pos: usize,
        length: usize,
        final_: bool,
    ) -> Option<usize> {
        let Some(q) = self.valid_start(pos + 1, pos + length, final_) else {
            if !final_ && self.undecided {
                return None;
            }
            self.flush_garbage(out, pos);
            let rec = self.frame(pos, length, false);
            out.push(rec);
            return Some(pos + length);
        };
        let q = self.damaged_start(pos + 1, q, final_);
        self.garbage(out, pos, q, Some(M::GARBAGE_BAD_CHECKSUM));
        Some(q)
    }

    /// Drop the decided bytes before pos (an open garbage run, shorter than MAX_GARBAGE,
    /// stays held) and the chunk times no record needs any more.
    fn keep_from(&mut self, pos: usize) {
        let keep_from = self.garbage_at.unwrap_or(pos);
        self.resume = pos - keep_from;
        if keep_from == 0 {
            return;
        }
        let s = &mut self.stream;
        if keep_from == s.buf.len() {
            s.buf.clear();
        } else {
            s.buf.drain(..keep_from);
        }
        s.base += keep_from as u64;
        if let Some(g) = self.garbage_at.as_mut() {
            *g -= keep_from;
        }
        while s.times.len() > 1 && s.times[0].end <= s.base {
            s.times.pop_front();
        }
    }

    /// First index in [lo, hi) where a valid frame starts. Sets `undecided` when a candidate
    /// there needs bytes not yet received (the caller then waits, unless final).
    fn valid_start(&mut self, lo: usize, hi: usize, final_: bool) -> Option<usize> {
        self.undecided = false;
        let mut q = lo;
        while q < hi {
            q = self.proto.next_start(&self.stream.buf, q);
            if q >= hi {
                break;
            }
            let r = self.proto.frame_at(&self.stream, q, final_);
            if r > 0 {
                return Some(q);
            }
            if r == NEED_MORE && !final_ {
                self.undecided = true;
                return None;
            }
            q += 1;
        }
        None
    }

    /// Where to resume before the valid frame at `valid`: the first candidate in [lo, valid)
    /// whose checksum fails and that ends by `valid`, else `valid`.
    fn damaged_start(&mut self, lo: usize, valid: usize, final_: bool) -> usize {
        let mut q = lo;
        while q < valid {
            q = self.proto.next_start(&self.stream.buf, q);
            if q >= valid {
                break;
            }
            let r = self.proto.frame_at(&self.stream, q, final_);
            if r < 0 && r != NEED_MORE && q as i64 - r <= valid as i64 {
                return q;
            }
            q += 1;
        }
        valid
    }

    /// Bytes [lo, hi) belong to no frame: extend the open garbage run (or open one) and emit
    /// it in pieces of MAX_GARBAGE bytes as it grows.
    fn garbage(&mut self, out: &mut Vec<Record>, lo: usize, hi: usize, why: Option<&'static str>) {
        let mut at = match self.garbage_at {
            None => {
                self.garbage_why = why.unwrap_or(M::GARBAGE_NO_FRAME);
                lo
            }
            Some(at) => {
                if let Some(why) = why {
                    self.garbage_why = why;
                }
                at
            }
        };
        while hi - at >= MAX_GARBAGE {
            let piece_end = at + MAX_GARBAGE;
            let rec = self.garbage_record(at, piece_end);
            out.push(rec);
            at = piece_end;
        }
        self.garbage_at = Some(at);
    }

    fn flush_garbage(&mut self, out: &mut Vec<Record>, end: usize) {
        if let Some(lo) = self.garbage_at {
            if end > lo {
                let rec = self.garbage_record(lo, end);
                out.push(rec);
            }
        }
        self.garbage_at = None;
    }

    fn garbage_record(&mut self, lo: usize, hi: usize) -> Record {
        let s = &mut self.stream;
        let raw = s.buf[lo..hi].to_vec();
        let n = raw.len();
        let mut rec = Record::new(None, s.bus.clone(), P::PROTOCOL, GARBAGE, raw);
        rec.offset = Some(s.base + lo as u64);
        rec.error_of(M::framing_garbage!(length = n, why = self.garbage_why));
        rec.summary = format!("{n} garbage bytes").into();
        s.stamp(&mut rec);
        rec
    }

    fn frame(&mut self, pos: usize, length: usize, valid: bool) -> Record {
        let s = &mut self.stream;
        let offset = s.base + pos as u64;
        if s.byte_time_s.is_none() {
            let t = s.time_of(offset);
            return self
                .proto
                .make_record(s, &s.buf[pos..pos + length], offset, t, valid);
        }
        let mut rec = self
            .proto
            .make_record(s, &s.buf[pos..pos + length], offset, None, valid);
        s.stamp(&mut rec);
        rec
    }

    /// The bytes from `pos` to the end: a frame cut off by the end of the stream.
    fn truncated(&mut self, pos: usize) -> Record {
        if self.stopping {
            return self.cut_off_record(pos);
        }
        let s = &mut self.stream;
        let raw = s.buf[pos..].to_vec();
        let n = raw.len();
        let reason = self.proto.truncated_reason(&raw);
        let mut rec = Record::new(None, s.bus.clone(), P::PROTOCOL, TRUNCATED, raw);
        rec.offset = Some(s.base + pos as u64);
        rec.errors.push(reason);
        rec.summary = format!("truncated frame ({n} bytes)").into();
        rec.flags.push(flags::TRUNCATED);
        s.stamp(&mut rec);
        rec
    }
}

impl<P: Framing> ByteStreamDecoder<P> {
    /// The bytes from `pos` to the end: a frame the capture's stop cut off.
    fn cut_off_record(&mut self, pos: usize) -> Record {
        let s = &mut self.stream;
        let raw = s.buf[pos..].to_vec();
        let n = if raw.len() == 1 {
            "1 byte".to_string()
        } else {
            format!("{} bytes", raw.len())
        };
        let mut rec = Record::new(None, s.bus.clone(), P::PROTOCOL, CUT_OFF, raw);
        rec.offset = Some(s.base + pos as u64);
        let (flag, words) = M::framing_cut_off!(bytes = n);
        rec.warnings.push(words);
        rec.summary = format!("frame cut off by the stop ({n})").into();
        rec.flags.push(flag);
        s.stamp(&mut rec);
        rec
    }
}

impl<P: Framing> StreamDecoder for ByteStreamDecoder<P> {
    fn feed(&mut self, data: &[u8], t: Option<f64>, out: &mut Vec<Record>) {
        self.feed_chunk(data, t, None, out);
    }

    fn finish(&mut self, out: &mut Vec<Record>) {
        self.scan(true, out);
    }

    fn stop(&mut self, out: &mut Vec<Record>) {
        self.stopping = true;
        self.scan(true, out);
        self.stopping = false;
    }

    fn start_at(&mut self, offset: u64) {
        assert!(
            self.stream.buf.is_empty() && self.stream.base == 0,
            "start_at() must come before the first feed()"
        );
        self.stream.base = offset;
    }

    fn held_from(&self) -> Option<u64> {
        if let Some(g) = self.garbage_at {
            return Some(self.stream.base + g as u64);
        }
        if self.stream.buf.is_empty() {
            None
        } else {
            Some(self.stream.base)
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::decoders::model::FRAME;

    /// A toy protocol: `AA len payload sum` (len = payload bytes, sum = payload sum & 0xFF).
    struct Toy;

    impl Framing for Toy {
        const PROTOCOL: &'static str = "toy";

        fn frame_at(&mut self, s: &Stream, pos: usize, _final: bool) -> i64 {
            let buf = &s.buf;
            if buf[pos] != 0xAA {
                return 0;
            }
            if pos + 1 >= buf.len() {
                return NEED_MORE;
            }
            let size = buf[pos + 1] as usize + 3;
            if pos + size > buf.len() {
                return NEED_MORE;
            }
            let sum = buf[pos + 2..pos + size - 1]
                .iter()
                .fold(0u8, |a, b| a.wrapping_add(*b));
            if sum == buf[pos + size - 1] {
                size as i64
            } else {
                -(size as i64)
            }
        }

        fn make_record(
            &mut self,
            s: &Stream,
            raw: &[u8],
            offset: u64,
            t: Option<f64>,
            valid: bool,
        ) -> Record {
            let mut r = Record::new(t, s.bus.clone(), "toy", FRAME, raw.to_vec());
            r.offset = Some(offset);
            if !valid {
                r.errors.push("bad".into());
            }
            r
        }
    }

    fn run(chunks: &[&[u8]]) -> Vec<Record> {
        let mut d = ByteStreamDecoder::with_protocol(Toy, Arc::from("b"), None);
        let mut out = Vec::new();
        for c in chunks {
            d.feed(c, None, &mut out);
        }
        d.finish(&mut out);
        out
    }

    #[test]
    fn every_byte_once_in_any_chunking() {
        let data: &[u8] = &[1, 2, 0xAA, 2, 5, 6, 11, 0xAA, 1, 9, 9, 0xAA, 3, 1];
        let whole = run(&[data]);
        let kinds: Vec<_> = whole.iter().map(|r| (r.kind, r.offset, r.length)).collect();
        assert_eq!(
            kinds,
            vec![
                (GARBAGE, Some(0), 2),
                (FRAME, Some(2), 5),
                (FRAME, Some(7), 4),
                (TRUNCATED, Some(11), 3)
            ]
        );
        let bytewise: Vec<&[u8]> = data.chunks(1).collect();
        let again: Vec<_> = run(&bytewise)
            .iter()
            .map(|r| (r.kind, r.offset, r.length))
            .collect();
        assert_eq!(kinds, again);
    }

    #[test]
    fn long_garbage_is_cut() {
        let data = vec![0u8; MAX_GARBAGE * 2 + 10];
        let out = run(&[&data]);
        let lens: Vec<_> = out.iter().map(|r| r.length).collect();
        assert_eq!(lens, vec![MAX_GARBAGE, MAX_GARBAGE, 10]);
        assert_eq!(
            out[0].errors[0],
            "garbage: 4096 bytes belong to no frame (no frame starts here)"
        );
    }

    #[test]
    fn bad_candidate_resynchronises_one_byte_on() {
        // AA 04 [AA 01 07 07] 00: the outer candidate fails its sum, a valid frame starts
        // inside it: its first two bytes are garbage, the inner frame is decoded
        let data: &[u8] = &[0xAA, 4, 0xAA, 1, 7, 7, 0];
        let out = run(&[data]);
        let kinds: Vec<_> = out.iter().map(|r| (r.kind, r.offset, r.length)).collect();
        assert_eq!(
            kinds,
            vec![
                (GARBAGE, Some(0), 2),
                (FRAME, Some(2), 4),
                (GARBAGE, Some(6), 1)
            ]
        );
        assert_eq!(
            out[0].errors[0],
            "garbage: 2 bytes belong to no frame \
             (bytes of a frame-shaped candidate with a bad checksum)"
        );
    }

    #[test]
    fn held_bytes_wait_for_more() {
        let mut d = ByteStreamDecoder::with_protocol(Toy, Arc::from("b"), None);
        let mut out = Vec::new();
        d.feed(&[0, 0xAA, 2, 1], None, &mut out);
        assert_eq!(out.len(), 0); // garbage waits for its end
        assert_eq!(d.held_from(), Some(0));
        d.feed(&[1, 2], None, &mut out);
        assert_eq!(out.len(), 2);
        assert_eq!(d.held_from(), None);
    }
}
