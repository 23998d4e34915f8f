//! The data every stage shares: decoded Records and the JSON values in their `fields`.
//!
//! Mirrors `decoders/model.py`. A Record is written by the writers in the same key order as
//! the Python `Record.to_dict()`; `fields` keeps insertion order (as a Python dict does).

use std::borrow::Cow;
use std::sync::Arc;

/// A string that is usually a literal from the register/command tables.
pub type Str = Cow<'static, str>;

pub const EG2_SERIAL: &str = "eg2-serial";
pub const MODBUS_RTU: &str = "modbus-rtu";
pub const EG2_CAN: &str = "eg2-can";
pub const FOREIGN_CAN: &str = "can";

pub const FRAME: &str = "frame";
pub const GARBAGE: &str = "garbage";
pub const TRUNCATED: &str = "truncated";

pub const REQUEST: &str = "request";
pub const RESPONSE: &str = "response";

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
    pub fields: Fields,
    pub errors: Vec<String>,
    pub warnings: Vec<String>,
    pub summary: String,
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
            fields: Vec::new(),
            errors: Vec::new(),
            warnings: Vec::new(),
            summary: String::new(),
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
    pub fn flag(&mut self, code: &'static str) {
        if !self.flags.contains(&code) {
            self.flags.push(code);
        }
    }
}
