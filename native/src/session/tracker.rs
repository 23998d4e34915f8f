//! One state per gripper, folded from the records of any protocol, one sample per reading.
//!
//! Mirrors `analyzer/session/tracker.py` (`Tracker.update`, `_registers`, `_serial`) and the JSON
//! of a state sample, `analyzer/model.py` (`StateSample.to_dict` with `derived`), which the MCAP
//! recorder writes as `orjson.dumps(sample.to_dict(), default=json_default)`.
//!
//! A state's values are a fixed array in `VALUE_KEYS` order (the Python dict always holds every
//! key, in that order); a sample keeps a copy of them and the indexes of the fields its record
//! set, in the order the Python `changed` dict got them. Only valid frames set values; a frame
//! with any value outside its documented range (flagged `out_of_range`) sets none at all, and a
//! request's write to a read-only register is not folded in (the record carries the flag).
//! Counters move on every frame of a device.

use std::sync::{Arc, OnceLock};

use crate::decoders::eg2_serial::{cmd, RUN_STATE};
use crate::decoders::flags::{OUT_OF_RANGE, UNANSWERED};
use crate::decoders::model::{Fields, Record, Value, EG2_SERIAL, FRAME, REQUEST, RESPONSE};
use crate::decoders::registers::{by_name, fault_text, opening_mm, state_text, STROKE_MM};
use crate::generated::cycles::FIELDS as CYCLE_FIELDS;
use crate::hash::FastMap;
use crate::json::{push_int, push_str, push_value};
use crate::pyfloat::{push_json_float, push_py_repr, py_round};

pub use crate::generated::tracker::{
    CATCH_MODE, CURRENT, FAULT, FORCE, FORCE_SETTING, KEY_JSON, LAST_COMMAND, LATENCY_MS,
    MAX_OPENING, MIN_OPENING, OPENING, REGISTER_FIELDS, SLOTS, SPEED, STATE, TARGET_OPENING,
    TEMPERATURE_C, VALUE_KEYS,
};

/// One state value. The Python values are whatever the decoder put in `fields` (ints for every
/// register and serial field), the summary text, a latency or None; `Text` shares a record's
/// summary instead of copying it, and anything unusual is kept as the record's `Value`.
#[derive(Clone, Debug, Default, PartialEq)]
pub enum Slot {
    #[default]
    Null,
    Int(i64),
    Float(f64),
    Bool(bool),
    Text(Arc<str>),
    Other(Box<Value>),
}

impl Slot {
    fn from_value(v: &Value) -> Slot {
        match v {
            Value::Null => Slot::Null,
            Value::Int(i) => Slot::Int(*i),
            Value::Float(f) => Slot::Float(*f),
            Value::Bool(b) => Slot::Bool(*b),
            Value::Str(s) => Slot::Text(Arc::from(&**s)),
            other => Slot::Other(Box::new(other.clone())),
        }
    }

    /// The value as a Python int (a bool is one), else None.
    pub(crate) fn as_int(&self) -> Option<i64> {
        match self {
            Slot::Int(i) => Some(*i),
            Slot::Bool(b) => Some(i64::from(*b)),
            _ => None,
        }
    }

    /// Python's truth of the value.
    fn truthy(&self) -> bool {
        match self {
            Slot::Null => false,
            Slot::Int(i) => *i != 0,
            Slot::Float(f) => *f != 0.0,
            Slot::Bool(b) => *b,
            Slot::Text(s) => !s.is_empty(),
            Slot::Other(v) => match &**v {
                Value::Str(s) => !s.is_empty(),
                Value::List(items) => !items.is_empty(),
                Value::Map(entries) => !entries.is_empty(),
                _ => true, // not made: the scalars are the other variants
            },
        }
    }

    pub fn push_json(&self, out: &mut String) {
        match self {
            Slot::Null => out.push_str("null"),
            Slot::Int(i) => push_int(out, *i),
            Slot::Float(f) => push_json_float(out, *f),
            Slot::Bool(b) => out.push_str(if *b { "true" } else { "false" }),
            Slot::Text(s) => push_str(out, s),
            Slot::Other(v) => push_value(out, v),
        }
    }
}

/// A gripper's values: every field of `VALUE_KEYS` (None until known; the counters from 0).
#[derive(Debug, Default, PartialEq)]
pub struct Values {
    pub slots: [Slot; SLOTS],
    pub frames: i64,
    pub errors: i64,
    pub unanswered: i64,
}

impl Values {
    /// A sample's values without a snapshot (`_changes_only`): the fields it changed and the
    /// counters.
    fn changes_only(&self, changed: Changed) -> Values {
        let mut kept = Values {
            frames: self.frames,
            errors: self.errors,
            unanswered: self.unanswered,
            ..Values::default()
        };
        for field in changed.iter() {
            kept.slots[field] = self.slots[field].clone();
        }
        kept
    }
}

impl Clone for Values {
    /// A sample's snapshot: one per reading, so the numbers are copied without the generic
    /// array clone's per-element dispatch (a third of a tracker's time with samples).
    fn clone(&self) -> Self {
        Values {
            slots: std::array::from_fn(|i| match &self.slots[i] {
                Slot::Null => Slot::Null,
                Slot::Int(v) => Slot::Int(*v),
                Slot::Float(v) => Slot::Float(*v),
                other => other.clone(),
            }),
            frames: self.frames,
            errors: self.errors,
            unanswered: self.unanswered,
        }
    }
}

/// The fields one record set, in the order the Python `changed` dict got them (a key set again
/// keeps its place, as in a dict).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Changed {
    len: u8,
    keys: [u8; SLOTS],
}

impl Changed {
    pub(crate) fn add(&mut self, field: usize) {
        let field = field as u8;
        if !self.keys[..self.len as usize].contains(&field) {
            self.keys[self.len as usize] = field;
            self.len += 1;
        }
    }

    pub fn is_empty(&self) -> bool {
        self.len == 0
    }

    pub fn len(&self) -> usize {
        self.len as usize
    }

    /// The fields, as indexes into `VALUE_KEYS`.
    pub fn iter(&self) -> impl Iterator<Item = usize> + '_ {
        self.keys[..self.len as usize].iter().map(|&k| k as usize)
    }
}

/// The last known state of one gripper on one bus (`DeviceState`).
#[derive(Clone, Debug)]
pub struct DeviceState {
    pub bus: Arc<str>,
    pub device: i64,
    /// the protocol of the first record of this (bus, device), as the Python keeps it
    pub protocol: &'static str,
    /// when it was last heard
    pub t: Option<f64>,
    pub values: Values,
}

/// One reading or setting of one gripper (`StateSample`): the fields its record changed and
/// the gripper's whole state after it.
#[derive(Clone, Debug)]
pub struct Sample {
    pub t: Option<f64>,
    pub bus: Arc<str>,
    pub device: i64,
    pub protocol: &'static str,
    pub seq: i64,
    pub changed: Changed,
    pub values: Values,
}

/// What a gripper's record set of the fields grip cycles read (`generated::cycles::FIELDS`),
/// made by the fold itself for a segmenter fed straight from the tracker (no sample).
#[derive(Clone, Debug)]
pub struct FieldReading {
    /// the gripper: its index in `Tracker::states`
    pub state: usize,
    pub seq: i64,
    pub t: Option<f64>,
    /// the fields set, as bits of their slots (`1 << slot`)
    pub kind: u16,
    /// the values of `FIELDS`, None where not set; `Err` for a value that is not an int
    pub values: Result<[Option<i64>; CYCLE_FIELDS.len()], NotAnInt>,
}

/// The slots of `FIELDS` as bits.
const CYCLE_MASK: u16 = {
    let mut mask = 0u16;
    let mut i = 0;
    while i < CYCLE_FIELDS.len() {
        mask |= 1 << CYCLE_FIELDS[i];
        i += 1;
    }
    mask
};

/// Writes a state's values into the state and notes them in `changed` (the Python builds the
/// `changed` dict and then updates the values with it: nothing between the two can fail, so
/// writing through gives the same state).
struct Fold<'a> {
    slots: &'a mut [Slot; SLOTS],
    changed: Changed,
}

impl Fold<'_> {
    #[inline]
    fn set(&mut self, field: usize, value: Slot) {
        self.slots[field] = value;
        self.changed.add(field);
    }
}

/// Folds records into `DeviceState`s (`Tracker`). `samples` false: fold only; `snapshots`
/// false: a sample's values are the fields it changed and the counters, the rest unset.
pub struct Tracker {
    pub samples: bool,
    pub snapshots: bool,
    /// bus names seen, so a state's key is two integers; the last one matched first (a
    /// decoder gives all its records the same `Arc`)
    buses: Vec<Arc<str>>,
    last_bus: usize,
    index: FastMap<(u32, i64), usize>,
    /// in the order they were first heard, as the Python dict
    states: Vec<DeviceState>,
    /// the `FieldReading`s of the last `update_many`, when asked for (Some)
    pub readings: Option<Vec<FieldReading>>,
}

impl Tracker {
    pub fn new(samples: bool) -> Self {
        Tracker {
            samples,
            snapshots: true,
            buses: Vec::new(),
            last_bus: 0,
            index: FastMap::default(),
            states: Vec::new(),
            readings: None,
        }
    }

    /// Every gripper heard, in the order first heard.
    pub fn states(&self) -> &[DeviceState] {
        &self.states
    }

    fn bus_id(&mut self, bus: &Arc<str>) -> u32 {
        if let Some(b) = self.buses.get(self.last_bus) {
            if Arc::ptr_eq(b, bus) || **b == **bus {
                return self.last_bus as u32;
            }
        }
        let i = match self.buses.iter().position(|b| **b == **bus) {
            Some(i) => i,
            None => {
                self.buses.push(bus.clone());
                self.buses.len() - 1
            }
        };
        self.last_bus = i;
        i as u32
    }

    /// Fold one record (`Tracker.update`); the sample it made, if it set anything and samples
    /// are asked for.
    pub fn update(&mut self, rec: &Record) -> Option<Sample> {
        let (i, changed) = self.fold(rec)?;
        let st = &self.states[i];
        if let Some(readings) = &mut self.readings {
            let kind = changed.iter().fold(0u16, |m, f| m | 1 << f) & CYCLE_MASK;
            if kind != 0 {
                readings.push(FieldReading {
                    state: i,
                    seq: rec.seq,
                    t: rec.t,
                    kind,
                    values: field_values(&st.values, kind),
                });
            }
        }
        if !self.samples {
            return None;
        }
        Some(Sample {
            t: rec.t,
            bus: rec.bus.clone(),
            device: st.device,
            protocol: st.protocol,
            seq: rec.seq,
            changed,
            values: if self.snapshots {
                st.values.clone()
            } else {
                st.values.changes_only(changed)
            },
        })
    }

    /// `update` for a writer of samples, without a copy of the state: `write` is given the
    /// gripper's state after the record and the fields the record set (the sample's time and
    /// seq are the record's), when it made a sample.
    pub fn update_with<R>(
        &mut self,
        rec: &Record,
        write: impl FnOnce(&DeviceState, Changed) -> R,
    ) -> Option<R> {
        let (i, changed) = self.fold(rec)?;
        self.samples.then(|| write(&self.states[i], changed))
    }

    /// Fold one record into its gripper's state; the state's index and the fields set, when
    /// that makes a sample.
    fn fold(&mut self, rec: &Record) -> Option<(usize, Changed)> {
        if rec.kind != FRAME {
            return None;
        }
        let device = rec.device?;
        let bus = self.bus_id(&rec.bus);
        let states = &mut self.states;
        let i = *self.index.entry((bus, device)).or_insert_with(|| {
            states.push(DeviceState {
                bus: rec.bus.clone(),
                device,
                protocol: rec.protocol,
                t: None,
                values: Values::default(),
            });
            states.len() - 1
        });
        let st = &mut self.states[i];
        st.values.frames += 1;
        if rec.t.is_some() {
            st.t = rec.t;
        }
        if !rec.errors.is_empty() {
            st.values.errors += 1;
            return None;
        }
        let request = rec.direction == Some(REQUEST);
        if request && rec.flags.contains(&UNANSWERED) {
            st.values.unanswered += 1;
        }
        let mut fold = Fold {
            slots: &mut st.values.slots,
            changed: Changed::default(),
        };
        if request {
            let command = if rec.summary.is_empty() {
                match &rec.name {
                    Some(name) => Slot::Text(Arc::from(&**name)),
                    None => Slot::Null,
                }
            } else {
                Slot::Text(rec.summary.clone())
            };
            fold.set(LAST_COMMAND, command);
        } else if rec.direction == Some(RESPONSE) {
            if let Some(ms) = rec.latency_ms {
                fold.set(LATENCY_MS, Slot::Float(ms));
            }
        }
        if rec.flags.contains(&OUT_OF_RANGE) {
            // a frame with a value out of range sets no value at all
        } else if rec.protocol == EG2_SERIAL {
            serial(rec, request, &mut fold);
        } else {
            registers(&rec.fields, request, &mut fold);
        }
        let changed = fold.changed;
        (!changed.is_empty()).then_some((i, changed))
    }

    /// The samples of a run of records, in order (`Tracker.update_many`).
    pub fn update_many(&mut self, records: &[Record], out: &mut Vec<Sample>) {
        if let Some(readings) = &mut self.readings {
            readings.clear();
        }
        if self.samples {
            out.reserve(records.len()); // at most one each: no copy of the samples as it grows
        }
        out.extend(records.iter().filter_map(|rec| self.update(rec)));
    }
}

/// The values of `FIELDS` a fold set (`kind`), as the cycle rules read them: ints (a bool is
/// one) or None.
fn field_values(values: &Values, kind: u16) -> Result<[Option<i64>; CYCLE_FIELDS.len()], NotAnInt> {
    let mut found = [None; CYCLE_FIELDS.len()];
    for (value, &field) in found.iter_mut().zip(CYCLE_FIELDS.iter()) {
        if kind & 1 << field != 0 {
            *value = match &values.slots[field] {
                Slot::Null => None,
                slot => Some(slot.as_int().ok_or(NotAnInt(VALUE_KEYS[field]))?),
            };
        }
    }
    Ok(found)
}

/// `fields.get(key)` (the decoders keep a field's keys unique, as a dict's).
#[inline]
fn get<'a>(fields: &'a [(crate::decoders::model::Str, Value)], key: &str) -> Option<&'a Value> {
    fields.iter().find(|(k, _)| k == key).map(|(_, v)| v)
}

/// `_FOLD`: what a register of `REGISTER_FIELDS` folds into: the state field, its documented
/// range and whether it is read-only (from the register table).
struct Spec {
    field: usize,
    lo: Option<i64>,
    hi: Option<i64>,
    read_only: bool,
}

fn spec(name: &str) -> Option<&'static Spec> {
    static SPECS: OnceLock<Vec<Spec>> = OnceLock::new();
    // a match compiles to a switch on the length and a few compares: faster than hashing
    let i = match name {
        "CMD_OPENLEN_SET" => 0,
        "CMD_SPEED_SET" => 1,
        "CMD_FORCE_SET" => 2,
        "CMD_CATCH_MOD" => 3,
        "CMD_MAX_OPENLEN" => 4,
        "CMD_MIN_OPENLEN" => 5,
        "CMD_FORCE_ACT" => 6,
        "CMD_OPENLEN_ACT" => 7,
        "CMD_CURRENT" => 8,
        "CMD_TEMP" => 9,
        "CMD_ERRORCODE" => 10,
        "CMD_STATUS" => 11,
        _ => return None,
    };
    let specs = SPECS.get_or_init(|| {
        REGISTER_FIELDS
            .iter()
            .map(|&(name, field)| {
                let reg = by_name(name).expect("REGISTER_FIELDS names registers of the table");
                Spec {
                    field,
                    lo: reg.lo,
                    hi: reg.hi,
                    read_only: reg.access == "ro",
                }
            })
            .collect()
    });
    debug_assert_eq!(REGISTER_FIELDS[i].0, name);
    Some(&specs[i])
}

/// `_registers`: register values into the state: none if any is out of its range, and not a
/// request's write of a read-only register (both are flagged on the record, and the gripper
/// ignores such a write).
fn registers(f: &Fields, request: bool, fold: &mut Fold<'_>) {
    let one;
    let values: &[(crate::decoders::model::Str, Value)] = match get(f, "values") {
        Some(Value::Map(values)) => values,
        _ => {
            // a single write (Modbus 0x06): {name: value}
            let (Some(value), Some(Value::Str(name))) = (get(f, "value"), get(f, "name")) else {
                return;
            };
            if !request {
                return;
            }
            one = [(name.clone(), value.clone())];
            &one
        }
    };
    let out_of_range = |(name, value): &(crate::decoders::model::Str, Value)| {
        let Some(spec) = spec(name) else {
            return false;
        };
        // isinstance(value, int): a bool is one too
        let as_int = match value {
            Value::Int(i) => Some(*i),
            Value::Bool(b) => Some(i64::from(*b)),
            _ => None,
        };
        matches!((spec.lo, spec.hi, as_int), (Some(lo), Some(hi), Some(v)) if !(lo <= v && v <= hi))
    };
    if values.iter().any(out_of_range) {
        return; // one value out of range: the frame sets none
    }
    for (name, value) in values {
        let Some(spec) = spec(name) else { continue };
        if !(request && spec.read_only) {
            fold.set(spec.field, Slot::from_value(value));
        }
    }
}

/// `_serial`: the commands whose request or response says something about the state.
fn serial(rec: &Record, request: bool, fold: &mut Fold<'_>) {
    let Some(code) = rec.code else { return };
    let f: &Fields = &rec.fields;
    let get_or_null = |key: &str| get(f, key).map_or(Slot::Null, Slot::from_value);
    // `key in f`: the value as it is
    let if_present = |fold: &mut Fold<'_>, key: &str, field: usize| {
        if let Some(v) = get(f, key) {
            fold.set(field, Slot::from_value(v));
        }
    };
    // a Python table lookup by an int: codes outside a byte match nothing
    let Ok(code) = u8::try_from(code) else { return };
    if request {
        match code {
            cmd::MOVE_CATCH_XG | cmd::MOVE_CATCH2_XG => {
                // catch: close with a force limit
                fold.set(SPEED, get_or_null("speed"));
                fold.set(FORCE_SETTING, get_or_null("force_g"));
                fold.set(TARGET_OPENING, Slot::Int(0));
                let continuous = code == cmd::MOVE_CATCH2_XG;
                fold.set(CATCH_MODE, Slot::Int(i64::from(continuous)));
            }
            cmd::MOVE_RELEASE => {
                fold.set(SPEED, get_or_null("speed"));
                fold.set(TARGET_OPENING, Slot::Int(1000));
            }
            cmd::SEEKPOS => if_present(fold, "position", TARGET_OPENING),
            cmd::SET_EG_PARA => limits(fold, &get_or_null),
            _ => {}
        }
    } else {
        // every other direction (None too) reads the responses' table, as the Python does
        match code {
            cmd::READ_EG_PARA => limits(fold, &get_or_null),
            cmd::READ_ACTPOS => if_present(fold, "position", OPENING),
            cmd::READ_EG_RUNSTATE => {
                for value in RUN_STATE {
                    if_present(fold, value.key, value.state);
                }
            }
            cmd::READ_EG_STATE => {
                // 0x14's layout is not documented: only the fields one client reads
                if let Some(Value::Map(p)) = get(f, "probable") {
                    for (key, field) in [("opening", OPENING), ("force", FORCE)] {
                        match get(p, key) {
                            None | Some(Value::Null) => {}
                            Some(v) => fold.set(field, Slot::from_value(v)),
                        }
                    }
                }
            }
            _ => {}
        }
    }
}

fn limits(fold: &mut Fold<'_>, get_or_null: &dyn Fn(&str) -> Slot) {
    fold.set(MAX_OPENING, get_or_null("max"));
    fold.set(MIN_OPENING, get_or_null("min"));
}

/// A value `derived` cannot use, where the Python raises TypeError (no decoder makes one: the
/// state fields it reads are ints or None).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct NotAnInt(pub &'static str);

impl std::fmt::Display for NotAnInt {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "the state's {} is not an integer", self.0)
    }
}

impl std::error::Error for NotAnInt {}

/// `_mm`: an opening 0-1000 in millimetres, as JSON (`_MM[value]` for 0-1000 is
/// `opening_mm(value)`, which is `round(value * 70.0 / 1000.0, 2)` for any value).
fn push_mm(out: &mut String, v: &Slot, key: &'static str) -> Result<(), NotAnInt> {
    // the JSON text of 0-1000 in millimetres, made once (as the Python's `_MM` table): the
    // rounding costs more than the rest of a sample's JSON
    static MM: OnceLock<Vec<Box<str>>> = OnceLock::new();
    match v {
        Slot::Null => out.push_str("null"),
        Slot::Int(_) | Slot::Bool(_) => {
            let i = v.as_int().unwrap_or_default();
            match usize::try_from(i) {
                Ok(i) if i <= 1000 => {
                    let table = MM.get_or_init(|| {
                        (0..=1000)
                            .map(|v| {
                                let mut text = String::new();
                                push_json_float(&mut text, opening_mm(v));
                                text.into_boxed_str()
                            })
                            .collect()
                    });
                    out.push_str(&table[i]);
                }
                _ => push_json_float(out, opening_mm(i)),
            }
        }
        // `_MM[5.0]` is a TypeError; outside 0-1000 (NaN too) a float gets opening_mm
        Slot::Float(x) if !(0.0..=1000.0).contains(x) => {
            push_json_float(out, py_round(x * STROKE_MM / 1000.0, 2));
        }
        _ => return Err(NotAnInt(key)),
    }
    Ok(())
}

/// Writes `derived`'s keys (after the values): opening_mm, target_mm, state_text, fault_text.
fn push_derived(out: &mut String, values: &Values) -> Result<(), NotAnInt> {
    let slots = &values.slots;
    out.push_str(",\"opening_mm\":");
    push_mm(out, &slots[OPENING], "opening")?;
    out.push_str(",\"target_mm\":");
    push_mm(out, &slots[TARGET_OPENING], "target_opening")?;
    out.push_str(",\"state_text\":");
    match &slots[STATE] {
        Slot::Null => out.push_str("null"),
        Slot::Int(_) | Slot::Bool(_) => {
            push_str(out, &state_text(slots[STATE].as_int().unwrap_or_default()))
        }
        // out of 0-255 a float is named as Python formats it ("unknown state 300.0")
        Slot::Float(x) if !(0.0..256.0).contains(x) => {
            let mut text = String::from("unknown state ");
            push_py_repr(&mut text, *x);
            push_str(out, &text);
        }
        _ => return Err(NotAnInt("state")),
    }
    out.push_str(",\"fault_text\":[");
    let fault = &slots[FAULT];
    if fault.truthy() {
        let Some(bits) = fault.as_int() else {
            return Err(NotAnInt("fault"));
        };
        for (i, word) in fault_text(bits).iter().enumerate() {
            if i > 0 {
                out.push(',');
            }
            push_str(out, word);
        }
    }
    out.push(']');
    Ok(())
}

/// `orjson.dumps(sample.to_dict(), default=json_default)`: identity, the values in
/// `VALUE_KEYS` order, the derived words, then `changed` (the fields this sample set).
pub fn push_sample_json(out: &mut String, s: &Sample) -> Result<(), NotAnInt> {
    out.push_str("{\"t\":");
    match s.t {
        Some(t) => push_json_float(out, t),
        None => out.push_str("null"),
    }
    out.push_str(",\"bus\":");
    push_str(out, &s.bus);
    out.push_str(",\"device\":");
    push_int(out, s.device);
    out.push_str(",\"protocol\":");
    push_str(out, s.protocol);
    out.push_str(",\"seq\":");
    push_int(out, s.seq);
    for (key, slot) in KEY_JSON.iter().zip(&s.values.slots) {
        out.push_str(key);
        slot.push_json(out);
    }
    let counters = [s.values.frames, s.values.errors, s.values.unanswered];
    for (key, n) in KEY_JSON[SLOTS..].iter().zip(counters) {
        out.push_str(key);
        push_int(out, n);
    }
    push_derived(out, &s.values)?;
    out.push_str(",\"changed\":[");
    for (i, field) in s.changed.iter().enumerate() {
        if i > 0 {
            out.push(',');
        }
        let key = KEY_JSON[field];
        out.push_str(&key[1..key.len() - 1]); // the quoted name
    }
    out.push_str("]}");
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::decoders::model::{Str, EG2_CAN, MODBUS_RTU};
    use std::borrow::Cow;

    fn rec(protocol: &'static str, direction: &'static str, fields: Fields) -> Record {
        let mut r = Record::new(Some(1.5), Arc::from("can0"), protocol, FRAME, vec![1]);
        r.direction = Some(direction);
        r.device = Some(3);
        r.fields = fields.into();
        r.summary = Arc::from("summary");
        r.seq = 7;
        r
    }

    fn values(pairs: &[(&'static str, Value)]) -> Fields {
        let map = pairs.iter().map(|(k, v)| (Str::Borrowed(*k), v.clone()));
        vec![(Cow::Borrowed("values"), Value::Map(map.collect()))]
    }

    #[test]
    fn readings_fold_in_range_only() {
        let mut t = Tracker::new(true);
        let r = rec(
            EG2_CAN,
            RESPONSE,
            values(&[
                ("CMD_FORCE_ACT", Value::Int(99999)), // no documented range: folded
                ("CMD_TEMP", Value::Int(40)),
                ("REG_1008", Value::Int(1)), // not a state field
            ]),
        );
        let s = t.update(&r).unwrap();
        assert_eq!(
            s.changed.iter().collect::<Vec<_>>(),
            vec![FORCE, TEMPERATURE_C]
        );
        assert_eq!(s.values.slots[FORCE], Slot::Int(99999));
        assert_eq!(s.values.slots[OPENING], Slot::Null);
        assert_eq!(s.values.frames, 1);
        assert_eq!((s.seq, s.protocol, s.t), (7, EG2_CAN, Some(1.5)));
    }

    #[test]
    fn a_frame_with_a_value_out_of_range_sets_none() {
        // the manual's misread reply: opening 59395 out of range, so force 243 is not trusted
        let mut t = Tracker::new(true);
        let misread = values(&[
            ("CMD_FORCE_ACT", Value::Int(243)),
            ("CMD_OPENLEN_ACT", Value::Int(59395)),
        ]);
        assert!(t.update(&rec(EG2_CAN, RESPONSE, misread.clone())).is_none());
        // flagged by the decoder: nothing either, whatever the values
        let mut flagged = rec(EG2_SERIAL, RESPONSE, vec![]);
        flagged.code = Some(i64::from(cmd::READ_ACTPOS));
        flagged.fields = vec![(Cow::Borrowed("position"), Value::Int(500))].into();
        flagged.flags = vec![OUT_OF_RANGE];
        assert!(t.update(&flagged).is_none());
        let st = &t.states()[0];
        assert_eq!(st.values.slots[FORCE], Slot::Null);
        assert_eq!(st.values.slots[OPENING], Slot::Null);
        assert_eq!(st.values.frames, 2);
        // a request's command is still noted
        let mut request = rec(EG2_CAN, REQUEST, misread);
        request.flags = vec![OUT_OF_RANGE];
        let s = t.update(&request).unwrap();
        assert_eq!(s.changed.iter().collect::<Vec<_>>(), vec![LAST_COMMAND]);
    }

    #[test]
    fn requests_command_and_skip_read_only() {
        let mut t = Tracker::new(true);
        let mut r = rec(
            EG2_CAN,
            REQUEST,
            values(&[
                ("CMD_STATUS", Value::Int(1)),
                ("CMD_OPENLEN_SET", Value::Int(500)),
            ]),
        );
        r.flags.push(UNANSWERED);
        let s = t.update(&r).unwrap();
        assert_eq!(
            s.changed.iter().collect::<Vec<_>>(),
            vec![LAST_COMMAND, TARGET_OPENING]
        );
        assert_eq!(
            s.values.slots[LAST_COMMAND],
            Slot::Text(Arc::from("summary"))
        );
        assert_eq!(s.values.slots[STATE], Slot::Null);
        assert_eq!(s.values.unanswered, 1);
        // a response without register values and no latency changes nothing
        let r = rec(EG2_CAN, RESPONSE, Fields::new());
        assert!(t.update(&r).is_none());
        assert_eq!(t.states()[0].values.frames, 2);
    }

    #[test]
    fn modbus_single_write_and_errors() {
        let mut t = Tracker::new(true);
        let fields = vec![
            (Cow::Borrowed("name"), Value::from("CMD_SPEED_SET")),
            (Cow::Borrowed("value"), Value::Int(300)),
        ];
        let mut r = rec(MODBUS_RTU, REQUEST, fields.clone());
        r.summary = crate::decoders::model::empty_text();
        r.name = Some(Cow::Borrowed("CMD_SPEED_SET"));
        let s = t.update(&r).unwrap();
        assert_eq!(s.values.slots[SPEED], Slot::Int(300));
        assert_eq!(
            s.values.slots[LAST_COMMAND],
            Slot::Text(Arc::from("CMD_SPEED_SET"))
        );
        // the echo (a response) is not folded; with a latency it still makes a sample
        let mut r = rec(MODBUS_RTU, RESPONSE, fields);
        r.latency_ms = Some(2.5);
        let s = t.update(&r).unwrap();
        assert_eq!(s.changed.iter().collect::<Vec<_>>(), vec![LATENCY_MS]);
        let mut r = rec(MODBUS_RTU, RESPONSE, Fields::new());
        r.errors.push("bad".into());
        r.t = None;
        assert!(t.update(&r).is_none());
        let st = &t.states()[0];
        assert_eq!(
            (st.values.frames, st.values.errors, st.t),
            (3, 1, Some(1.5))
        );
    }

    #[test]
    fn serial_catch_and_run_state() {
        let mut t = Tracker::new(true);
        let mut r = rec(
            EG2_SERIAL,
            REQUEST,
            vec![(Cow::Borrowed("speed"), Value::Int(500))],
        );
        r.code = Some(i64::from(cmd::MOVE_CATCH2_XG));
        let s = t.update(&r).unwrap();
        let order = vec![
            LAST_COMMAND,
            SPEED,
            FORCE_SETTING,
            TARGET_OPENING,
            CATCH_MODE,
        ];
        assert_eq!(s.changed.iter().collect::<Vec<_>>(), order);
        assert_eq!(s.values.slots[FORCE_SETTING], Slot::Null);
        assert_eq!(s.values.slots[CATCH_MODE], Slot::Int(1));
        let mut r = rec(
            EG2_SERIAL,
            RESPONSE,
            vec![
                (Cow::Borrowed("position"), Value::Int(2000)),
                (Cow::Borrowed("state"), Value::Int(9)),
            ],
        );
        r.code = Some(i64::from(cmd::READ_EG_RUNSTATE));
        let s = t.update(&r).unwrap();
        assert_eq!(s.changed.iter().collect::<Vec<_>>(), vec![STATE, OPENING]);
        let mut json = String::new();
        push_sample_json(&mut json, &s).unwrap();
        assert!(
            json.contains("\"opening_mm\":140.0,\"target_mm\":0.0,"),
            "{json}"
        );
        assert!(json.contains("\"state_text\":\"unknown state 9\",\"fault_text\":[],"));
        assert!(
            json.ends_with(",\"changed\":[\"state\",\"opening\"]}"),
            "{json}"
        );
    }

    #[test]
    fn samples_off_and_other_kinds() {
        let mut t = Tracker::new(false);
        let r = rec(EG2_CAN, RESPONSE, values(&[("CMD_TEMP", Value::Int(40))]));
        assert!(t.update(&r).is_none());
        assert_eq!(t.states()[0].values.slots[TEMPERATURE_C], Slot::Int(40));
        let mut g = r.clone();
        g.kind = crate::decoders::model::GARBAGE;
        let mut n = r.clone();
        n.device = None;
        assert!(t.update(&g).is_none() && t.update(&n).is_none());
        assert_eq!(t.states()[0].values.frames, 1);
    }

    #[test]
    fn key_texts() {
        for (text, key) in KEY_JSON.iter().zip(VALUE_KEYS) {
            assert_eq!(*text, format!(",\"{key}\":"));
        }
    }

    #[test]
    fn json_layout() {
        let mut v = Values::default();
        v.slots[OPENING] = Slot::Int(500);
        v.slots[FAULT] = Slot::Int(0x21);
        v.slots[LATENCY_MS] = Slot::Float(1.25);
        v.frames = 4;
        let mut changed = Changed::default();
        changed.add(FAULT);
        changed.add(OPENING);
        changed.add(FAULT);
        let s = Sample {
            t: None,
            bus: Arc::from("b\"us"),
            device: 2,
            protocol: EG2_CAN,
            seq: -1,
            changed,
            values: v,
        };
        let mut json = String::new();
        push_sample_json(&mut json, &s).unwrap();
        assert_eq!(
            json,
            "{\"t\":null,\"bus\":\"b\\\"us\",\"device\":2,\"protocol\":\"eg2-can\",\"seq\":-1,\
             \"opening\":500,\"force\":null,\"current\":null,\"temperature_c\":null,\
             \"state\":null,\"fault\":33,\"target_opening\":null,\"speed\":null,\
             \"force_setting\":null,\"catch_mode\":null,\"max_opening\":null,\
             \"min_opening\":null,\"last_command\":null,\"latency_ms\":1.25,\"frames\":4,\
             \"errors\":0,\"unanswered\":0,\"opening_mm\":35.0,\"target_mm\":null,\
             \"state_text\":null,\"fault_text\":[\"stall\",\"reserved bit 5\"],\
             \"changed\":[\"fault\",\"opening\"]}"
        );
        let mut bad = s.clone();
        bad.values.slots[STATE] = Slot::Float(3.0);
        assert_eq!(push_sample_json(&mut json, &bad), Err(NotAnInt("state")));
    }
}
