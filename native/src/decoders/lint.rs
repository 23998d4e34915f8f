//! Timing rules from the manual (section 1.4), applied to requests as they pass: a port of
//! decoders/lint.py (`TimingLinter`).
//!
//! - at least 5 ms between commands to one gripper;
//! - more than 1 s after a parameter save before the next command to that gripper.
//!
//! Both need timestamps; records without `t` pass untouched (raw byte dumps have none).

use crate::decoders::model::{Record, FRAME, REQUEST};
use crate::decoders::pairing::StreamIds;
use crate::generated::messages as M;
use crate::hash::FastMap;

pub use crate::generated::lint::{AFTER_SAVE_S, MIN_GAP_S};

/// (bus and protocol, device) as the Python key `(rec.bus, rec.protocol, rec.device)`.
type Key = (u32, Option<i64>);

/// Flags requests that break the manual's timing rules (each rule once per request).
#[derive(Default)]
pub struct TimingLinter {
    streams: StreamIds,
    last: FastMap<Key, f64>,
    save: FastMap<Key, f64>,
}

impl TimingLinter {
    /// The linter with the manual's limits (the only ones the pipeline uses: the texts below
    /// print AFTER_SAVE_S as the Python's `f"{after_save_s:g}"` does, 1.0 as "1").
    pub fn new() -> Self {
        Self::default()
    }

    pub fn check(&mut self, rec: &mut Record) {
        if rec.direction != Some(REQUEST) || rec.kind != FRAME {
            return;
        }
        let Some(t) = rec.t else { return };
        let key = (self.streams.id(&rec.bus, rec.protocol), rec.device);
        if let Some(&saved) = self.save.get(&key) {
            let dt = t - saved;
            if dt < AFTER_SAVE_S {
                note(
                    rec,
                    M::lint_during_save!(ms = dt * 1000.0, wait = AFTER_SAVE_S),
                );
            } else {
                self.save.remove(&key);
            }
        }
        if let Some(&last) = self.last.get(&key) {
            if t - last < MIN_GAP_S {
                let gap_ms = MIN_GAP_S * 1000.0;
                note(
                    rec,
                    M::lint_too_close!(ms = (t - last) * 1000.0, min_gap_ms = gap_ms),
                );
            }
        }
        self.last.insert(key, t);
        if rec.is_save {
            self.save.insert(key, t);
        }
    }
}

/// A warning and its code, the code appended even when the record has it (as the Python's).
fn note(rec: &mut Record, (code, text): (&'static str, String)) {
    rec.warnings.push(text);
    rec.flags.push(code);
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::decoders::flags::{CLOSER_THAN_5MS, DURING_SAVE};
    use crate::decoders::model::EG2_SERIAL;
    use std::sync::Arc;

    fn req(t: f64, device: i64, save: bool) -> Record {
        let mut r = Record::new(Some(t), Arc::from("serial"), EG2_SERIAL, FRAME, vec![1, 2]);
        r.direction = Some(REQUEST);
        r.device = Some(device);
        r.is_save = save;
        r
    }

    #[test]
    fn gap_and_save_rules() {
        let mut lint = TimingLinter::new();
        let mut a = req(10.0, 1, true);
        lint.check(&mut a);
        assert!(a.warnings.is_empty());
        let mut b = req(10.0031, 1, false);
        lint.check(&mut b);
        assert_eq!(
            b.warnings,
            vec![
                "command 3 ms after a parameter save (the manual asks to wait more than 1 s)",
                "command 3.10 ms after the previous one to this device (the manual asks for at \
                 least 5 ms)"
            ]
        );
        assert_eq!(b.flags, vec![DURING_SAVE, CLOSER_THAN_5MS]);
        // another device: its own timing
        let mut c = req(10.004, 2, false);
        lint.check(&mut c);
        assert!(c.warnings.is_empty());
        // after the save window the save is forgotten
        let mut d = req(11.5, 1, false);
        lint.check(&mut d);
        assert!(d.warnings.is_empty());
        let mut e = req(11.6, 1, false);
        lint.check(&mut e);
        assert!(e.warnings.is_empty());
    }

    #[test]
    fn no_time_no_check() {
        let mut lint = TimingLinter::new();
        let mut a = req(1.0, 1, false);
        a.t = None;
        lint.check(&mut a);
        let mut b = req(1.0, 1, false);
        b.t = None;
        lint.check(&mut b);
        assert!(b.warnings.is_empty());
    }
}
