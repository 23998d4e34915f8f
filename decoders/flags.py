"""Machine-readable codes for what is wrong or notable about a record (``Record.flags``).

Every error and warning a stage puts on a record in words also puts one of these codes in
``Record.flags``, so statistics, the device state, the TUI's problems panel and other programs
read codes and never match wording. The words may improve; the codes are a contract (JSONL key
``flags``; docs/contracts.md lists them).
"""

from __future__ import annotations

from typing import Final

# -- framing and integrity (errors) --------------------------------------------------------
BAD_CHECKSUM: Final = "bad_checksum"  # serial sum or Modbus CRC does not match
GARBAGE: Final = "garbage"  # bytes that belong to no frame
TRUNCATED: Final = "truncated"  # a frame cut off by the end of the input
MALFORMED: Final = "malformed"  # a frame whose payload does not fit its command's layout
CAN_ERROR_FRAME: Final = "can_error_frame"  # a CAN error frame seen on the bus
DECODER_ERROR: Final = "decoder_error"  # a decoder bug caught on this frame

# -- the capture's own end (not the bus: no error) -----------------------------------------
CUT_OFF: Final = "cut_off"  # a frame begun, or a request waiting, when the capture was stopped

# -- request/response pairing --------------------------------------------------------------
UNANSWERED: Final = "unanswered"  # a request that never got its response
ORPHAN_RESPONSE: Final = "orphan_response"  # a response with no request before it
RETRANSMISSION: Final = "retransmission"  # the same request sent again before an answer
LENGTH_MISMATCH: Final = "length_mismatch"  # a response of another length than asked for
RESPONSE_MISMATCH: Final = "response_mismatch"  # an echo or write response unlike its request
UNTRUSTED_REQUEST: Final = "untrusted_request"  # named from a request whose checksum failed
AMBIGUOUS_DIRECTION: Final = "ambiguous_direction"  # fits both request and response shapes

# -- values and the manual's rules ---------------------------------------------------------
OUT_OF_RANGE: Final = "out_of_range"  # a value outside its documented range
CLOSER_THAN_5MS: Final = "closer_than_5ms"  # commands to one gripper less than 5 ms apart
DURING_SAVE: Final = "during_save"  # a command within 1 s of a parameter save
WRITE_FAILED: Final = "write_failed"  # the gripper answered a write with a failure status
EXCEPTION_RESPONSE: Final = "exception_response"  # a Modbus exception response
SWAPPED_CRC: Final = "swapped_crc"  # Modbus CRC sent high byte first (as the manual prints)
SHORT_REGISTER_NUMBERS: Final = "short_register_numbers"  # 10 for 1010, as some clients send
UNDOCUMENTED: Final = "undocumented"  # a register, address or command the manual does not list
READ_ONLY_WRITE: Final = "read_only_write"  # a write to a read-only register
ODD_SPAN: Final = "odd_span"  # a CAN span with an odd address or length
RESERVED_BIT: Final = "reserved_bit"  # a reserved identifier bit is set
INVALID_ID: Final = "invalid_id"  # a device ID outside the settable range
BROADCAST: Final = "broadcast"  # sent to every device; nobody answers
DEVICE_FAULT: Final = "device_fault"  # the gripper reports fault bits

# -- everything else on the bus ------------------------------------------------------------
FOREIGN: Final = "foreign"  # a frame that belongs to no EG2 device (other CAN traffic)

# -- timing --------------------------------------------------------------------------------
ESTIMATED_TIME: Final = "estimated_time"  # t estimated from its place in a chunk (baud rate)

DESCRIPTIONS: Final[dict[str, str]] = {
    BAD_CHECKSUM: "checksum or CRC does not match",
    GARBAGE: "bytes that belong to no frame",
    TRUNCATED: "frame cut off by the end of the input",
    MALFORMED: "payload does not fit the command's layout",
    CAN_ERROR_FRAME: "CAN error frame",
    DECODER_ERROR: "internal decoder error on this frame",
    CUT_OFF: "cut off by the capture's stop (not a bus error)",
    UNANSWERED: "request never answered",
    ORPHAN_RESPONSE: "response without a request",
    RETRANSMISSION: "request sent again before the first was answered",
    LENGTH_MISMATCH: "response length differs from the request",
    RESPONSE_MISMATCH: "response does not match its request",
    UNTRUSTED_REQUEST: "named from a request whose checksum failed",
    AMBIGUOUS_DIRECTION: "could be a request or a response",
    OUT_OF_RANGE: "value outside its documented range",
    CLOSER_THAN_5MS: "less than 5 ms after the previous command to this gripper",
    DURING_SAVE: "less than 1 s after a parameter save",
    WRITE_FAILED: "the gripper reported a failed write",
    EXCEPTION_RESPONSE: "Modbus exception response",
    SWAPPED_CRC: "CRC sent high byte first",
    SHORT_REGISTER_NUMBERS: "register numbers without the 1000 offset",
    UNDOCUMENTED: "register, address or command not in the manual",
    READ_ONLY_WRITE: "write to a read-only register",
    ODD_SPAN: "CAN span with an odd address or length",
    RESERVED_BIT: "reserved identifier bit set",
    INVALID_ID: "device ID outside the settable range",
    BROADCAST: "broadcast: nobody answers",
    DEVICE_FAULT: "the gripper reports a fault",
    FOREIGN: "not an EG2 frame",
    ESTIMATED_TIME: "time estimated from the position in a read (baud rate)",
}

ALL: Final = frozenset(DESCRIPTIONS)
