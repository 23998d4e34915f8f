//! `rerun_log_rows(batch, polls, quiet)`: what `eg2scope plot`'s logs show of a `RecordBatch`,
//! gathered per bus and per gripper in one pass over the Rust records (analyzer/plot/logs.py
//! `log_rows`, the reference, does the same on a list of Records; tests/rerun require equal
//! results). A warning-heavy capture shows most of its records in the logs: reading them
//! here makes no Python Record per record, only the columns the plot sends.

use super::python_live::RecordBatch;
use crate::decoders::flags::{DEVICE_FAULT, UNANSWERED};
use crate::decoders::model::{Record, FRAME, REQUEST};
use crate::hash::FastMap;
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyList, PyString, PyTuple};
use std::sync::Arc;

/// A log's rows: times (NaN: none), seqs, texts (None: a command without a name), levels.
#[derive(Default)]
struct TextRows {
    t: Vec<f64>,
    seq: Vec<i64>,
    text: Vec<Option<String>>,
    level: Vec<Level>,
}

impl TextRows {
    fn push(&mut self, rec: &Record, text: Option<String>, level: Level) {
        self.t.push(rec.t.unwrap_or(f64::NAN));
        self.seq.push(rec.seq);
        self.text.push(text);
        self.level.push(level);
    }

    fn to_py<'py>(
        &self,
        py: Python<'py>,
        levels: &[Bound<'py, PyString>; 3],
    ) -> PyResult<[Bound<'py, PyAny>; 4]> {
        Ok([
            PyList::new(py, &self.t)?.into_any(),
            PyList::new(py, &self.seq)?.into_any(),
            PyList::new(py, &self.text)?.into_any(),
            PyList::new(py, self.level.iter().map(|l| &levels[*l as usize]))?.into_any(),
        ])
    }
}

#[derive(Clone, Copy)]
enum Level {
    Error,
    Warn,
    Info,
}

/// A bus's error log and the times its health rates count.
#[derive(Default)]
struct BusRows {
    errors: TextRows,
    nonframes: Vec<f64>,
    problems: Vec<f64>,
    unanswered: Vec<f64>,
}

/// A gripper's commands and fault marks.
#[derive(Default)]
struct GripperRows {
    commands: TextRows,
    mark_t: Vec<f64>,
    mark_seq: Vec<i64>,
}

/// Rows by key, in the order keys first appear.
struct Ordered<K, V> {
    index: FastMap<K, usize>,
    rows: Vec<(K, V)>,
}

impl<K: std::hash::Hash + Eq + Clone, V: Default> Ordered<K, V> {
    fn new() -> Self {
        Ordered {
            index: FastMap::default(),
            rows: Vec::new(),
        }
    }

    fn get(&mut self, key: K) -> &mut V {
        let i = *self.index.entry(key.clone()).or_insert_with(|| {
            self.rows.push((key, V::default()));
            self.rows.len() - 1
        });
        &mut self.rows[i].1
    }
}

/// `_problem_text`: "ID 2 <summary, name or kind>: <errors and warnings>", into `out`.
fn problem_text(rec: &Record, out: &mut String) {
    use std::fmt::Write;
    out.clear();
    if let Some(d) = rec.device {
        let _ = write!(out, "ID {d} ");
    }
    out.push_str(if !rec.summary.is_empty() {
        &rec.summary
    } else {
        match rec.name.as_deref() {
            Some(n) if !n.is_empty() => n,
            _ => rec.kind,
        }
    });
    out.push_str(": ");
    for (i, note) in rec.errors.iter().chain(&rec.warnings).enumerate() {
        if i > 0 {
            out.push_str("; ");
        }
        out.push_str(note);
    }
}

/// `rec.summary or rec.name`: a command in words.
fn command_text(rec: &Record) -> Option<String> {
    if !rec.summary.is_empty() {
        return Some(rec.summary.to_string());
    }
    rec.name.as_deref().map(str::to_string)
}

/// `(buses, grippers)`: `{bus: (t, seq, text, level, nonframes, problems, unanswered)}` (its
/// error log, and the times of its records that are no frames, have errors, went unanswered)
/// and `{(bus, device): (t, seq, text, level, mark_t, mark_seq)}` (its commands and fault
/// marks), each in the order first met. `polls`: the (protocol, code) of requests that only
/// read; `quiet`: flags that say nothing is wrong.
pub(super) fn rerun_log_rows<'py>(
    py: Python<'py>,
    records: PyRef<'py, RecordBatch>,
    polls: Vec<(String, i64)>,
    quiet: Vec<String>,
) -> PyResult<Bound<'py, PyTuple>> {
    let is_poll = |rec: &Record| {
        polls
            .iter()
            .any(|(p, c)| rec.protocol == p && rec.code == Some(*c))
    };
    let mut buses: Ordered<usize, BusRows> = Ordered::new();
    let mut bus_names: FastMap<usize, Arc<str>> = FastMap::default();
    let mut grippers: Ordered<(usize, i64), GripperRows> = Ordered::new();
    let mut text = String::with_capacity(256);
    for rec in &records.records {
        let problem = !rec.errors.is_empty() || !rec.warnings.is_empty();
        let command = rec.direction == Some(REQUEST) && !is_poll(rec);
        if !problem && !command {
            continue;
        }
        let bus_key = Arc::as_ptr(&rec.bus) as *const u8 as usize;
        bus_names.entry(bus_key).or_insert_with(|| rec.bus.clone());
        let mut command_level = Some(Level::Info);
        if problem {
            let nothing_wrong =
                !rec.flags.is_empty() && rec.flags.iter().all(|f| quiet.iter().any(|q| q == f));
            let bus = buses.get(bus_key);
            if !rec.errors.is_empty() {
                problem_text(rec, &mut text);
                bus.errors.push(rec, Some(text.clone()), Level::Error);
            } else if !nothing_wrong {
                problem_text(rec, &mut text);
                bus.errors.push(rec, Some(text.clone()), Level::Warn);
            }
            if let Some(t) = rec.t {
                if rec.kind != FRAME {
                    bus.nonframes.push(t);
                }
                if !rec.errors.is_empty() {
                    bus.problems.push(t);
                }
                if rec.flags.contains(&UNANSWERED) {
                    bus.unanswered.push(t);
                }
            }
            let fault = !rec.errors.is_empty() || rec.flags.contains(&DEVICE_FAULT);
            command_level = None;
            match rec.device {
                Some(device) if fault => {
                    let g = grippers.get((bus_key, device));
                    g.mark_t.push(rec.t.unwrap_or(f64::NAN));
                    g.mark_seq.push(rec.seq);
                }
                _ if command => {
                    command_level = Some(if nothing_wrong {
                        Level::Info
                    } else {
                        Level::Warn
                    })
                }
                _ => {}
            }
        }
        if let (Some(level), Some(device)) = (command_level, rec.device) {
            if rec.kind == FRAME {
                let text = command_text(rec);
                grippers
                    .get((bus_key, device))
                    .commands
                    .push(rec, text, level);
            }
        }
    }
    let levels = [
        PyString::new(py, "ERROR"),
        PyString::new(py, "WARN"),
        PyString::new(py, "INFO"),
    ];
    let names: FastMap<usize, Bound<'py, PyString>> = bus_names
        .iter()
        .map(|(k, name)| (*k, PyString::new(py, name)))
        .collect();
    let out_buses = PyDict::new(py);
    for (key, rows) in &buses.rows {
        let [t, seq, text, level] = rows.errors.to_py(py, &levels)?;
        let times = [&rows.nonframes, &rows.problems, &rows.unanswered]
            .map(|v| PyList::new(py, v.iter()).map(Bound::into_any));
        let [nonframes, problems, unanswered] = times;
        let row = PyTuple::new(
            py,
            [t, seq, text, level, nonframes?, problems?, unanswered?],
        )?;
        out_buses.set_item(&names[key], row)?;
    }
    let out_grippers = PyDict::new(py);
    for ((bus, device), rows) in &grippers.rows {
        let [t, seq, text, level] = rows.commands.to_py(py, &levels)?;
        let mark_t = PyList::new(py, &rows.mark_t)?.into_any();
        let mark_seq = PyList::new(py, &rows.mark_seq)?.into_any();
        let row = PyTuple::new(py, [t, seq, text, level, mark_t, mark_seq])?;
        let key = PyTuple::new(
            py,
            [
                names[bus].clone().into_any(),
                device.into_pyobject(py)?.into_any(),
            ],
        )?;
        out_grippers.set_item(key, row)?;
    }
    PyTuple::new(py, [out_buses.into_any(), out_grippers.into_any()])
}
