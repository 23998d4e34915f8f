//! eg2scope's native decoding core.
//!
//! The same stages as the Python decoders (the readable reference), in one streaming pass with
//! no Python object per frame. Each module names the Python module it mirrors; the
//! differential tests (tests/native/) require byte-identical output from both.

mod alloc;
pub mod cycles;
pub mod decoders;
pub mod generated;
pub mod hash;
pub mod health;
pub mod json;
pub mod parquet;
pub mod pyfloat;
pub mod session;
pub mod sinks;
pub mod sources;

#[cfg(feature = "python")]
mod bindings;
