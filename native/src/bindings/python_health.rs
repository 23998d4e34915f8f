//! Bus health for Python: `can_seconds(items)`, analyzer/health/can_load.py
//! `python_can_seconds` without a Python object per frame (tests/health/test_can_seconds_native.py
//! requires the same result).

use super::python_frames::FrameBatch;
use super::python_live::{for_each_item, is_can_item, read_item};
use crate::decoders::model::CanFrame;
use crate::health::can_seconds::{BitsMemo, SecondsCount};
use pyo3::prelude::*;
use pyo3::types::{PyBytes, PyList, PyString, PyTuple};
use std::cell::Cell;
use std::sync::Arc;

thread_local! {
    /// The bits of the frames this thread has counted, from one call to the next (taken out
    /// while a call runs).
    static MEMO: Cell<BitsMemo> = Cell::new(BitsMemo::default());
}

/// `can_seconds(items) -> (seconds, error_frames, others)`: the CAN frames of `items` (a native
/// `FrameBatch`, or Items: byte chunks among them are counted in `others` and skipped) per bus
/// and whole second, `(bus, second, frames, bits, uncounted, first_t, first_bits, last_t)` each,
/// in the order they first appear; the error frames as `(bus, t, error_class, data)`.
#[pyfunction]
fn can_seconds<'py>(py: Python<'py>, items: &Bound<'py, PyAny>) -> PyResult<Bound<'py, PyTuple>> {
    let mut count = SecondsCount::with_memo(MEMO.with(Cell::take));
    let mut buses: Vec<String> = Vec::new();
    let counted = match items.downcast::<FrameBatch>() {
        Ok(batch) => {
            count_batch(&mut count, &mut buses, &batch.get().frames);
            Ok(0)
        }
        Err(_) => count_items(&mut count, &mut buses, items),
    };
    MEMO.with(|m| m.set(std::mem::take(&mut count.memo)));
    let others: u64 = counted?;
    let seconds = count.seconds.iter().map(|s| {
        (
            &buses[s.bus],
            s.second,
            s.frames,
            s.bits,
            s.uncounted,
            s.first_t,
            s.first_bits,
            s.last_t,
        )
    });
    let seconds = PyList::new(py, seconds.collect::<Vec<_>>())?;
    let mut errors = Vec::with_capacity(count.errors.len());
    for (bus, t, class, data) in &count.errors {
        errors.push((&buses[*bus], *t, *class, PyBytes::new(py, data)).into_pyobject(py)?);
    }
    (seconds, PyList::new(py, errors)?, others).into_pyobject(py)
}

/// The number of `name` in `buses` (added when new).
fn bus_number(buses: &mut Vec<String>, name: &str) -> usize {
    match buses.iter().position(|b| b == name) {
        Some(i) => i,
        None => {
            buses.push(name.to_owned());
            buses.len() - 1
        }
    }
}

fn count_batch(count: &mut SecondsCount, buses: &mut Vec<String>, frames: &[(Arc<str>, CanFrame)]) {
    let mut last: Option<(&Arc<str>, usize)> = None;
    for (bus, frame) in frames {
        let id = match last {
            Some((name, id)) if Arc::ptr_eq(name, bus) => id,
            _ => bus_number(buses, bus),
        };
        last = Some((bus, id));
        count.add(id, frame);
    }
}

/// Count the CAN items of `items`; how many were no CAN frames.
fn count_items(
    count: &mut SecondsCount,
    buses: &mut Vec<String>,
    items: &Bound<'_, PyAny>,
) -> PyResult<u64> {
    let mut others = 0;
    let mut bytes = Vec::new();
    let mut frame = CanFrame::default();
    let mut last: Option<(Bound<'_, PyString>, usize)> = None;
    for_each_item(items, |item| {
        if !is_can_item(item)? {
            others += 1;
            return Ok(());
        }
        bytes.clear();
        let f = read_item(item, &mut bytes, false, "can_seconds")?;
        let id = match &last {
            Some((name, id)) if name.is(&f.bus) => *id,
            _ => bus_number(buses, f.bus.to_str()?),
        };
        frame.t = f.t;
        frame.arbitration_id = f.aid;
        frame.is_extended = f.extended;
        frame.is_remote = f.remote;
        frame.is_error = f.error;
        frame.is_fd = f.fd;
        frame.dlc = f.dlc;
        frame.data.clear();
        frame.data.extend_from_slice(&bytes[f.data.clone()]);
        count.add(id, &frame);
        last = Some((f.bus, id));
        Ok(())
    })?;
    Ok(others)
}

pub(super) fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(can_seconds, m)?)?;
    Ok(())
}
