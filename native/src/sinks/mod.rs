//! The text output formats, mirroring analyzer/sinks/ (jsonl, csv, text), and the grouping of
//! records `stats` counts.

pub mod stats;
pub mod writers;
