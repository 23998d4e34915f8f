//! Grip cycles for Python: `CycleSegmenter`, analyzer/cycles/segmenter.py's `Segmenter` fed a
//! native `SampleBatch` where it is (no Python object per sample), for the cycles listener
//! on the native engine. Commands and answers come as the Python objects the listener found
//! (a few a batch); each ended cycle goes back as the arguments of rules.py `build_cycle`.
//! tests/native/test_cycles_native.py requires the same cycles as the Python segmenter.

use super::python_live::RecordBatch;
use super::python_tracker::SampleBatch;
use crate::cycles::rules::{Command, Decided};
use crate::cycles::segmenter::{Event, Key, Reading, Segmenter, Values};
use crate::decoders::model::RESPONSE;
use crate::generated::cycles::FIELDS;
use crate::generated::flags::{EXCEPTION_RESPONSE, WRITE_FAILED};
use crate::session::tracker::{Sample, Slot};
use pyo3::exceptions::PyTypeError;
use pyo3::intern;
use pyo3::prelude::*;
use pyo3::types::{PyList, PyTuple};
use pyo3::IntoPyObjectExt;
use std::sync::Arc;

type Payload = Arc<Py<PyAny>>;

/// `CycleSegmenter()`: `feed(samples, commands)`, `take()`, `finish()` as the Python
/// `Segmenter`'s, `samples` a `SampleBatch` or None.
#[pyclass(name = "CycleSegmenter", module = "analyzer._native")]
#[derive(Default)]
pub struct PyCycleSegmenter {
    inner: Segmenter<Payload>,
    /// the answers `candidates` found, for the next `feed` (commands.py `answer_of`)
    answers: Vec<(Key, Event<Payload>)>,
}

#[pymethods]
impl PyCycleSegmenter {
    #[new]
    fn new() -> Self {
        Self::default()
    }

    /// One batch: its samples (None: it set no state) and the `(bus, device, event)` of its
    /// commands and answers, `event[3]` the `Command` or `Answer`.
    fn feed(
        &mut self,
        samples: Option<PyRef<'_, SampleBatch>>,
        commands: &Bound<'_, PyList>,
    ) -> PyResult<()> {
        let readings = match samples {
            Some(batch) => self.readings(batch.samples())?,
            None => Vec::new(),
        };
        let mut events = std::mem::take(&mut self.answers);
        events.reserve(commands.len());
        for item in commands.iter() {
            let (bus, device, event): (String, i64, Bound<'_, PyTuple>) = item.extract()?;
            events.push(((Arc::from(bus), device), event_of(&event.get_item(3)?)?));
        }
        self.inner.feed(readings, events);
        Ok(())
    }

    /// The indexes of the records of `records` (a `RecordBatch`) whose code is one of `codes`
    /// (`commands.CODES`) and that may carry a command, without a Python object per record;
    /// the responses among them are the answers (commands.py `answer_of`), kept for the next
    /// `feed`.
    fn candidates(&mut self, records: PyRef<'_, RecordBatch>, codes: Vec<i64>) -> Vec<usize> {
        let mut found = Vec::new();
        for (i, rec) in records.records.iter().enumerate() {
            if !rec.code.is_some_and(|c| codes.contains(&c)) {
                continue;
            }
            if rec.direction != Some(RESPONSE) {
                found.push(i);
            } else if let (Some(request), Some(device)) = (rec.pair, rec.device) {
                let answer = Event::Answer {
                    seq: rec.seq,
                    t: rec.t,
                    request,
                    refused: rec.flags.contains(&WRITE_FAILED)
                        || rec.flags.contains(&EXCEPTION_RESPONSE),
                    garbled: !rec.errors.is_empty(),
                };
                self.answers.push(((rec.bus.clone(), device), answer));
            }
        }
        found
    }

    /// Whether answers wait for the next `feed`.
    #[getter]
    fn waiting(&self) -> bool {
        !self.answers.is_empty()
    }

    /// The cycles that ended since the last call, in the order they ended.
    fn take<'py>(&mut self, py: Python<'py>) -> PyResult<Bound<'py, PyList>> {
        rows(py, self.inner.take())
    }

    /// The end of the capture: every cycle in progress ends (in the order they began).
    fn finish<'py>(&mut self, py: Python<'py>) -> PyResult<Bound<'py, PyList>> {
        rows(py, self.inner.finish())
    }
}

impl PyCycleSegmenter {
    /// The batch's readings, in the order of its samples, their grippers numbered in the
    /// order they first appear (made in that order, as the Python's `holder` calls make them).
    fn readings(&mut self, samples: &[Sample]) -> PyResult<Vec<Reading>> {
        let wanted = FIELDS.iter().fold(0u16, |m, &f| m | 1 << f);
        let mut found: Vec<Reading> = Vec::new();
        let mut last: Option<(&Arc<str>, i64, usize)> = None;
        for s in samples {
            let kind = s.changed.iter().fold(0u16, |m, f| m | 1 << f) & wanted;
            if kind == 0 {
                continue;
            }
            let gripper = match last {
                Some((bus, device, g)) if Arc::ptr_eq(bus, &s.bus) && device == s.device => g,
                _ => {
                    let key: Key = (s.bus.clone(), s.device);
                    self.inner.gripper(&key)
                }
            };
            last = Some((&s.bus, s.device, gripper));
            let mut values: Values = [None; 7];
            for (value, &field) in values.iter_mut().zip(FIELDS.iter()) {
                if kind & 1 << field != 0 {
                    *value = int_of(&s.values.slots[field])?;
                }
            }
            found.push(Reading {
                gripper,
                seq: s.seq,
                t: s.t,
                values,
                kind,
            });
        }
        Ok(found)
    }
}

/// A state value as the rules read it: an int (a bool is one) or None.
fn int_of(slot: &Slot) -> PyResult<Option<i64>> {
    match slot {
        Slot::Null => Ok(None),
        other => other
            .as_int()
            .map(Some)
            .ok_or_else(|| PyTypeError::new_err("a gripper reading that is not an int")),
    }
}

/// A `Command` or an `Answer` (analyzer/cycles/commands.py) as an event.
fn event_of(obj: &Bound<'_, PyAny>) -> PyResult<Event<Payload>> {
    let py = obj.py();
    let seq: i64 = obj.getattr(intern!(py, "seq"))?.extract()?;
    let t: Option<f64> = obj.getattr(intern!(py, "t"))?.extract()?;
    if obj.hasattr(intern!(py, "request"))? {
        return Ok(Event::Answer {
            seq,
            t,
            request: obj.getattr(intern!(py, "request"))?.extract()?,
            refused: obj.getattr(intern!(py, "refused"))?.extract()?,
            garbled: obj.getattr(intern!(py, "garbled"))?.extract()?,
        });
    }
    Ok(Event::Command(Command {
        seq,
        t,
        kind: obj.getattr(intern!(py, "kind"))?.extract()?,
        target: obj.getattr(intern!(py, "target"))?.extract()?,
        fate: obj.getattr(intern!(py, "fate"))?.extract()?,
        broadcast: obj.getattr(intern!(py, "broadcast"))?.extract()?,
        retransmission: obj.getattr(intern!(py, "retransmission"))?.extract()?,
        same: obj.getattr(intern!(py, "same"))?.extract()?,
        payload: Arc::new(obj.clone().unbind()),
    }))
}

/// Each cycle as the arguments of rules.py `build_cycle`.
fn rows<'py>(py: Python<'py>, cycles: Vec<Decided<Payload>>) -> PyResult<Bound<'py, PyList>> {
    let mut out = Vec::with_capacity(cycles.len());
    for c in cycles {
        let row = [
            c.command.payload.clone_ref(py).into_bound(py),
            c.device.into_bound_py_any(py)?,
            c.target.into_bound_py_any(py)?,
            c.outcome.into_bound_py_any(py)?,
            c.end.seq.into_bound_py_any(py)?,
            c.end.t.into_bound_py_any(py)?,
            c.width.into_bound_py_any(py)?,
            c.force_peak.into_bound_py_any(py)?,
            c.contact_t.into_bound_py_any(py)?,
            c.settle_t.into_bound_py_any(py)?,
            c.retries.into_bound_py_any(py)?,
            c.faults.into_bound_py_any(py)?,
            c.warnings.into_bound_py_any(py)?,
            c.unknown.into_bound_py_any(py)?,
            c.evidence.into_bound_py_any(py)?,
        ];
        out.push(PyTuple::new(py, row)?);
    }
    PyList::new(py, out)
}

pub(super) fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<PyCycleSegmenter>()?;
    Ok(())
}
