//! Grip cycles (analyzer/cycles/): the segmenter and the rules, for the native session's
//! samples. The Python is the reference.

pub mod rules;
pub mod segmenter;
