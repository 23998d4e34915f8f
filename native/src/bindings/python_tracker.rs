//! `analyzer._native.Tracker` and `SampleBatch`: analyzer/session/tracker.py's `Tracker`
//! folding the records of a `RecordBatch` (python_live.rs) in Rust (session/tracker.rs), its
//! samples kept in Rust until asked for.
//!
//! A `SampleBatch` is a sequence of `analyzer.model.StateSample`, each built only when indexed
//! or iterated (and then the same object every time), with bulk methods that need no Python
//! object per sample: `messages()` (each sample's JSON, byte-identical to
//! `orjson.dumps(sample.to_dict(), default=json_default)`), `times()`, `keys()`, `column(name)`
//! (any attribute, as `[getattr(s, name) for s in batch]`; tests/native/test_batch_columns.py),
//! `series(fields)` (analyzer/session/batches.py `SampleSequence.series`: the values of some
//! fields grouped by gripper, what the Rerun listener plots; tests/native/test_sample_series.py).
//! `Tracker.states` builds fresh `analyzer.session.tracker.DeviceState` objects equal to the Python
//! tracker's.
//!
//! A child module of bindings/mod.rs.

use super::python_arrow::{column_specs, parts_to_py, state_parts};
use super::python_live::RecordBatch;
use super::Unsupported;
use crate::decoders::flags::{OUT_OF_RANGE, UNANSWERED};
use crate::decoders::model::{
    Fields, Record, Str, Value, CUT_OFF, EG2_CAN, EG2_SERIAL, FOREIGN_CAN, FRAME, GARBAGE,
    MODBUS_RTU, REQUEST, RESPONSE, TRUNCATED,
};
use crate::hash::FastMap;
use crate::parquet::states::StateColumns;
use crate::session::tracker::{
    push_sample_json, DeviceState, FieldReading, Sample, Slot, Tracker, Values, SLOTS, VALUE_KEYS,
};
use pyo3::exceptions::{PyAttributeError, PyIndexError, PyTypeError, PyValueError};
use pyo3::intern;
use pyo3::prelude::*;
use pyo3::sync::GILOnceCell;
use pyo3::types::{
    PyBool, PyByteArray, PyBytes, PyDict, PyFloat, PyFrozenSet, PyInt, PyList, PyMemoryView, PySet,
    PySlice, PyString, PyTuple, PyType,
};
use std::borrow::Cow;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::{Arc, Mutex, MutexGuard, OnceLock, PoisonError};

static STATE_SAMPLE: GILOnceCell<Py<PyType>> = GILOnceCell::new();
static DEVICE_STATE: GILOnceCell<Py<PyType>> = GILOnceCell::new();
static KEYS: GILOnceCell<Vec<Py<PyString>>> = GILOnceCell::new();
static TEMPLATE: GILOnceCell<Py<PyDict>> = GILOnceCell::new();

/// VALUE_KEYS as interned Python strings (their hashes are kept: dict inserts are cheap).
fn value_keys(py: Python<'_>) -> &'static [Py<PyString>] {
    KEYS.get_or_init(py, || {
        VALUE_KEYS
            .iter()
            .map(|k| PyString::intern(py, k).unbind())
            .collect()
    })
}

fn value_to_py<'py>(py: Python<'py>, v: &Value) -> PyResult<Bound<'py, PyAny>> {
    Ok(match v {
        Value::Null => py.None().into_bound(py),
        Value::Bool(b) => PyBool::new(py, *b).to_owned().into_any(),
        Value::Int(i) => i.into_pyobject(py)?.into_any(),
        Value::Float(f) => PyFloat::new(py, *f).into_any(),
        Value::Str(s) => PyString::new(py, s).into_any(),
        Value::List(items) => {
            let items = items
                .iter()
                .map(|x| value_to_py(py, x))
                .collect::<PyResult<Vec<_>>>()?;
            PyList::new(py, items)?.into_any()
        }
        Value::Map(entries) => {
            let d = PyDict::new(py);
            for (k, v) in entries {
                d.set_item(PyString::new(py, k), value_to_py(py, v)?)?;
            }
            d.into_any()
        }
    })
}

fn slot_to_py<'py>(py: Python<'py>, slot: &Slot) -> PyResult<Bound<'py, PyAny>> {
    Ok(match slot {
        Slot::Null => py.None().into_bound(py),
        Slot::Int(i) => i.into_pyobject(py)?.into_any(),
        Slot::Float(f) => PyFloat::new(py, *f).into_any(),
        Slot::Bool(b) => PyBool::new(py, *b).to_owned().into_any(),
        Slot::Text(s) => PyString::new(py, s).into_any(),
        Slot::Other(v) => value_to_py(py, v)?,
    })
}

/// A state's `values` dict: every VALUE_KEYS key, in order.
fn values_dict<'py>(py: Python<'py>, values: &Values) -> PyResult<Bound<'py, PyDict>> {
    let keys = value_keys(py);
    // a copy of a dict that has every key already (None) is made at its final size, and the
    // values below replace its entries: no resizing as 17 keys are added
    let template = TEMPLATE.get_or_try_init(py, || -> PyResult<_> {
        let d = PyDict::new(py);
        for key in keys {
            d.set_item(key.bind(py), py.None())?;
        }
        Ok(d.unbind())
    })?;
    let d = template.bind(py).copy()?;
    for (key, slot) in keys.iter().zip(&values.slots) {
        d.set_item(key.bind(py), slot_to_py(py, slot)?)?;
    }
    let counters = [values.frames, values.errors, values.unanswered];
    for (key, n) in keys[SLOTS..].iter().zip(counters) {
        d.set_item(key.bind(py), n)?;
    }
    Ok(d)
}

/// `StateSample(t, bus, device, protocol, seq, changed, values)`; `changed` holds the same
/// value objects as `values`, as the Python's does.
fn sample_to_py(py: Python<'_>, s: &Sample) -> PyResult<Py<PyAny>> {
    let keys = value_keys(py);
    let values = values_dict(py, &s.values)?;
    let changed = PyDict::new(py);
    for field in s.changed.iter() {
        let key = keys[field].bind(py);
        let value = values
            .get_item(key)?
            .unwrap_or_else(|| py.None().into_bound(py));
        changed.set_item(key, value)?;
    }
    let cls = STATE_SAMPLE.import(py, "analyzer.model", "StateSample")?;
    let args = (
        s.t,
        &*s.bus,
        s.device,
        PyString::intern(py, s.protocol),
        s.seq,
        changed,
        values,
    );
    Ok(cls.call1(args)?.unbind())
}

/// Python's truth of a value (the Python tracker's `samples` is any object, used as a bool).
struct Truthy(bool);

impl<'py> FromPyObject<'py> for Truthy {
    fn extract_bound(ob: &Bound<'py, PyAny>) -> PyResult<Self> {
        Ok(Truthy(ob.is_truthy()?))
    }
}

/// `Tracker(samples=True)`: analyzer.tracker.Tracker for the records of a `RecordBatch`.
///
/// Frozen, its state behind a mutex that is never held while Python code runs: a thread that
/// reads `states` (the TUI) while the session's thread folds a batch can neither see a
/// half-folded batch nor make the other's call fail with PyO3's "already borrowed" (as a
/// `&mut self` method could, were the GIL to switch threads while Python builds the states).
#[pyclass(name = "Tracker", module = "analyzer._native", frozen)]
pub struct PyTracker {
    inner: Mutex<Tracker>,
}

impl PyTracker {
    fn tracker(&self) -> MutexGuard<'_, Tracker> {
        // nothing in a fold panics; were one to, the states stay as usable as the Python
        // tracker's after an exception
        self.inner.lock().unwrap_or_else(PoisonError::into_inner)
    }

    /// `read` the cycle fields' readings of the last `update_many` (none unless `readings`),
    /// with the states they index.
    pub(super) fn with_readings<R>(
        &self,
        read: impl FnOnce(&[FieldReading], &[DeviceState]) -> R,
    ) -> R {
        let tracker = self.tracker();
        read(
            tracker.readings.as_deref().unwrap_or_default(),
            tracker.states(),
        )
    }
}

#[pymethods]
impl PyTracker {
    #[new]
    #[pyo3(signature = (samples = Truthy(true)))]
    fn new(samples: Truthy) -> Self {
        PyTracker {
            inner: Mutex::new(Tracker::new(samples.0)),
        }
    }

    /// False: fold only (no sample is made; the states are still kept).
    #[getter]
    fn samples(&self) -> bool {
        self.tracker().samples
    }

    #[setter]
    fn set_samples(&self, samples: Truthy) {
        self.tracker().samples = samples.0;
    }

    /// Whether each `update_many` keeps what its records set of the fields grip cycles read,
    /// for a `CycleSegmenter` fed straight from the tracker (`feed_from`): no sample needed.
    #[getter]
    fn readings(&self) -> bool {
        self.tracker().readings.is_some()
    }

    #[setter]
    fn set_readings(&self, readings: Truthy) {
        let mut tracker = self.tracker();
        if readings.0 != tracker.readings.is_some() {
            tracker.readings = readings.0.then(Vec::new);
        }
    }

    /// Whether a sample holds the whole state (else the fields it changed and the counters).
    #[getter]
    fn snapshots(&self) -> bool {
        self.tracker().snapshots
    }

    #[setter]
    fn set_snapshots(&self, snapshots: Truthy) {
        self.tracker().snapshots = snapshots.0;
    }

    /// Fold each record of the batch in order (`Tracker.update`); the samples they made.
    ///
    /// The GIL is kept: a fold costs a fraction of a microsecond per record, and the batch is
    /// borrowed meanwhile (with the GIL released, another thread's `+=` on it would fail).
    fn update_many(&self, records: PyRef<'_, RecordBatch>) -> SampleBatch {
        let mut samples = Vec::new();
        self.tracker().update_many(&records.records, &mut samples);
        SampleBatch::from(samples)
    }

    /// Every gripper heard, by (bus, device), in the order first heard: fresh
    /// `analyzer.session.tracker.DeviceState` objects.
    #[getter]
    fn states<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let states = self.tracker().states().to_vec(); // unlocked before Python runs
        let cls = DEVICE_STATE.import(py, "analyzer.session.tracker", "DeviceState")?;
        let out = PyDict::new(py);
        for st in &states {
            let bus = PyString::new(py, &st.bus);
            let protocol = PyString::intern(py, st.protocol);
            let obj = cls.call1((&bus, st.device, protocol))?;
            obj.setattr(intern!(py, "t"), st.t)?;
            obj.setattr(intern!(py, "values"), values_dict(py, &st.values)?)?;
            out.set_item((bus, st.device), obj)?;
        }
        Ok(out)
    }

    /// For the differential tests: fold Python `decoders.model.Record`s (the Python decoders'
    /// output, any protocol), converted to the core's records field by field. Only the flag
    /// the tracker reads (`unanswered`) is carried over; `raw` is not.
    fn _update_records(&self, records: Vec<Bound<'_, PyAny>>) -> PyResult<SampleBatch> {
        let mut buses: Vec<Arc<str>> = Vec::new();
        let records = records
            .iter()
            .map(|r| record_from_py(r, &mut buses))
            .collect::<PyResult<Vec<_>>>()?;
        let mut samples = Vec::new();
        self.tracker().update_many(&records, &mut samples);
        Ok(SampleBatch::from(samples))
    }
}

/// A lazy sequence of `analyzer.model.StateSample` (see the module's text).
///
/// Frozen: the samples never change, and each object is built outside any lock and then kept
/// in its slot (the first one kept wins, so every reader gets the same object): threads may
/// read one batch together (the recorder's `messages()` while the TUI iterates).
#[pyclass(name = "SampleBatch", module = "analyzer._native", sequence, frozen)]
pub struct SampleBatch {
    samples: Vec<Sample>,
    /// the objects built so far, by index (allocated when the first is asked for)
    cache: OnceLock<Box<[OnceLock<Py<PyAny>>]>>,
}

impl From<Vec<Sample>> for SampleBatch {
    fn from(samples: Vec<Sample>) -> Self {
        SampleBatch {
            samples,
            cache: OnceLock::new(),
        }
    }
}

impl SampleBatch {
    /// The sample at `i` (< len) as a Python object, built once.
    fn object(&self, py: Python<'_>, i: usize) -> PyResult<Py<PyAny>> {
        let slots = self
            .cache
            .get_or_init(|| (0..self.samples.len()).map(|_| OnceLock::new()).collect());
        if let Some(obj) = slots[i].get() {
            return Ok(obj.clone_ref(py));
        }
        // not `get_or_init`: building runs Python code, during which another thread may take
        // the GIL and ask for the same sample (it would wait for this one, holding the GIL)
        let obj = sample_to_py(py, &self.samples[i])?;
        let _ = slots[i].set(obj); // another thread's, kept meanwhile, stays
        Ok(slots[i].get().expect("set above").clone_ref(py))
    }
}

#[pymethods]
impl SampleBatch {
    /// An empty batch.
    #[new]
    fn new() -> Self {
        SampleBatch::from(Vec::new())
    }

    fn __len__(&self) -> usize {
        self.samples.len()
    }

    /// `batch[i]` (negative counts from the end) or `batch[a:b:c]` (a list), as a list does.
    fn __getitem__(&self, py: Python<'_>, index: &Bound<'_, PyAny>) -> PyResult<Py<PyAny>> {
        let n = self.samples.len();
        if let Ok(slice) = index.downcast::<PySlice>() {
            let ind = slice.indices(n as isize)?;
            let mut out = Vec::with_capacity(ind.slicelength);
            let mut i = ind.start;
            for _ in 0..ind.slicelength {
                out.push(self.object(py, i as usize)?);
                i += ind.step;
            }
            return Ok(PyList::new(py, out)?.into_any().unbind());
        }
        let i: isize = index.extract().map_err(|_| {
            let kind = index
                .get_type()
                .name()
                .map_or_else(|_| "?".into(), |n| n.to_string());
            PyTypeError::new_err(format!(
                "SampleBatch indices must be integers or slices, not {kind}"
            ))
        })?;
        let at = if i < 0 { i + n as isize } else { i };
        if !(0..n as isize).contains(&at) {
            return Err(PyIndexError::new_err("SampleBatch index out of range"));
        }
        self.object(py, at as usize)
    }

    fn __iter__(slf: Bound<'_, Self>) -> SampleIter {
        SampleIter {
            batch: slf.unbind(),
            next: AtomicUsize::new(0),
        }
    }

    fn __repr__(&self) -> String {
        format!("<SampleBatch of {} samples>", self.samples.len())
    }

    /// Per sample: `orjson.dumps(sample.to_dict(), default=json_default)`, byte-identical.
    /// TypeError where the Python's `derived` raises it (a non-integer opening, state or fault,
    /// which no decoder makes).
    fn messages<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyList>> {
        let mut buf = String::with_capacity(1024);
        let mut out = Vec::with_capacity(self.samples.len());
        for s in &self.samples {
            buf.clear();
            push_sample_json(&mut buf, s).map_err(|e| PyTypeError::new_err(e.to_string()))?;
            out.push(PyBytes::new(py, buf.as_bytes()));
        }
        PyList::new(py, out)
    }

    /// The samples as Arrow columns (parquet/states.rs; `columns` described as `ArrowRun`'s
    /// `states`): `(rows, columns)`, as `ArrowRun` hands out the states of a batch. ValueError
    /// for a value its column does not take.
    fn arrow<'py>(
        &self,
        py: Python<'py>,
        columns: Vec<(String, String, usize)>,
    ) -> PyResult<(usize, Bound<'py, PyList>)> {
        let specs = column_specs(&columns)?;
        let mut built = StateColumns::new(&specs).map_err(Unsupported::new_err)?;
        for s in &self.samples {
            built.push(s).map_err(PyValueError::new_err)?;
        }
        let (rows, parts) = state_parts(&mut built);
        Ok((rows, parts_to_py(py, parts)?))
    }

    /// `sample.t` per sample.
    fn times<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyList>> {
        PyList::new(py, self.samples.iter().map(|s| s.t))
    }

    /// `(sample.bus, sample.device)` per sample.
    fn keys<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyList>> {
        let mut buses = BusNames::default();
        let mut out = Vec::with_capacity(self.samples.len());
        for s in &self.samples {
            let bus = buses.get(py, &s.bus);
            let device = s.device.into_pyobject(py)?.into_any();
            out.push(PyTuple::new(py, [bus.into_any(), device])?);
        }
        PyList::new(py, out)
    }

    /// `[getattr(sample, name) for sample in batch]`, read from the samples (no StateSample
    /// is made): the values the materialized samples would have, `changed` and `values` as new
    /// dicts with their keys in the same order. AttributeError for a name that is not one of
    /// StateSample's attributes.
    fn column<'py>(&self, py: Python<'py>, name: &str) -> PyResult<Bound<'py, PyList>> {
        let samples = &self.samples;
        match name {
            "t" => PyList::new(py, samples.iter().map(|s| s.t)),
            "bus" => {
                let mut buses = BusNames::default();
                PyList::new(py, samples.iter().map(|s| buses.get(py, &s.bus)))
            }
            "device" => PyList::new(py, samples.iter().map(|s| s.device)),
            "protocol" => {
                // the interned names materialization uses, looked up once per protocol
                let mut names: Vec<(&'static str, Bound<'py, PyString>)> = Vec::new();
                PyList::new(
                    py,
                    samples.iter().map(|s| {
                        match names.iter().find(|(p, _)| std::ptr::eq(*p, s.protocol)) {
                            Some((_, obj)) => obj.clone(),
                            None => {
                                let obj = PyString::intern(py, s.protocol);
                                names.push((s.protocol, obj.clone()));
                                obj
                            }
                        }
                    }),
                )
            }
            "seq" => PyList::new(py, samples.iter().map(|s| s.seq)),
            "changed" => {
                let keys = value_keys(py);
                let dicts = samples
                    .iter()
                    .map(|s| {
                        let d = PyDict::new(py);
                        for field in s.changed.iter() {
                            d.set_item(
                                keys[field].bind(py),
                                slot_to_py(py, &s.values.slots[field])?,
                            )?;
                        }
                        Ok(d)
                    })
                    .collect::<PyResult<Vec<_>>>()?;
                PyList::new(py, dicts)
            }
            "values" => {
                let mut maker = ValuesDicts::default();
                let dicts = samples
                    .iter()
                    .map(|s| maker.make(py, s))
                    .collect::<PyResult<Vec<_>>>()?;
                PyList::new(py, dicts)
            }
            _ => Err(PyAttributeError::new_err(format!(
                "'StateSample' object has no attribute '{name}'"
            ))),
        }
    }

    /// `analyzer.batches.SampleSequence(batch).series(fields)`, read from the samples (no
    /// StateSample is made): the samples that changed any of `fields`, grouped by (bus,
    /// device, names), `names` the fields among `fields` the sample changed, in `fields` order
    /// (a field given twice is named and filled twice, as there); per group
    /// `(bus, device, names, times, seqs, columns)` in the order groups first appear, one column
    /// of values per name, each value as the sample's `changed` holds it.
    fn series<'py>(
        &self,
        py: Python<'py>,
        fields: &Bound<'py, PyTuple>,
    ) -> PyResult<Bound<'py, PyList>> {
        let samples = &self.samples;
        if samples.is_empty() {
            // the Python looks no field up before a sample (an unhashable one raises only then)
            return Ok(PyList::empty(py));
        }
        // the fields a sample can have changed, with their slots, in `fields` order; looked up
        // in a dict of the slot names, as the Python's `field in changed` does (a str subclass,
        // an unhashable field's TypeError); the others never match
        let slot_of = slot_names(py)?.bind(py);
        let mut want: Vec<(usize, Bound<'py, PyAny>)> = Vec::with_capacity(fields.len());
        let mut wanted: u16 = 0;
        for field in fields.iter() {
            if let Some(slot) = slot_of.get_item(&field)? {
                let slot: usize = slot.extract()?;
                wanted |= 1 << slot;
                want.push((slot, field));
            }
        }
        if wanted == 0 {
            return Ok(PyList::empty(py));
        }

        // a group's names follow from the wanted fields its samples changed (a bit set over
        // the slots), so (bus, device, those bits) is the Python's (bus, device, names)
        let mut buses = BusIds::default();
        let mut group_of: FastMap<(u32, i64, u16), usize> = FastMap::default();
        let mut groups: Vec<Group> = Vec::new();
        for (i, s) in samples.iter().enumerate() {
            let changed = s.changed.iter().fold(0u16, |m, f| m | 1 << f) & wanted;
            if changed == 0 {
                continue;
            }
            let key = (buses.id(&s.bus), s.device, changed);
            let g = *group_of.entry(key).or_insert_with(|| {
                groups.push(Group {
                    first: i,
                    changed,
                    rows: Vec::new(),
                });
                groups.len() - 1
            });
            groups[g].rows.push(i);
        }

        let mut names = BusNames::default();
        let out = groups
            .iter()
            .map(|g| {
                let first = &samples[g.first];
                let named: Vec<_> = want
                    .iter()
                    .filter(|(slot, _)| g.changed & 1 << slot != 0)
                    .collect();
                let rows = || g.rows.iter().map(|&i| &samples[i]);
                let columns = named
                    .iter()
                    .map(|(slot, _)| column(py, rows().map(|s| &s.values.slots[*slot])))
                    .collect::<PyResult<Vec<_>>>()?;
                PyTuple::new(
                    py,
                    [
                        names.get(py, &first.bus).into_any(),
                        first.device.into_pyobject(py)?.into_any(),
                        PyTuple::new(py, named.iter().map(|(_, field)| field))?.into_any(),
                        PyList::new(py, rows().map(|s| s.t))?.into_any(),
                        PyList::new(py, rows().map(|s| s.seq))?.into_any(),
                        PyList::new(py, columns)?.into_any(),
                    ],
                )
            })
            .collect::<PyResult<Vec<_>>>()?;
        PyList::new(py, out)
    }
}

/// The slot fields' names (VALUE_KEYS but the counters, which no sample changes) -> slot.
fn slot_names(py: Python<'_>) -> PyResult<&Py<PyDict>> {
    static SLOT_NAMES: GILOnceCell<Py<PyDict>> = GILOnceCell::new();
    SLOT_NAMES.get_or_try_init(py, || {
        let d = PyDict::new(py);
        for (slot, key) in value_keys(py)[..SLOTS].iter().enumerate() {
            d.set_item(key.bind(py), slot)?;
        }
        Ok(d.unbind())
    })
}

/// One group of `SampleBatch.series`: the index of its first sample, the wanted fields its
/// samples changed (bits by slot) and the indexes of its samples.
struct Group {
    first: usize,
    changed: u16,
    rows: Vec<usize>,
}

/// A small number per bus name (equal names are one bus, whichever `Arc` holds them).
#[derive(Default)]
struct BusIds<'a> {
    seen: Vec<&'a Arc<str>>,
    last: Option<(&'a Arc<str>, u32)>,
}

impl<'a> BusIds<'a> {
    #[inline]
    fn id(&mut self, bus: &'a Arc<str>) -> u32 {
        if let Some((b, id)) = self.last {
            if Arc::ptr_eq(b, bus) {
                return id;
            }
        }
        let id = match self
            .seen
            .iter()
            .position(|b| Arc::ptr_eq(b, bus) || **b == *bus)
        {
            Some(id) => id,
            None => {
                self.seen.push(bus);
                self.seen.len() - 1
            }
        } as u32;
        self.last = Some((bus, id));
        id
    }
}

/// A column of values as Python objects. Readings repeat (a state, a fault, a temperature):
/// a value that is the same immutable object as the one before it (`same_object`) takes that
/// object again instead of a new one.
fn column<'a, 'py>(
    py: Python<'py>,
    values: impl ExactSizeIterator<Item = &'a Slot>,
) -> PyResult<Bound<'py, PyList>> {
    let mut last: Option<(&Slot, Bound<'py, PyAny>)> = None;
    PyList::new(
        py,
        values.map(|v| {
            if let Some((prev, obj)) = &last {
                if same_object(v, prev) {
                    return Made(Ok(obj.clone()));
                }
            }
            let made = slot_to_py(py, v);
            if let Ok(obj) = &made {
                last = Some((v, obj.clone()));
            }
            Made(made)
        }),
    )
}

/// A value made for a list (`PyList::new` takes the error of any).
struct Made<'py>(PyResult<Bound<'py, PyAny>>);

impl<'py> IntoPyObject<'py> for Made<'py> {
    type Target = PyAny;
    type Output = Bound<'py, PyAny>;
    type Error = PyErr;

    fn into_pyobject(self, _py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        self.0
    }
}

/// One str object per bus name (a batch has a few buses; the samples of one share an `Arc`).
#[derive(Default)]
struct BusNames<'py> {
    seen: Vec<(Arc<str>, Bound<'py, PyString>)>,
}

impl<'py> BusNames<'py> {
    fn get(&mut self, py: Python<'py>, bus: &Arc<str>) -> Bound<'py, PyString> {
        if let Some((_, obj)) = self.seen.iter().find(|(b, _)| Arc::ptr_eq(b, bus)) {
            return obj.clone();
        }
        let obj = PyString::new(py, bus);
        self.seen.push((bus.clone(), obj.clone()));
        obj
    }
}

/// The `values` dicts of a column. A gripper's values change by a few fields from one sample
/// to its next, so a sample's dict is a copy of the one made for the gripper's last sample
/// (every key already in place, in order) with only the values that differ replaced: the
/// unchanged entries keep that dict's objects, which are immutable (None, bool, int, float,
/// str), so sharing them shows nowhere. Other values (lists, dicts) are made anew every time.
#[derive(Default)]
struct ValuesDicts<'a, 'py> {
    last: FastMap<(usize, i64), (&'a Values, Bound<'py, PyDict>)>,
}

impl<'a, 'py> ValuesDicts<'a, 'py> {
    fn make(&mut self, py: Python<'py>, s: &'a Sample) -> PyResult<Bound<'py, PyDict>> {
        let key = (Arc::as_ptr(&s.bus) as *const u8 as usize, s.device);
        let Some((prev, prev_dict)) = self.last.get(&key) else {
            let d = values_dict(py, &s.values)?;
            self.last.insert(key, (&s.values, d.clone()));
            return Ok(d);
        };
        let keys = value_keys(py);
        let d = prev_dict.copy()?;
        for (i, (slot, old)) in s.values.slots.iter().zip(&prev.slots).enumerate() {
            if !same_object(slot, old) {
                d.set_item(keys[i].bind(py), slot_to_py(py, slot)?)?;
            }
        }
        let counters = [
            (s.values.frames, prev.frames),
            (s.values.errors, prev.errors),
            (s.values.unanswered, prev.unanswered),
        ];
        for (key, (n, old)) in keys[SLOTS..].iter().zip(counters) {
            if n != old {
                d.set_item(key.bind(py), n)?;
            }
        }
        self.last.insert(key, (&s.values, d.clone()));
        Ok(d)
    }
}

/// Whether the Python object made for `old` may stand for `new` too: an equal immutable value
/// of the same type (floats by their bits: 0.0 and -0.0 differ).
fn same_object(new: &Slot, old: &Slot) -> bool {
    match (new, old) {
        (Slot::Null, Slot::Null) => true,
        (Slot::Int(a), Slot::Int(b)) => a == b,
        (Slot::Float(a), Slot::Float(b)) => a.to_bits() == b.to_bits(),
        (Slot::Bool(a), Slot::Bool(b)) => a == b,
        (Slot::Text(a), Slot::Text(b)) => a == b,
        _ => false, // Other: a list or a dict, which a sample must not share
    }
}

/// Iterates a `SampleBatch` (building each sample on the way, as indexing does).
#[pyclass(module = "analyzer._native", frozen)]
pub struct SampleIter {
    batch: Py<SampleBatch>,
    next: AtomicUsize,
}

#[pymethods]
impl SampleIter {
    fn __iter__(slf: PyRef<'_, Self>) -> PyRef<'_, Self> {
        slf
    }

    fn __next__(&self, py: Python<'_>) -> PyResult<Option<Py<PyAny>>> {
        let batch = self.batch.get();
        let n = batch.samples.len();
        let i = self.next.fetch_add(1, Ordering::Relaxed);
        if i >= n {
            self.next.store(n, Ordering::Relaxed); // stays exhausted, never wraps
            return Ok(None);
        }
        batch.object(py, i).map(Some)
    }
}

// -- Python records into the core's, for `_update_records` ---------------------------------

/// `name` as one of the core's static names (a protocol, kind or direction).
fn static_name(name: &str, known: &[&'static str], what: &str) -> PyResult<&'static str> {
    known
        .iter()
        .find(|k| **k == name)
        .copied()
        .ok_or_else(|| PyValueError::new_err(format!("unknown {what} {name:?}")))
}

/// A field value as orjson would write it with `json_default`: tuples and sets as lists,
/// bytes as spaced upper-case hex, anything else unknown as its `str`.
fn value_from_py(obj: &Bound<'_, PyAny>) -> PyResult<Value> {
    Ok(if obj.is_none() {
        Value::Null
    } else if let Ok(b) = obj.downcast::<PyBool>() {
        Value::Bool(b.is_true())
    } else if obj.is_instance_of::<PyInt>() {
        Value::Int(obj.extract()?)
    } else if let Ok(f) = obj.downcast::<PyFloat>() {
        Value::Float(f.value())
    } else if let Ok(s) = obj.downcast::<PyString>() {
        Value::Str(Cow::Owned(s.to_str()?.to_owned()))
    } else if let Ok(d) = obj.downcast::<PyDict>() {
        let mut entries = Vec::with_capacity(d.len());
        for (k, v) in d.iter() {
            let k: String = k.extract()?;
            entries.push((Str::Owned(k), value_from_py(&v)?));
        }
        Value::Map(entries)
    } else if obj.is_instance_of::<PyList>()
        || obj.is_instance_of::<PyTuple>()
        || obj.is_instance_of::<PySet>()
        || obj.is_instance_of::<PyFrozenSet>()
    {
        let items = obj
            .try_iter()?
            .map(|x| value_from_py(&x?))
            .collect::<PyResult<Vec<_>>>()?;
        Value::List(items)
    } else if obj.is_instance_of::<PyBytes>()
        || obj.is_instance_of::<PyByteArray>()
        || obj.is_instance_of::<PyMemoryView>()
    {
        let bytes = PyBytes::new(obj.py(), &[]).get_type().call1((obj,))?;
        let hex = bytes.call_method1(intern!(obj.py(), "hex"), (" ",))?;
        let text: String = hex.call_method0(intern!(obj.py(), "upper"))?.extract()?;
        Value::Str(Cow::Owned(text))
    } else {
        Value::Str(Cow::Owned(obj.str()?.to_str()?.to_owned()))
    })
}

fn record_from_py(rec: &Bound<'_, PyAny>, buses: &mut Vec<Arc<str>>) -> PyResult<Record> {
    let py = rec.py();
    let bus_name: String = rec.getattr(intern!(py, "bus"))?.extract()?;
    let bus = match buses.iter().find(|b| ***b == *bus_name) {
        Some(b) => b.clone(),
        None => {
            let b: Arc<str> = Arc::from(bus_name);
            buses.push(b.clone());
            b
        }
    };
    let protocol: String = rec.getattr(intern!(py, "protocol"))?.extract()?;
    let protocol = static_name(
        &protocol,
        &[EG2_SERIAL, MODBUS_RTU, EG2_CAN, FOREIGN_CAN],
        "protocol",
    )?;
    let kind: String = rec.getattr(intern!(py, "kind"))?.extract()?;
    let kind = static_name(&kind, &[FRAME, GARBAGE, TRUNCATED, CUT_OFF], "kind")?;
    let mut r = Record::new(
        rec.getattr(intern!(py, "t"))?.extract()?,
        bus,
        protocol,
        kind,
        Vec::new(),
    );
    r.length = rec.getattr(intern!(py, "length"))?.extract()?;
    let direction: Option<String> = rec.getattr(intern!(py, "direction"))?.extract()?;
    r.direction = match direction {
        Some(d) => Some(static_name(&d, &[REQUEST, RESPONSE], "direction")?),
        None => None,
    };
    r.device = rec.getattr(intern!(py, "device"))?.extract()?;
    r.code = rec.getattr(intern!(py, "code"))?.extract()?;
    let name: Option<String> = rec.getattr(intern!(py, "name"))?.extract()?;
    r.name = name.map(Cow::Owned);
    let fields = rec.getattr(intern!(py, "fields"))?;
    let fields = fields.downcast::<PyDict>()?;
    let mut items: Fields = Vec::with_capacity(fields.len());
    for (k, v) in fields.iter() {
        items.push((Str::Owned(k.extract()?), value_from_py(&v)?));
    }
    r.fields = items.into();
    r.errors = rec.getattr(intern!(py, "errors"))?.extract()?;
    r.warnings = rec.getattr(intern!(py, "warnings"))?.extract()?;
    let summary: String = rec.getattr(intern!(py, "summary"))?.extract()?;
    r.summary = Arc::from(summary);
    r.seq = rec.getattr(intern!(py, "seq"))?.extract()?;
    r.pair = rec.getattr(intern!(py, "pair"))?.extract()?;
    r.latency_ms = rec.getattr(intern!(py, "latency_ms"))?.extract()?;
    // the flags the tracker reads
    let flags: Vec<String> = rec.getattr(intern!(py, "flags"))?.extract()?;
    for code in [UNANSWERED, OUT_OF_RANGE] {
        if flags.iter().any(|f| f == code) {
            r.flags.push(code);
        }
    }
    Ok(r)
}

pub(super) fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<PyTracker>()?;
    m.add_class::<SampleBatch>()
}
