//! Flag codes: one per error/warning text on a record (mirrors decoders/flags.py; the codes
//! are a contract, the differential tests compare them).

/// serial sum or Modbus CRC does not match
pub const BAD_CHECKSUM: &str = "bad_checksum";
/// bytes that belong to no frame
pub const GARBAGE: &str = "garbage";
/// a frame cut off by the end of the input
pub const TRUNCATED: &str = "truncated";
/// a frame whose payload does not fit its command's layout
pub const MALFORMED: &str = "malformed";
/// a CAN error frame seen on the bus
pub const CAN_ERROR_FRAME: &str = "can_error_frame";
/// a decoder bug caught on this frame
pub const DECODER_ERROR: &str = "decoder_error";
/// a frame begun, or a request waiting, when the capture was stopped (not a bus error)
pub const CUT_OFF: &str = "cut_off";
/// a request that never got its response
pub const UNANSWERED: &str = "unanswered";
/// a response with no request before it
pub const ORPHAN_RESPONSE: &str = "orphan_response";
/// the same request sent again before an answer
pub const RETRANSMISSION: &str = "retransmission";
/// a response of another length than asked for
pub const LENGTH_MISMATCH: &str = "length_mismatch";
/// an echo or write response unlike its request
pub const RESPONSE_MISMATCH: &str = "response_mismatch";
/// named from a request whose checksum failed
pub const UNTRUSTED_REQUEST: &str = "untrusted_request";
/// fits both request and response shapes
pub const AMBIGUOUS_DIRECTION: &str = "ambiguous_direction";
/// a value outside its documented range
pub const OUT_OF_RANGE: &str = "out_of_range";
/// commands to one gripper less than 5 ms apart
pub const CLOSER_THAN_5MS: &str = "closer_than_5ms";
/// a command within 1 s of a parameter save
pub const DURING_SAVE: &str = "during_save";
/// the gripper answered a write with a failure status
pub const WRITE_FAILED: &str = "write_failed";
/// a Modbus exception response
pub const EXCEPTION_RESPONSE: &str = "exception_response";
/// Modbus CRC sent high byte first (as the manual prints)
pub const SWAPPED_CRC: &str = "swapped_crc";
/// 10 for 1010, as some clients send
pub const SHORT_REGISTER_NUMBERS: &str = "short_register_numbers";
/// a register, address or command the manual does not list
pub const UNDOCUMENTED: &str = "undocumented";
/// a write to a read-only register
pub const READ_ONLY_WRITE: &str = "read_only_write";
/// a CAN span with an odd address or length
pub const ODD_SPAN: &str = "odd_span";
/// a reserved identifier bit is set
pub const RESERVED_BIT: &str = "reserved_bit";
/// a device ID outside the settable range
pub const INVALID_ID: &str = "invalid_id";
/// sent to every device; nobody answers
pub const BROADCAST: &str = "broadcast";
/// the gripper reports fault bits
pub const DEVICE_FAULT: &str = "device_fault";
/// a frame that belongs to no EG2 device (other CAN traffic)
pub const FOREIGN: &str = "foreign";
/// t estimated from its place in a chunk (baud rate)
pub const ESTIMATED_TIME: &str = "estimated_time";
