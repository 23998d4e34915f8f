//! Request/response pairing: link each response to its request, with latency. A port of
//! decoders/pairing.py (`Pairer`); read its docstring for the rules.
//!
//! Records arrive in stream order. A request that expects a response is held back until its
//! fate is known (answered, superseded, timed out, or the stream ended), so that both records
//! carry the link when they leave and an unanswered request is flagged on itself. Everything
//! behind a held request waits with it (output stays in stream order); the hold is bounded in
//! count, in input bytes and, with timestamps, in time.
//!
//! The Python keeps the held records in a deque and refers to the pending ones by identity.
//! Here every record that enters the hold gets a ticket (consecutive numbers), so a pending
//! request is found in the hold by arithmetic, and "waiting" is a flag beside the record.

use crate::decoders::model::{PairKey, Record, EG2_SERIAL, FRAME, MODBUS_RTU, REQUEST, RESPONSE};
use crate::generated::messages as M;
use crate::pyfloat::py_round;
use std::collections::VecDeque;
use std::sync::Arc;

/// Why a request will not be answered: (its flag code, its text), a catalogue message.
type Why<'a> = (&'static str, &'a str);

/// Protocols on which a host has one question open at a time (RS232 question/answer, RS485
/// half duplex): a new request on the bus means the previous one will not be answered.
fn one_outstanding(protocol: &str) -> bool {
    protocol == EG2_SERIAL || protocol == MODBUS_RTU
}

// -- small keyed maps ------------------------------------------------------------------------

use crate::hash::{FastMap, FastSet};

/// Numbers the (bus, protocol) pairs seen, so keys that start with them (the Python tuples
/// `(rec.bus, rec.protocol, ...)`) are small integers. A decoder gives all its records the
/// same `Arc` bus name, so the last one matched is almost always the answer.
#[derive(Default)]
pub struct StreamIds {
    known: Vec<(Arc<str>, &'static str)>,
    last: usize,
}

impl StreamIds {
    pub fn id(&mut self, bus: &Arc<str>, protocol: &'static str) -> u32 {
        if let Some((b, p)) = self.known.get(self.last) {
            if Arc::ptr_eq(b, bus) && *p == protocol {
                return self.last as u32;
            }
        }
        let found = self
            .known
            .iter()
            .position(|(b, p)| **b == **bus && *p == protocol);
        let i = found.unwrap_or_else(|| {
            self.known.push((bus.clone(), protocol));
            self.known.len() - 1
        });
        self.last = i;
        i as u32
    }

    pub fn bus(&self, id: u32) -> &str {
        &self.known[id as usize].0
    }

    pub fn protocol(&self, id: u32) -> &'static str {
        self.known[id as usize].1
    }
}

/// Python's `round(x, 3)`, quickly where that is easy to get right: `x * 1000` rounded to an
/// integer n is the correctly rounded result unless the product lands within a few ulps of a
/// half (then the exact decimal value decides: `py_round`); n / 1000 is then the double nearest
/// to the decimal n·10⁻³ (one correctly rounded division of exact operands), as Python's
/// string round trip gives.
fn round3(x: f64) -> f64 {
    let y = x * 1000.0;
    // NaN, infinities and the huge: the slow way
    if y.is_nan() || y.abs() >= (1u64 << 52) as f64 {
        return py_round(x, 3);
    }
    let frac = y - y.floor();
    if (frac - 0.5).abs() <= 4.0 * f64::EPSILON * y.abs().max(1.0) {
        return py_round(x, 3);
    }
    let n = y.round();
    if n == 0.0 {
        // keep the sign Python keeps: round(-0.0001, 3) is -0.0
        return 0.0_f64.copysign(x);
    }
    n / 1000.0
}

// -- the pairer ------------------------------------------------------------------------------

/// `(rec.bus, rec.protocol, *rec.pair_key)`: the stream's number and the pair key.
type Key = (u32, PairKey);

/// The requests waiting on one key: one, or a request and its retransmissions, oldest first
/// (tickets of held records; the first inline, as there is rarely a second).
struct Copies {
    first: u64,
    more: Vec<u64>,
}

impl Copies {
    fn len(&self) -> usize {
        1 + self.more.len()
    }
    fn iter(&self) -> impl Iterator<Item = u64> + '_ {
        std::iter::once(self.first).chain(self.more.iter().copied())
    }
    /// Take out `ticket`; false when none is left.
    fn remove(&mut self, ticket: u64) -> bool {
        if self.first == ticket {
            if self.more.is_empty() {
                return false;
            }
            self.first = self.more.remove(0);
        } else if let Some(i) = self.more.iter().position(|&x| x == ticket) {
            self.more.remove(i);
        }
        true
    }
}

struct Held {
    rec: Record,
    /// a pending request (the Python's `id(rec) in self._waiting`)
    waiting: bool,
}

/// The pairing stage. `push` a record, get the records that are ready, in order.
pub struct Pairer {
    pub timeout_s: f64,
    pub save_timeout_s: f64,
    pub max_held: usize,
    pub max_held_bytes: i64,
    /// seq is the record's place in its input (offset, or CAN frame index)
    pub positional: bool,
    held_bytes: i64,
    held: VecDeque<Held>,
    /// ticket the next record entering the hold gets; held[0] has `next_ticket - held.len()`
    next_ticket: u64,
    pending: FastMap<Key, Copies>,
    /// keys whose first copy got its answer
    answered: FastSet<Key>,
    next_expiry: f64,
    seq: i64,
    streams: StreamIds,
    scratch: Vec<Key>,
    /// whether the record `admit` saw last waits for an answer (for `hold`)
    admitted_waits: bool,
}

impl Default for Pairer {
    fn default() -> Self {
        Self::new(false)
    }
}

impl Pairer {
    /// The pairer with the Python's default limits (0.5 s, 2 s after a save, 10 000 records,
    /// 64 KiB of input).
    pub fn new(positional: bool) -> Self {
        Pairer {
            timeout_s: 0.5,
            save_timeout_s: 2.0,
            max_held: 10_000,
            max_held_bytes: 64 << 10,
            positional,
            held_bytes: 0,
            held: VecDeque::new(),
            next_ticket: 0,
            pending: FastMap::default(),
            answered: FastSet::default(),
            next_expiry: f64::INFINITY,
            seq: 0,
            streams: StreamIds::default(),
            scratch: Vec::new(),
            admitted_waits: false,
        }
    }

    /// Push one record; the records that are ready are appended to `out`, in order.
    pub fn push(&mut self, mut rec: Record, out: &mut Vec<Record>) {
        if self.admit(&mut rec) {
            out.push(rec);
        } else {
            self.hold(rec, out);
        }
    }

    /// The first half of `push`: number the record and pair it. True when it is ready at once
    /// (nothing held before it, nothing waiting): the caller takes it on as it is. Otherwise
    /// the caller must hand it to `hold`.
    #[inline]
    pub fn admit(&mut self, rec: &mut Record) -> bool {
        if self.positional {
            rec.seq = match rec.offset {
                Some(o) => o as i64,
                None => rec.index.unwrap_or(0) as i64,
            };
        } else {
            rec.seq = self.seq;
            self.seq += 1;
        }
        if let Some(t) = rec.t {
            if t > self.next_expiry {
                self.expire(t);
            }
        }
        // a frame that fails its checksum cannot be trusted to say who it is for
        self.admitted_waits = false;
        if let Some(pk) = rec.pair_key {
            if rec.kind == FRAME && rec.errors.is_empty() {
                if rec.direction == Some(REQUEST) {
                    self.admitted_waits = self.request(rec, pk);
                } else if rec.direction == Some(RESPONSE) {
                    self.response(rec, pk);
                }
            }
        }
        self.pending.is_empty() && self.held.is_empty()
    }

    /// The second half of `push`, for a record `admit` did not let through.
    pub fn hold(&mut self, rec: Record, out: &mut Vec<Record>) {
        if self.pending.is_empty() {
            out.extend(self.held.drain(..).map(|h| h.rec));
            out.push(rec);
            self.held_bytes = 0;
            return;
        }
        self.held_bytes += rec.length as i64;
        self.held.push_back(Held {
            rec,
            waiting: self.admitted_waits,
        });
        self.next_ticket += 1;
        if self.held[0].waiting && !self.over_limit() {
            return;
        }
        self.release(out);
    }

    /// `hold`, handing the records released to `emit` where they lie (no copy of a record
    /// into `out` and out again: the offline pipeline writes them as they are).
    pub fn hold_with(&mut self, rec: Record, emit: &mut impl FnMut(&Record)) {
        if self.pending.is_empty() {
            for h in &self.held {
                emit(&h.rec);
            }
            self.held.clear();
            emit(&rec);
            self.held_bytes = 0;
            return;
        }
        self.held_bytes += rec.length as i64;
        self.held.push_back(Held {
            rec,
            waiting: self.admitted_waits,
        });
        self.next_ticket += 1;
        if self.held[0].waiting && !self.over_limit() {
            return;
        }
        loop {
            let ready = self.held.iter().take_while(|h| !h.waiting).count();
            for h in self.held.range(..ready) {
                emit(&h.rec);
                self.held_bytes -= h.rec.length as i64;
            }
            self.held.drain(..ready);
            if self.held.is_empty() {
                self.held_bytes = 0;
                return;
            }
            if !self.over_limit() {
                return;
            }
            self.give_up_oldest();
        }
    }

    /// Live streams: time passes with no record (a quiet bus); expire and release.
    pub fn tick(&mut self, now: f64, out: &mut Vec<Record>) {
        if self.pending.is_empty() {
            return;
        }
        self.expire(now);
        self.release(out);
    }

    /// End of stream: every request still waiting was never answered.
    pub fn flush(&mut self, out: &mut Vec<Record>) {
        let mut keys = std::mem::take(&mut self.scratch);
        keys.clear();
        keys.extend(self.pending.keys().copied());
        // the Python closes them in insertion order; each flag lands on its own record, so
        // the order does not show
        for key in keys.drain(..) {
            self.close(key, M::PAIRING_END);
        }
        self.scratch = keys;
        out.extend(self.held.drain(..).map(|h| h.rec));
        self.held_bytes = 0;
    }

    /// The source of `bus` went away: its waiting requests are flagged and released.
    pub fn gap(&mut self, bus: &str, out: &mut Vec<Record>) {
        let mut keys = std::mem::take(&mut self.scratch);
        keys.clear();
        keys.extend(
            self.pending
                .keys()
                .copied()
                .filter(|k| self.streams.bus(k.0) == bus),
        );
        for key in keys.drain(..) {
            self.close(key, M::PAIRING_SOURCE_LOST);
        }
        self.scratch = keys;
        self.release(out);
    }

    /// The capture of `bus` (None: of every bus) was stopped: the requests waiting there are
    /// flagged `cut_off`, not unanswered (their answers may have come after the stop), and
    /// released. With `bus` None nothing is held afterwards.
    pub fn cut_off(&mut self, bus: Option<&str>, out: &mut Vec<Record>) {
        let mut keys = std::mem::take(&mut self.scratch);
        keys.clear();
        keys.extend(
            self.pending
                .keys()
                .copied()
                .filter(|k| bus.is_none_or(|b| self.streams.bus(k.0) == b)),
        );
        for key in keys.drain(..) {
            self.close(key, M::PAIRING_STOPPED);
        }
        self.scratch = keys;
        self.release(out);
    }

    /// A request from before `position` (a byte offset, or a CAN frame index) still waits.
    pub fn waiting_before(&self, position: u64) -> bool {
        self.held.iter().filter(|h| h.waiting).any(|h| {
            let r = &h.rec;
            r.offset.or(r.index).is_some_and(|w| w < position)
        })
    }

    // -- internals -------------------------------------------------------------------------

    fn over_limit(&self) -> bool {
        self.held.len() > self.max_held || self.held_bytes > self.max_held_bytes
    }

    fn held_mut(&mut self, ticket: u64) -> &mut Held {
        let front = self.next_ticket - self.held.len() as u64;
        &mut self.held[(ticket - front) as usize]
    }

    fn expiry_limit(&self, is_save: bool) -> f64 {
        if is_save {
            self.save_timeout_s
        } else {
            self.timeout_s
        }
    }

    /// A request (not yet in the hold: it will get ticket `next_ticket`). True when it waits.
    fn request(&mut self, rec: &mut Record, pk: PairKey) -> bool {
        let sid = self.streams.id(&rec.bus, rec.protocol);
        let key = (sid, pk);
        let ticket = self.next_ticket;
        let same_first = self.pending.get(&key).map(|c| c.first);
        let retransmitted = match same_first {
            Some(first) if !self.answered.contains(&key) => self.held_mut(first).rec.raw == rec.raw,
            _ => false,
        };
        if retransmitted {
            rec.warning_of(M::PAIRING_RETRANSMISSION);
            if let Some(c) = self.pending.get_mut(&key) {
                c.more.push(ticket);
            }
        } else {
            if one_outstanding(rec.protocol) {
                let mut keys = std::mem::take(&mut self.scratch);
                keys.clear();
                keys.extend(self.pending.keys().copied().filter(|k| k.0 == sid));
                for other in keys.drain(..) {
                    self.close(other, M::PAIRING_NEXT_REQUEST);
                }
                self.scratch = keys;
            } else if same_first.is_some() {
                self.close(key, M::PAIRING_NEXT_SAME_ID);
            }
            if !rec.expects_response {
                return false;
            }
            self.pending.insert(
                key,
                Copies {
                    first: ticket,
                    more: Vec::new(),
                },
            );
        }
        if let Some(t) = rec.t {
            let limit = self.expiry_limit(rec.is_save);
            self.next_expiry = self.next_expiry.min(t + limit);
        }
        true
    }

    fn response(&mut self, rec: &mut Record, pk: PairKey) {
        let key = (self.streams.id(&rec.bus, rec.protocol), pk);
        let Some(copies) = self.pending.get_mut(&key) else {
            rec.warning_of(M::PAIRING_NO_REQUEST);
            return;
        };
        let ticket = copies.first; // answers come in the order the copies were sent
        if copies.len() == 1 {
            self.pending.remove(&key);
            self.answered.remove(&key);
        } else {
            copies.remove(ticket);
            self.answered.insert(key);
        }
        let seq = rec.seq;
        let t = rec.t;
        let held = self.held_mut(ticket);
        held.waiting = false;
        let req = &mut held.rec;
        req.pair = Some(seq);
        rec.pair = Some(req.seq);
        if let (Some(t0), Some(t1)) = (req.t, t) {
            let latency = round3((t1 - t0) * 1000.0);
            req.latency_ms = Some(latency);
            rec.latency_ms = Some(latency);
        }
    }

    fn expire(&mut self, now: f64) {
        let mut nxt = f64::INFINITY;
        let mut keys = std::mem::take(&mut self.scratch);
        keys.clear();
        keys.extend(self.pending.keys().copied());
        let mut tickets: Vec<u64> = Vec::new();
        for &key in &keys {
            tickets.clear();
            if let Some(c) = self.pending.get(&key) {
                tickets.extend(c.iter());
            }
            for &ticket in &tickets {
                let (t, is_save) = {
                    let r = &self.held_mut(ticket).rec;
                    (r.t, r.is_save)
                };
                let Some(t) = t else { continue };
                let limit = self.expiry_limit(is_save);
                if now - t > limit {
                    let (code, text) = M::pairing_timeout!(ms = limit * 1000.0);
                    self.drop_request(key, ticket, (code, &text));
                } else {
                    nxt = nxt.min(t + limit);
                }
            }
        }
        self.scratch = keys;
        self.next_expiry = nxt;
    }

    /// No more answers will come for the requests waiting on key.
    fn close(&mut self, key: Key, why: Why) {
        let Some(c) = self.pending.get(&key) else {
            return;
        };
        let tickets: Vec<u64> = c.iter().collect();
        for ticket in tickets {
            self.drop_request(key, ticket, why);
        }
    }

    /// A waiting request will not be answered (`why`, with its flag): say so on it (unless an
    /// earlier copy of it was answered) and stop waiting.
    fn drop_request(&mut self, key: Key, ticket: u64, why: Why) {
        let answered = self.answered.contains(&key);
        let held = self.held_mut(ticket);
        if !answered {
            held.rec.warning_of(why);
        }
        held.waiting = false;
        let left = self.pending.get_mut(&key).is_some_and(|c| c.remove(ticket));
        if !left {
            self.pending.remove(&key);
            self.answered.remove(&key);
        }
    }

    fn release(&mut self, out: &mut Vec<Record>) {
        loop {
            while self.held.front().is_some_and(|h| !h.waiting) {
                let h = self.held.pop_front().expect("front checked");
                self.held_bytes -= h.rec.length as i64;
                out.push(h.rec);
            }
            if self.held.is_empty() {
                self.held_bytes = 0;
                return;
            }
            if !self.over_limit() {
                return;
            }
            self.give_up_oldest();
        }
    }

    /// Bound memory: give up on the oldest request rather than hold the stream.
    fn give_up_oldest(&mut self) {
        let head = self.next_ticket - self.held.len() as u64;
        let (bus, protocol, pk) = {
            let r = &self.held[0].rec;
            (
                r.bus.clone(),
                r.protocol,
                r.pair_key.expect("a waiting request has a key"),
            )
        };
        let key = (self.streams.id(&bus, protocol), pk);
        self.drop_request(key, head, M::PAIRING_WINDOW);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::decoders::model::{EG2_CAN, GARBAGE};

    fn rec(
        t: Option<f64>,
        protocol: &'static str,
        dir: &'static str,
        key: i64,
        raw: &[u8],
    ) -> Record {
        let mut r = Record::new(t, Arc::from("bus"), protocol, FRAME, raw.to_vec());
        r.direction = Some(dir);
        r.pair_key = Some([key, 0]);
        r.expects_response = dir == REQUEST;
        r
    }

    fn push_all(p: &mut Pairer, recs: Vec<Record>) -> Vec<Record> {
        let mut out = Vec::new();
        for r in recs {
            p.push(r, &mut out);
        }
        p.flush(&mut out);
        out
    }

    #[test]
    fn round3_is_pythons_round() {
        let mut seed = 0x2545_f491_4f6c_dd1d_u64;
        let mut next = || {
            seed ^= seed << 13;
            seed ^= seed >> 7;
            seed ^= seed << 17;
            seed
        };
        for i in 0..200_000 {
            let r = next();
            let x = match i % 4 {
                0 => (r % 10_000_000) as f64 / 1e4, // ms with a few digits
                1 => f64::from_bits(r) % 1e6,       // anything
                2 => ((r % 100_000) as f64 + 0.5) / 1000.0, // ties in decimal
                _ => (1_763_700_000.0 + (r % 1_000_000) as f64 * 1.2e-4) - 1_763_700_000.0,
            };
            let x = if r & 1 == 1 { -x } else { x };
            if !x.is_finite() {
                continue;
            }
            let (a, b) = (round3(x), py_round(x, 3));
            assert_eq!(a.to_bits(), b.to_bits(), "{x:?}: {a:?} vs {b:?}");
        }
    }

    /// `admit` + `hold_with` (records released in place) give what `push` gives, in order,
    /// on a random mix of requests, answers, retransmissions, garbage, timeouts and limits.
    #[test]
    fn hold_with_releases_as_push() {
        let mut seed = 0x9E37_79B9_7F4A_7C15_u64;
        let mut next = move || {
            seed ^= seed << 13;
            seed ^= seed >> 7;
            seed ^= seed << 17;
            seed
        };
        let mut recs = Vec::new();
        let mut t = 0.0;
        for i in 0..20_000 {
            t += (next() % 300) as f64 * 1e-3;
            let r = next();
            let proto = if r % 3 == 0 { EG2_CAN } else { EG2_SERIAL };
            let dir = if r % 5 < 2 { RESPONSE } else { REQUEST };
            let key = (r >> 8) as i64 % 4;
            let mut x = rec(
                (r % 7 != 0).then_some(t),
                proto,
                dir,
                key,
                &[key as u8, (r >> 20) as u8 % 2],
            );
            if r % 11 == 0 {
                x.kind = GARBAGE;
            }
            x.offset = Some(i);
            recs.push(x);
        }
        let fingerprint = |r: &Record| (r.offset, r.seq, r.pair, r.latency_ms, r.warnings.clone());
        for (max_held, max_bytes) in [(10_000, 64 << 10), (3, 64 << 10), (100, 10)] {
            let (mut a, mut b) = (Pairer::new(true), Pairer::new(true));
            for p in [&mut a, &mut b] {
                p.max_held = max_held;
                p.max_held_bytes = max_bytes;
            }
            let want: Vec<_> = push_all(&mut a, recs.clone())
                .iter()
                .map(fingerprint)
                .collect();
            let mut got = Vec::new();
            for mut r in recs.clone() {
                if b.admit(&mut r) {
                    got.push(fingerprint(&r));
                } else {
                    b.hold_with(r, &mut |r| got.push(fingerprint(r)));
                }
            }
            let mut rest = Vec::new();
            b.flush(&mut rest);
            got.extend(rest.iter().map(fingerprint));
            assert!(want.iter().filter(|w| w.2.is_some()).count() > 1000);
            assert!(want.iter().filter(|w| !w.4.is_empty()).count() > 1000);
            assert_eq!(got, want, "limits {max_held} / {max_bytes}");
        }
    }

    #[test]
    fn pairs_with_latency() {
        let mut p = Pairer::new(false);
        let out = push_all(
            &mut p,
            vec![
                rec(Some(1.0), EG2_CAN, REQUEST, 5, &[1]),
                rec(Some(1.0015), EG2_CAN, RESPONSE, 5, &[2]),
            ],
        );
        assert_eq!(out.len(), 2);
        assert_eq!(out[0].pair, Some(1));
        assert_eq!(out[1].pair, Some(0));
        assert_eq!(out[0].latency_ms, Some(1.5));
        assert!(out[0].warnings.is_empty());
    }

    #[test]
    fn retransmission_then_answer() {
        let mut p = Pairer::new(false);
        let out = push_all(
            &mut p,
            vec![
                rec(None, EG2_SERIAL, REQUEST, 1, &[1, 2]),
                rec(None, EG2_SERIAL, REQUEST, 1, &[1, 2]),
                rec(None, EG2_SERIAL, RESPONSE, 1, &[3]),
            ],
        );
        assert_eq!(out.iter().map(|r| r.seq).collect::<Vec<_>>(), vec![0, 1, 2]);
        assert_eq!(out[0].pair, Some(2));
        assert_eq!(out[1].warnings, vec![M::PAIRING_RETRANSMISSION.1]);
        assert_eq!(out[1].flags, vec![M::PAIRING_RETRANSMISSION.0]);
        assert_eq!(out[1].pair, None); // answered exchange: not flagged unanswered at the end
    }

    #[test]
    fn next_request_closes_on_one_outstanding_bus() {
        let mut p = Pairer::new(false);
        let out = push_all(
            &mut p,
            vec![
                rec(None, MODBUS_RTU, REQUEST, 1, &[1]),
                rec(None, MODBUS_RTU, REQUEST, 2, &[2]),
                rec(None, MODBUS_RTU, RESPONSE, 7, &[3]),
            ],
        );
        assert_eq!(out[0].warnings, vec!["no response before the next request"]);
        assert_eq!(
            out[1].warnings,
            vec!["no response before the end of the capture"]
        );
        assert_eq!(out[2].warnings, vec!["response without a request"]);
    }

    #[test]
    fn time_out_and_window() {
        let mut p = Pairer::new(false);
        let mut out = Vec::new();
        p.push(rec(Some(0.0), EG2_CAN, REQUEST, 1, &[1]), &mut out);
        assert!(out.is_empty());
        p.push(rec(Some(0.4), EG2_CAN, RESPONSE, 9, &[1]), &mut out);
        assert!(out.is_empty());
        p.push(rec(Some(0.6), EG2_CAN, RESPONSE, 9, &[1]), &mut out);
        assert_eq!(out.len(), 3);
        assert_eq!(out[0].warnings, vec!["no response within 500 ms"]);
        // the byte bound: garbage behind a request that never comes back
        let mut p = Pairer::new(true);
        let mut out = Vec::new();
        let mut r = rec(None, EG2_SERIAL, REQUEST, 1, &[1]);
        r.offset = Some(0);
        p.push(r, &mut out);
        let mut g = Record::new(None, Arc::from("bus"), EG2_SERIAL, GARBAGE, vec![0; 40000]);
        g.offset = Some(1);
        p.push(g.clone(), &mut out);
        assert!(out.is_empty());
        g.offset = Some(40001);
        p.push(g, &mut out);
        assert_eq!(out.len(), 3);
        assert_eq!(
            out[0].warnings,
            vec!["no response within the pairing window"]
        );
        assert_eq!(out[2].seq, 40001);
    }
}
