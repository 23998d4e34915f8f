//! Bus health (analyzer/health/): the parts that run once per frame.

pub mod can_seconds;
