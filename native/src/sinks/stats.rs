//! A batch's records grouped for `eg2scope stats` (analyzer/stats.py `stats_groups`, the
//! reference): the records alike for its counts, counted once per group, so that `CaptureStats`
//! adds a few groups a batch instead of a Python object per record.

use crate::decoders::model::{Record, FRAME, RESPONSE};
use crate::hash::FastMap;
use std::borrow::Cow;
use std::hash::{Hash, Hasher};

/// What tells records apart for the counts: protocol, kind, flags, whether there are errors
/// and warnings, and for a device's frame its bus, device, command and direction.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct GroupKey<'a> {
    pub protocol: &'static str,
    pub kind: &'static str,
    pub device: Option<DeviceKey<'a>>,
    pub flags: &'a [&'static str],
    pub errors: bool,
    pub warnings: bool,
}

/// A device's frame: bus, device, command (its name, or "code N") and direction.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct DeviceKey<'a> {
    pub bus: &'a str,
    pub device: i64,
    pub command: Cow<'a, str>,
    pub direction: Option<&'static str>,
}

/// The text of a key hashed by its length and last byte, not every byte: hashing the names
/// took most of the grouping's time, and the few keys of a batch that share a hash are told
/// apart by `Eq`.
fn hash_text<H: Hasher>(text: &str, state: &mut H) {
    state.write_usize(text.len() << 8 | usize::from(text.as_bytes().last().copied().unwrap_or(0)));
}

impl Hash for GroupKey<'_> {
    fn hash<H: Hasher>(&self, state: &mut H) {
        hash_text(self.protocol, state);
        hash_text(self.kind, state);
        state.write_usize(
            self.flags.len() << 2 | usize::from(self.errors) << 1 | usize::from(self.warnings),
        );
        if let Some(d) = &self.device {
            hash_text(d.bus, state);
            state.write_i64(d.device);
            hash_text(&d.command, state);
            hash_text(d.direction.unwrap_or(""), state);
        }
    }
}

/// A response's device and command: `(bus, protocol, device, command)`.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct LatencyKey<'a>(pub &'a str, pub &'static str, pub i64, pub Cow<'a, str>);

impl Hash for LatencyKey<'_> {
    fn hash<H: Hasher>(&self, state: &mut H) {
        hash_text(self.0, state);
        state.write_i64(self.2);
        hash_text(&self.3, state);
    }
}

/// A group's records: how many, and the bytes they span (`length`).
#[derive(Debug, Default, Clone, PartialEq)]
pub struct Tally {
    pub count: u64,
    pub length: u64,
}

/// The groups of a batch, in the order each first appears; the response latencies per
/// device and command (`(bus, protocol, device, command)`), in record order; the earliest and
/// latest time (NaN times left out).
#[derive(Debug, Default)]
pub struct StatsGroups<'a> {
    pub groups: Vec<(GroupKey<'a>, Tally)>,
    pub latencies: Vec<(LatencyKey<'a>, Vec<f64>)>,
    pub first_t: Option<f64>,
    pub last_t: Option<f64>,
}

/// The command a device's frame counts under: its name, or its code ("code None" for none).
fn command_of(rec: &Record) -> Cow<'_, str> {
    match &rec.name {
        Some(name) if !name.is_empty() => Cow::Borrowed(name.as_ref()),
        _ => match rec.code {
            Some(code) => Cow::Owned(format!("code {code}")),
            None => Cow::Borrowed("code None"),
        },
    }
}

pub fn stats_groups(records: &[Record]) -> StatsGroups<'_> {
    let mut out = StatsGroups::default();
    let mut groups: FastMap<GroupKey<'_>, usize> = FastMap::default();
    let mut latencies: FastMap<LatencyKey<'_>, usize> = FastMap::default();
    for rec in records {
        if let Some(t) = rec.t.filter(|t| !t.is_nan()) {
            if out.first_t.is_none_or(|first| t < first) {
                out.first_t = Some(t);
            }
            if out.last_t.is_none_or(|last| t > last) {
                out.last_t = Some(t);
            }
        }
        let device = match rec.device {
            Some(device) if rec.kind == FRAME => Some(DeviceKey {
                bus: &rec.bus,
                device,
                command: command_of(rec),
                direction: rec.direction,
            }),
            _ => None,
        };
        if let (Some(d), Some(ms)) = (&device, rec.latency_ms) {
            if d.direction == Some(RESPONSE) {
                let key = LatencyKey(d.bus, rec.protocol, d.device, d.command.clone());
                let at = *latencies.entry(key.clone()).or_insert_with(|| {
                    out.latencies.push((key, Vec::new()));
                    out.latencies.len() - 1
                });
                out.latencies[at].1.push(ms);
            }
        }
        let key = GroupKey {
            protocol: rec.protocol,
            kind: rec.kind,
            device,
            flags: &rec.flags,
            errors: !rec.errors.is_empty(),
            warnings: !rec.warnings.is_empty(),
        };
        let at = match groups.get(&key) {
            Some(&at) => at,
            None => {
                groups.insert(key.clone(), out.groups.len());
                out.groups.push((key, Tally::default()));
                out.groups.len() - 1
            }
        };
        let tally = &mut out.groups[at].1;
        tally.count += 1;
        tally.length += rec.length as u64;
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::decoders::model::{EG2_CAN, GARBAGE, REQUEST};
    use std::sync::Arc;

    fn frame(t: f64, device: i64, direction: &'static str, latency: Option<f64>) -> Record {
        let mut rec = Record::new(Some(t), Arc::from("can0"), EG2_CAN, FRAME, vec![1; 8]);
        rec.device = Some(device);
        rec.direction = Some(direction);
        rec.code = Some(1);
        rec.latency_ms = latency;
        rec.length = 8;
        rec
    }

    #[test]
    fn groups_count_alike_records_once_in_the_order_they_first_appear() {
        let mut garbage = Record::new(Some(0.5), Arc::from("can0"), EG2_CAN, GARBAGE, vec![0; 3]);
        garbage.length = 3;
        garbage.device = Some(1); // not a frame: counted without its device
        let records = vec![
            frame(2.0, 1, REQUEST, None),
            garbage.clone(),
            frame(1.0, 1, RESPONSE, Some(0.25)),
            frame(f64::NAN, 1, REQUEST, None),
            frame(3.0, 1, RESPONSE, Some(0.5)),
            garbage,
        ];
        let found = stats_groups(&records);
        let tallies: Vec<_> = found
            .groups
            .iter()
            .map(|(k, t)| (k.kind, t.count))
            .collect();
        assert_eq!(tallies, [(FRAME, 2), (GARBAGE, 2), (FRAME, 2)]);
        assert_eq!(found.groups[1].1.length, 6);
        assert!(found.groups[1].0.device.is_none());
        let command = &found.groups[0].0.device.as_ref().unwrap().command;
        assert_eq!(command, "code 1");
        assert_eq!(found.latencies.len(), 1);
        assert_eq!(found.latencies[0].1, [0.25, 0.5]);
        assert_eq!((found.first_t, found.last_t), (Some(0.5), Some(3.0)));
    }
}
