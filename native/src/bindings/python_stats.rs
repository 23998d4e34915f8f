//! `RecordBatch.stats_groups()`: native/src/sinks/stats.rs's groups as analyzer/stats.py
//! `stats_groups` returns them (tests/native/test_stats_groups.py requires the same).

use crate::decoders::model::Record;
use crate::sinks::stats::{stats_groups as group, LatencyKey};
use pyo3::prelude::*;
use pyo3::types::{PyList, PyString, PyTuple};
use pyo3::IntoPyObjectExt;

/// `(groups, latencies, first_t, last_t)`: each group `(protocol, kind, bus, device, command,
/// direction, flags, errors, warnings, count, length)`, the four device fields None but for a
/// device's frame; each latency list `(bus, protocol, device, command, [ms, ...])`.
pub(super) fn stats_groups<'py>(
    py: Python<'py>,
    records: &[Record],
) -> PyResult<Bound<'py, PyTuple>> {
    let found = group(records);
    let text = |s: &str| PyString::intern(py, s);
    let mut groups = Vec::with_capacity(found.groups.len());
    for (key, tally) in &found.groups {
        let device = key.device.as_ref();
        let flags = PyTuple::new(py, key.flags.iter().map(|f| text(f)))?;
        let row = [
            text(key.protocol).into_any(),
            text(key.kind).into_any(),
            device
                .map(|d| PyString::new(py, d.bus))
                .into_bound_py_any(py)?,
            device.map(|d| d.device).into_bound_py_any(py)?,
            device
                .map(|d| PyString::new(py, &d.command))
                .into_bound_py_any(py)?,
            device
                .and_then(|d| d.direction)
                .map(text)
                .into_bound_py_any(py)?,
            flags.into_any(),
            key.errors.into_bound_py_any(py)?,
            key.warnings.into_bound_py_any(py)?,
            tally.count.into_bound_py_any(py)?,
            tally.length.into_bound_py_any(py)?,
        ];
        groups.push(PyTuple::new(py, row)?);
    }
    let mut latencies = Vec::with_capacity(found.latencies.len());
    for (LatencyKey(bus, protocol, device, command), values) in &found.latencies {
        let values = PyList::new(py, values)?;
        latencies
            .push((*bus, text(protocol), *device, command.as_ref(), values).into_pyobject(py)?);
    }
    let groups = PyList::new(py, groups)?;
    let latencies = PyList::new(py, latencies)?;
    (groups, latencies, found.first_t, found.last_t).into_pyobject(py)
}
