//! CAN frames counted per bus and whole second of capture time (analyzer/health/can_load.py
//! `python_can_seconds`, the reference): what a bus's load is made of, with no Python object per
//! frame. Error frames are kept apart, each with its bus, time, identifier and data; they are
//! few and decoded in Python (decoders/can_errors.py).

use crate::decoders::can_bits::frame_bits;
use crate::decoders::model::CanFrame;
use crate::hash::{FastHasher, FastMap};
use std::hash::Hasher;

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

/// Places of the memo: a gripper's polls repeat within far fewer frames; a fixed table keeps
/// the memory flat and in the cache (256 KiB: 16,384 places of 16 bytes).
const MEMO_PLACES: usize = 1 << 14;

/// `frame_bits` remembered per distinct classic frame, one frame per place (a frame that hashes
/// to a taken place takes it over): a gripper's polls repeat, and the CRC and stuff bits of each
/// would cost more than the rest of the count.
#[derive(Default)]
pub struct BitsMemo {
    /// by the key's hash, the key with its bits in `BITS_FIELD`; 0: an empty place
    /// (`memo_key` is never 0). Made on first use: a memo handed on (`std::mem::take`) leaves
    /// an empty one, which costs nothing
    places: Vec<u128>,
}

/// Where a place keeps the bits of its key's frame, plus one (0: not counted): bits no field of
/// a key uses, so that a place is one number, 16 bytes.
const BITS_SHIFT: u32 = 81;
const BITS_FIELD: u128 = 0x1FF << BITS_SHIFT;

impl BitsMemo {
    /// `frame_bits` of `frame`, None for a frame whose bits are not counted.
    pub fn bits(&mut self, frame: &CanFrame) -> Option<u32> {
        let Some(key) = memo_key(frame) else {
            return frame_bits(frame).ok();
        };
        if self.places.is_empty() {
            self.places = vec![0; MEMO_PLACES];
        }
        let mut hasher = FastHasher::default();
        hasher.write_u128(key);
        let place = &mut self.places[hasher.finish() as usize % MEMO_PLACES];
        if *place & !BITS_FIELD != key {
            // a classic frame has at most 160 bits: they fit the field
            let code = frame_bits(frame).map_or(0, |b| u128::from(b.min(0x1FE)) + 1);
            *place = key | code << BITS_SHIFT;
        }
        match (*place & BITS_FIELD) >> BITS_SHIFT {
            0 => None,
            code => Some(code as u32 - 1),
        }
    }
}

/// A bit no field of a key uses, set in every key: a key is never 0.
const MEMO_KEY_MARK: u128 = 1 << 80;

/// Everything `frame_bits` reads, as one number: the data (at most 8 bytes), their count, the
/// DLC, the flags and the identifier; None for a frame that does not fit (never a classic one).
fn memo_key(frame: &CanFrame) -> Option<u128> {
    let (data, length) = (&frame.data, frame.length());
    if data.len() > 8 || length > 15 {
        return None;
    }
    let mut bytes = [0u8; 8];
    bytes[..data.len()].copy_from_slice(data);
    let flags = u128::from(frame.is_extended)
        | u128::from(frame.is_remote) << 1
        | u128::from(frame.is_error) << 2
        | u128::from(frame.is_fd) << 3;
    Some(
        MEMO_KEY_MARK
            | u128::from(u64::from_le_bytes(bytes))
            | (data.len() as u128) << 64
            | (length as u128) << 68
            | flags << 72
            | u128::from(frame.arbitration_id) << 96,
    )
}

/// `floor(t)` of a finite time, without the call to libm's `floor` that the default x86-64
/// target makes of `f64::floor` (a million frames a second).
fn whole_second(t: f64) -> i64 {
    let s = t as i64; // towards zero, saturating as `floor(t) as i64` does
    if (s as f64) > t {
        s.saturating_sub(1)
    } else {
        s
    }
}

/// The seconds and error frames of a run of frames, in the order each first appears.
#[derive(Default)]
pub struct SecondsCount {
    index: FastMap<(usize, Option<i64>), usize>,
    /// the last frame's key and its second's place: frames come in time order, mostly
    last: Option<((usize, Option<i64>), usize)>,
    pub memo: BitsMemo,
    pub seconds: Vec<Second>,
    pub errors: Vec<ErrorFrame>,
}

impl SecondsCount {
    /// A count that starts with the bits `memo` remembers.
    pub fn with_memo(memo: BitsMemo) -> Self {
        Self {
            memo,
            ..Self::default()
        }
    }

    /// Count one frame of bus number `bus`.
    pub fn add(&mut self, bus: usize, frame: &CanFrame) {
        let t = frame.t.filter(|t| t.is_finite());
        if frame.is_error {
            self.errors
                .push((bus, t, frame.arbitration_id, frame.data.clone()));
            return;
        }
        let bits = self.memo.bits(frame);
        let key = (bus, t.map(whole_second));
        let at = match self.last {
            Some((last, at)) if last == key => at,
            _ => self.place(key, t, bits),
        };
        self.last = Some((key, at));
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

    /// Where the second `key` is counted, a new one (with this first frame) when it is new.
    fn place(&mut self, key: (usize, Option<i64>), t: Option<f64>, bits: Option<u32>) -> usize {
        let seconds = &mut self.seconds;
        *self.index.entry(key).or_insert_with(|| {
            seconds.push(Second {
                bus: key.0,
                second: key.1,
                frames: 0,
                bits: 0,
                uncounted: 0,
                first_t: t,
                first_bits: bits.unwrap_or(0),
                last_t: t,
            });
            seconds.len() - 1
        })
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
    fn remembered_bits_are_the_bits_of_each_frame() {
        let mut memo = BitsMemo::default();
        let mut frames = vec![frame(Some(1.0), &[1, 2]), frame(None, &[0; 8])];
        let mut remote = frame(None, &[]);
        remote.is_remote = true;
        remote.dlc = Some(2);
        let mut fd = frame(None, &[0; 12]);
        fd.is_fd = true;
        let mut wrong_dlc = frame(None, &[1, 2]);
        wrong_dlc.dlc = Some(3);
        let mut extended = frame(None, &[1, 2]);
        extended.is_extended = true;
        frames.extend([remote, fd, wrong_dlc, extended]);
        let standard = frames.iter().map(|f| CanFrame {
            arbitration_id: 0x123,
            ..f.clone()
        });
        frames.extend(standard.collect::<Vec<_>>());
        let mut widest = frame(None, &[0xFF; 8]);
        (widest.arbitration_id, widest.is_extended, widest.dlc) = (0x1FFF_FFFF, true, Some(15));
        frames.push(widest);
        let field = |f: &CanFrame| memo_key(f).map_or(0, |k| k & BITS_FIELD);
        assert!(
            frames.iter().all(|f| field(f) == 0),
            "no key uses the field"
        );
        for _ in 0..2 {
            for f in &frames {
                assert_eq!(memo.bits(f), frame_bits(f).ok());
            }
        }
        let taken = memo.places.iter().filter(|p| **p != 0).count();
        assert_eq!(taken, 11); // all but the 12 data bytes, each in a place of its own
        assert_eq!(frames.iter().filter(|f| memo.bits(f).is_some()).count(), 6);
    }

    #[test]
    fn whole_seconds_are_floors() {
        let times = [0.0, -0.0, 0.5, -0.5, -1.0, 1.0, 1e9 + 0.999, -1e9 - 0.001];
        for t in times
            .into_iter()
            .chain([1_763_700_000.25, -9.3e18, 9.3e18, -9.2e18])
        {
            assert_eq!(whole_second(t), t.floor() as i64, "{t}");
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
