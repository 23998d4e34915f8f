//! The session core, mirroring analyzer/session/: the decoding stages of CAN frames and of one byte stream, the
//! state tracker and the offline run of one capture.

pub mod byte_stage;
pub mod can_stage;
pub mod offline_run;
pub mod tracker;
