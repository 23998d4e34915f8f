//! The session core, mirroring analyzer/session/: the decoding stage of CAN frames, the
//! state tracker and the offline run of one capture.

pub mod can_stage;
pub mod offline_run;
pub mod tracker;
