//! Grip cycles for Python: `CycleSegmenter`, analyzer/cycles/segmenter.py's `Segmenter` for
//! the cycles listener on the native engine, fed the commands it finds in a batch's records
//! (native/src/cycles/commands.rs) and the readings the session's tracker kept of them, with no
//! Python object per record or sample; each ended cycle goes back as a `Cycle`, as rules.py
//! `build_cycle` makes it (or, made with `counts=True`, counted as model.py `counts_of` counts
//! them: all `stats` needs).
//! tests/native/test_cycles_native.py requires the same cycles as the Python.

use super::python_live::RecordBatch;
use super::python_tracker::PyTracker;
use crate::cycles::commands::{event_of, Said};
use crate::cycles::rules::Decided;
use crate::cycles::segmenter::{Reading, Segmenter};
use crate::decoders::registers::{fault_text, opening_mm};
use crate::pyfloat::py_round;
use crate::session::tracker::{DeviceState, FieldReading};
use pyo3::exceptions::PyTypeError;
use pyo3::prelude::*;
use pyo3::sync::GILOnceCell;
use pyo3::types::{PyList, PyString, PyTuple, PyType};
use pyo3::IntoPyObjectExt;
use std::sync::Arc;

type Payload = Arc<Said>;

/// `CycleSegmenter(counts=False)`: the Python `Segmenter` (`feed`, `take`, `finish`) fed straight from the
/// native session: its commands and answers found in a `RecordBatch` (commands.py), its
/// readings from the session's `Tracker` (no Python object per record or sample).
#[pyclass(name = "CycleSegmenter", module = "analyzer._native")]
#[derive(Default)]
pub struct PyCycleSegmenter {
    inner: Segmenter<Payload>,
    /// the segmenter's number of each of the tracker's states (by index), once it has one
    grippers: Vec<Option<usize>>,
    /// the ended cycles counted per gripper (model.py `counts_of`), no `Cycle` made
    counts: bool,
}

#[pymethods]
impl PyCycleSegmenter {
    #[new]
    #[pyo3(signature = (counts = false))]
    fn new(counts: bool) -> Self {
        Self {
            counts,
            ..Self::default()
        }
    }

    /// One batch: the commands and answers among `records`, and the readings the tracker
    /// (its `readings` on) kept of them: the session's tracker folded these records just
    /// before.
    fn feed_from(
        &mut self,
        tracker: PyRef<'_, PyTracker>,
        records: PyRef<'_, RecordBatch>,
    ) -> PyResult<()> {
        let readings = tracker.with_readings(|found, states| self.readings(found, states))?;
        let events = records.records.iter().filter_map(event_of).collect();
        self.inner.feed(readings, events);
        Ok(())
    }

    /// The cycles that ended since the last call, in the order they ended.
    fn take<'py>(&mut self, py: Python<'py>) -> PyResult<Bound<'py, PyList>> {
        let done = self.inner.take();
        self.hand_back(py, done)
    }

    /// The end of the capture: every cycle in progress ends (in the order they began).
    fn finish<'py>(&mut self, py: Python<'py>) -> PyResult<Bound<'py, PyList>> {
        let done = self.inner.finish();
        self.hand_back(py, done)
    }
}

impl PyCycleSegmenter {
    /// Ended cycles for Python: `Cycle`s, or their counts.
    fn hand_back<'py>(
        &self,
        py: Python<'py>,
        done: Vec<Decided<Payload>>,
    ) -> PyResult<Bound<'py, PyList>> {
        if self.counts {
            counts_of(py, done)
        } else {
            cycles(py, done)
        }
    }

    /// The tracker's readings as the segmenter's, their grippers numbered in the order they
    /// first appear (as the Python's `holder` calls make them).
    fn readings(
        &mut self,
        found: &[FieldReading],
        states: &[DeviceState],
    ) -> PyResult<Vec<Reading>> {
        let mut out = Vec::with_capacity(found.len());
        for r in found {
            let gripper = match self.grippers.get(r.state) {
                Some(&Some(g)) => g,
                _ => {
                    let st = &states[r.state];
                    let g = self.inner.gripper(&(st.bus.clone(), st.device));
                    if self.grippers.len() <= r.state {
                        self.grippers.resize(r.state + 1, None);
                    }
                    self.grippers[r.state] = Some(g);
                    g
                }
            };
            let values = r
                .values
                .clone()
                .map_err(|_| PyTypeError::new_err("a gripper reading that is not an int"))?;
            out.push(Reading {
                gripper,
                seq: r.seq,
                t: r.t,
                values,
                kind: r.kind,
            });
        }
        Ok(out)
    }
}

static CYCLE: GILOnceCell<Py<PyType>> = GILOnceCell::new();

/// The milliseconds from `start` to `t`, as model.py rounds them.
fn ms_from(start: Option<f64>, t: Option<f64>) -> Option<f64> {
    Some(py_round((t? - start?) * 1000.0, 3))
}

/// model.py `counts_of`: per gripper, in the order they first appear, `(bus, device, outcomes,
/// durations, settles)`, the times those known.
fn counts_of<'py>(py: Python<'py>, done: Vec<Decided<Payload>>) -> PyResult<Bound<'py, PyList>> {
    type Counts<'a> = (&'a str, i64, Vec<&'static str>, Vec<f64>, Vec<f64>);
    let mut found: Vec<Counts<'_>> = Vec::new();
    for c in &done {
        let bus: &str = &c.command.payload.bus;
        let at = match found.iter().position(|f| f.0 == bus && f.1 == c.device) {
            Some(at) => at,
            None => {
                found.push((bus, c.device, Vec::new(), Vec::new(), Vec::new()));
                found.len() - 1
            }
        };
        let counts = &mut found[at];
        let start = c.command.t;
        counts.2.push(c.outcome);
        counts.3.extend(ms_from(start, c.end.t));
        counts.4.extend(ms_from(start, c.settle_t));
    }
    let mut out = Vec::with_capacity(found.len());
    for (bus, device, outcomes, durations, settles) in found {
        let outcomes: Vec<_> = outcomes
            .into_iter()
            .map(|o| PyString::intern(py, o))
            .collect();
        out.push((bus, device, outcomes, durations, settles).into_pyobject(py)?);
    }
    PyList::new(py, out)
}

/// Each cycle as the outputs write it, an `analyzer.cycles.model.Cycle`: rules.py
/// `build_cycle`'s (openings in mm, times from the command in ms).
fn cycles<'py>(py: Python<'py>, done: Vec<Decided<Payload>>) -> PyResult<Bound<'py, PyList>> {
    let cls = CYCLE.import(py, "analyzer.cycles.model", "Cycle")?;
    let mut out = Vec::with_capacity(done.len());
    for c in done {
        let said = &c.command.payload;
        let start = c.command.t;
        let ms = |t: Option<f64>| ms_from(start, t);
        let args = [
            PyString::new(py, &said.bus).into_any(),
            c.device.into_bound_py_any(py)?,
            start.into_bound_py_any(py)?,
            c.end.t.into_bound_py_any(py)?,
            c.command.seq.into_bound_py_any(py)?,
            c.end.seq.into_bound_py_any(py)?,
            PyString::new(py, &said.words).into_any(),
            opening_mm(c.target).into_bound_py_any(py)?,
            PyString::intern(py, c.outcome).into_any(),
            c.width.map(opening_mm).into_bound_py_any(py)?,
            c.force_peak.into_bound_py_any(py)?,
            ms(c.contact_t).into_bound_py_any(py)?,
            ms(c.settle_t).into_bound_py_any(py)?,
            c.retries.into_bound_py_any(py)?,
            fault_text(c.faults).into_bound_py_any(py)?,
            c.warnings.into_bound_py_any(py)?,
            c.unknown.into_bound_py_any(py)?,
            c.evidence.into_bound_py_any(py)?,
        ];
        out.push(cls.call1(PyTuple::new(py, args)?)?);
    }
    PyList::new(py, out)
}

pub(super) fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<PyCycleSegmenter>()?;
    Ok(())
}
