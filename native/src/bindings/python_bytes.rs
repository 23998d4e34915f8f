//! `ByteStage`: analyzer/session/stage.py `Decoding` for a session on one byte stream (a raw
//! serial or Modbus dump replayed), handing out `RecordBatch`es as `CanStage` does, so the
//! native `Tracker`, `CycleSegmenter` and listeners' bulk methods take them as they take CAN's.

use super::protocol_by_name;
use super::python_live::RecordBatch;
use crate::decoders::model::{Record, REQUEST, RESPONSE};
use crate::session::byte_stage::ByteStage;
use pyo3::exceptions::{PyTypeError, PyValueError};
use pyo3::intern;
use pyo3::prelude::*;
use pyo3::types::{PyBytes, PyString};

/// `ByteStage(protocol=None, positional=True)`: one byte stream's decoding.
#[pyclass(name = "ByteStage", module = "analyzer._native")]
struct PyByteStage {
    core: ByteStage,
}

/// A chunk's direction as the decoders name it.
fn direction_of(v: &Bound<'_, PyAny>) -> PyResult<Option<&'static str>> {
    if v.is_none() {
        return Ok(None);
    }
    match v.downcast::<PyString>()?.to_str()? {
        REQUEST => Ok(Some(REQUEST)),
        RESPONSE => Ok(Some(RESPONSE)),
        other => Err(PyValueError::new_err(format!(
            "Chunk.direction must be {REQUEST:?}, {RESPONSE:?} or None, not {other:?}"
        ))),
    }
}

/// Decode one Item (a Chunk payload) into `out`.
fn feed_item(core: &mut ByteStage, item: &Bound<'_, PyAny>, out: &mut Vec<Record>) -> PyResult<()> {
    let py = item.py();
    let chunk = item.getattr(intern!(py, "payload"))?;
    let data = chunk.getattr(intern!(py, "data"))?;
    let Ok(data) = data.downcast::<PyBytes>() else {
        return Err(PyTypeError::new_err(
            "ByteStage.feed: an Item's payload is a Chunk of bytes (byte streams only)",
        ));
    };
    let t = chunk.getattr(intern!(py, "t"))?;
    let t: Option<f64> = if t.is_none() {
        None
    } else {
        Some(t.extract()?)
    };
    let direction = direction_of(&chunk.getattr(intern!(py, "direction"))?)?;
    let bus = item.getattr(intern!(py, "bus"))?;
    let stream = item.getattr(intern!(py, "stream"))?;
    let key = (
        bus.downcast::<PyString>()?.to_str()?,
        stream.downcast::<PyString>()?.to_str()?,
    );
    core.feed(key, (data.as_bytes(), t, direction), out)
        .map_err(PyValueError::new_err)
}

#[pymethods]
impl PyByteStage {
    #[new]
    #[pyo3(signature = (protocol=None, positional=true))]
    fn new(protocol: Option<&str>, positional: bool) -> PyResult<Self> {
        Ok(PyByteStage {
            core: ByteStage::new(protocol_by_name(protocol)?, positional),
        })
    }

    /// The records of `items` (Items whose payload is a Chunk, all of one stream).
    fn feed(&mut self, items: &Bound<'_, PyAny>) -> PyResult<RecordBatch> {
        let mut out = Vec::new();
        for item in items.try_iter()? {
            feed_item(&mut self.core, &item?, &mut out)?;
        }
        Ok(RecordBatch::from_records(out))
    }

    /// `Decoding.set_protocol(bus, protocol)`, before the stream's first bytes.
    fn set_protocol(&mut self, _bus: &str, protocol: &str) -> PyResult<()> {
        if let Some(p) = protocol_by_name(Some(protocol))? {
            self.core.set_protocol(p);
        }
        Ok(())
    }

    /// `Decoding.tick(now)`: quiet bytes decided, requests that timed out released.
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
        self.core.cut_off(Some(bus), &mut out);
        RecordBatch::from_records(out)
    }

    /// `Decoding.stop()`: the capture was stopped before its input ended.
    fn stop(&mut self) -> RecordBatch {
        let mut out = Vec::new();
        self.core.cut_off(None, &mut out);
        RecordBatch::from_records(out)
    }
}

/// `decoders.registry.detect_protocol(sample)`: the byte-stream protocol that finds the most
/// valid frames in `sample`, None if neither finds any (sniffing a capture's head).
#[pyfunction]
fn detect_protocol(py: Python<'_>, sample: &[u8]) -> Option<&'static str> {
    py.allow_threads(|| crate::decoders::registry::detect_protocol(sample))
}

pub(super) fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<PyByteStage>()?;
    m.add_function(wrap_pyfunction!(detect_protocol, m)?)
}
