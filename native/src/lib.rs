//! eg2scope's native decoding core.
//!
//! The same stages as the Python decoders (the readable reference), in one streaming pass with
//! no Python object per frame. Each module names the Python module it mirrors; the
//! differential tests (tests/native/) require byte-identical output from both.

mod alloc;
pub mod arrow;
pub mod arrow_states;
#[warn(clippy::too_many_lines, clippy::cognitive_complexity)] // clippy.toml: the limits
pub mod can;
pub mod candump;
pub mod detect;
pub mod flags;
#[warn(clippy::too_many_lines, clippy::cognitive_complexity)] // clippy.toml: the limits
pub mod framing;
pub mod hash;
pub mod json;
pub mod lint;
pub mod live;
#[warn(clippy::too_many_lines, clippy::cognitive_complexity)] // clippy.toml: the limits
pub mod modbus; // with modbus_framing and modbus_pdu
pub mod model;
#[warn(clippy::too_many_lines, clippy::cognitive_complexity)] // clippy.toml: the limits
pub mod pairing;
pub mod pipeline;
pub mod pyfloat;
pub mod rawfile;
pub mod registers;
#[warn(clippy::too_many_lines, clippy::cognitive_complexity)] // clippy.toml: the limits
pub mod serial;
pub mod sniff;
pub mod tracker;
pub mod writers;

#[cfg(feature = "python")]
mod python;
