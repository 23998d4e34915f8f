//! eg2scope's native decoding core.
//!
//! The same stages as the Python decoders (the readable reference), in one streaming pass with
//! no Python object per frame. Each module names the Python module it mirrors; the
//! differential tests (tests/native/) require byte-identical output from both.

mod alloc;
pub mod arrow;
pub mod arrow_states;
pub mod can;
pub mod candump;
pub mod detect;
pub mod flags;
pub mod framing;
pub mod generated;
pub mod hash;
pub mod json;
pub mod lint;
pub mod live;
pub mod modbus;
pub mod model;
pub mod pairing;
pub mod pipeline;
pub mod pyfloat;
pub mod rawfile;
pub mod registers;
pub mod serial;
pub mod sniff;
pub mod tracker;
pub mod writers;

#[cfg(feature = "python")]
mod python;
