"""One state per gripper, folded from the records of any protocol.

The device panel, the Rerun timelines and the MCAP ``/state`` topics all read DeviceState.
Only valid frames count; values outside their documented range are not folded in (they are
flagged on the record instead), so one corrupt reading does not spike a plot.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field
from typing import Any

from decoders.model import EG2_SERIAL, FRAME, REQUEST, RESPONSE, Record
from decoders.registers import BY_NAME, fault_text, opening_mm, state_text

from .stats import unanswered

# register name -> DeviceState attribute
REGISTER_FIELDS: dict[str, str] = {
    "CMD_OPENLEN_SET": "target_opening",
    "CMD_SPEED_SET": "speed",
    "CMD_FORCE_SET": "force_setting",
    "CMD_CATCH_MOD": "catch_mode",
    "CMD_MAX_OPENLEN": "max_opening",
    "CMD_MIN_OPENLEN": "min_opening",
    "CMD_FORCE_ACT": "force",
    "CMD_OPENLEN_ACT": "opening",
    "CMD_CURRENT": "current",
    "CMD_TEMP": "temperature_c",
    "CMD_ERRORCODE": "fault",
    "CMD_STATUS": "state",
}


@dataclass
class DeviceState:
    bus: str
    device: int
    protocol: str
    t: float | None = None
    opening: int | None = None  # 0-1000
    force: int | None = None  # measured
    current: int | None = None
    temperature_c: int | None = None
    state: int | None = None
    fault: int | None = None
    target_opening: int | None = None
    speed: int | None = None
    force_setting: int | None = None
    catch_mode: int | None = None
    max_opening: int | None = None
    min_opening: int | None = None
    last_command: str | None = None
    frames: int = 0
    errors: int = 0
    unanswered: int = 0
    latency_ms: float | None = None
    extra: dict[str, Any] = field(default_factory=dict)

    def to_dict(self) -> dict[str, Any]:
        d = asdict(self)
        d["opening_mm"] = None if self.opening is None else opening_mm(self.opening)
        d["target_mm"] = None if self.target_opening is None else opening_mm(self.target_opening)
        d["state_text"] = None if self.state is None else state_text(self.state)
        d["fault_text"] = [] if self.fault is None else fault_text(self.fault)
        return d


class Tracker:
    """Folds records into DeviceStates; ``update`` returns the state a record changed."""

    def __init__(self) -> None:
        self.states: dict[tuple[str, int], DeviceState] = {}

    def update(self, rec: Record) -> DeviceState | None:
        if rec.kind != FRAME or rec.device is None:
            return None
        key = (rec.bus, rec.device)
        st = self.states.get(key)
        if st is None:
            st = self.states[key] = DeviceState(rec.bus, rec.device, rec.protocol)
        st.frames += 1
        if rec.t is not None:
            st.t = rec.t
        if rec.errors:
            st.errors += 1
            return st
        if rec.direction == REQUEST:
            st.last_command = rec.summary or rec.name
            if unanswered(rec):
                st.unanswered += 1
        elif rec.direction == RESPONSE and rec.latency_ms is not None:
            st.latency_ms = rec.latency_ms
        if rec.protocol == EG2_SERIAL:
            self._serial(st, rec)
        else:
            self._registers(st, rec)
        return st

    @staticmethod
    def _set(st: DeviceState, name: str, value: Any) -> None:
        reg = BY_NAME.get(name)
        if isinstance(value, int) and reg is not None and reg.range_warning(value):
            return
        attr = REGISTER_FIELDS.get(name)
        if attr is not None:
            setattr(st, attr, value)

    def _registers(self, st: DeviceState, rec: Record) -> None:
        f = rec.fields
        values = f.get("values")
        if isinstance(values, dict):
            for name, value in values.items():
                self._set(st, name, value)
        elif rec.direction == REQUEST and "value" in f and isinstance(f.get("name"), str):
            self._set(st, f["name"], f["value"])

    def _serial(self, st: DeviceState, rec: Record) -> None:
        f, code = rec.fields, rec.code
        if rec.direction == REQUEST:
            if code in (0x10, 0x18):  # catch: close with a force limit
                st.speed, st.force_setting, st.target_opening = f.get("speed"), f.get("force_g"), 0
                st.catch_mode = 1 if code == 0x18 else 0
            elif code == 0x11:
                st.speed, st.target_opening = f.get("speed"), 1000
            elif code == 0x54 and "position" in f:
                st.target_opening = f["position"]
            elif code == 0x12:
                st.max_opening, st.min_opening = f.get("max"), f.get("min")
            return
        if code == 0x13:
            st.max_opening, st.min_opening = f.get("max"), f.get("min")
        elif code == 0xD9 and "position" in f:
            st.opening = f["position"]
        elif code == 0x41:
            for attr, key in (
                ("state", "state"),
                ("fault", "fault"),
                ("temperature_c", "temperature_c"),
                ("opening", "position"),
                ("force_setting", "force_setting_g"),
            ):
                if key in f:
                    setattr(st, attr, f[key])
        elif code == 0x14 and isinstance(f.get("probable"), dict):
            p = f["probable"]
            st.opening, st.force = p.get("opening", st.opening), p.get("force", st.force)
