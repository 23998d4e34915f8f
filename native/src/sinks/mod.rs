//! The text output formats, mirroring analyzer/sinks/ (jsonl, csv, text).

pub mod writers;
