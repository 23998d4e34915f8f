//! CAN frames counted per bus and whole second of capture time (analyzer/health/can_load.py
//! `python_can_seconds`, the reference): what a bus's load is made of, with no Python object per
//! frame. Error frames are kept apart, each with its bus, time, identifier and data; they are
//! few and decoded in Python (decoders/can_errors.py).

use crate::decoders::can_bits::frame_bits;
use crate::decoders::model::CanFrame;
use crate::hash::FastMap;

/// One bus's frames in one second (`second`: `floor(t)`, None for frames without a time).
#[derive(Debug, Clone, PartialEq)]
pub struct Second {
    pub bus: usize,
    pub second: Option<i64>,
    pub frames: u64,
    /// the exact bits of the frames counted (decoders/can_bits.rs)
    pub bits: u64,
    /// frames whose bits are not counted (CAN FD, or no frame a classic controller sends)
    pub uncounted: u64,
    /// the earliest time among them, and the bits of the frame that had it
    pub first_t: Option<f64>,
    pub first_bits: u32,
    pub last_t: Option<f64>,
}

/// An error frame: bus, time, error class (its identifier), data.
pub type ErrorFrame = (usize, Option<f64>, u32, Vec<u8>);

/// The seconds and error frames of a run of frames, in the order each first appears.
#[derive(Default)]
pub struct SecondsCount {
    index: FastMap<(usize, Option<i64>), usize>,
    pub seconds: Vec<Second>,
    pub errors: Vec<ErrorFrame>,
}

impl SecondsCount {
    /// Count one frame of bus number `bus`.
    pub fn add(&mut self, bus: usize, frame: &CanFrame) {
        let t = frame.t.filter(|t| t.is_finite());
        if frame.is_error {
            self.errors
                .push((bus, t, frame.arbitration_id, frame.data.clone()));
            return;
        }
        let bits = frame_bits(frame).ok();
        let key = (bus, t.map(|t| t.floor() as i64));
        let seconds = &mut self.seconds;
        let at = *self.index.entry(key).or_insert_with(|| {
            seconds.push(Second {
                bus,
                second: key.1,
                frames: 0,
                bits: 0,
                uncounted: 0,
                first_t: t,
                first_bits: bits.unwrap_or(0),
                last_t: t,
            });
            seconds.len() - 1
        });
        let s = &mut self.seconds[at];
        s.frames += 1;
        match bits {
            Some(b) => s.bits += u64::from(b),
            None => s.uncounted += 1,
        }
        if let (Some(t), Some(first), Some(last)) = (t, s.first_t, s.last_t) {
            if t < first {
                s.first_t = Some(t);
                s.first_bits = bits.unwrap_or(0);
            }
            if t > last {
                s.last_t = Some(t);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn frame(t: Option<f64>, data: &[u8]) -> CanFrame {
        CanFrame {
            t,
            arbitration_id: 0x0118_0001,
            data: data.to_vec(),
            ..CanFrame::default()
        }
    }

    #[test]
    fn seconds_per_bus_with_their_first_frame() {
        let mut count = SecondsCount::default();
        let mut f = frame(Some(10.5), &[1]);
        f.is_extended = true;
        count.add(0, &f);
        let bits = frame_bits(&f).unwrap();
        f.t = Some(10.25);
        count.add(0, &f);
        f.t = Some(11.0);
        count.add(0, &f);
        f.is_fd = true;
        count.add(1, &f);
        let mut e = frame(Some(11.5), &[0; 8]);
        e.is_error = true;
        count.add(0, &e);
        let s = &count.seconds;
        assert_eq!(s.len(), 3);
        assert_eq!((s[0].frames, s[0].bits), (2, 2 * u64::from(bits)));
        assert_eq!((s[0].first_t, s[0].last_t), (Some(10.25), Some(10.5)));
        assert_eq!((s[2].bus, s[2].uncounted, s[2].bits), (1, 1, 0));
        assert_eq!(count.errors, vec![(0, Some(11.5), 0x0118_0001, vec![0; 8])]);
    }
}
