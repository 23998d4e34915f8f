//! One fast hasher for the core's keyed tables (pending requests, memoised decodes, column
//! names): SipHash would cost more than the rest of a look-up at a million frames a second, and
//! its flood resistance buys nothing here (every table is bounded; a hostile input gains at most
//! a slower decode).

use std::collections::{HashMap, HashSet};
use std::hash::{BuildHasherDefault, Hasher};

const K: u64 = 0x51_7c_c1_b7_27_22_0a_95;

/// FxHash's mixing (rustc's), 8 bytes at a time, with murmur3's fmix64 at the end: a multiply
/// only carries bits upwards and hashbrown takes the bucket from the low bits, so keys that
/// differ only in their last bytes would all collide without the final mix.
#[derive(Default, Clone, Copy)]
pub struct FastHasher(u64);

impl FastHasher {
    #[inline]
    fn add(&mut self, word: u64) {
        self.0 = (self.0.rotate_left(5) ^ word).wrapping_mul(K);
    }
}

impl Hasher for FastHasher {
    fn write(&mut self, bytes: &[u8]) {
        let mut chunks = bytes.chunks_exact(8);
        for c in &mut chunks {
            self.add(u64::from_le_bytes(c.try_into().expect("8 bytes")));
        }
        let rest = chunks.remainder();
        if !rest.is_empty() {
            let mut w = [0u8; 8];
            w[..rest.len()].copy_from_slice(rest);
            self.add(u64::from_le_bytes(w));
        }
    }
    fn write_u8(&mut self, i: u8) {
        self.add(i as u64);
    }
    fn write_u16(&mut self, i: u16) {
        self.add(i as u64);
    }
    fn write_u32(&mut self, i: u32) {
        self.add(i as u64);
    }
    fn write_u64(&mut self, i: u64) {
        self.add(i);
    }
    fn write_u128(&mut self, i: u128) {
        self.add(i as u64);
        self.add((i >> 64) as u64);
    }
    fn write_usize(&mut self, i: usize) {
        self.add(i as u64);
    }
    fn write_i64(&mut self, i: i64) {
        self.add(i as u64);
    }
    fn finish(&self) -> u64 {
        let mut h = self.0;
        h ^= h >> 33;
        h = h.wrapping_mul(0xff51_afd7_ed55_8ccd);
        h ^= h >> 33;
        h = h.wrapping_mul(0xc4ce_b9fe_1a85_ec53);
        h ^ (h >> 33)
    }
}

pub type FastMap<K, V> = HashMap<K, V, BuildHasherDefault<FastHasher>>;
pub type FastSet<K> = HashSet<K, BuildHasherDefault<FastHasher>>;

/// A memo of decodes by frame bytes, bounded in memory and nearly as good as an LRU of twice
/// its generation: entries go into the current generation; when it is full it becomes the
/// old one (the previous old one is dropped), and an entry found in the old generation moves
/// back into the current one. The tables grow as entries come (a decoder that sees few frames,
/// one per CAN bus, stays small). A cache: what it drops changes no output.
pub struct FrameMemo<V> {
    current: FastMap<Box<[u8]>, V>,
    old: FastMap<Box<[u8]>, V>,
    generation: usize,
}

impl<V> FrameMemo<V> {
    pub fn new(generation: usize) -> Self {
        FrameMemo {
            current: FastMap::default(),
            old: FastMap::default(),
            generation,
        }
    }

    /// The value of `key`, made by `make` if it is not held.
    #[inline]
    pub fn get_or_insert_with(&mut self, key: &[u8], make: impl FnOnce() -> V) -> &V {
        if let Some(v) = self.current.get(key) {
            // SAFETY: `v` borrows `self.current`, which is not touched again before the
            // borrow ends; returning it directly is refused only by a limitation of today's
            // borrow checker (a conditional return of a borrow, NLL problem case 3)
            return unsafe { &*(v as *const V) };
        }
        let value = match self.old.remove_entry(key) {
            Some((_, v)) => v,
            None => make(),
        };
        if self.current.len() >= self.generation {
            std::mem::swap(&mut self.current, &mut self.old);
            self.current.clear(); // keeps its table: no allocation
        }
        self.current.entry(key.into()).or_insert(value)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::hash::BuildHasher;

    #[test]
    fn frame_memo_keeps_two_generations() {
        let mut memo = FrameMemo::new(2);
        let made = std::cell::Cell::new(0);
        let mut get = |k: u8| {
            *memo.get_or_insert_with(&[k], || {
                made.set(made.get() + 1);
                k
            })
        };
        for k in [1, 2, 1, 3, 1, 4, 5, 1, 5] {
            assert_eq!(get(k), k);
        }
        // 1 stayed (moved back each time it was found in the old generation), and 5 was
        // still in the old one: only the first sight of each key made a value
        assert_eq!(made.get(), 5);
        assert_eq!(get(3), 3); // 3 went with its generation
        assert_eq!(made.get(), 6);
    }

    #[test]
    fn keys_that_differ_in_their_last_bytes_spread_over_the_low_bits() {
        let build = BuildHasherDefault::<FastHasher>::default();
        let low: FastSet<u64> = (0u16..=255)
            .map(|i| build.hash_one([0xEE, 0x16, 1, 3, 0xD9, 0, i as u8, 7u8]) & 0xFF)
            .collect();
        assert!(low.len() > 128, "{} distinct low bytes", low.len());
    }
}
