//! The live decoding of CAN frames: analyzer/session/stage.py `Decoding`, for sessions whose input
//! is CAN frames only (a CAN tap, a CAN capture replayed).
//!
//! The same stages as `Decoding.feed_can` / `_decode_can` / `tick` / `gap` / `finish`: one
//! `Eg2CanDecoder` per bus name, frames numbered across all buses (`can_index`), then the
//! timing linter, then request/response pairing. With CAN items only, the Python's byte
//! streams never exist, so `tick` is the pairer's time-out, `gap` its gap and `finish` its flush
//! (the Python's `_post([])` of the empty stream list adds nothing).
//!
//! No Python here: python_live.rs reads the Items and hands over `CanFrame`s. Bus names are
//! interned (one `Arc` per name), which the pairer's and linter's stream numbering relies on
//! for speed (`Arc::ptr_eq` before comparing text).

use crate::decoders::eg2_can::{CanMemos, Eg2CanDecoder};
use crate::decoders::lint::TimingLinter;
use crate::decoders::model::{CanFrame, Record};
use crate::decoders::pairing::Pairer;
use std::sync::Arc;

/// `Decoding` for CAN frames: frames in, records out in stream order.
pub struct CanStage {
    /// by bus name, in the order first seen (`Decoding._can`)
    decoders: Vec<(Arc<str>, Eg2CanDecoder)>,
    /// one set of memos for every bus (a decode does not depend on the bus: offline_run.rs does
    /// the same), so memory stays bounded however many buses a session names
    memos: CanMemos,
    linter: TimingLinter,
    pairer: Pairer,
    can_index: u64,
}

impl CanStage {
    /// `Decoding(positional_seq=positional, can_index=can_index)`.
    pub fn new(positional: bool, can_index: u64) -> Self {
        CanStage {
            decoders: Vec::new(),
            memos: CanMemos::default(),
            linter: TimingLinter::new(),
            pairer: Pairer::new(positional),
            can_index,
        }
    }

    /// The number the next frame gets (frames so far plus the starting number).
    pub fn can_index(&self) -> u64 {
        self.can_index
    }

    /// Whether seq is each record's CAN index (`positional_seq`).
    pub fn positional(&self) -> bool {
        self.pairer.positional
    }

    /// The number of the decoder of `bus`, made on first sight. Numbers stay valid for the life
    /// of this decoding (decoders are never dropped, as in the Python).
    pub fn bus_id(&mut self, bus: &str) -> usize {
        match self.decoders.iter().position(|(b, _)| **b == *bus) {
            Some(i) => i,
            None => {
                let name: Arc<str> = Arc::from(bus);
                self.decoders.push((name.clone(), Eg2CanDecoder::new(name)));
                self.decoders.len() - 1
            }
        }
    }

    /// The (interned) name of bus number `id`.
    pub fn bus_name(&self, id: usize) -> &Arc<str> {
        &self.decoders[id].0
    }

    /// One frame of bus number `id` (`Decoding.feed_can`); the records it releases are
    /// appended to `out`, in order.
    pub fn feed(&mut self, id: usize, frame: &CanFrame, out: &mut Vec<Record>) {
        let index = self.can_index;
        self.can_index += 1;
        let mut rec = self.decoders[id]
            .1
            .decode_with(&mut self.memos, frame, index);
        self.linter.check(&mut rec);
        self.pairer.push(rec, out);
    }

    /// `feed` by bus name.
    pub fn feed_bus(&mut self, bus: &str, frame: &CanFrame, out: &mut Vec<Record>) {
        let id = self.bus_id(bus);
        self.feed(id, frame, out);
    }

    /// Idle: requests that timed out by `now` are released (`Decoding.tick`).
    pub fn tick(&mut self, now: f64, out: &mut Vec<Record>) {
        self.pairer.tick(now, out);
    }

    /// The source of `bus` went away (`Decoding.gap`): its waiting requests are flagged and
    /// released. As in the Python, the bus's decoder keeps its pending directions.
    pub fn gap(&mut self, bus: &str, out: &mut Vec<Record>) {
        self.pairer.gap(bus, out);
    }

    /// The end of the input (`Decoding.finish`): every request still waiting is unanswered.
    pub fn finish(&mut self, out: &mut Vec<Record>) {
        self.pairer.flush(out);
    }

    /// The capture of `bus` was stopped (`Decoding.cut_off`): its waiting requests are
    /// flagged `cut_off` and released.
    pub fn cut_off(&mut self, bus: &str, out: &mut Vec<Record>) {
        self.pairer.cut_off(Some(bus), out);
    }

    /// The capture was stopped before its input ended (`Decoding.stop`): every request still
    /// waiting is `cut_off`.
    pub fn stop(&mut self, out: &mut Vec<Record>) {
        self.pairer.cut_off(None, out);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::decoders::flags::{CUT_OFF, ORPHAN_RESPONSE, UNANSWERED};
    use crate::decoders::model::{EG2_CAN, FOREIGN_CAN, REQUEST, RESPONSE};

    fn frame(t: Option<f64>, aid: u32, data: &[u8]) -> CanFrame {
        CanFrame {
            t,
            arbitration_id: aid,
            data: data.to_vec(),
            is_extended: true,
            ..Default::default()
        }
    }

    /// read 8 bytes at 1120 from device 1 (operation 0)
    const READ_1120: u32 = 1120 << 14 | 1;

    #[test]
    fn pairs_across_frames_and_numbers_them() {
        let mut live = CanStage::new(false, 10);
        let mut out = Vec::new();
        live.feed_bus("can0", &frame(Some(1.0), READ_1120, &[8]), &mut out);
        assert!(out.is_empty(), "the request waits for its answer");
        live.feed_bus("can0", &frame(Some(1.001), READ_1120, &[0; 8]), &mut out);
        assert_eq!(out.len(), 2);
        assert_eq!(out[0].direction, Some(REQUEST));
        assert_eq!(out[1].direction, Some(RESPONSE));
        assert_eq!((out[0].index, out[1].index), (Some(10), Some(11)));
        assert_eq!((out[0].seq, out[1].seq), (0, 1));
        assert_eq!((out[0].pair, out[1].pair), (Some(1), Some(0)));
        assert_eq!(out[0].latency_ms, Some(1.0));
        assert_eq!(live.can_index(), 12);
    }

    #[test]
    fn buses_are_apart_and_interned() {
        let mut live = CanStage::new(true, 0);
        let mut out = Vec::new();
        live.feed_bus("can0", &frame(Some(1.0), READ_1120, &[8]), &mut out);
        // the answer on another bus answers nothing there
        live.feed_bus("can1", &frame(Some(1.001), READ_1120, &[0; 8]), &mut out);
        assert_eq!(live.bus_id("can0"), 0);
        assert_eq!(live.bus_id("can1"), 1);
        assert!(out.is_empty());
        live.finish(&mut out);
        assert_eq!(out.len(), 2);
        assert_eq!(out[0].flags, vec![UNANSWERED]);
        assert_eq!(out[1].flags, vec![ORPHAN_RESPONSE]);
        assert_eq!((out[0].seq, out[1].seq), (0, 1)); // positional: the CAN index
        assert!(Arc::ptr_eq(&out[0].bus, live.bus_name(0)));
    }

    #[test]
    fn tick_and_gap_release_waiting_requests() {
        let mut live = CanStage::new(false, 0);
        let mut out = Vec::new();
        live.feed_bus("can0", &frame(Some(1.0), READ_1120, &[8]), &mut out);
        live.tick(1.4, &mut out);
        assert!(out.is_empty());
        live.tick(1.6, &mut out);
        assert_eq!(out.len(), 1);
        assert_eq!(out[0].warnings, vec!["no response within 500 ms"]);
        out.clear();
        live.feed_bus("can1", &frame(None, READ_1120, &[8]), &mut out);
        let standard = CanFrame {
            is_extended: false,
            ..frame(None, 0x7FF, &[])
        };
        live.feed_bus("can1", &standard, &mut out);
        live.gap("can0", &mut out);
        assert!(out.is_empty(), "another bus's gap");
        live.gap("can1", &mut out);
        assert_eq!(out.len(), 2);
        assert_eq!(
            out[0].warnings,
            vec!["no response before the source was lost"]
        );
        assert_eq!(out[0].protocol, EG2_CAN);
        assert_eq!(out[1].protocol, FOREIGN_CAN);
    }

    #[test]
    fn a_stop_cuts_off_waiting_requests() {
        let mut live = CanStage::new(false, 0);
        let mut out = Vec::new();
        live.feed_bus("can0", &frame(Some(1.0), READ_1120, &[8]), &mut out);
        live.feed_bus("can1", &frame(Some(1.0), READ_1120, &[8]), &mut out);
        live.cut_off("can1", &mut out);
        assert_eq!(
            out.len(),
            0,
            "can0's request waits first, and can1's behind it"
        );
        live.stop(&mut out);
        assert_eq!(out.len(), 2);
        for rec in &out {
            assert_eq!(rec.flags, vec![CUT_OFF]);
            assert_eq!(
                rec.warnings,
                vec!["no response before the capture was stopped"]
            );
        }
    }
}
