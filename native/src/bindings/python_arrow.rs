//! `analyzer._native.ArrowRun`: a decode of one capture whose records come out as Arrow
//! buffers in `PARSE_SCHEMA`'s layout (parquet/records.rs), for analyzer/parquet/native.py,
//! which makes arrays of them (`pa.Array.from_buffers`, no copy) and hands them to
//! `ParquetRecordWriter.write_parsed`. No JSON, no Python object per record.
//!
//! The decode runs in a thread of its own, one batch ahead: while Python and Arrow write a
//! batch to Parquet, the next one is decoded (two cores: the two halves of the work overlap).
//! The run is opened in that thread and never leaves it; batches come over a channel of one.
//!
//! A child module of bindings/mod.rs: it shares its errors, options and GIL helpers.

use super::{os_error, protocol_by_name, Unsupported};
use crate::parquet::records::{ArrowTables, ArrowWriter, Buffers, ColumnSpec, RecordColumns, Type};
use crate::parquet::states::StateColumns;
use crate::session::offline_run::{DecodeOptions, DecodeRun};
use crate::sinks::writers::{Format, TextOptions};
use pyo3::ffi;
use pyo3::prelude::*;
use pyo3::types::{PyList, PyTuple};
use std::os::raw::{c_int, c_void};
use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::mpsc::{sync_channel, Receiver};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;

/// Rows per batch: a quarter of a Parquet row group of analyzer/parquet/writer.py
/// (`ROW_GROUP_ROWS`): small batches keep memory low, and cost Python nothing per row.
const BATCH_ROWS: u64 = 16_384;

/// One column of a batch, owned (parquet/records.rs `Buffers`).
pub(super) enum Part {
    AllNull(usize),
    Data {
        len: usize,
        nulls: usize,
        validity: Option<Vec<u8>>,
        values: Vec<u8>,
        bytes: Option<Vec<u8>>,
    },
}

impl Part {
    /// A column as `take` hands it out, copied out of the builders.
    fn own(b: Buffers<'_>) -> Part {
        match b {
            Buffers::AllNull(n) => Part::AllNull(n),
            Buffers::Data {
                len,
                nulls,
                validity,
                values,
                bytes,
            } => Part::Data {
                len,
                nulls,
                validity: validity.map(<[u8]>::to_vec),
                values: values.to_vec(),
                bytes: bytes.map(<[u8]>::to_vec),
            },
        }
    }
}

/// Columns as Python takes them: per column its length (all null) or `(length, null_count,
/// validity or None, values, bytes or None)` (buffer objects, no copy).
pub(super) fn parts_to_py<'py>(py: Python<'py>, parts: Vec<Part>) -> PyResult<Bound<'py, PyList>> {
    let list = PyList::empty(py);
    for part in parts {
        let item = match part {
            Part::AllNull(n) => n.into_pyobject(py)?.into_any(),
            Part::Data {
                len,
                nulls,
                validity,
                values,
                bytes,
            } => (len, nulls, validity.map(Buf), Buf(values), bytes.map(Buf))
                .into_pyobject(py)?
                .into_any(),
        };
        list.append(item)?;
    }
    Ok(list)
}

/// State samples as columns (parquet/states.rs), owned: `SampleBatch.arrow` and the fleet runs.
pub(super) fn state_parts(columns: &mut StateColumns) -> (usize, Vec<Part>) {
    let rows = columns.rows();
    let mut parts = Vec::new();
    columns.take(&mut |b| parts.push(Part::own(b)));
    (rows, parts)
}

/// A column description as Python gives it: `(name, type, number of children)`, depth first.
pub(super) fn column_specs(columns: &[(String, String, usize)]) -> PyResult<Vec<ColumnSpec>> {
    columns
        .iter()
        .map(|(name, ty, children)| {
            let ty = Type::by_name(ty)
                .ok_or_else(|| Unsupported::new_err(format!("column {name}: type {ty}")))?;
            Ok(ColumnSpec::new(name, ty, *children))
        })
        .collect()
}

/// What the decoding thread sends.
enum Msg {
    /// records, and the state samples made of them (when asked for)
    Batch(usize, Vec<Part>, Option<(usize, Vec<Part>)>),
    /// the end, with the input's damage
    End(Vec<String>),
    /// a state sample that could not be written: the run ends
    Failed(String),
}

/// What Python may read while the thread runs.
#[derive(Default)]
struct Progress {
    position: AtomicU64,
    written: AtomicU64,
    stop: AtomicBool,
}

/// Bytes handed to Python without a copy (the buffer protocol: `pa.py_buffer` keeps it alive).
#[pyclass(frozen, module = "analyzer._native")]
struct Buf(Vec<u8>);

#[pymethods]
impl Buf {
    /// # Safety
    /// `view` is the Py_buffer Python asks to fill; the bytes are never changed (frozen).
    unsafe fn __getbuffer__(
        slf: Bound<'_, Self>,
        view: *mut ffi::Py_buffer,
        flags: c_int,
    ) -> PyResult<()> {
        let data = &slf.get().0;
        // SAFETY: the bytes live as long as the object, which the view holds a reference to
        // (PyBuffer_FillInfo takes one); read-only.
        let ret = unsafe {
            ffi::PyBuffer_FillInfo(
                view,
                slf.as_ptr(),
                data.as_ptr() as *mut c_void,
                data.len() as ffi::Py_ssize_t,
                1,
                flags,
            )
        };
        if ret == -1 {
            return Err(PyErr::fetch(slf.py()));
        }
        Ok(())
    }

    fn __len__(&self) -> usize {
        self.0.len()
    }
}

/// `ArrowRun(path, columns, families, other, values_key, protocol=None, bus=None, device=None,
/// errors_only=False, batch_rows=16384, states=None)`: `columns` describes the parse schema
/// depth first as `(name, type, number of children)` (type: int64, float64, string, bool, list,
/// struct); `families`: `(protocol, column)` pairs; `other`: the column of what no column
/// holds; `states`: the state sample columns (parquet/states.rs) to fill from a Tracker fed the
/// records, or None. Iterate it for `(rows, columns, states)`: per column of the description,
/// its length (all null) or `(length, null_count, validity or None, values, bytes or None)`
/// (buffer objects); `states` None, or `(samples, columns)` laid out the same way. A sample
/// that does not fit its columns raises ValueError.
#[pyclass(name = "ArrowRun", module = "analyzer._native")]
struct PyArrowRun {
    batches: Mutex<Option<Receiver<Msg>>>,
    thread: Mutex<Option<JoinHandle<()>>>,
    progress: Arc<Progress>,
    size: u64,
    errors: Mutex<Vec<String>>,
    done: AtomicBool,
}

/// The decoding thread: batches of `max` records as owned columns, until the end or `stop`.
fn produce(
    mut run: DecodeRun,
    shared: Arc<Mutex<ArrowTables>>,
    max: u64,
    progress: Arc<Progress>,
    tx: std::sync::mpsc::SyncSender<Msg>,
) {
    let mut scratch = Vec::new();
    loop {
        let more = run.next_records(&mut scratch, max);
        scratch.clear(); // the writer writes no bytes
        progress.position.store(run.position(), Ordering::Relaxed);
        progress
            .written
            .store(run.records_written(), Ordering::Relaxed);
        let mut tables = shared.lock().unwrap_or_else(|e| e.into_inner());
        if let Some(why) = tables.failure.take() {
            let _ = tx.send(Msg::Failed(why));
            return;
        }
        let rows = tables.records.rows();
        if rows > 0 {
            let mut parts = Vec::new();
            tables.records.take(&mut |b| parts.push(Part::own(b)));
            let states = tables.states.as_mut().map(|(_, cols)| state_parts(cols));
            drop(tables);
            let sent = tx.send(Msg::Batch(rows, parts, states));
            if sent.is_err() || progress.stop.load(Ordering::Relaxed) {
                return; // Python went away
            }
        }
        if !more {
            // a read error that ended the input early ends the output there, as DecodeRun's
            // batches do (bindings/mod.rs); the damage is in `errors`
            let _ = tx.send(Msg::End(run.errors().to_vec()));
            return;
        }
    }
}

#[pymethods]
impl PyArrowRun {
    #[new]
    #[pyo3(signature = (path, columns, families, other, values_key, protocol=None, bus=None,
                        device=None, errors_only=false, batch_rows=BATCH_ROWS, states=None))]
    #[allow(clippy::too_many_arguments)] // the decode command's options, by keyword
    fn new(
        py: Python<'_>,
        path: PathBuf,
        columns: Vec<(String, String, usize)>,
        families: Vec<(String, String)>,
        other: &str,
        values_key: &str,
        protocol: Option<&str>,
        bus: Option<String>,
        device: Option<i64>,
        errors_only: bool,
        batch_rows: u64,
        states: Option<Vec<(String, String, usize)>>,
    ) -> PyResult<Self> {
        let specs = column_specs(&columns)?;
        let records = RecordColumns::new(&specs, &families, other, values_key)
            .map_err(Unsupported::new_err)?;
        let states = match states {
            Some(columns) => {
                let specs = column_specs(&columns)?;
                Some(StateColumns::new(&specs).map_err(Unsupported::new_err)?)
            }
            None => None,
        };
        let shared = Arc::new(Mutex::new(ArrowTables::new(records, states)));
        let opts = DecodeOptions {
            protocol: protocol_by_name(protocol)?,
            bus,
            device,
            errors_only,
            format: Format::Jsonl, // unused: the writer is the columns
            text: TextOptions::default(),
        };
        let progress = Arc::new(Progress::default());
        let (tx, rx) = sync_channel(1);
        let (opened_tx, opened_rx) = sync_channel(1);
        let thread = {
            let (path, progress) = (path.clone(), progress.clone());
            let max = batch_rows.max(1);
            std::thread::Builder::new()
                .name("eg2scope-arrow".into())
                .spawn(move || {
                    let writer = Box::new(ArrowWriter(shared.clone()));
                    match DecodeRun::open_with_writer(&path, opts, writer) {
                        Ok(run) => {
                            let _ = opened_tx.send(Ok(run.size()));
                            produce(run, shared, max, progress, tx);
                        }
                        Err(e) => {
                            let _ = opened_tx.send(Err(e));
                        }
                    }
                })?
        };
        // opening reads the head of the file (protocol detection): no GIL needed
        let opened = py.allow_threads(move || opened_rx.recv());
        let size = match opened {
            Ok(Ok(size)) => size,
            Ok(Err(e)) => {
                let _ = thread.join();
                return Err(os_error(e, &path));
            }
            Err(_) => {
                let _ = thread.join();
                return Err(pyo3::exceptions::PyRuntimeError::new_err(
                    "the decoding thread failed",
                ));
            }
        };
        Ok(PyArrowRun {
            batches: Mutex::new(Some(rx)),
            thread: Mutex::new(Some(thread)),
            progress,
            size,
            errors: Mutex::new(Vec::new()),
            done: AtomicBool::new(false),
        })
    }

    fn __iter__(slf: PyRef<'_, Self>) -> PyRef<'_, Self> {
        slf
    }

    /// The next batch of rows; StopIteration when every record has been handed out.
    fn __next__<'py>(&self, py: Python<'py>) -> PyResult<Option<Bound<'py, PyTuple>>> {
        // taken out while waiting (a Receiver is Send, not Sync), put back after
        let Some(rx) = self
            .batches
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .take()
        else {
            return Ok(None);
        };
        let (rx, msg) = py.allow_threads(move || {
            let msg = rx.recv();
            (rx, msg)
        });
        *self.batches.lock().unwrap_or_else(|e| e.into_inner()) = Some(rx);
        match msg {
            Ok(Msg::Batch(rows, parts, states)) => {
                let records = parts_to_py(py, parts)?;
                let states = match states {
                    Some((n, parts)) => (n, parts_to_py(py, parts)?).into_pyobject(py)?.into_any(),
                    None => py.None().into_bound(py),
                };
                Ok(Some((rows, records, states).into_pyobject(py)?))
            }
            Ok(Msg::Failed(why)) => {
                self.finish(py);
                Err(pyo3::exceptions::PyValueError::new_err(why))
            }
            Ok(Msg::End(errors)) => {
                self.finish(py);
                *self.errors.lock().unwrap_or_else(|e| e.into_inner()) = errors;
                Ok(None)
            }
            Err(_) => {
                // the thread ended without its last message: it panicked (a bug), or
                // `close` stopped it
                self.finish(py);
                if self.progress.stop.load(Ordering::Relaxed) {
                    return Ok(None);
                }
                Err(pyo3::exceptions::PyRuntimeError::new_err(
                    "the native decoding thread failed",
                ))
            }
        }
    }

    /// Stop decoding (the output failed, or Python stops early); the thread ends.
    fn close(&self, py: Python<'_>) {
        self.progress.stop.store(true, Ordering::Relaxed);
        self.finish(py);
    }

    /// Bytes of the input read so far (compressed bytes for .gz), for a progress bar.
    #[getter]
    fn position(&self) -> u64 {
        if self.done.load(Ordering::Relaxed) {
            return self.size;
        }
        self.progress.position.load(Ordering::Relaxed)
    }

    /// The input file's size in bytes.
    #[getter]
    fn size(&self) -> u64 {
        self.size
    }

    /// Damage found in the input (known at the end), as the Python readers' `errors` say it.
    #[getter]
    fn errors(&self) -> Vec<String> {
        self.errors
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .clone()
    }

    /// Records decoded so far (after the --device / --errors-only filter).
    #[getter]
    fn records_written(&self) -> u64 {
        self.progress.written.load(Ordering::Relaxed)
    }

    /// Whether every record has been handed out.
    #[getter]
    fn finished(&self) -> bool {
        self.done.load(Ordering::Relaxed)
    }
}

impl PyArrowRun {
    /// Drop the channel (a thread blocked on sending wakes up and ends) and join the thread.
    fn finish(&self, py: Python<'_>) {
        self.done.store(true, Ordering::Relaxed);
        drop(
            self.batches
                .lock()
                .unwrap_or_else(|e| e.into_inner())
                .take(),
        );
        let thread = self.thread.lock().unwrap_or_else(|e| e.into_inner()).take();
        if let Some(thread) = thread {
            let _ = py.allow_threads(|| thread.join());
        }
    }
}

impl Drop for PyArrowRun {
    fn drop(&mut self) {
        self.progress.stop.store(true, Ordering::Relaxed);
        drop(
            self.batches
                .get_mut()
                .unwrap_or_else(|e| e.into_inner())
                .take(),
        );
        // the thread ends at its next send; not joined here (no GIL to release)
    }
}

/// Add the classes to the module (bindings/mod.rs's module init calls this).
pub(super) fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<PyArrowRun>()?;
    m.add_class::<Buf>()
}
