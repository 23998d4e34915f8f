//! Records as Arrow columns, laid out as analyzer/parquet/schema.py `PARSE_SCHEMA`, for the
//! Parquet output (analyzer/parquet/writer.py `ParquetRecordWriter.write_parsed`): no JSON.
//!
//! The layout is not written down here: Python describes `PARSE_SCHEMA` at the start of a run
//! (analyzer/parquet/native.py, one home for the columns) as a depth-first list of columns, and
//! these builders fill it. What goes where mirrors analyzer/parquet/writer.py `_line_by_line`
//! and `_split_fields`, the exact path of the Python engine:
//! - the record columns take the `Record` attribute of their name (as `Record.to_dict` gives it:
//!   `raw` as hex, NaN and infinities null as orjson writes them);
//! - `fields` goes to its family's struct column (`fields_serial`, ...); a key the struct has
//!   and whose value fits its type exactly (`_fits`) is kept; `values` (a register map) is split
//!   register by register; everything else is written as JSON (orjson's text) to
//!   `other_fields`, in the order found: no value is dropped.
//!
//! Each column is an Arrow array under construction (validity bitmap, values or offsets and
//! bytes, children). Nulls are filled in lazily (a column catches up to the row where its next
//! value goes, and to the end of the batch when it is handed out): most columns are empty in
//! most rows, and a column with no value in a batch is handed out as "all null", with no
//! buffer at all.

use crate::decoders::model::{Record, Value};
use crate::json::{push_map, push_str, push_value};
use crate::parquet::states::{Row, StateColumns};
use crate::session::tracker::Tracker;
use std::sync::{Arc, Mutex};

// -- the schema as Python describes it --------------------------------------------------------

/// The Arrow types the builders make (`pa.int64()`, `pa.float64()`, ...).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Type {
    Int,
    Float,
    Str,
    Bool,
    /// `pa.list_(child)`: one child column follows
    List,
    /// `pa.struct(...)`: its children follow
    Struct,
}

impl Type {
    pub fn by_name(name: &str) -> Option<Type> {
        Some(match name {
            "int64" => Type::Int,
            "float64" => Type::Float,
            "string" => Type::Str,
            "bool" => Type::Bool,
            "list" => Type::List,
            "struct" => Type::Struct,
            _ => return None,
        })
    }
}

/// One column of the depth-first description: its name (a struct child's key), its type, the
/// number of its children (which follow it, each with its own).
#[derive(Clone, Debug)]
pub struct ColumnSpec {
    pub name: String,
    pub ty: Type,
    pub children: usize,
}

impl ColumnSpec {
    pub fn new(name: &str, ty: Type, children: usize) -> Self {
        ColumnSpec {
            name: name.to_owned(),
            ty,
            children,
        }
    }
}

// -- bitmaps ------------------------------------------------------------------------------------

/// An Arrow bitmap (LSB first).
#[derive(Default)]
struct Bits {
    bytes: Vec<u8>,
    len: usize,
}

impl Bits {
    #[inline]
    fn push(&mut self, bit: bool) {
        if self.len.is_multiple_of(8) {
            self.bytes.push(0);
        }
        if bit {
            self.bytes[self.len / 8] |= 1 << (self.len % 8);
        }
        self.len += 1;
    }

    /// `n` one bits.
    fn push_ones(&mut self, mut n: usize) {
        while n > 0 && !self.len.is_multiple_of(8) {
            self.push(true);
            n -= 1;
        }
        self.bytes.resize(self.bytes.len() + n / 8, 0xFF);
        self.len += n / 8 * 8;
        for _ in 0..n % 8 {
            self.push(true);
        }
    }

    /// `n` zero bits.
    fn push_zeros(&mut self, n: usize) {
        self.len += n;
        self.bytes.resize(self.len.div_ceil(8), 0);
    }

    fn clear(&mut self) {
        self.bytes.clear();
        self.len = 0;
    }
}

// -- one column -----------------------------------------------------------------------------------

type Keys = crate::hash::FastMap<String, usize>;

enum Data {
    Int(Vec<i64>),
    Float(Vec<f64>),
    Bool(Bits),
    Str {
        offsets: Vec<i32>,
        bytes: Vec<u8>,
    },
    List {
        offsets: Vec<i32>,
        child: Box<Column>,
    },
    Struct {
        children: Vec<Column>,
        keys: Keys,
    },
}

/// One Arrow array under construction.
pub(crate) struct Column {
    pub(crate) ty: Type,
    /// the validity bitmap, kept only once a null is pushed (Arrow needs none without nulls)
    valid: Bits,
    /// values pushed (null or not)
    len: usize,
    /// of which null
    nulls: usize,
    data: Data,
}

impl Column {
    /// The column described at `specs[*at]` (and its children, after it); `*at` moves past them.
    pub(crate) fn build(specs: &[ColumnSpec], at: &mut usize) -> Result<Column, String> {
        let spec = specs.get(*at).ok_or("the column description ends early")?;
        *at += 1;
        let data = match spec.ty {
            Type::Int => Data::Int(Vec::new()),
            Type::Float => Data::Float(Vec::new()),
            Type::Bool => Data::Bool(Bits::default()),
            Type::Str => Data::Str {
                offsets: vec![0],
                bytes: Vec::new(),
            },
            Type::List => {
                if spec.children != 1 {
                    return Err(format!(
                        "list column {} has {} children",
                        spec.name, spec.children
                    ));
                }
                Data::List {
                    offsets: vec![0],
                    child: Box::new(Column::build(specs, at)?),
                }
            }
            Type::Struct => {
                let mut children = Vec::with_capacity(spec.children);
                let mut keys = Keys::default();
                for i in 0..spec.children {
                    keys.insert(
                        specs
                            .get(*at)
                            .ok_or("the column description ends early")?
                            .name
                            .clone(),
                        i,
                    );
                    children.push(Column::build(specs, at)?);
                }
                Data::Struct { children, keys }
            }
        };
        if spec.ty != Type::List && spec.ty != Type::Struct && spec.children != 0 {
            return Err(format!(
                "column {} of type {:?} has children",
                spec.name, spec.ty
            ));
        }
        Ok(Column {
            ty: spec.ty,
            valid: Bits::default(),
            len: 0,
            nulls: 0,
            data,
        })
    }

    pub(crate) fn push_null(&mut self) {
        if self.nulls == 0 {
            self.valid.push_ones(self.len); // the bitmap, kept from the first null on
        }
        self.valid.push(false);
        self.len += 1;
        self.nulls += 1;
        match &mut self.data {
            Data::Int(v) => v.push(0),
            Data::Float(v) => v.push(0.0),
            Data::Bool(b) => b.push(false),
            Data::Str { offsets, bytes } => offsets.push(bytes.len() as i32),
            Data::List { offsets, child } => offsets.push(child.len as i32),
            Data::Struct { .. } => {} // children catch up when they next get a value
        }
    }

    /// Nulls up to `row` (the row the next value goes to).
    #[inline]
    fn pad_to(&mut self, row: usize) {
        if self.len >= row {
            return;
        }
        let n = row - self.len;
        if self.len == self.nulls && !matches!(self.data, Data::Struct { .. } | Data::List { .. }) {
            // nothing but nulls so far: in bulk
            self.valid.push_zeros(n);
            self.len += n;
            self.nulls += n;
            match &mut self.data {
                Data::Int(v) => v.resize(self.len, 0),
                Data::Float(v) => v.resize(self.len, 0.0),
                Data::Bool(b) => b.push_zeros(n),
                Data::Str { offsets, bytes } => offsets.resize(self.len + 1, bytes.len() as i32),
                _ => unreachable!(),
            }
            return;
        }
        for _ in 0..n {
            self.push_null();
        }
    }

    #[inline]
    fn mark_valid(&mut self) {
        if self.nulls > 0 {
            self.valid.push(true);
        }
        self.len += 1;
    }

    #[inline]
    pub(crate) fn push_int(&mut self, v: i64) {
        if let Data::Int(vals) = &mut self.data {
            vals.push(v);
            self.mark_valid();
        }
    }

    #[inline]
    fn push_float(&mut self, v: Option<f64>) {
        // orjson writes NaN and infinities as null
        match v {
            Some(x) if x.is_finite() => {
                if let Data::Float(vals) = &mut self.data {
                    vals.push(x);
                    self.mark_valid();
                }
            }
            _ => self.push_null(),
        }
    }

    /// A float as it is (NaN and infinities kept: `pa.array` of Python floats keeps them).
    #[inline]
    pub(crate) fn push_raw_float(&mut self, v: f64) {
        if let Data::Float(vals) = &mut self.data {
            vals.push(v);
            self.mark_valid();
        }
    }

    #[inline]
    pub(crate) fn push_str(&mut self, s: &str) {
        if let Data::Str { offsets, bytes } = &mut self.data {
            bytes.extend_from_slice(s.as_bytes());
            offsets.push(bytes.len() as i32);
            self.mark_valid();
        }
    }

    fn push_opt_str(&mut self, s: Option<&str>) {
        match s {
            Some(s) => self.push_str(s),
            None => self.push_null(),
        }
    }

    fn push_opt_int(&mut self, v: Option<i64>) {
        match v {
            Some(v) => self.push_int(v),
            None => self.push_null(),
        }
    }

    /// A list of strings, from an iterator (no list in between).
    pub(crate) fn push_strs<'a>(&mut self, items: impl Iterator<Item = &'a str>) {
        if let Data::List { offsets, child } = &mut self.data {
            for s in items {
                child.push_str(s);
            }
            offsets.push(child.len as i32);
            self.mark_valid();
        }
    }

    /// A list of strings (errors, warnings, flags).
    pub(crate) fn push_str_list<S: AsRef<str>>(&mut self, items: &[S]) {
        if let Data::List { offsets, child } = &mut self.data {
            for s in items {
                child.push_str(s.as_ref());
            }
            offsets.push(child.len as i32);
            self.mark_valid();
        }
    }

    /// The child of a struct column by key.
    #[inline]
    fn child(&mut self, key: &str) -> Option<&mut Column> {
        match &mut self.data {
            Data::Struct { children, keys } => keys.get(key).map(|&i| &mut children[i]),
            _ => None,
        }
    }

    /// Whether `value` converts to this column's type exactly (parquet.py `_fits`; null always
    /// does).
    fn fits(&self, value: &Value) -> bool {
        match (value, &self.data) {
            (Value::Null, _) => true,
            (Value::Int(_), Data::Int(_) | Data::Float(_)) => true,
            (Value::Float(_), Data::Float(_)) => true,
            (Value::Str(_), Data::Str { .. }) => true,
            (Value::Bool(_), Data::Bool(_)) => true,
            (Value::List(items), Data::List { child, .. }) => items.iter().all(|v| child.fits(v)),
            (Value::Map(entries), Data::Struct { children, keys }) => entries
                .iter()
                .all(|(k, v)| keys.get(k.as_ref()).is_some_and(|&i| children[i].fits(v))),
            _ => false,
        }
    }

    /// Append a value that fits (`fits`).
    fn push_value(&mut self, value: &Value) {
        match (value, &mut self.data) {
            (Value::Null, _) => self.push_null(),
            (Value::Int(i), Data::Int(_)) => self.push_int(*i),
            (Value::Int(i), Data::Float(_)) => self.push_float(Some(*i as f64)),
            (Value::Float(x), Data::Float(_)) => self.push_float(Some(*x)),
            (Value::Str(s), Data::Str { .. }) => self.push_str(s),
            (Value::Bool(b), Data::Bool(bits)) => {
                bits.push(*b);
                self.mark_valid();
            }
            (Value::List(items), Data::List { offsets, child }) => {
                for item in items {
                    child.push_value(item);
                }
                offsets.push(child.len as i32);
                self.mark_valid();
            }
            (Value::Map(entries), Data::Struct { .. }) => {
                let row = self.len;
                self.mark_valid();
                for (k, v) in entries {
                    if let Some(child) = self.child(k) {
                        if child.len <= row {
                            // (a key twice: the first value, as in no Python dict; never made)
                            child.pad_to(row);
                            child.push_value(v);
                        }
                    }
                }
            }
            _ => debug_assert!(false, "push_value of a value that does not fit"),
        }
    }

    /// Whether the column holds no value (only nulls, or nothing) in its first `rows` rows.
    fn all_null(&self) -> bool {
        self.len == self.nulls
    }

    /// Hand out the column (padded to `rows`) and its children, depth first, then empty it.
    pub(crate) fn take(&mut self, rows: usize, out: &mut dyn FnMut(Buffers<'_>)) {
        if self.all_null() {
            self.skip(rows, out);
            return;
        }
        self.pad_to(rows);
        let validity = (self.nulls > 0).then_some(&self.valid.bytes[..]);
        let (len, nulls) = (self.len, self.nulls);
        match &mut self.data {
            Data::Int(v) => out(Buffers::Data {
                len,
                nulls,
                validity,
                values: as_bytes(v),
                bytes: None,
            }),
            Data::Float(v) => out(Buffers::Data {
                len,
                nulls,
                validity,
                values: as_bytes(v),
                bytes: None,
            }),
            Data::Bool(b) => out(Buffers::Data {
                len,
                nulls,
                validity,
                values: &b.bytes,
                bytes: None,
            }),
            Data::Str { offsets, bytes } => out(Buffers::Data {
                len,
                nulls,
                validity,
                values: as_bytes(offsets),
                bytes: Some(bytes),
            }),
            Data::List { offsets, child } => {
                out(Buffers::Data {
                    len,
                    nulls,
                    validity,
                    values: as_bytes(offsets),
                    bytes: None,
                });
                let items = child.len;
                child.take(items, out);
            }
            Data::Struct { children, .. } => {
                out(Buffers::Data {
                    len,
                    nulls,
                    validity,
                    values: &[],
                    bytes: None,
                });
                for c in children {
                    c.take(len, out);
                }
            }
        }
        self.clear();
    }

    /// Hand out the column and its children as all null (the children of an all-null struct
    /// and list are handed out too: the description is walked in step).
    fn skip(&mut self, rows: usize, out: &mut dyn FnMut(Buffers<'_>)) {
        out(Buffers::AllNull(rows));
        match &mut self.data {
            Data::List { child, .. } => child.skip(0, out),
            Data::Struct { children, .. } => children.iter_mut().for_each(|c| c.skip(rows, out)),
            _ => {}
        }
        self.clear();
    }

    fn clear(&mut self) {
        self.valid.clear();
        self.len = 0;
        self.nulls = 0;
        match &mut self.data {
            Data::Int(v) => v.clear(),
            Data::Float(v) => v.clear(),
            Data::Bool(b) => b.clear(),
            Data::Str { offsets, bytes } => {
                offsets.clear();
                offsets.push(0);
                bytes.clear();
            }
            Data::List { offsets, child } => {
                offsets.clear();
                offsets.push(0);
                child.clear();
            }
            Data::Struct { children, .. } => children.iter_mut().for_each(Column::clear),
        }
    }
}

/// The bytes of a slice of plain numbers (i64, f64, i32: no padding, every bit pattern valid),
/// in the machine's byte order, as Arrow keeps them.
fn as_bytes<T: Copy>(v: &[T]) -> &[u8] {
    // SAFETY: T is a plain number type (see above); the bytes live as long as the slice.
    unsafe { std::slice::from_raw_parts(v.as_ptr().cast::<u8>(), std::mem::size_of_val(v)) }
}

/// One column of a batch as handed out, depth first: Arrow's buffers for
/// `pa.Array.from_buffers` (`values`: the values, the offsets of a string or list, a bool's
/// bits, nothing for a struct; `bytes`: a string's UTF-8), or "all null" (`pa.nulls`).
#[derive(Debug, PartialEq)]
pub enum Buffers<'a> {
    AllNull(usize),
    Data {
        len: usize,
        nulls: usize,
        validity: Option<&'a [u8]>,
        values: &'a [u8],
        bytes: Option<&'a [u8]>,
    },
}

// -- the record columns -------------------------------------------------------------------------

/// The attributes of a Record that are columns (decoders/model.py `to_dict`, `fields` aside).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Attr {
    T,
    Bus,
    Protocol,
    Kind,
    Offset,
    Index,
    Length,
    Direction,
    Device,
    Code,
    Name,
    Raw,
    Errors,
    Warnings,
    Flags,
    Summary,
    Seq,
    Pair,
    LatencyMs,
}

impl Attr {
    /// The attribute of a column name, with the type its column must have.
    fn by_name(name: &str) -> Option<(Attr, Type)> {
        use Attr::*;
        Some(match name {
            "t" => (T, Type::Float),
            "bus" => (Bus, Type::Str),
            "protocol" => (Protocol, Type::Str),
            "kind" => (Kind, Type::Str),
            "offset" => (Offset, Type::Int),
            "index" => (Index, Type::Int),
            "length" => (Length, Type::Int),
            "direction" => (Direction, Type::Str),
            "device" => (Device, Type::Int),
            "code" => (Code, Type::Int),
            "name" => (Name, Type::Str),
            "raw" => (Raw, Type::Str),
            "errors" => (Errors, Type::List),
            "warnings" => (Warnings, Type::List),
            "flags" => (Flags, Type::List),
            "summary" => (Summary, Type::Str),
            "seq" => (Seq, Type::Int),
            "pair" => (Pair, Type::Int),
            "latency_ms" => (LatencyMs, Type::Float),
            _ => return None,
        })
    }
}

/// What a top-level column holds.
enum Role {
    Attr(Attr),
    /// the `fields` of the protocols of this family
    Family,
    /// `other_fields`
    Other,
}

const HEX: &[u8; 16] = b"0123456789ABCDEF";

/// `raw.hex(" ").upper()`, as `Record.to_dict` writes it.
fn push_hex(out: &mut Vec<u8>, raw: &[u8]) {
    for (i, &b) in raw.iter().enumerate() {
        if i > 0 {
            out.push(b' ');
        }
        out.push(HEX[(b >> 4) as usize]);
        out.push(HEX[(b & 15) as usize]);
    }
}

/// A batch of records as the columns of `PARSE_SCHEMA`.
pub struct RecordColumns {
    columns: Vec<(Role, Column)>,
    /// protocol -> index of its family's column
    families: Vec<(String, usize)>,
    other: usize,
    values_key: String,
    rows: usize,
    /// the JSON of `other_fields` (reused)
    json: String,
}

/// Whether a column of type `ty` takes a list of strings.
pub(crate) fn is_str_list(col: &Column) -> bool {
    matches!(&col.data, Data::List { child, .. } if child.ty == Type::Str)
}

impl RecordColumns {
    /// Builders for the columns `specs` describe (depth first; top-level columns are record
    /// attributes by name, family struct columns named in `families` (protocol -> column), or
    /// `other`); `values_key`: the key of `fields` split register by register. An error for a
    /// description these builders cannot fill.
    pub fn new(
        specs: &[ColumnSpec],
        families: &[(String, String)],
        other: &str,
        values_key: &str,
    ) -> Result<RecordColumns, String> {
        let mut columns = Vec::new();
        let mut names = Vec::new();
        let mut at = 0;
        let mut other_at = None;
        while at < specs.len() {
            let spec = &specs[at];
            let role = if let Some((attr, ty)) = Attr::by_name(&spec.name) {
                if ty != spec.ty {
                    return Err(format!(
                        "column {} is {:?}, not {:?}",
                        spec.name, spec.ty, ty
                    ));
                }
                Role::Attr(attr)
            } else if families.iter().any(|(_, c)| *c == spec.name) {
                if spec.ty != Type::Struct {
                    return Err(format!("family column {} is not a struct", spec.name));
                }
                Role::Family
            } else if spec.name == other && spec.ty == Type::Str {
                other_at = Some(columns.len());
                Role::Other
            } else {
                return Err(format!("no record value for column {}", spec.name));
            };
            let column = Column::build(specs, &mut at)?;
            if matches!(role, Role::Attr(_)) && column.ty == Type::List && !is_str_list(&column) {
                return Err(format!("column {} is not a list of strings", spec.name));
            }
            names.push(spec.name.clone());
            columns.push((role, column));
        }
        let mut fams = Vec::new();
        for (protocol, name) in families {
            let i = names
                .iter()
                .position(|n| n == name)
                .ok_or_else(|| format!("no column {name}"))?;
            fams.push((protocol.clone(), i));
        }
        Ok(RecordColumns {
            columns,
            families: fams,
            other: other_at.ok_or_else(|| format!("no column {other}"))?,
            values_key: values_key.to_owned(),
            rows: 0,
            json: String::new(),
        })
    }

    /// Rows held.
    pub fn rows(&self) -> usize {
        self.rows
    }

    /// One record as one row (`_line_by_line` for one line).
    pub fn push(&mut self, rec: &Record) {
        let row = self.rows;
        self.rows += 1;
        let mut family = None;
        for (role, col) in &mut self.columns {
            let Role::Attr(attr) = role else {
                continue;
            };
            match attr {
                Attr::T => col.push_float(rec.t),
                Attr::Bus => col.push_str(&rec.bus),
                Attr::Protocol => col.push_str(rec.protocol),
                Attr::Kind => col.push_str(rec.kind),
                Attr::Offset => col.push_opt_int(rec.offset.map(|v| v as i64)),
                Attr::Index => col.push_opt_int(rec.index.map(|v| v as i64)),
                Attr::Length => col.push_int(rec.length as i64),
                Attr::Direction => col.push_opt_str(rec.direction),
                Attr::Device => col.push_opt_int(rec.device),
                Attr::Code => col.push_opt_int(rec.code),
                Attr::Name => col.push_opt_str(rec.name.as_deref()),
                Attr::Raw => {
                    if let Data::Str { offsets, bytes } = &mut col.data {
                        push_hex(bytes, &rec.raw);
                        offsets.push(bytes.len() as i32);
                        col.mark_valid();
                    }
                }
                Attr::Errors => col.push_str_list(&rec.errors),
                Attr::Warnings => col.push_str_list(&rec.warnings),
                Attr::Flags => col.push_str_list(&rec.flags),
                Attr::Summary => col.push_str(&rec.summary),
                Attr::Seq => col.push_int(rec.seq),
                Attr::Pair => col.push_opt_int(rec.pair),
                Attr::LatencyMs => col.push_float(rec.latency_ms),
            }
        }
        for (protocol, i) in &self.families {
            if protocol == rec.protocol {
                family = Some(*i);
                break;
            }
        }
        self.json.clear();
        match family {
            Some(i) => {
                let col = &mut self.columns[i].1;
                split_fields(col, row, &rec.fields, &self.values_key, &mut self.json);
            }
            None if !rec.fields.is_empty() => push_map(&mut self.json, &rec.fields),
            None => {}
        }
        if !self.json.is_empty() {
            let col = &mut self.columns[self.other].1;
            col.pad_to(row);
            col.push_str(&self.json);
        }
    }

    /// Hand out the rows held, column by column depth first (in the order of the description),
    /// and start a new batch.
    pub fn take(&mut self, out: &mut dyn FnMut(Buffers<'_>)) {
        let rows = self.rows;
        for (_, col) in &mut self.columns {
            col.take(rows, out);
        }
        self.rows = 0;
    }
}

/// parquet.py `_split_fields` for one record of a family: what the family's struct column `col`
/// holds goes into it at `row`; the rest is written to `json` as the JSON object of
/// `other_fields` (left empty when nothing is left).
fn split_fields(
    col: &mut Column,
    row: usize,
    fields: &[(crate::decoders::model::Str, Value)],
    values_key: &str,
    json: &mut String,
) {
    col.pad_to(row);
    col.mark_valid();
    let mut other = 0;
    for (key, value) in fields {
        let Some(child) = col.child(key) else {
            add_other(json, &mut other, key, value);
            continue;
        };
        if child.len > row {
            continue; // a key twice (never made)
        }
        match (value, child.ty) {
            (Value::Map(entries), Type::Struct) if key == values_key => {
                // register by register: those of the map in their columns, the rest as JSON
                child.pad_to(row);
                child.mark_valid();
                let mut rest = 0;
                for (k, v) in entries {
                    match child.child(k) {
                        Some(reg) if reg.len <= row && reg.fits(v) => {
                            reg.pad_to(row);
                            reg.push_value(v);
                        }
                        _ => {
                            if rest == 0 {
                                add_key(json, &mut other, key);
                                json.push('{');
                            } else {
                                json.push(',');
                            }
                            rest += 1;
                            push_str(json, k);
                            json.push(':');
                            push_value(json, v);
                        }
                    }
                }
                if rest > 0 {
                    json.push('}');
                }
            }
            _ if child.fits(value) => {
                child.pad_to(row);
                child.push_value(value);
            }
            _ => add_other(json, &mut other, key, value),
        }
    }
    if other > 0 {
        json.push('}');
    }
}

/// Start the next key of the `other_fields` object.
fn add_key(json: &mut String, count: &mut usize, key: &str) {
    json.push(if *count == 0 { '{' } else { ',' });
    *count += 1;
    push_str(json, key);
    json.push(':');
}

fn add_other(json: &mut String, count: &mut usize, key: &str, value: &Value) {
    add_key(json, count, key);
    push_value(json, value);
}

// -- as a writer of the pipeline ------------------------------------------------------------------

/// What the pipeline's Arrow writer fills: the records' columns and, for the fleet dataset, the
/// state samples a Tracker makes of the same records, in the order the session's Tracker sees
/// them (the order they are written).
pub struct ArrowTables {
    pub records: RecordColumns,
    pub states: Option<(Tracker, StateColumns)>,
    /// why a sample could not be written (the run ends there)
    pub failure: Option<String>,
}

impl ArrowTables {
    pub fn new(records: RecordColumns, states: Option<StateColumns>) -> Self {
        ArrowTables {
            records,
            states: states.map(|columns| (Tracker::new(true), columns)),
            failure: None,
        }
    }

    fn push(&mut self, rec: &Record) {
        self.records.push(rec);
        if let Some((tracker, columns)) = &mut self.states {
            let pushed = tracker.update_with(rec, |state, changed| {
                columns.push_row(&Row {
                    t: rec.t,
                    bus: &rec.bus,
                    device: state.device,
                    protocol: state.protocol,
                    seq: rec.seq,
                    values: &state.values,
                    changed,
                })
            });
            if let Some(Err(why)) = pushed {
                self.failure.get_or_insert(why);
            }
        }
    }
}

/// The pipeline's writer (sinks/writers.rs `RecordWriter`) that puts records into shared columns
/// instead of bytes: the Python binding takes the columns out between batches.
pub struct ArrowWriter(pub Arc<Mutex<ArrowTables>>);

impl crate::sinks::writers::RecordWriter for ArrowWriter {
    fn write(&mut self, rec: &Record, _out: &mut Vec<u8>) {
        self.0.lock().unwrap_or_else(|e| e.into_inner()).push(rec);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::decoders::model::{Record, EG2_CAN, MODBUS_RTU};
    use std::borrow::Cow;

    /// A small parse schema: two record columns, one family with a register map, other_fields.
    fn columns() -> RecordColumns {
        let specs = [
            ColumnSpec::new("t", Type::Float, 0),
            ColumnSpec::new("flags", Type::List, 1),
            ColumnSpec::new("item", Type::Str, 0),
            ColumnSpec::new("fields_modbus", Type::Struct, 3),
            ColumnSpec::new("slave", Type::Int, 0),
            ColumnSpec::new("bits", Type::List, 1),
            ColumnSpec::new("item", Type::Int, 0),
            ColumnSpec::new("values", Type::Struct, 2),
            ColumnSpec::new("CMD_A", Type::Int, 0),
            ColumnSpec::new("CMD_B", Type::Int, 0),
            ColumnSpec::new("other_fields", Type::Str, 0),
        ];
        let families = [(MODBUS_RTU.to_owned(), "fields_modbus".to_owned())];
        RecordColumns::new(&specs, &families, "other_fields", "values").unwrap()
    }

    fn record(protocol: &'static str, t: f64, fields: Vec<(&'static str, Value)>) -> Record {
        let mut rec = Record::new(Some(t), Arc::from("bus"), protocol, "frame", vec![1]);
        rec.fields = fields
            .into_iter()
            .map(|(k, v)| (Cow::Borrowed(k), v))
            .collect();
        rec
    }

    /// A column as `take` hands it out, owned: (len, nulls, validity, values), or its length.
    type Taken = Result<(usize, usize, Option<Vec<u8>>, Vec<u8>), usize>;

    /// What `take` hands out.
    fn taken(cols: &mut RecordColumns) -> Vec<Taken> {
        let mut out = Vec::new();
        cols.take(&mut |b| {
            out.push(match b {
                Buffers::AllNull(n) => Err(n),
                Buffers::Data {
                    len,
                    nulls,
                    validity,
                    values,
                    ..
                } => Ok((len, nulls, validity.map(<[u8]>::to_vec), values.to_vec())),
            })
        });
        out
    }

    fn ints(bytes: &[u8]) -> Vec<i64> {
        bytes
            .chunks(8)
            .map(|c| i64::from_ne_bytes(c.try_into().unwrap()))
            .collect()
    }

    #[test]
    fn the_validity_bitmap_begins_at_the_first_null() {
        for valid_first in [0, 1, 7, 8, 9, 17] {
            let specs = [ColumnSpec::new("x", Type::Int, 0)];
            let mut col = Column::build(&specs, &mut 0).unwrap();
            for i in 0..valid_first {
                col.push_int(i as i64);
            }
            col.push_null();
            col.push_int(1);
            let want: Vec<bool> = (0..valid_first)
                .map(|_| true)
                .chain([false, true])
                .collect();
            let got: Vec<bool> = (0..want.len())
                .map(|i| col.valid.bytes[i / 8] >> (i % 8) & 1 == 1)
                .collect();
            assert_eq!((got, col.valid.len, col.nulls), (want, valid_first + 2, 1));
        }
    }

    #[test]
    fn nulls_fill_in_lazily_and_empty_columns_have_no_buffers() {
        let mut cols = columns();
        cols.push(&record(
            MODBUS_RTU,
            f64::NAN,
            vec![("slave", Value::Int(1))],
        ));
        cols.push(&record(MODBUS_RTU, 2.0, vec![]));
        cols.push(&record(
            MODBUS_RTU,
            3.0,
            vec![(
                "values",
                Value::Map(vec![(Cow::Borrowed("CMD_B"), Value::Int(7))]),
            )],
        ));
        let out = taken(&mut cols);
        // t: NaN is null (orjson writes null)
        let (len, nulls, validity, _) = out[0].clone().unwrap();
        assert_eq!((len, nulls, validity), (3, 1, Some(vec![0b110])));
        // slave: a value, then nulls up to the end of the batch
        let (len, nulls, validity, values) = out[4].clone().unwrap();
        assert_eq!(
            (len, nulls, validity, ints(&values)),
            (3, 2, Some(vec![0b001]), vec![1, 0, 0])
        );
        assert_eq!(out[5], Err(3)); // bits: never set
        assert_eq!(out[6], Err(0)); // its items
        assert_eq!(out[8], Err(3)); // CMD_A: never set
        let (_, nulls, _, values) = out[9].clone().unwrap();
        assert_eq!((nulls, ints(&values)), (2, vec![0, 0, 7]));
        assert_eq!(out[10], Err(3)); // other_fields: nothing left over
        assert_eq!(cols.rows(), 0);
    }

    #[test]
    fn what_no_column_holds_is_json_in_other_fields() {
        let mut cols = columns();
        let values = Value::Map(vec![
            (Cow::Borrowed("CMD_A"), Value::Int(1)),
            (Cow::Borrowed("CMD_X"), Value::Int(2)),
            (Cow::Borrowed("CMD_B"), Value::Str("no".into())),
        ]);
        let fields = vec![
            ("slave", Value::Str("not an int".into())),
            ("values", values),
            ("new", Value::Float(f64::INFINITY)),
            ("bits", Value::List(vec![Value::Int(1), Value::Null])),
        ];
        cols.push(&record(MODBUS_RTU, 1.0, fields));
        cols.push(&record(EG2_CAN, 1.0, vec![("slave", Value::Int(3))])); // no family: all JSON
        let mut json = Vec::new();
        cols.take(&mut |b| {
            if let Buffers::Data {
                bytes: Some(bytes), ..
            } = b
            {
                json.push(String::from_utf8(bytes.to_vec()).unwrap());
            }
        });
        assert_eq!(
            json.last().unwrap(),
            "{\"slave\":\"not an int\",\"values\":{\"CMD_X\":2,\"CMD_B\":\"no\"},\"new\":null}\
             {\"slave\":3}"
        );
    }

    #[test]
    fn a_description_the_builders_cannot_fill_is_refused() {
        let bad = [
            ColumnSpec::new("t", Type::Str, 0),
            ColumnSpec::new("o", Type::Str, 0),
        ];
        assert!(RecordColumns::new(&bad, &[], "o", "values").is_err());
        let unknown = [
            ColumnSpec::new("nope", Type::Int, 0),
            ColumnSpec::new("o", Type::Str, 0),
        ];
        assert!(RecordColumns::new(&unknown, &[], "o", "values").is_err());
    }
}
