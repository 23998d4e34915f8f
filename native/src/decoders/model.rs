//! The data every stage shares: decoded Records and the JSON values in their `fields`.
//!
//! Mirrors `decoders/model.py`. A Record is written by the writers in the same key order as
//! the Python `Record.to_dict()`; `fields` keeps insertion order (as a Python dict does).

use std::borrow::Cow;
use std::ops::Deref;
use std::sync::{Arc, OnceLock};

/// A string that is usually a literal from the register/command tables.
pub type Str = Cow<'static, str>;

pub use crate::generated::model::{
    CUT_OFF, EG2_CAN, EG2_SERIAL, FOREIGN_CAN, FRAME, GARBAGE, MODBUS_RTU, REQUEST, RESPONSE,
    TRUNCATED,
};

/// A value in `Record.fields`, in the order and with the types the Python decoders produce
/// (int stays int, float stays float: the JSON text differs).
#[derive(Clone, Debug, PartialEq)]
pub enum Value {
    Null,
    Bool(bool),
    Int(i64),
    Float(f64),
    Str(Str),
    List(Vec<Value>),
    Map(Vec<(Str, Value)>),
}

impl From<i64> for Value {
    fn from(v: i64) -> Self {
        Value::Int(v)
    }
}
impl From<f64> for Value {
    fn from(v: f64) -> Self {
        Value::Float(v)
    }
}
impl From<&'static str> for Value {
    fn from(v: &'static str) -> Self {
        Value::Str(Cow::Borrowed(v))
    }
}
impl From<String> for Value {
    fn from(v: String) -> Self {
        Value::Str(Cow::Owned(v))
    }
}
impl From<bool> for Value {
    fn from(v: bool) -> Self {
        Value::Bool(v)
    }
}

/// Ordered `fields` of a record (a Python dict keeps insertion order).
pub type Fields = Vec<(Str, Value)>;

/// A record's `fields`, shared (read-only) by every record decoded from the same frame: the
/// decoders memoise a frame's decode, so a record takes a reference count instead of a copy of
/// the map, and the JSONL writer formats the map (with the identity before it and the raw
/// bytes after it) once per shared decode instead of once per record ([`SharedFields::segment`]).
#[derive(Clone, Debug, Default)]
pub struct SharedFields(Arc<FieldsBody>);

#[derive(Debug, Default)]
struct FieldsBody {
    items: Fields,
    segment: OnceLock<Segment>,
}

/// The JSON text of the keys `direction` .. `raw` of the first record written with these
/// fields, and what it was made of: the writer reuses it for a record with the same values.
#[derive(Debug)]
pub struct Segment {
    pub direction: Option<&'static str>,
    pub device: Option<i64>,
    pub code: Option<i64>,
    pub name: Option<Str>,
    pub raw: Box<[u8]>,
    pub text: Box<str>,
    /// the JSON text of `,"errors":[],"warnings":[],"flags":[],"summary":…` for a record with
    /// no notes and this summary (the shared `Arc`), when the first record had none
    pub quiet: Option<(Text, Box<str>)>,
}

impl Segment {
    /// True when `rec` has the values this text was made of.
    #[inline]
    pub fn matches(&self, rec: &Record) -> bool {
        self.device == rec.device
            && self.code == rec.code
            && *self.raw == *rec.raw
            && match (self.direction, rec.direction) {
                (Some(a), Some(b)) => std::ptr::eq(a, b) || a == b,
                (a, b) => a == b,
            }
            && self.name.as_deref() == rec.name.as_deref()
    }

    /// The text of `quiet` if `rec` has no errors, warnings or flags and the same summary.
    #[inline]
    pub fn quiet_text(&self, rec: &Record) -> Option<&str> {
        let (summary, text) = self.quiet.as_ref()?;
        let quiet = rec.errors.is_empty() && rec.warnings.is_empty() && rec.flags.is_empty();
        (quiet && Arc::ptr_eq(summary, &rec.summary)).then_some(&**text)
    }
}

impl SharedFields {
    /// The empty map (no allocation: one shared instance).
    pub fn empty() -> Self {
        static EMPTY: OnceLock<SharedFields> = OnceLock::new();
        EMPTY
            .get_or_init(|| SharedFields(Arc::new(FieldsBody::default())))
            .clone()
    }

    /// The JSON segment made for these fields, if one was.
    #[inline]
    pub fn segment(&self) -> Option<&Segment> {
        self.0.segment.get()
    }

    /// True when another record or a decoder's memo holds these fields too (a segment made for
    /// them may be used again).
    #[inline]
    pub fn is_shared(&self) -> bool {
        Arc::strong_count(&self.0) > 1
    }

    /// Keep `make()`'s segment for the records that share these fields (the first one wins).
    pub fn set_segment(&self, make: impl FnOnce() -> Segment) {
        if self.0.segment.get().is_none() {
            let _ = self.0.segment.set(make());
        }
    }

    /// The fields to change (copied first if shared; the copy has no segment).
    pub fn make_mut(&mut self) -> &mut Fields {
        if Arc::get_mut(&mut self.0).is_none() {
            self.0 = Arc::new(FieldsBody {
                items: self.0.items.clone(),
                segment: OnceLock::new(),
            });
        }
        let body = Arc::get_mut(&mut self.0).expect("unique after the copy");
        body.segment = OnceLock::new(); // the text no longer describes them
        &mut body.items
    }
}

impl Deref for SharedFields {
    type Target = Fields;
    #[inline]
    fn deref(&self) -> &Fields {
        &self.0.items
    }
}

impl From<Fields> for SharedFields {
    fn from(mut items: Fields) -> Self {
        if items.is_empty() {
            return SharedFields::empty();
        }
        items.shrink_to_fit(); // a memo holds thousands: no spare room in each
        SharedFields(Arc::new(FieldsBody {
            items,
            segment: OnceLock::new(),
        }))
    }
}

impl FromIterator<(Str, Value)> for SharedFields {
    fn from_iter<I: IntoIterator<Item = (Str, Value)>>(iter: I) -> Self {
        Fields::from_iter(iter).into()
    }
}

impl PartialEq for SharedFields {
    fn eq(&self, other: &Self) -> bool {
        self.0.items == other.0.items
    }
}

/// A record's summary: shared by the records of one memoised decode, like its fields.
pub type Text = Arc<str>;

/// One CAN frame (decoders/model.py `CanFrame`).
#[derive(Clone, Debug, Default)]
pub struct CanFrame {
    pub t: Option<f64>,
    pub arbitration_id: u32,
    pub data: Vec<u8>,
    pub is_extended: bool,
    pub is_remote: bool,
    pub is_error: bool,
    pub is_fd: bool,
    /// None: data.len(); remote frames carry a DLC but no data
    pub dlc: Option<usize>,
    pub channel: Option<String>,
}

impl CanFrame {
    pub fn length(&self) -> usize {
        self.dlc.unwrap_or(self.data.len())
    }
}

/// What pairs a request with its response within one bus and protocol: the Python tuple
/// `pair_key` (serial: (device, cmd); Modbus: (slave, function); CAN: (arbitration id,)).
/// Unused trailing slots are 0 (keys are only compared within one protocol).
pub type PairKey = [i64; 2];

/// One decoded frame, or one run of bytes that belongs to no frame (decoders/model.py).
#[derive(Clone, Debug)]
pub struct Record {
    pub t: Option<f64>,
    pub bus: Arc<str>,
    pub protocol: &'static str,
    pub kind: &'static str,
    pub length: usize,
    pub raw: Vec<u8>,
    pub offset: Option<u64>,
    pub index: Option<u64>,
    pub direction: Option<&'static str>,
    pub device: Option<i64>,
    pub code: Option<i64>,
    pub name: Option<Str>,
    pub fields: SharedFields,
    pub errors: Vec<String>,
    pub warnings: Vec<String>,
    pub summary: Text,
    pub seq: i64,
    pub pair: Option<i64>,
    pub latency_ms: Option<f64>,
    // internal, for pairing and lint (not written)
    pub pair_key: Option<PairKey>,
    pub expects_response: bool,
    pub is_save: bool,
    /// one code per error/warning text (decoders/flags.py)
    pub flags: Vec<&'static str>,
}

/// The empty summary (no allocation: one shared instance).
pub fn empty_text() -> Text {
    static EMPTY: OnceLock<Text> = OnceLock::new();
    EMPTY.get_or_init(|| Arc::from("")).clone()
}

impl Record {
    /// A record with the given identity and everything else empty (Python's defaults).
    pub fn new(
        t: Option<f64>,
        bus: Arc<str>,
        protocol: &'static str,
        kind: &'static str,
        raw: Vec<u8>,
    ) -> Self {
        Record {
            t,
            bus,
            protocol,
            kind,
            length: raw.len(),
            raw,
            offset: None,
            index: None,
            direction: None,
            device: None,
            code: None,
            name: None,
            fields: SharedFields::empty(),
            errors: Vec::new(),
            warnings: Vec::new(),
            summary: empty_text(),
            seq: -1,
            pair: None,
            latency_ms: None,
            pair_key: None,
            expects_response: false,
            is_save: false,
            flags: Vec::new(),
        }
    }

    pub fn ok(&self) -> bool {
        self.kind == FRAME && self.errors.is_empty()
    }

    /// Add an error with its flag code (no code twice on one record, as in Python).
    pub fn error(&mut self, flag: &'static str, text: String) {
        self.errors.push(text);
        self.flag(flag);
    }

    /// Add a warning with its flag code.
    pub fn warning(&mut self, flag: &'static str, text: String) {
        self.warnings.push(text);
        self.flag(flag);
    }

    /// An error in a catalogue's words (`generated::messages`): (its code, its text).
    pub fn error_of(&mut self, (flag, text): (&'static str, impl Into<String>)) {
        self.error(flag, text.into());
    }

    /// A warning in a catalogue's words (`generated::messages`): (its code, its text).
    pub fn warning_of(&mut self, (flag, text): (&'static str, impl Into<String>)) {
        self.warning(flag, text.into());
    }

    pub fn flag(&mut self, flag: &'static str) {
        if !self.flags.contains(&flag) {
            self.flags.push(flag);
        }
    }
}

/// Errors, warnings and their flag codes found while decoding one frame, in the order found
/// (codes once): decoders/notes.py.
#[derive(Clone, Debug, Default)]
pub struct Notes {
    pub errors: Vec<String>,
    pub warnings: Vec<String>,
    pub flags: Vec<&'static str>,
}

impl Notes {
    pub fn error(&mut self, code: &'static str, text: String) {
        self.errors.push(text);
        self.flag(code);
    }
    pub fn warn(&mut self, code: &'static str, text: String) {
        self.warnings.push(text);
        self.flag(code);
    }
    /// An error in a catalogue's words (`generated::messages`): (its code, its text).
    pub fn error_of(&mut self, (code, text): (&'static str, impl Into<String>)) {
        self.error(code, text.into());
    }
    /// A warning in a catalogue's words (`generated::messages`): (its code, its text).
    pub fn warn_of(&mut self, (code, text): (&'static str, impl Into<String>)) {
        self.warn(code, text.into());
    }
    pub fn flag(&mut self, code: &'static str) {
        if !self.flags.contains(&code) {
            self.flags.push(code);
        }
    }
}
