//! Flag codes: one per error/warning text on a record (mirrors decoders/flags.py; the codes
//! are a contract, the differential tests compare them). Written from the Python by
//! native/codegen.py.

pub use crate::generated::flags::*;
