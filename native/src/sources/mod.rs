//! Capture readers, each mirroring the module of the same name in analyzer/sources/.

pub mod candump;
pub mod capture;
pub mod compressed;
pub mod sniff;
