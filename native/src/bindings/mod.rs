//! The Python extension module `analyzer._native` (built with the cargo feature `python` by
//! setuptools-rust, see pyproject.toml). Python drives it from `analyzer/session/engine.py`.
//!
//! One class, `DecodeRun`: a decode of one capture file, iterated for `bytes` batches of
//! output (about `batch_bytes` each) that Python writes to its output stream, or told to write
//! each batch straight to a file descriptor (`write_batch(fd)`: no copy into a Python object).
//! Decoding runs with the GIL released, so a progress bar or a signal handler keeps working
//! between batches; Python never sees one object per frame.
//!
//! Errors: an input that cannot be opened raises `OSError` (its subclass by errno, the file
//! named); an input or an option the native core does not handle raises `Unsupported`, which
//! tells Python to decode with its own engine instead.

use crate::decoders::model::{EG2_SERIAL, MODBUS_RTU};
use crate::session::offline_run::{DecodeOptions, DecodeRun};
use crate::sinks::writers::{Format, TextOptions};
use pyo3::create_exception;
use pyo3::exceptions::{PyException, PyOSError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::PyBytes;
use std::io;
use std::path::PathBuf;

mod python_arrow; // ArrowRun: records as Arrow columns for the Parquet output
mod python_bytes; // ByteStage: the session's decoding of one byte stream (a raw dump)
mod python_cycles; // CycleSegmenter: grip cycles from a RecordBatch and the Tracker
mod python_frames; // CandumpFrames, FrameBatch: a candump log's frames for the native session
mod python_health; // can_seconds: CAN frames per bus and second, for the bus load
mod python_live; // CanStage, RecordBatch, can_raw_messages: the live CAN path
mod python_rerun; // RecordBatch.rerun_log_rows: what a plot's logs show of a RecordBatch
mod python_stats; // RecordBatch.stats_groups: a batch's records grouped for `eg2scope stats`
mod python_tracker; // Tracker, SampleBatch: the live state tracker

create_exception!(
    analyzer._native,
    Unsupported,
    PyException,
    "The native core cannot decode this input with these options: use the Python engine."
);

/// The default size of one output batch: large enough that Python's per-batch cost (one
/// `bytes` object, one write) vanishes, small enough to keep memory flat (a few batches are
/// in flight to the writer thread).
const BATCH_BYTES: usize = 256 << 10;

/// Room for one batch: `next_batch` stops after the step that reaches the batch size, which
/// adds at most about 150 KB (session/offline_run.rs `FEED_SLICE`, `CAN_STEP`): no regrowth.
fn batch_capacity(batch_bytes: usize) -> usize {
    batch_bytes + batch_bytes / 2 + (192 << 10)
}

fn format_by_name(name: &str) -> PyResult<Format> {
    match name {
        "jsonl" => Ok(Format::Jsonl),
        "csv" => Ok(Format::Csv),
        "text" => Ok(Format::Text),
        _ => Err(PyValueError::new_err(format!(
            "unknown format {name:?} (jsonl, csv or text)"
        ))),
    }
}

/// The protocol names of decoders/model.py (what `decoders.registry.resolve_protocol` gives).
fn protocol_by_name(name: Option<&str>) -> PyResult<Option<&'static str>> {
    match name {
        None => Ok(None),
        Some(EG2_SERIAL) => Ok(Some(EG2_SERIAL)),
        Some(MODBUS_RTU) => Ok(Some(MODBUS_RTU)),
        Some(other) => Err(Unsupported::new_err(format!(
            "protocol {other:?} is not a byte-stream protocol of the native core"
        ))),
    }
}

/// An io error as Python's `OSError`, its subclass chosen as Python chooses it: from the errno
/// (`OSError(errno, strerror, filename)` gives FileNotFoundError, PermissionError, ...), or from
/// the error's kind when the pipeline wrote the message itself ("capture file not found: x").
fn os_error(err: io::Error, path: &std::path::Path) -> PyErr {
    if err.kind() == io::ErrorKind::Unsupported {
        return Unsupported::new_err(err.to_string());
    }
    match err.raw_os_error() {
        Some(errno) => {
            // the strerror alone: OSError.__str__ adds the errno and the file name
            PyOSError::new_err((errno, strerror(errno), path.to_path_buf()))
        }
        None => PyErr::from(err),
    }
}

/// The text of an errno, as Python's `os.strerror` gives it.
fn strerror(errno: i32) -> String {
    let text = io::Error::from_raw_os_error(errno).to_string();
    match text.find(" (os error") {
        Some(end) => text[..end].to_owned(),
        None => text,
    }
}

/// Write all of `data` to the file descriptor `fd`, which stays open (it is Python's).
#[cfg(unix)]
fn write_fd(fd: i32, data: &[u8]) -> io::Result<usize> {
    use std::io::Write;
    use std::mem::ManuallyDrop;
    use std::os::fd::FromRawFd;

    if fd < 0 {
        return Err(io::Error::from_raw_os_error(9)); // EBADF, as os.write(-1, ...) says
    }
    // SAFETY: the descriptor is open for the whole call (Python holds the file object) and
    // ManuallyDrop keeps it from being closed here.
    let mut file = ManuallyDrop::new(unsafe { std::fs::File::from_raw_fd(fd) });
    file.write_all(data)?; // retries EINTR and short writes
    Ok(data.len())
}

/// Elsewhere Python writes the `bytes` batches itself (analyzer/session/native_run.py uses
/// `write_batch` on POSIX only).
#[cfg(not(unix))]
fn write_fd(_fd: i32, _data: &[u8]) -> io::Result<usize> {
    Err(io::ErrorKind::Unsupported.into())
}

/// A value handed to `Python::allow_threads`, which asks for `Send` only so that nothing tied to
/// the GIL is used without it. The decoding state holds no Python object and the closure runs
/// synchronously on the calling thread (`allow_threads` does not move it), and the class is
/// `unsendable` (PyO3 refuses access from any other thread), so the state never changes
/// threads even where it is not `Send` (an `Rc` inside the pipeline).
struct NoGil<T>(T);

// SAFETY: see above: used only for a closure that runs on the thread that owns the value.
unsafe impl<T> Send for NoGil<T> {}

impl<T> NoGil<T> {
    /// The value (a method, so that a closure captures the whole wrapper, not its field).
    fn into_inner(self) -> T {
        self.0
    }
}

/// `DecodeRun(path, format, protocol=None, bus=None, device=None, errors_only=False,
/// colour=False, absolute_time=False, batch_bytes=256 KiB)`: iterate it for the output bytes.
#[pyclass(name = "DecodeRun", module = "analyzer._native", unsendable)]
struct PyDecodeRun {
    run: DecodeRun,
    buf: Vec<u8>,
    batch_bytes: usize,
    done: bool,
    writer: Option<FdWriter>,
}

/// Batches written to a file descriptor by a thread of their own, so that decoding the next
/// batch overlaps the kernel's copy of this one (writing hundreds of MB of JSONL costs about as
/// much system time as decoding it). At most `IN_FLIGHT` batches wait; their buffers come back
/// for reuse. A failed write is reported by the next call (and by `finish`).
struct FdWriter {
    fd: i32,
    full: Option<std::sync::mpsc::SyncSender<Vec<u8>>>,
    empty: std::sync::mpsc::Receiver<Vec<u8>>,
    failed: std::sync::Arc<std::sync::Mutex<Option<io::Error>>>,
    thread: Option<std::thread::JoinHandle<()>>,
}

const IN_FLIGHT: usize = 4;

impl FdWriter {
    fn start(fd: i32) -> FdWriter {
        use std::sync::{mpsc, Arc, Mutex};
        let (full, batches) = mpsc::sync_channel::<Vec<u8>>(IN_FLIGHT);
        let (give_back, empty) = mpsc::channel::<Vec<u8>>();
        let failed = Arc::new(Mutex::new(None));
        let slot = Arc::clone(&failed);
        let thread = std::thread::spawn(move || {
            for mut batch in batches {
                if let Err(e) = write_fd(fd, &batch) {
                    *slot.lock().expect("writer error slot") = Some(e);
                    return; // dropping `batches`: the next send fails and says so
                }
                batch.clear();
                let _ = give_back.send(batch);
            }
        });
        FdWriter {
            fd,
            full: Some(full),
            empty,
            failed,
            thread: Some(thread),
        }
    }

    /// A buffer to fill: one the thread has written, or a new one of `capacity` bytes.
    fn buffer(&self, capacity: usize) -> Vec<u8> {
        self.empty
            .try_recv()
            .unwrap_or_else(|_| Vec::with_capacity(capacity))
    }

    fn error(&self) -> io::Result<()> {
        match self.failed.lock().expect("writer error slot").take() {
            Some(e) => Err(e),
            None => Ok(()),
        }
    }

    /// Queue a batch (blocks while `IN_FLIGHT` batches wait).
    fn send(&self, batch: Vec<u8>) -> io::Result<()> {
        self.error()?;
        let sent = self.full.as_ref().map(|tx| tx.send(batch));
        match sent {
            Some(Ok(())) => Ok(()),
            _ => Err(self
                .error()
                .err()
                .unwrap_or_else(|| io::Error::other("writer stopped"))),
        }
    }

    /// Every queued batch written (or the first error).
    fn finish(&mut self) -> io::Result<()> {
        self.full = None;
        if let Some(thread) = self.thread.take() {
            let _ = thread.join();
        }
        self.error()
    }
}

impl Drop for FdWriter {
    fn drop(&mut self) {
        // the descriptor belongs to Python, which may close it right after: write what is
        // queued first
        let _ = self.finish();
    }
}

#[pymethods]
impl PyDecodeRun {
    #[new]
    #[pyo3(signature = (path, format, protocol=None, bus=None, device=None, errors_only=false,
                        colour=false, absolute_time=false, batch_bytes=BATCH_BYTES))]
    #[allow(clippy::too_many_arguments)] // the decode command's options, by keyword
    fn new(
        py: Python<'_>,
        path: PathBuf,
        format: &str,
        protocol: Option<&str>,
        bus: Option<String>,
        device: Option<i64>,
        errors_only: bool,
        colour: bool,
        absolute_time: bool,
        batch_bytes: usize,
    ) -> PyResult<Self> {
        let opts = DecodeOptions {
            protocol: protocol_by_name(protocol)?,
            bus,
            device,
            errors_only,
            format: format_by_name(format)?,
            text: TextOptions {
                colour,
                absolute_time,
            },
        };
        // opening reads the head of the file (protocol detection): no GIL needed
        let run = {
            let path = path.as_path();
            let run = py.allow_threads(|| NoGil(DecodeRun::open(path, opts)));
            run.into_inner().map_err(|e| os_error(e, path))?
        };
        let batch_bytes = batch_bytes.max(1);
        Ok(PyDecodeRun {
            run,
            buf: Vec::with_capacity(batch_capacity(batch_bytes)),
            batch_bytes,
            done: false,
            writer: None,
        })
    }

    fn __iter__(slf: PyRef<'_, Self>) -> PyRef<'_, Self> {
        slf
    }

    /// The next batch of output bytes; StopIteration when everything has been written.
    fn __next__<'py>(mut slf: PyRefMut<'py, Self>, py: Python<'py>) -> Option<Bound<'py, PyBytes>> {
        let this = &mut *slf;
        while !this.done {
            this.buf.clear();
            let work = NoGil((&mut this.run, &mut this.buf, this.batch_bytes));
            let more = py.allow_threads(move || {
                let (run, buf, max) = work.into_inner();
                run.next_batch(buf, max)
            });
            this.done = !more;
            if !this.buf.is_empty() {
                let batch = PyBytes::new(py, &this.buf);
                if this.buf.capacity() > 4 * this.batch_bytes {
                    this.buf = Vec::new(); // one huge batch must not pin its memory
                }
                return Some(batch);
            }
        }
        None
    }

    /// Decode the next batch and write it to the file descriptor `fd` (an open, blocking file,
    /// pipe or terminal that Python has flushed): no `bytes` object, no copy. Returns the
    /// number of bytes written, 0 once everything has been written. A failed write raises
    /// OSError from its errno (BrokenPipeError for a closed pipe, ...), as Python's own write
    /// would.
    fn write_batch(&mut self, py: Python<'_>, fd: i32) -> PyResult<usize> {
        let as_os_error = |e: io::Error| match e.raw_os_error() {
            Some(errno) => PyOSError::new_err((errno, strerror(errno))),
            None => PyErr::from(e),
        };
        if self.writer.as_ref().is_some_and(|w| w.fd != fd) {
            return Err(PyValueError::new_err("write_batch: one descriptor per run"));
        }
        let writer = self.writer.get_or_insert_with(|| FdWriter::start(fd));
        while !self.done {
            let mut buf = writer.buffer(batch_capacity(self.batch_bytes));
            let work = NoGil((&mut self.run, &mut buf, self.batch_bytes));
            let more = py.allow_threads(move || {
                let (run, buf, max) = work.into_inner();
                run.next_batch(buf, max)
            });
            self.done = !more;
            let n = buf.len();
            if n > 0 {
                let queued = NoGil((&*writer, buf));
                py.allow_threads(move || {
                    let (writer, buf) = queued.into_inner();
                    writer.send(buf)
                })
                .map_err(as_os_error)?;
                return Ok(n);
            }
        }
        let finishing = NoGil(&mut *writer);
        py.allow_threads(move || finishing.into_inner().finish())
            .map_err(as_os_error)?;
        Ok(0)
    }

    /// Wait until every batch handed to `write_batch` is written (after an interrupt, before
    /// Python flushes or closes the descriptor). A failed write raises OSError.
    fn finish_writing(&mut self, py: Python<'_>) -> PyResult<()> {
        let Some(writer) = self.writer.as_mut() else {
            return Ok(());
        };
        let finishing = NoGil(writer);
        py.allow_threads(move || finishing.into_inner().finish())
            .map_err(|e| match e.raw_os_error() {
                Some(errno) => PyOSError::new_err((errno, strerror(errno))),
                None => PyErr::from(e),
            })
    }

    /// Bytes of the input read so far (compressed bytes for .gz), for a progress bar.
    #[getter]
    fn position(&self) -> u64 {
        self.run.position()
    }

    /// The input file's size in bytes.
    #[getter]
    fn size(&self) -> u64 {
        self.run.size()
    }

    /// Damage found in the input so far, as the Python readers' `errors` say it.
    #[getter]
    fn errors(&self) -> Vec<String> {
        self.run.errors().to_vec()
    }

    /// Records written so far (after the --device / --errors-only filter).
    #[getter]
    fn records_written(&self) -> u64 {
        self.run.records_written()
    }

    /// Whether every output byte has been handed out.
    #[getter]
    fn finished(&self) -> bool {
        self.done
    }
}

#[pymodule]
fn _native(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<PyDecodeRun>()?;
    python_arrow::register(m)?;
    python_bytes::register(m)?;
    python_cycles::register(m)?;
    python_frames::register(m)?;
    python_health::register(m)?;
    python_live::register(m)?;
    python_tracker::register(m)?;
    m.add("Unsupported", m.py().get_type::<Unsupported>())?;
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    m.add("FORMATS", ("jsonl", "csv", "text"))?;
    m.add("PROTOCOLS", (EG2_SERIAL, MODBUS_RTU))?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn strerror_is_the_text_python_shows() {
        assert_eq!(strerror(2), "No such file or directory");
        assert_eq!(strerror(28), "No space left on device");
    }

    #[cfg(unix)]
    #[test]
    fn write_fd_writes_everything_and_keeps_the_descriptor() {
        use std::io::{Read, Seek};
        use std::os::fd::AsRawFd;

        let path = std::env::temp_dir().join(format!("eg2native-fd-{}", std::process::id()));
        let mut file = std::fs::File::options()
            .read(true)
            .write(true)
            .create(true)
            .truncate(true)
            .open(&path)
            .unwrap();
        std::fs::remove_file(&path).unwrap(); // the open file stays usable
        let data = vec![b'x'; 3 << 20];
        assert_eq!(write_fd(file.as_raw_fd(), &data).unwrap(), data.len());
        assert_eq!(write_fd(file.as_raw_fd(), b"end").unwrap(), 3); // still open
        let mut back = Vec::new();
        file.rewind().unwrap();
        file.read_to_end(&mut back).unwrap();
        assert_eq!(back.len(), data.len() + 3);
        assert_eq!(write_fd(-1, b"x").unwrap_err().raw_os_error(), Some(9));
    }
}
