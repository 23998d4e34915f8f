"""python-can's ``can.Message`` <-> the decoders' ``CanFrame``: the one conversion, both ways.

Used by the CAN capture readers, the live CAN tap and the simulated gripper, so a frame means
the same everywhere:

- ``dlc`` is python-can's: the DLC of a remote frame (which carries no data), the byte count of
  a CAN FD frame, and up to 15 for a classic frame with 8 data bytes;
- more than 8 data bytes make a frame CAN FD even where a file format lost the flag (.csv);
- the channel is kept as text (python-can numbers ASC/BLF channels, names socketcan ones).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from decoders.model import CanFrame

if TYPE_CHECKING:  # python-can is imported where a Message is made: it costs 0.1 s to import
    import can


def message_to_frame(msg: can.Message, t: float | None = None) -> CanFrame:
    """``msg`` as a CanFrame; ``t`` replaces the message's timestamp (a live tap puts its
    frames on the host clock)."""
    data = bytes(msg.data) if msg.data is not None else b""
    channel = msg.channel
    return CanFrame(
        t=msg.timestamp if t is None else t,
        arbitration_id=msg.arbitration_id,
        data=data,
        is_extended=msg.is_extended_id,
        is_remote=msg.is_remote_frame,
        is_error=msg.is_error_frame,
        is_fd=msg.is_fd or len(data) > 8,
        dlc=msg.dlc,
        channel=None if channel is None else str(channel),
    )


def frame_to_message(frame: CanFrame) -> can.Message:
    """``frame`` as a python-can Message (a frame without a time gets python-can's 0.0)."""
    import can

    return can.Message(
        timestamp=0.0 if frame.t is None else frame.t,
        arbitration_id=frame.arbitration_id,
        is_extended_id=frame.is_extended,
        is_remote_frame=frame.is_remote,
        is_error_frame=frame.is_error,
        is_fd=frame.is_fd,
        dlc=frame.length,
        data=frame.data,
        channel=frame.channel,
    )
