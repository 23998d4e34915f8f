//! A candump log's frames for a session that decodes them natively: `CandumpFrames` reads the
//! file with the reader `DecodeRun` uses (candump.rs, named per channel as `CanLogReader`
//! names buses) and hands over `FrameBatch`es, which `CanStage.feed` decodes without a Python
//! object per frame (analyzer/sources/source.py `CaptureSource.read_natively`).
//!
//! A `FrameBatch` is opaque to Python (only its length): a session reads a capture this way
//! only when no listener wants the raw items and its decoding is the native `CanStage`.

use crate::decoders::model::CanFrame;
use crate::sources::candump::{BusNamer, CandumpReader};
use pyo3::prelude::*;
use std::path::PathBuf;
use std::sync::Arc;

/// Frames read, each with its bus name (one `Arc` per name: `CanStage` finds its decoder by
/// identity first).
#[pyclass(module = "analyzer._native", frozen)]
pub struct FrameBatch {
    pub(crate) frames: Vec<(Arc<str>, CanFrame)>,
}

#[pymethods]
impl FrameBatch {
    fn __len__(&self) -> usize {
        self.frames.len()
    }

    fn __repr__(&self) -> String {
        format!("<FrameBatch of {} CAN frames>", self.frames.len())
    }
}

/// `CandumpFrames(path, bus=None)`: a candump log (`.gz` too) read in batches of frames
/// (`read(n)`: a `FrameBatch`, None at the end). `errors`: the damage found, in the words of
/// the Python reader (`CanLogReader.errors`); `position`/`size`: bytes, for a progress bar.
/// `Unsupported` for what only the Python reader reads here (`-tA` dates off Unix).
#[pyclass(name = "CandumpFrames", module = "analyzer._native", unsendable)]
pub struct PyCandumpFrames {
    reader: CandumpReader,
    names: BusNamer,
    size: u64,
    done: bool,
}

#[pymethods]
impl PyCandumpFrames {
    #[new]
    #[pyo3(signature = (path, bus=None))]
    fn new(path: PathBuf, bus: Option<&str>) -> PyResult<Self> {
        let size = std::fs::metadata(&path)
            .map_err(|e| super::os_error(e, &path))?
            .len();
        let reader = CandumpReader::open(&path).map_err(|e| super::os_error(e, &path))?;
        if reader.dated && cfg!(not(unix)) {
            return Err(super::Unsupported::new_err(
                "candump -tA dates are read by the Python engine on this system",
            ));
        }
        Ok(PyCandumpFrames {
            reader,
            // `--bus ""` is no --bus, as the Python reader takes it (`bus or ...`)
            names: BusNamer::new(bus.filter(|b| !b.is_empty())),
            size,
            done: false,
        })
    }

    /// The next `max_frames` frames at most (read with the GIL released); None at the end.
    fn read(&mut self, py: Python<'_>, max_frames: usize) -> Option<FrameBatch> {
        if self.done {
            return None;
        }
        let work = super::NoGil((&mut self.reader, &mut self.names));
        let frames = py.allow_threads(move || {
            let (reader, names) = work.into_inner();
            let mut frames = Vec::with_capacity(max_frames.max(1));
            let mut frame = CanFrame::default();
            while frames.len() < max_frames.max(1) && reader.next_into(&mut frame) {
                let bus = names.bus(frame.channel.as_deref());
                frames.push((bus, frame.clone()));
            }
            frames
        });
        if frames.is_empty() {
            self.done = true;
            return None;
        }
        Some(FrameBatch { frames })
    }

    /// Bytes read so far (of the compressed file for `.gz`); the size once at the end.
    #[getter]
    fn position(&self) -> u64 {
        if self.done {
            self.size
        } else {
            self.reader.position().min(self.size)
        }
    }

    #[getter]
    fn size(&self) -> u64 {
        self.size
    }

    /// The damage found so far, in order.
    #[getter]
    fn errors(&self) -> Vec<String> {
        self.reader.errors.clone()
    }
}

pub(super) fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<FrameBatch>()?;
    m.add_class::<PyCandumpFrames>()?;
    Ok(())
}
