//! The decoders, each mirroring the module of the same name in decoders/.

#[warn(clippy::too_many_lines, clippy::cognitive_complexity)] // clippy.toml: the limits
pub mod can_bits;
#[warn(clippy::too_many_lines, clippy::cognitive_complexity)] // clippy.toml: the limits
pub mod eg2_can;
#[warn(clippy::too_many_lines, clippy::cognitive_complexity)] // clippy.toml: the limits
pub mod eg2_serial;
pub mod flags;
#[warn(clippy::too_many_lines, clippy::cognitive_complexity)] // clippy.toml: the limits
pub mod framing;
pub mod lint;
#[warn(clippy::too_many_lines, clippy::cognitive_complexity)] // clippy.toml: the limits
pub mod modbus_framing;
#[warn(clippy::too_many_lines, clippy::cognitive_complexity)] // clippy.toml: the limits
pub mod modbus_pdu;
pub mod modbus_registers;
#[warn(clippy::too_many_lines, clippy::cognitive_complexity)] // clippy.toml: the limits
pub mod modbus_rtu;
pub mod model;
#[warn(clippy::too_many_lines, clippy::cognitive_complexity)] // clippy.toml: the limits
pub mod pairing;
pub mod registers;
pub mod registry;
