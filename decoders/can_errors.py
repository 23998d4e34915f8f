"""A SocketCAN error frame's layout (linux/can/error.h): its classes, the controller's status,
the error counters, and the controller state the frame reports.

An error frame is the controller's report, not a frame seen on the wire: its identifier (the
error flag masked off, as candump and python-can give it) holds the error class bits, its data
the details. data[1] is the controller's status when the class says "controller problem",
data[6] and data[7] the TX and RX error counters (marked by CAN_ERR_CNT since Linux 6.2; older
drivers fill them without the mark). The kernel reports a change of the controller's state with
one frame (``can_change_state``): "controller problem" with the new state in data[1] (warning,
passive, or active again), or the class "bus off"; "controller restarted" follows bus-off.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Final

# (bit of the identifier, key, words): CAN_ERR_TX_TIMEOUT ... CAN_ERR_RESTARTED
ERROR_CLASSES: Final = (
    (0x001, "tx_timeout", "TX timeout"),
    (0x002, "lost_arbitration", "lost arbitration"),
    (0x004, "controller", "controller problem"),
    (0x008, "protocol_violation", "protocol violation"),
    (0x010, "transceiver", "transceiver status"),
    (0x020, "no_ack", "no ACK on transmission"),
    (0x040, "bus_off", "bus off"),
    (0x080, "bus_error", "bus error"),
    (0x100, "restarted", "controller restarted"),
)
CAN_ERR_CRTL: Final = 0x004
CAN_ERR_BUSOFF: Final = 0x040
CAN_ERR_RESTARTED: Final = 0x100
CAN_ERR_CNT: Final = 0x200  # data[6] and data[7] hold the error counters

# data[1] of a controller problem: CAN_ERR_CRTL_*
CRTL_WARNING: Final = 0x04 | 0x08  # RX or TX error counter reached the warning level (96)
CRTL_PASSIVE: Final = 0x10 | 0x20  # RX or TX error counter passed 127: error passive
CRTL_ACTIVE: Final = 0x40  # recovered to error active

# the controller states an error frame can report
ERROR_ACTIVE: Final = "error_active"
ERROR_WARNING: Final = "error_warning"
ERROR_PASSIVE: Final = "error_passive"
BUS_OFF: Final = "bus_off"

#: every key ``error_report`` may count: the classes, the controller's states within
#: "controller problem", and "unspecified" for an error frame with no class bit (candump's and
#: PCAN traces' ERROR lines)
ERROR_KEYS: Final = (
    *(key for _, key, _ in ERROR_CLASSES[:3]),
    ERROR_WARNING,
    ERROR_PASSIVE,
    *(key for _, key, _ in ERROR_CLASSES[3:]),
    "unspecified",
)


@dataclass(frozen=True, slots=True)
class ErrorReport:
    """What one error frame says: its keys (``ERROR_KEYS``), the controller state it reports
    (None: none), and the error counters where it carries them."""

    keys: tuple[str, ...]
    state: str | None
    tx_errors: int | None
    rx_errors: int | None


def error_report(error_class: int, data: bytes) -> ErrorReport:
    """An error frame (its identifier without the error flag, and its data) decoded."""
    found = {key for bit, key, _ in ERROR_CLASSES if error_class & bit}
    status = data[1] if error_class & CAN_ERR_CRTL and len(data) > 1 else 0
    if status & CRTL_WARNING:
        found.add(ERROR_WARNING)
    if status & CRTL_PASSIVE:
        found.add(ERROR_PASSIVE)
    keys = tuple(key for key in ERROR_KEYS if key in found) or ("unspecified",)
    tx = rx = None
    if len(data) >= 8 and (error_class & CAN_ERR_CNT or data[6] or data[7]):
        tx, rx = data[6], data[7]
    return ErrorReport(keys, _state(error_class, status), tx, rx)


def _state(error_class: int, status: int) -> str | None:
    """The controller state an error frame reports (bus-off over the rest: the worst)."""
    if error_class & CAN_ERR_BUSOFF:
        return BUS_OFF
    if status & CRTL_PASSIVE:
        return ERROR_PASSIVE
    if status & CRTL_WARNING:
        return ERROR_WARNING
    if status & CRTL_ACTIVE or error_class & CAN_ERR_RESTARTED:
        return ERROR_ACTIVE
    return None


def error_class_words(error_class: int) -> list[str]:
    """The words of the classes set in an error frame's identifier, in bit order."""
    return [words for bit, _, words in ERROR_CLASSES if error_class & bit]
