"""Trouble on a CAN bus as a SocketCAN controller reports it (linux/can/error.h): the error
frames of a node that goes error-warning, error-passive and bus-off, and of its restart.

Each error while transmitting adds 8 to the node's transmit error counter (ISO 11898-1): at 96
the controller warns, at 128 it is error-passive, past 255 it is bus-off and takes no part in
the bus until it is restarted (the kernel's ``restart-ms``), when the counters start again at 0.
"""

from __future__ import annotations

from typing import Final

from decoders import build
from decoders.model import CanFrame

TX_ERROR_STEP: Final = 8
WARNING_LEVEL: Final = 96
PASSIVE_LEVEL: Final = 128
BUS_OFF_LEVEL: Final = 256
FRAME_GAP_S: Final = 0.001  # between two error frames of the ramp
# the controller's status as the counter reaches a level
STATUS_AT: Final = {
    WARNING_LEVEL: build.CAN_ERR_CRTL_TX_WARNING,
    PASSIVE_LEVEL: build.CAN_ERR_CRTL_TX_PASSIVE,
}


def bus_off_frames(off_s: float) -> list[tuple[float, CanFrame]]:
    """(delay, error frame) from the first error: bit errors on transmission with the counters,
    error-warning at 96, error-passive at 128, bus-off at 256; ``off_s`` later the restart and
    the return to error-active. The node is silent from the first frame to the restart."""
    out: list[tuple[float, CanFrame]] = []
    t = 0.0
    bit_error = build.CAN_ERR_PROT | build.CAN_ERR_BUSERROR
    violation = build.CAN_ERR_PROT_BIT0 | build.CAN_ERR_PROT_TX
    for tx_errors in range(TX_ERROR_STEP, BUS_OFF_LEVEL, TX_ERROR_STEP):
        out.append(
            (t, build.can_error_frame(bit_error, protocol=violation, counters=(tx_errors, 0)))
        )
        t += FRAME_GAP_S
        if tx_errors in STATUS_AT:
            crtl = build.can_error_frame(
                build.CAN_ERR_CRTL, controller=STATUS_AT[tx_errors], counters=(tx_errors, 0)
            )
            out.append((t, crtl))
            t += FRAME_GAP_S
    out.append((t, build.can_error_frame(build.CAN_ERR_BUSOFF)))
    t += off_s
    out.append((t, build.can_error_frame(build.CAN_ERR_RESTARTED)))
    active = build.can_error_frame(
        build.CAN_ERR_CRTL, controller=build.CAN_ERR_CRTL_ACTIVE, counters=(0, 0)
    )
    out.append((t + FRAME_GAP_S, active))
    return out
