//! Grip cycles (analyzer/cycles/): the commands, the segmenter and the rules, for the native
//! session's records and the tracker's readings. The Python is the reference.

pub mod commands;
pub mod rules;
pub mod segmenter;
