//! The native live CAN path, for Python: `CanStage` (analyzer/session/stage.py `Decoding`, CAN
//! items only), `RecordBatch` (the records it gives, a lazy sequence of decoders/model.py
//! `Record`) and `can_raw_messages` (analyzer/recording/recorder.py `McapRecorder.on_raw`'s JSON of
//! CAN frames).
//!
//! The decoding itself is live.rs; here Items are read and records handed back. A batch keeps
//! its Rust records: a Python `Record` is made for an index only when asked for (then kept,
//! so `batch[i] is batch[i]`), and the bulk methods (`messages`, `times`, `column`, ...) read
//! the Rust records directly, so a recorder that only writes JSON never makes one object per
//! frame. Both are checked against the Python classes by tests/native/test_live_native.py
//! (materialized records `==` the Python's, JSON byte-identical) and test_batch_columns.py
//! (every column identical, types included, to the materialized records' attributes).
//!
//! Inputs are read strictly: a frame's `t` must be a float or None, its flags bools, its
//! identifier and DLC non-negative ints that fit (u32, usize). The Python decoders accept more
//! (an int `t` would stay an int and be written `5`, not `5.0`); rather than differ silently
//! the native path raises TypeError (or OverflowError) before decoding any item of the call.
//!
//! A child module of bindings/mod.rs (python_tracker.rs, a sibling, reads `RecordBatch::records`).

use super::python_frames::FrameBatch;
use crate::decoders::model::{CanFrame, Record, SharedFields, Str, Value, EG2_CAN};
use crate::hash::FastMap;
use crate::session::can_stage::CanStage as Core;
use crate::sinks::writers::{JsonlWriter, RecordWriter};
use pyo3::exceptions::{PyAttributeError, PyIndexError, PyTypeError};
use pyo3::intern;
use pyo3::prelude::*;
use pyo3::sync::GILOnceCell;
use pyo3::types::{
    PyBool, PyByteArray, PyBytes, PyDict, PyFloat, PyInt, PyList, PySlice, PyString, PyTuple,
    PyType,
};
use std::borrow::Cow;
use std::cell::Cell;
use std::sync::Arc;

/// decoders/model.py `Record` and `CanFrame`, imported once.
static RECORD: GILOnceCell<Py<PyType>> = GILOnceCell::new();
static CAN_FRAME: GILOnceCell<Py<PyType>> = GILOnceCell::new();

/// Batches of at least this many frames are decoded with the GIL released (other Python
/// threads, a capture thread, run meanwhile); for fewer, releasing and taking back the GIL
/// would cost more than it gives.
const RELEASE_GIL_FRAMES: usize = 256;

// ---------------------------------------------------------------------------------------------
// Rust records -> Python objects

/// Python objects made for parts that many records share, so a record is made from fewer new
/// objects: the strings of the tables (`&'static str`: protocols, kinds, flag codes, field
/// keys, register names), the shared texts (`Arc<str>`: bus names, a memoised decode's
/// summary) and a memoised decode's `fields` dict. Python strings cannot change, so sharing
/// them shows nowhere; the `fields` dict is shared as the Python decoder shares it between the
/// records of one memoised decode (nothing downstream changes a record's fields). The shared
/// Rust values are held, so the addresses used as keys cannot be reused meanwhile.
#[derive(Default)]
struct PyParts {
    statics: FastMap<(usize, usize), Py<PyString>>,
    texts: FastMap<usize, (Arc<str>, Py<PyString>)>,
    fields: FastMap<usize, (SharedFields, Py<PyDict>)>,
}

/// Shared texts and fields dicts kept (then the caches start again).
const PARTS_LIMIT: usize = 4096;

thread_local! {
    /// The parts of the thread's materializations (taken out while one runs: a materialization
    /// started meanwhile, from a finalizer, makes its own).
    static PARTS: Cell<Option<Box<PyParts>>> = const { Cell::new(None) };
}

impl PyParts {
    /// Run `f` with this thread's parts.
    fn with<R>(f: impl FnOnce(&mut PyParts) -> R) -> R {
        let mut parts = PARTS.with(Cell::take).unwrap_or_default();
        let r = f(&mut parts);
        PARTS.with(|p| p.set(Some(parts)));
        r
    }

    fn static_str<'py>(&mut self, py: Python<'py>, s: &'static str) -> Bound<'py, PyString> {
        self.statics
            .entry((s.as_ptr() as usize, s.len()))
            .or_insert_with(|| PyString::new(py, s).unbind())
            .bind(py)
            .clone()
    }

    fn text<'py>(&mut self, py: Python<'py>, s: &Arc<str>) -> Bound<'py, PyString> {
        let key = Arc::as_ptr(s) as *const u8 as usize;
        if let Some((_, obj)) = self.texts.get(&key) {
            return obj.bind(py).clone();
        }
        if self.texts.len() >= PARTS_LIMIT {
            self.texts.clear();
        }
        let obj = PyString::new(py, s);
        self.texts.insert(key, (s.clone(), obj.clone().unbind()));
        obj
    }

    fn cow<'py>(&mut self, py: Python<'py>, s: &Str) -> Bound<'py, PyString> {
        match s {
            Cow::Borrowed(s) => self.static_str(py, s),
            Cow::Owned(s) => PyString::new(py, s),
        }
    }

    /// A `fields` value as the Python decoders make it (int stays int, maps keep their order).
    fn value<'py>(&mut self, py: Python<'py>, v: &Value) -> PyResult<Bound<'py, PyAny>> {
        Ok(match v {
            Value::Null => py.None().into_bound(py),
            Value::Bool(b) => PyBool::new(py, *b).to_owned().into_any(),
            Value::Int(i) => i.into_pyobject(py)?.into_any(),
            Value::Float(f) => PyFloat::new(py, *f).into_any(),
            Value::Str(s) => self.cow(py, s).into_any(),
            Value::List(items) => {
                let list = PyList::empty(py);
                for x in items {
                    list.append(self.value(py, x)?)?;
                }
                list.into_any()
            }
            Value::Map(entries) => self.map(py, entries)?.into_any(),
        })
    }

    fn map<'py>(
        &mut self,
        py: Python<'py>,
        entries: &[(Str, Value)],
    ) -> PyResult<Bound<'py, PyDict>> {
        let dict = PyDict::new(py);
        for (k, v) in entries {
            dict.set_item(self.cow(py, k), self.value(py, v)?)?;
        }
        Ok(dict)
    }

    /// A record's `fields` dict: one per shared decode.
    fn fields<'py>(&mut self, py: Python<'py>, f: &SharedFields) -> PyResult<Bound<'py, PyDict>> {
        let key = &**f as *const _ as usize;
        if let Some((_, obj)) = self.fields.get(&key) {
            return Ok(obj.bind(py).clone());
        }
        let dict = self.map(py, f)?;
        if f.is_shared() {
            // a decode of one record only is not looked for again
            if self.fields.len() >= PARTS_LIMIT {
                self.fields.clear();
            }
            self.fields.insert(key, (f.clone(), dict.clone().unbind()));
        }
        Ok(dict)
    }

    /// A decoders.model.Record equal to `rec`, made by calling the class positionally (its
    /// errors, warnings and flags lists its own, as the Python decoders copy them per record).
    fn record<'py>(&mut self, py: Python<'py>, rec: &Record) -> PyResult<Bound<'py, PyAny>> {
        let cls = RECORD.import(py, "decoders.model", "Record")?;
        // ATTRS's order, spelled out: each `attr` call is then inlined for its attribute
        let mut attr = |a| self.attr(py, rec, a);
        let args: [Bound<'py, PyAny>; ATTRS.len()] = [
            attr(Attr::T)?,
            attr(Attr::Bus)?,
            attr(Attr::Protocol)?,
            attr(Attr::Kind)?,
            attr(Attr::Length)?,
            attr(Attr::Raw)?,
            attr(Attr::Offset)?,
            attr(Attr::Index)?,
            attr(Attr::Direction)?,
            attr(Attr::Device)?,
            attr(Attr::Code)?,
            attr(Attr::Name)?,
            attr(Attr::Fields)?,
            attr(Attr::Errors)?,
            attr(Attr::Warnings)?,
            attr(Attr::Summary)?,
            attr(Attr::Seq)?,
            attr(Attr::Pair)?,
            attr(Attr::LatencyMs)?,
            attr(Attr::PairKey)?,
            attr(Attr::ExpectsResponse)?,
            attr(Attr::IsSave)?,
            attr(Attr::Flags)?,
        ];
        cls.call1(PyTuple::new(py, args)?)
    }

    /// One attribute of `rec` as its Python Record has it: what materialization passes the
    /// class, and what `RecordBatch.column` lists (one definition, so the two cannot differ).
    fn attr<'py>(
        &mut self,
        py: Python<'py>,
        rec: &Record,
        attr: Attr,
    ) -> PyResult<Bound<'py, PyAny>> {
        let none = || py.None().into_bound(py);
        Ok(match attr {
            Attr::T => opt_float(py, rec.t),
            Attr::Bus => self.text(py, &rec.bus).into_any(),
            Attr::Protocol => self.static_str(py, rec.protocol).into_any(),
            Attr::Kind => self.static_str(py, rec.kind).into_any(),
            Attr::Length => rec.length.into_pyobject(py)?.into_any(),
            Attr::Raw => PyBytes::new(py, &rec.raw).into_any(),
            Attr::Offset => match rec.offset {
                Some(o) => o.into_pyobject(py)?.into_any(),
                None => none(),
            },
            Attr::Index => match rec.index {
                Some(i) => i.into_pyobject(py)?.into_any(),
                None => none(),
            },
            Attr::Direction => match rec.direction {
                Some(d) => self.static_str(py, d).into_any(),
                None => none(),
            },
            Attr::Device => opt_int(py, rec.device)?,
            Attr::Code => opt_int(py, rec.code)?,
            Attr::Name => match &rec.name {
                Some(n) => self.cow(py, n).into_any(),
                None => none(),
            },
            Attr::Fields => self.fields(py, &rec.fields)?.into_any(),
            Attr::Errors => str_list(py, &rec.errors)?.into_any(),
            Attr::Warnings => str_list(py, &rec.warnings)?.into_any(),
            Attr::Summary => self.text(py, &rec.summary).into_any(),
            Attr::Seq => rec.seq.into_pyobject(py)?.into_any(),
            Attr::Pair => opt_int(py, rec.pair)?,
            Attr::LatencyMs => opt_float(py, rec.latency_ms),
            Attr::PairKey => pair_key(py, rec)?,
            Attr::ExpectsResponse => PyBool::new(py, rec.expects_response).to_owned().into_any(),
            Attr::IsSave => PyBool::new(py, rec.is_save).to_owned().into_any(),
            Attr::Flags => {
                let flags = PyList::empty(py);
                for f in &rec.flags {
                    flags.append(self.static_str(py, f))?;
                }
                flags.into_any()
            }
        })
    }
}

/// An attribute of decoders.model.Record.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Attr {
    T,
    Bus,
    Protocol,
    Kind,
    Length,
    Raw,
    Offset,
    Index,
    Direction,
    Device,
    Code,
    Name,
    Fields,
    Errors,
    Warnings,
    Summary,
    Seq,
    Pair,
    LatencyMs,
    PairKey,
    ExpectsResponse,
    IsSave,
    Flags,
}

/// Record's attributes with their names, in the order of its dataclass fields (the order the
/// class takes them positionally).
const ATTRS: [(Attr, &str); 23] = [
    (Attr::T, "t"),
    (Attr::Bus, "bus"),
    (Attr::Protocol, "protocol"),
    (Attr::Kind, "kind"),
    (Attr::Length, "length"),
    (Attr::Raw, "raw"),
    (Attr::Offset, "offset"),
    (Attr::Index, "index"),
    (Attr::Direction, "direction"),
    (Attr::Device, "device"),
    (Attr::Code, "code"),
    (Attr::Name, "name"),
    (Attr::Fields, "fields"),
    (Attr::Errors, "errors"),
    (Attr::Warnings, "warnings"),
    (Attr::Summary, "summary"),
    (Attr::Seq, "seq"),
    (Attr::Pair, "pair"),
    (Attr::LatencyMs, "latency_ms"),
    (Attr::PairKey, "pair_key"),
    (Attr::ExpectsResponse, "expects_response"),
    (Attr::IsSave, "is_save"),
    (Attr::Flags, "flags"),
];

impl Attr {
    fn named(name: &str) -> Option<Attr> {
        ATTRS.iter().find(|(_, n)| *n == name).map(|&(a, _)| a)
    }
}

/// The texts of errors and warnings (made per record) as a list of new strings.
fn str_list<'py>(py: Python<'py>, items: &[String]) -> PyResult<Bound<'py, PyList>> {
    PyList::new(py, items.iter().map(|s| PyString::new(py, s)))
}

fn opt_int<'py>(py: Python<'py>, v: Option<i64>) -> PyResult<Bound<'py, PyAny>> {
    Ok(match v {
        Some(v) => v.into_pyobject(py)?.into_any(),
        None => py.None().into_bound(py),
    })
}

fn opt_float<'py>(py: Python<'py>, v: Option<f64>) -> Bound<'py, PyAny> {
    match v {
        Some(v) => PyFloat::new(py, v).into_any(),
        None => py.None().into_bound(py),
    }
}

/// `rec.pair_key` as the Python tuple: `(arbitration id,)` on CAN, `(device, command)` /
/// `(slave, function)` on the byte-stream protocols (model.rs `PairKey`).
fn pair_key<'py>(py: Python<'py>, rec: &Record) -> PyResult<Bound<'py, PyAny>> {
    Ok(match rec.pair_key {
        None => py.None().into_bound(py),
        Some([a, _]) if rec.protocol == EG2_CAN => PyTuple::new(py, [a])?.into_any(),
        Some(key) => PyTuple::new(py, key)?.into_any(),
    })
}

// ---------------------------------------------------------------------------------------------
// RecordBatch

/// `RecordBatch()`: decoded records, each a decoders.model.Record when indexed or iterated
/// (made once per index, then the same object). Behaves as a read-only list of them, plus
/// `+=` of another batch and bulk methods that read the records without making objects.
/// The bulk methods describe the records as decoded: changes made to a materialized Record
/// object are not seen by them.
#[pyclass(module = "analyzer._native")]
pub struct RecordBatch {
    pub(crate) records: Vec<Record>,
    /// the Python object of each index, once made (empty until the first is)
    objects: Vec<Option<Py<PyAny>>>,
}

impl RecordBatch {
    pub(crate) fn from_records(records: Vec<Record>) -> Self {
        RecordBatch {
            records,
            objects: Vec::new(),
        }
    }

    /// The Python Record of index `i` (< len), made on first use.
    fn object(&mut self, py: Python<'_>, i: usize) -> PyResult<Py<PyAny>> {
        if self.objects.len() < self.records.len() {
            self.objects.resize_with(self.records.len(), || None);
        }
        if let Some(obj) = &self.objects[i] {
            return Ok(obj.clone_ref(py));
        }
        let obj = PyParts::with(|parts| parts.record(py, &self.records[i]))?.unbind();
        self.objects[i] = Some(obj.clone_ref(py));
        Ok(obj)
    }

    /// Append `records` with their objects (`objects` empty: none made yet).
    fn append(&mut self, records: Vec<Record>, objects: Vec<Option<Py<PyAny>>>) {
        if !objects.is_empty() {
            self.objects.resize_with(self.records.len(), || None);
            self.objects.extend(objects);
        }
        self.records.extend(records);
    }
}

#[pymethods]
impl RecordBatch {
    #[new]
    fn new() -> Self {
        RecordBatch::from_records(Vec::new())
    }

    fn __len__(&self) -> usize {
        self.records.len()
    }

    fn __repr__(&self) -> String {
        format!("<RecordBatch of {} records>", self.records.len())
    }

    /// `batch[i]` (negative counts from the end) or `batch[a:b:c]` (a list), as a list does.
    fn __getitem__(&mut self, py: Python<'_>, key: &Bound<'_, PyAny>) -> PyResult<PyObject> {
        let n = self.records.len();
        if let Ok(slice) = key.downcast::<PySlice>() {
            let ix = slice.indices(n as isize)?;
            let mut out = Vec::with_capacity(ix.slicelength);
            let mut i = ix.start;
            for _ in 0..ix.slicelength {
                out.push(self.object(py, i as usize)?);
                i += ix.step;
            }
            return Ok(PyList::new(py, out)?.into_any().unbind());
        }
        let Ok(i) = key.extract::<isize>() else {
            if key.is_instance_of::<PyInt>() {
                // an int too large for an index: as a list says it
                return Err(PyIndexError::new_err(
                    "cannot fit 'int' into an index-sized integer",
                ));
            }
            return Err(PyTypeError::new_err(format!(
                "RecordBatch indices must be integers or slices, not {}",
                key.get_type().name()?
            )));
        };
        let j = if i < 0 { i + n as isize } else { i };
        if j < 0 || j >= n as isize {
            return Err(PyIndexError::new_err("RecordBatch index out of range"));
        }
        self.object(py, j as usize)
    }

    fn __iter__(slf: &Bound<'_, Self>) -> RecordBatchIter {
        RecordBatchIter {
            batch: slf.clone().unbind(),
            next: 0,
            reverse: false,
        }
    }

    /// Last to first (`reversed(batch)`).
    fn __reversed__(slf: &Bound<'_, Self>) -> RecordBatchIter {
        RecordBatchIter {
            batch: slf.clone().unbind(),
            next: slf.borrow().records.len(),
            reverse: true,
        }
    }

    /// `batch += other`: other's records appended (other is left as it was, unless nothing
    /// else can see it: a temporary, whose records are then moved rather than copied).
    fn __iadd__(slf: &Bound<'_, Self>, other: &Bound<'_, PyAny>) -> PyResult<()> {
        let py = slf.py();
        if other.is(slf) {
            let mut me = slf.borrow_mut();
            let records = me.records.clone();
            let objects = me
                .objects
                .iter()
                .map(|o| o.as_ref().map(|o| o.clone_ref(py)))
                .collect();
            me.append(records, objects);
            return Ok(());
        }
        let Ok(other) = other.downcast::<RecordBatch>() else {
            return Err(PyTypeError::new_err(format!(
                "can only add a RecordBatch to a RecordBatch, not {}",
                other.get_type().name()?
            )));
        };
        // the interpreter's own reference (the operand on its stack) and the one this call
        // borrows are the same one: 1 means no name, list or frame holds the batch
        let temporary = other.get_refcnt() <= 1;
        let mut theirs = other.borrow_mut();
        let (records, objects) = if temporary {
            (
                std::mem::take(&mut theirs.records),
                std::mem::take(&mut theirs.objects),
            )
        } else {
            let objects = theirs
                .objects
                .iter()
                .map(|o| o.as_ref().map(|o| o.clone_ref(py)))
                .collect();
            (theirs.records.clone(), objects)
        };
        drop(theirs);
        slf.borrow_mut().append(records, objects);
        Ok(())
    }

    /// Per record, `orjson.dumps(rec.to_dict(), default=analyzer.model.json_default)`.
    fn messages<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyList>> {
        let mut writer = JsonlWriter::default();
        let mut line = Vec::with_capacity(1024);
        PyList::new(
            py,
            self.records.iter().map(|rec| {
                line.clear();
                writer.write(rec, &mut line); // the JSONL line: the same text and a newline
                PyBytes::new(py, &line[..line.len() - 1])
            }),
        )
    }

    /// `rec.t` per record.
    fn times<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyList>> {
        PyList::new(py, self.records.iter().map(|r| opt_float(py, r.t)))
    }

    /// `rec.bus` per record (one string object per run of one bus).
    fn buses<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyList>> {
        let mut last: Option<(&Arc<str>, Bound<'py, PyString>)> = None;
        let mut out = Vec::with_capacity(self.records.len());
        for rec in &self.records {
            let name = match &last {
                Some((bus, name)) if Arc::ptr_eq(bus, &rec.bus) => name.clone(),
                _ => {
                    let name = PyString::new(py, &rec.bus);
                    last = Some((&rec.bus, name.clone()));
                    name
                }
            };
            out.push(name);
        }
        PyList::new(py, out)
    }

    /// How many records have errors.
    fn error_count(&self) -> usize {
        self.records.iter().filter(|r| !r.errors.is_empty()).count()
    }

    /// How many records have `getattr(rec, name) == value` (`column(name).count(value)`),
    /// without a list for the text attributes (bus, protocol, kind, direction).
    fn count_of(&self, py: Python<'_>, name: &str, value: &Bound<'_, PyAny>) -> PyResult<usize> {
        let Ok(text) = value.downcast::<PyString>() else {
            return self
                .column(py, name)?
                .call_method1("count", (value,))?
                .extract();
        };
        let text = text.to_str()?;
        let same = |s: &str| s == text;
        Ok(match name {
            "bus" => self.records.iter().filter(|r| same(&r.bus)).count(),
            "protocol" => self.records.iter().filter(|r| same(r.protocol)).count(),
            "kind" => self.records.iter().filter(|r| same(r.kind)).count(),
            "direction" => (self.records.iter())
                .filter(|r| r.direction.is_some_and(same))
                .count(),
            _ => {
                return self
                    .column(py, name)?
                    .call_method1("count", (value,))?
                    .extract()
            }
        })
    }

    /// The indexes of the records with errors or warnings.
    fn problems(&self) -> Vec<usize> {
        self.records
            .iter()
            .enumerate()
            .filter(|(_, r)| !r.errors.is_empty() || !r.warnings.is_empty())
            .map(|(i, _)| i)
            .collect()
    }

    /// `[getattr(rec, name) for rec in batch]`, read from the records (no Record is made):
    /// the values the materialized records would have, of the same types, strings and
    /// `fields` dicts shared as materialization shares them (the `fields` of a memoised decode
    /// is the very dict its materialized records hold). AttributeError for a name that is not
    /// one of Record's attributes (the property `ok` is not one).
    fn column<'py>(&self, py: Python<'py>, name: &str) -> PyResult<Bound<'py, PyList>> {
        let Some(attr) = Attr::named(name) else {
            return Err(PyAttributeError::new_err(format!(
                "'Record' object has no attribute '{name}'"
            )));
        };
        let values = PyParts::with(|parts| {
            self.records
                .iter()
                .map(|rec| parts.attr(py, rec, attr))
                .collect::<PyResult<Vec<_>>>()
        })?;
        PyList::new(py, values)
    }

    /// The records at `indexes`, in that order, as a new batch (`RecordSequence.take`): the
    /// Records already made are shared, the others are still made only when read.
    fn take(&self, py: Python<'_>, indexes: Vec<usize>) -> PyResult<RecordBatch> {
        let mut records = Vec::with_capacity(indexes.len());
        let mut objects = Vec::new();
        for &i in &indexes {
            let Some(rec) = self.records.get(i) else {
                return Err(PyIndexError::new_err("RecordBatch index out of range"));
            };
            records.push(rec.clone());
            if !self.objects.is_empty() {
                objects.push(self.objects[i].as_ref().map(|o| o.clone_ref(py)));
            }
        }
        Ok(RecordBatch { records, objects })
    }

    /// The records as JSONL lines, as `decode --format jsonl` writes them (each of
    /// `messages()` and a newline).
    fn jsonl<'py>(&self, py: Python<'py>) -> Bound<'py, PyBytes> {
        let mut writer = JsonlWriter::default();
        let mut out = Vec::with_capacity(self.records.len() * 256);
        for rec in &self.records {
            writer.write(rec, &mut out);
        }
        PyBytes::new(py, &out)
    }

    /// What `eg2scope plot`'s logs show of the records (python_rerun.rs): `polls`, the
    /// (protocol, code) of requests that only read; `quiet`, flags that say nothing is wrong.
    fn rerun_log_rows<'py>(
        slf: PyRef<'py, Self>,
        polls: Vec<(String, i64)>,
        quiet: Vec<String>,
    ) -> PyResult<Bound<'py, PyTuple>> {
        let py = slf.py();
        super::python_rerun::rerun_log_rows(py, slf, polls, quiet)
    }

    /// analyzer/stats.py `stats_groups` of the records (python_stats.rs).
    fn stats_groups<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyTuple>> {
        super::python_stats::stats_groups(py, &self.records)
    }
}

/// The iterator of a RecordBatch (by index, as a list's: records appended meanwhile are seen
/// going forwards).
#[pyclass(module = "analyzer._native")]
struct RecordBatchIter {
    batch: Py<RecordBatch>,
    /// going forwards, the next index; backwards, one past it
    next: usize,
    reverse: bool,
}

#[pymethods]
impl RecordBatchIter {
    fn __iter__(slf: PyRef<'_, Self>) -> PyRef<'_, Self> {
        slf
    }

    fn __next__(&mut self, py: Python<'_>) -> PyResult<Option<PyObject>> {
        let mut batch = self.batch.bind(py).borrow_mut();
        if self.reverse {
            if self.next == 0 || self.next > batch.records.len() {
                self.next = 0; // exhausted stays exhausted, as a list's reverse iterator
                return Ok(None);
            }
            self.next -= 1;
            return batch.object(py, self.next).map(Some);
        }
        if self.next >= batch.records.len() {
            self.next = usize::MAX; // exhausted stays exhausted, as a list iterator
            return Ok(None);
        }
        let obj = batch.object(py, self.next)?;
        self.next += 1;
        Ok(Some(obj))
    }
}

// ---------------------------------------------------------------------------------------------
// reading Items

/// What `feed` and `can_raw_messages` read of one Item: its bus (the str object) and frame
/// (the data in a shared buffer, `data` its range there).
pub(super) struct ItemFrame<'py> {
    pub(super) bus: Bound<'py, PyString>,
    pub(super) t: Option<f64>,
    pub(super) aid: u32,
    pub(super) extended: bool,
    pub(super) remote: bool,
    pub(super) error: bool,
    pub(super) fd: bool,
    pub(super) dlc: Option<usize>,
    pub(super) data: std::ops::Range<usize>,
    /// only read for `can_raw_messages`
    channel: Option<Bound<'py, PyAny>>,
}

pub(super) fn type_name(obj: &Bound<'_, PyAny>) -> String {
    obj.get_type()
        .name()
        .map(|n| n.to_string())
        .unwrap_or_else(|_| "?".into())
}

fn flag(frame: &Bound<'_, PyAny>, name: &Bound<'_, PyString>) -> PyResult<bool> {
    let v = frame.getattr(name)?;
    match v.downcast_exact::<PyBool>() {
        Ok(b) => Ok(b.is_true()),
        Err(_) => Err(PyTypeError::new_err(format!(
            "CanFrame.{name} must be a bool, not {}",
            type_name(&v)
        ))),
    }
}

/// An int attribute of a frame (a bool is refused: the recorder's JSON would say `true`).
fn exact_int<'py, T: FromPyObject<'py>>(v: &Bound<'py, PyAny>, name: &str) -> PyResult<T> {
    if !v.is_exact_instance_of::<PyInt>() {
        return Err(PyTypeError::new_err(format!(
            "CanFrame.{name} must be an int, not {}",
            type_name(v)
        )));
    }
    v.extract()
}

/// Whether an Item's payload is a CanFrame (not a byte chunk).
pub(super) fn is_can_item(item: &Bound<'_, PyAny>) -> PyResult<bool> {
    let py = item.py();
    let can_frame = CAN_FRAME.import(py, "decoders.model", "CanFrame")?;
    let frame = item.getattr(intern!(py, "payload"))?;
    Ok(frame.get_type().is(can_frame) || frame.is_instance(can_frame)?)
}

/// Read one Item (a CanFrame payload) into `bytes` and an `ItemFrame`.
pub(super) fn read_item<'py>(
    item: &Bound<'py, PyAny>,
    bytes: &mut Vec<u8>,
    with_channel: bool,
    who: &str,
) -> PyResult<ItemFrame<'py>> {
    let py = item.py();
    let can_frame = CAN_FRAME.import(py, "decoders.model", "CanFrame")?;
    let Ok(frame) = item.getattr(intern!(py, "payload")) else {
        return Err(PyTypeError::new_err(format!(
            "{who}: expected an Item, got {}",
            type_name(item)
        )));
    };
    if !frame.get_type().is(can_frame) && !frame.is_instance(can_frame)? {
        return Err(PyTypeError::new_err(format!(
            "{who}: an Item's payload is a {}, not a CanFrame (CAN items only)",
            type_name(&frame)
        )));
    }
    let bus = item.getattr(intern!(py, "bus"))?;
    let Ok(bus) = bus.downcast_into::<PyString>() else {
        return Err(PyTypeError::new_err(format!(
            "{who}: an Item's bus must be a str"
        )));
    };
    let t = frame.getattr(intern!(py, "t"))?;
    let t = if t.is_none() {
        None
    } else if let Ok(f) = t.downcast_exact::<PyFloat>() {
        Some(f.value())
    } else {
        return Err(PyTypeError::new_err(format!(
            "CanFrame.t must be a float or None, not {}",
            type_name(&t)
        )));
    };
    let aid: u32 = exact_int(
        &frame.getattr(intern!(py, "arbitration_id"))?,
        "arbitration_id",
    )?;
    let data = frame.getattr(intern!(py, "data"))?;
    let start = bytes.len();
    if let Ok(b) = data.downcast_exact::<PyBytes>() {
        bytes.extend_from_slice(b.as_bytes());
    } else if let Ok(b) = data.downcast::<PyByteArray>() {
        bytes.extend_from_slice(&b.to_vec());
    } else {
        // what the Python decoder does with any other buffer: bytes(data)
        let b = py.get_type::<PyBytes>().call1((data,))?;
        bytes.extend_from_slice(b.downcast::<PyBytes>()?.as_bytes());
    }
    let dlc = frame.getattr(intern!(py, "dlc"))?;
    let dlc = if dlc.is_none() {
        None
    } else {
        Some(exact_int(&dlc, "dlc")?)
    };
    let channel = if with_channel {
        let c = frame.getattr(intern!(py, "channel"))?;
        if !c.is_none() && !c.is_instance_of::<PyString>() && !c.is_exact_instance_of::<PyInt>() {
            return Err(PyTypeError::new_err(format!(
                "CanFrame.channel must be a str or None, not {}",
                type_name(&c)
            )));
        }
        Some(c)
    } else {
        None
    };
    Ok(ItemFrame {
        bus,
        t,
        aid,
        extended: flag(&frame, intern!(py, "is_extended"))?,
        remote: flag(&frame, intern!(py, "is_remote"))?,
        error: flag(&frame, intern!(py, "is_error"))?,
        fd: flag(&frame, intern!(py, "is_fd"))?,
        dlc,
        data: start..bytes.len(),
        channel,
    })
}

/// Every item of `items` (a list, a tuple or any iterable), in order.
pub(super) fn for_each_item<'py>(
    items: &Bound<'py, PyAny>,
    mut f: impl FnMut(&Bound<'py, PyAny>) -> PyResult<()>,
) -> PyResult<()> {
    if let Ok(list) = items.downcast::<PyList>() {
        for item in list.iter() {
            f(&item)?;
        }
    } else if let Ok(tuple) = items.downcast::<PyTuple>() {
        for item in tuple.iter() {
            f(&item)?;
        }
    } else {
        for item in items.try_iter()? {
            f(&item?)?;
        }
    }
    Ok(())
}

// ---------------------------------------------------------------------------------------------
// CanStage

/// A frame read from an Item, waiting to be decoded (its data in `PyCanStage::bytes`).
struct Queued {
    bus: usize,
    t: Option<f64>,
    aid: u32,
    extended: bool,
    remote: bool,
    error: bool,
    fd: bool,
    dlc: Option<usize>,
    data: std::ops::Range<usize>,
}

/// `CanStage(positional=False, can_index=0)`: analyzer.session.stage.Decoding for CAN items.
#[pyclass(name = "CanStage", module = "analyzer._native")]
struct PyCanStage {
    core: Core,
    /// the bus str objects seen, with their decoder's number: a source names every frame of a
    /// bus with one object, so the number is found by identity (the object is held, its
    /// address cannot be reused)
    buses: Vec<(Py<PyString>, usize)>,
    queue: Vec<Queued>,
    bytes: Vec<u8>,
    frame: CanFrame,
}

impl PyCanStage {
    /// `feed` of frames read natively (python_frames.rs): no Python object to read.
    fn feed_frames(&mut self, py: Python<'_>, batch: &FrameBatch) -> RecordBatch {
        let core = &mut self.core;
        let mut out = Vec::with_capacity(batch.frames.len() + 8);
        py.allow_threads(|| {
            let mut last: Option<(&Arc<str>, usize)> = None;
            for (bus, frame) in &batch.frames {
                let id = match last {
                    Some((name, id)) if Arc::ptr_eq(name, bus) => id,
                    _ => {
                        let id = core.bus_id(bus);
                        last = Some((bus, id));
                        id
                    }
                };
                core.feed(id, frame, &mut out);
            }
        });
        RecordBatch::from_records(out)
    }

    fn bus_id(&mut self, bus: &Bound<'_, PyString>) -> PyResult<usize> {
        let py = bus.py();
        if let Some((_, id)) = self.buses.iter().find(|(b, _)| b.bind(py).is(bus)) {
            return Ok(*id);
        }
        let id = self.core.bus_id(bus.to_str()?);
        if self.buses.len() >= 64 {
            self.buses.clear(); // new str objects per item: look the name up each time
        }
        self.buses.push((bus.clone().unbind(), id));
        Ok(id)
    }
}

/// Decode the queued frames (their data in `bytes`) into `out`; `frame` is scratch.
fn decode_queue(
    core: &mut Core,
    queue: &[Queued],
    bytes: &[u8],
    frame: &mut CanFrame,
    out: &mut Vec<Record>,
) {
    for q in queue {
        frame.t = q.t;
        frame.arbitration_id = q.aid;
        frame.is_extended = q.extended;
        frame.is_remote = q.remote;
        frame.is_error = q.error;
        frame.is_fd = q.fd;
        frame.dlc = q.dlc;
        frame.data.clear();
        frame.data.extend_from_slice(&bytes[q.data.clone()]);
        core.feed(q.bus, frame, out);
    }
}

#[pymethods]
impl PyCanStage {
    #[new]
    #[pyo3(signature = (positional=false, can_index=0))]
    fn new(positional: bool, can_index: u64) -> Self {
        PyCanStage {
            core: Core::new(positional, can_index),
            buses: Vec::new(),
            queue: Vec::new(),
            bytes: Vec::new(),
            frame: CanFrame::default(),
        }
    }

    /// The records of `items` (Items whose payload is a CanFrame): `Decoding.feed` of each,
    /// concatenated. Every item is read before any is decoded: an item that is not a CAN
    /// frame raises TypeError with nothing decoded.
    fn feed(&mut self, py: Python<'_>, items: &Bound<'_, PyAny>) -> PyResult<RecordBatch> {
        if let Ok(batch) = items.downcast::<FrameBatch>() {
            return Ok(self.feed_frames(py, batch.get()));
        }
        self.queue.clear();
        self.bytes.clear();
        let mut bytes = std::mem::take(&mut self.bytes);
        let mut queue = std::mem::take(&mut self.queue);
        let read = for_each_item(items, |item| {
            let f = read_item(item, &mut bytes, false, "CanStage.feed")?;
            queue.push(Queued {
                bus: self.bus_id(&f.bus)?,
                t: f.t,
                aid: f.aid,
                extended: f.extended,
                remote: f.remote,
                error: f.error,
                fd: f.fd,
                dlc: f.dlc,
                data: f.data,
            });
            Ok(())
        });
        self.bytes = bytes;
        self.queue = queue;
        read?;
        let mut out = Vec::with_capacity(self.queue.len() + 8);
        let (core, queue, bytes, frame) =
            (&mut self.core, &self.queue, &self.bytes, &mut self.frame);
        if queue.len() >= RELEASE_GIL_FRAMES {
            // no Python object in there: the decoding state, the frames read, the records
            py.allow_threads(|| decode_queue(core, queue, bytes, frame, &mut out));
        } else {
            decode_queue(core, queue, bytes, frame, &mut out);
        }
        if self.bytes.capacity() > 1 << 20 {
            self.bytes = Vec::new(); // one huge batch must not pin its memory
        }
        Ok(RecordBatch::from_records(out))
    }

    /// `Decoding.tick(now)`: requests that timed out by `now` are released.
    fn tick(&mut self, now: f64) -> RecordBatch {
        let mut out = Vec::new();
        self.core.tick(now, &mut out);
        RecordBatch::from_records(out)
    }

    /// `Decoding.gap(bus)`: the bus's source went away.
    fn gap(&mut self, bus: &str) -> RecordBatch {
        let mut out = Vec::new();
        self.core.gap(bus, &mut out);
        RecordBatch::from_records(out)
    }

    /// `Decoding.finish()`: the end of the input.
    fn finish(&mut self) -> RecordBatch {
        let mut out = Vec::new();
        self.core.finish(&mut out);
        RecordBatch::from_records(out)
    }

    /// `Decoding.cut_off(bus)`: the capture of the bus was stopped.
    fn cut_off(&mut self, bus: &str) -> RecordBatch {
        let mut out = Vec::new();
        self.core.cut_off(bus, &mut out);
        RecordBatch::from_records(out)
    }

    /// `Decoding.stop()`: the capture was stopped before its input ended.
    fn stop(&mut self) -> RecordBatch {
        let mut out = Vec::new();
        self.core.stop(&mut out);
        RecordBatch::from_records(out)
    }

    /// The number the next frame gets (`Decoding.can_index`).
    #[getter]
    fn can_index(&self) -> u64 {
        self.core.can_index()
    }

    /// Whether seq is each record's CAN index.
    #[getter]
    fn positional(&self) -> bool {
        self.core.positional()
    }
}

// ---------------------------------------------------------------------------------------------
// can_raw_messages

const B64: &[u8; 64] = b"ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";

/// `binascii.b2a_base64(data, newline=False)` (standard alphabet, `=` padded).
fn push_base64(out: &mut String, data: &[u8]) {
    let mut buf = Vec::with_capacity(data.len().div_ceil(3) * 4);
    for chunk in data.chunks(3) {
        let b = [
            chunk[0],
            chunk.get(1).copied().unwrap_or(0),
            chunk.get(2).copied().unwrap_or(0),
        ];
        let n = u32::from(b[0]) << 16 | u32::from(b[1]) << 8 | u32::from(b[2]);
        buf.push(B64[(n >> 18) as usize & 63]);
        buf.push(B64[(n >> 12) as usize & 63]);
        buf.push(if chunk.len() > 1 {
            B64[(n >> 6) as usize & 63]
        } else {
            b'='
        });
        buf.push(if chunk.len() > 2 {
            B64[n as usize & 63]
        } else {
            b'='
        });
    }
    crate::json::push_ascii(out, &buf);
}

fn push_bool(out: &mut String, b: bool) {
    out.push_str(if b { "true" } else { "false" });
}

/// Per CAN item, the JSON message analyzer/recording/recorder.py `McapRecorder.on_raw` writes on
/// `/raw/<bus>` (`_message` of `{"t", "id", "extended", "remote", "error", "fd", "dlc",
/// "data" (base64), "channel"}`), byte-identical. Items that are not CAN frames raise
/// TypeError.
#[pyfunction]
fn can_raw_messages<'py>(
    py: Python<'py>,
    items: &Bound<'py, PyAny>,
) -> PyResult<Bound<'py, PyList>> {
    use crate::json::{push_int, push_str, push_u64};
    use crate::pyfloat::push_json_float;
    let mut bytes = Vec::new();
    let mut text = String::with_capacity(256);
    let mut out = Vec::new();
    for_each_item(items, |item| {
        bytes.clear();
        let f = read_item(item, &mut bytes, true, "can_raw_messages")?;
        let data = &bytes[f.data.clone()];
        text.clear();
        text.push_str("{\"t\":");
        match f.t {
            Some(t) => push_json_float(&mut text, t),
            None => text.push_str("null"),
        }
        text.push_str(",\"id\":");
        push_u64(&mut text, u64::from(f.aid));
        text.push_str(",\"extended\":");
        push_bool(&mut text, f.extended);
        text.push_str(",\"remote\":");
        push_bool(&mut text, f.remote);
        text.push_str(",\"error\":");
        push_bool(&mut text, f.error);
        text.push_str(",\"fd\":");
        push_bool(&mut text, f.fd);
        text.push_str(",\"dlc\":");
        push_u64(&mut text, f.dlc.unwrap_or(data.len()) as u64);
        text.push_str(",\"data\":\"");
        push_base64(&mut text, data);
        text.push_str("\",\"channel\":");
        match &f.channel {
            Some(c) if c.is_instance_of::<PyString>() => {
                push_str(&mut text, c.downcast::<PyString>()?.to_str()?)
            }
            Some(c) if !c.is_none() => push_int(&mut text, c.extract::<i64>()?),
            _ => text.push_str("null"),
        }
        text.push('}');
        out.push(PyBytes::new(py, text.as_bytes()));
        Ok(())
    })?;
    PyList::new(py, out)
}

/// Add the classes and the function to the module; `RecordBatch` is registered as a
/// `collections.abc.Sequence` (it behaves as one).
pub(super) fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<RecordBatch>()?;
    m.add_class::<PyCanStage>()?;
    m.add_function(wrap_pyfunction!(can_raw_messages, m)?)?;
    let py = m.py();
    py.import("collections.abc")?
        .getattr("Sequence")?
        .call_method1("register", (py.get_type::<RecordBatch>(),))?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn base64_is_binascii() {
        let cases: [(&[u8], &str); 5] = [
            (b"", ""),
            (b"\x00", "AA=="),
            (b"\x01\x02", "AQI="),
            (b"\xff\xfe\xfd", "//79"),
            (b"\x00\x01\x02\x03\x04\x05\x06\x07", "AAECAwQFBgc="),
        ];
        for (data, want) in cases {
            let mut s = String::new();
            push_base64(&mut s, data);
            assert_eq!(s, want);
        }
    }
}
