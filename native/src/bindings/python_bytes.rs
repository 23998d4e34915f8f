//! `ByteStage`: analyzer/session/stage.py `Decoding` for a session on one byte stream (a raw
//! serial or Modbus dump replayed), handing out `RecordBatch`es as `CanStage` does, so the
//! native `Tracker`, `CycleSegmenter` and listeners' bulk methods take them as they take CAN's.
//!
//! Items are read strictly, as `CanStage` reads them: the payload a `Chunk`, its `t` a float
//! or None (an int would stay an int in the Python's records), its data any buffer (read as
//! `bytes(data)`, as the Python decoders take it); every item of a call is read, and its
//! stream checked, before any is decoded, so a refused call decodes nothing.

use super::protocol_by_name;
use super::python_live::{for_each_item, type_name, RecordBatch};
use crate::decoders::model::{Record, REQUEST, RESPONSE};
use crate::session::byte_stage::ByteStage;
use pyo3::exceptions::{PyTypeError, PyValueError};
use pyo3::intern;
use pyo3::prelude::*;
use pyo3::sync::GILOnceCell;
use pyo3::types::{PyBytes, PyFloat, PyString, PyType};

/// decoders/model.py `Chunk`, imported once.
static CHUNK: GILOnceCell<Py<PyType>> = GILOnceCell::new();

/// Calls with at least this many bytes are decoded with the GIL released (the TUI's drawing
/// thread runs meanwhile); for fewer, releasing and taking it back would cost more.
const RELEASE_GIL_BYTES: usize = 1 << 12;

/// `ByteStage(protocol=None, positional=True)`: one byte stream's decoding.
#[pyclass(name = "ByteStage", module = "analyzer._native")]
struct PyByteStage {
    core: ByteStage,
}

/// What `feed` reads of one Item: its stream and chunk.
struct ItemChunk<'py> {
    bus: Bound<'py, PyString>,
    stream: Bound<'py, PyString>,
    data: Bound<'py, PyBytes>,
    t: Option<f64>,
    direction: Option<&'static str>,
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

fn str_attr<'py>(
    item: &Bound<'py, PyAny>,
    name: &Bound<'py, PyString>,
) -> PyResult<Bound<'py, PyString>> {
    let v = item.getattr(name)?;
    v.downcast_into::<PyString>().map_err(|e| {
        PyTypeError::new_err(format!(
            "ByteStage.feed: an Item's {name} must be a str, not {}",
            type_name(e.into_inner().as_any())
        ))
    })
}

/// Read one Item (a Chunk payload).
fn read_item<'py>(item: &Bound<'py, PyAny>) -> PyResult<ItemChunk<'py>> {
    let py = item.py();
    let chunk_type = CHUNK.import(py, "decoders.model", "Chunk")?;
    let Ok(chunk) = item.getattr(intern!(py, "payload")) else {
        return Err(PyTypeError::new_err(format!(
            "ByteStage.feed: expected an Item, got {}",
            type_name(item)
        )));
    };
    if !chunk.is_instance(chunk_type)? {
        return Err(PyTypeError::new_err(format!(
            "ByteStage.feed: an Item's payload is a {}, not a Chunk (byte streams only)",
            type_name(&chunk)
        )));
    }
    let t = chunk.getattr(intern!(py, "t"))?;
    let t = if t.is_none() {
        None
    } else if let Ok(f) = t.downcast_exact::<PyFloat>() {
        Some(f.value())
    } else {
        return Err(PyTypeError::new_err(format!(
            "Chunk.t must be a float or None, not {}",
            type_name(&t)
        )));
    };
    let data = chunk.getattr(intern!(py, "data"))?;
    let data = match data.downcast_exact::<PyBytes>() {
        Ok(b) => b.clone(),
        // what the Python decoders do with any other buffer: its bytes
        Err(_) => py
            .get_type::<PyBytes>()
            .call1((data,))?
            .downcast_into::<PyBytes>()?,
    };
    Ok(ItemChunk {
        bus: str_attr(item, intern!(py, "bus"))?,
        stream: str_attr(item, intern!(py, "stream"))?,
        data,
        t,
        direction: direction_of(&chunk.getattr(intern!(py, "direction"))?)?,
    })
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

    /// The records of `items` (Items whose payload is a Chunk, all of one stream): TypeError
    /// or ValueError, with nothing decoded, if one is not.
    fn feed(&mut self, py: Python<'_>, items: &Bound<'_, PyAny>) -> PyResult<RecordBatch> {
        let mut read = Vec::new();
        for_each_item(items, |item| {
            read.push(read_item(item)?);
            Ok(())
        })?;
        let mut chunks = Vec::with_capacity(read.len());
        for c in &read {
            let key = (c.bus.to_str()?, c.stream.to_str()?);
            let first = self.core.stream().or(chunks.first().map(|c: &Fed| c.0));
            if let Some(first) = first.filter(|&first| first != key) {
                return Err(PyValueError::new_err(format!(
                    "one byte stream per native decoding: {first:?} then {key:?}"
                )));
            }
            chunks.push((key, c.data.as_bytes(), c.t, c.direction));
        }
        let mut out = Vec::new();
        let core = &mut self.core;
        if chunks.iter().map(|c| c.1.len()).sum::<usize>() >= RELEASE_GIL_BYTES {
            // no Python object in there: the stage, the bytes (immutable) and the records
            py.allow_threads(|| decode(core, &chunks, &mut out));
        } else {
            decode(core, &chunks, &mut out);
        }
        Ok(RecordBatch::from_records(out))
    }

    /// `Decoding.set_protocol(bus, protocol)`: the protocol of `bus`'s stream, before it starts.
    fn set_protocol(&mut self, bus: &str, protocol: &str) -> PyResult<()> {
        if let Some(p) = protocol_by_name(Some(protocol))? {
            self.core.set_protocol(bus, p);
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

/// A chunk checked for its stream: ((bus, stream), data, t, direction).
type Fed<'a> = (
    (&'a str, &'a str),
    &'a [u8],
    Option<f64>,
    Option<&'static str>,
);

fn decode(core: &mut ByteStage, chunks: &[Fed<'_>], out: &mut Vec<Record>) {
    for &(key, data, t, direction) in chunks {
        core.feed(key, (data, t, direction), out)
            .expect("every chunk is of the stage's stream");
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
