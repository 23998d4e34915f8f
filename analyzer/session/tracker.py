"""One state per gripper, folded from the records of any protocol, one sample per reading.

``Tracker.update(record)`` folds a record into its gripper's ``DeviceState`` and returns a
``StateSample`` when the record set anything (a reading, a setpoint, a command): the device panel,
the Rerun timelines and the MCAP ``/state`` topics all read the samples, so every reading keeps its
own time and nothing is downsampled. Only valid frames set values, and a frame with any value
outside its documented range (flagged ``out_of_range`` on the record) sets none at all: a frame
misread in one value is not trusted in the others (the manual's reply with opening 59395 does not
make force 243 a reading), so one corrupt frame does not spike a plot. The command a request
carries and a response's latency are still noted. Counters (frames, errors, unanswered) move on
every frame but are not readings.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, Final

from decoders.eg2_serial import RUN_STATE, Cmd
from decoders.flags import OUT_OF_RANGE, UNANSWERED
from decoders.model import EG2_SERIAL, FRAME, REQUEST, RESPONSE, Record
from decoders.registers import BY_NAME

from ..model import StateSample, derived

# register name -> state field
REGISTER_FIELDS: Final[dict[str, str]] = {
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

# the state fields, in the order they are shown and recorded
READINGS: Final = ("opening", "force", "current", "temperature_c", "state", "fault")
SETTINGS: Final = (
    "target_opening",
    "speed",
    "force_setting",
    "catch_mode",
    "max_opening",
    "min_opening",
)
COUNTERS: Final = ("frames", "errors", "unanswered")
VALUE_KEYS: Final = (*READINGS, *SETTINGS, "last_command", "latency_ms", *COUNTERS)

# serial run-state response key -> state field
_RUN_STATE: Final = tuple((v.key, v.state) for v in RUN_STATE)


class DeviceState:
    """The last known state of one gripper on one bus. ``values`` holds every field of
    ``VALUE_KEYS`` (None until known); ``t`` is when it was last heard."""

    __slots__ = ("bus", "device", "protocol", "t", "values")

    def __init__(self, bus: str, device: int, protocol: str) -> None:
        self.bus = bus
        self.device = device
        self.protocol = protocol
        self.t: float | None = None
        self.values: dict[str, Any] = dict.fromkeys(VALUE_KEYS)
        for key in COUNTERS:
            self.values[key] = 0

    def __getattr__(self, name: str) -> Any:
        # state.opening, state.frames ... read the values (only called for missing attributes)
        try:
            return self.__getattribute__("values")[name]
        except KeyError:
            raise AttributeError(name) from None

    def to_dict(self) -> dict[str, Any]:
        """The whole state, flat, with millimetres and words (as a StateSample's)."""
        d: dict[str, Any] = {
            "t": self.t,
            "bus": self.bus,
            "device": self.device,
            "protocol": self.protocol,
        }
        d.update(self.values)
        return derived(d)


_UNSET: Final = dict.fromkeys(VALUE_KEYS)


def _changes_only(values: dict[str, Any], changed: dict[str, Any]) -> dict[str, Any]:
    """A sample's values without a snapshot: the fields it changed and the counters."""
    kept = _UNSET.copy()
    kept.update(changed)
    for key in COUNTERS:
        kept[key] = values[key]
    return kept


class Tracker:
    """Folds records into DeviceStates; ``update`` returns the sample a record made, if any.
    ``samples=False``: fold only (no listener reads samples; the states are still kept).
    ``snapshots=False``: a sample's values are only the fields it changed and the counters,
    the rest None (no listener reads more: ``Listener.reads_whole_states``)."""

    def __init__(self, samples: bool = True) -> None:
        self.states: dict[tuple[str, int], DeviceState] = {}
        self.samples = samples
        self.snapshots = True

    def update(self, rec: Record) -> StateSample | None:
        if rec.kind != FRAME or rec.device is None:
            return None
        key = (rec.bus, rec.device)
        st = self.states.get(key)
        if st is None:
            st = self.states[key] = DeviceState(rec.bus, rec.device, rec.protocol)
        values = st.values
        values["frames"] += 1
        if rec.t is not None:
            st.t = rec.t
        if rec.errors:
            values["errors"] += 1
            return None
        changed: dict[str, Any] = {}
        if rec.direction == REQUEST:
            changed["last_command"] = rec.summary or rec.name
            if UNANSWERED in rec.flags:
                values["unanswered"] += 1
        elif rec.direction == RESPONSE and rec.latency_ms is not None:
            changed["latency_ms"] = rec.latency_ms
        if OUT_OF_RANGE in rec.flags:
            pass  # a frame with a value out of range sets no value at all
        elif rec.protocol == EG2_SERIAL:
            _serial(rec, changed)
        else:
            _registers(rec, changed)
        if not changed:
            return None
        values.update(changed)
        if not self.samples:
            return None
        kept = values.copy() if self.snapshots else _changes_only(values, changed)
        return StateSample(rec.t, rec.bus, rec.device, st.protocol, rec.seq, changed, kept)

    def update_many(self, records: list[Record]) -> list[StateSample]:
        """The samples of a batch of records, in order."""
        update = self.update
        return [s for s in map(update, records) if s is not None]


# register name -> (state field, lowest, highest, read-only), for the fold's inner loop
_FOLD: Final[dict[str, tuple[str, int | None, int | None, bool]]] = {
    name: (attr, BY_NAME[name].lo, BY_NAME[name].hi, BY_NAME[name].access == "ro")
    for name, attr in REGISTER_FIELDS.items()
}


def _registers(rec: Record, changed: dict[str, Any]) -> None:
    """Register values into the state: none if any is out of its range, and not a request's
    write of a read-only register (both are flagged on the record, and the gripper ignores
    such a write)."""
    f = rec.fields
    request = rec.direction == REQUEST
    values = f.get("values")
    if not isinstance(values, dict):
        if not (request and "value" in f and isinstance(f.get("name"), str)):
            return
        values = {f["name"]: f["value"]}
    fold = _FOLD.get
    found: dict[str, Any] = {}
    for name, value in values.items():
        spec = fold(name)
        if spec is None:
            continue
        attr, lo, hi, read_only = spec
        if lo is not None and hi is not None and isinstance(value, int) and not lo <= value <= hi:
            return  # one value out of range: the frame sets none
        if not (request and read_only):
            found[attr] = value
    changed.update(found)


def _catch(f: dict[str, Any], changed: dict[str, Any], continuous: bool) -> None:
    """Catch: close with a force limit."""
    changed.update(
        speed=f.get("speed"),
        force_setting=f.get("force_g"),
        target_opening=0,
        catch_mode=1 if continuous else 0,
    )


def _limits(f: dict[str, Any], changed: dict[str, Any]) -> None:
    changed.update(max_opening=f.get("max"), min_opening=f.get("min"))


def _seek(f: dict[str, Any], changed: dict[str, Any]) -> None:
    if "position" in f:
        changed["target_opening"] = f["position"]


def _release(f: dict[str, Any], changed: dict[str, Any]) -> None:
    changed.update(speed=f.get("speed"), target_opening=1000)


def _position(f: dict[str, Any], changed: dict[str, Any]) -> None:
    if "position" in f:
        changed["opening"] = f["position"]


def _run_state(f: dict[str, Any], changed: dict[str, Any]) -> None:
    for key, attr in _RUN_STATE:
        if key in f:
            changed[attr] = f[key]


def _probable_state(f: dict[str, Any], changed: dict[str, Any]) -> None:
    # 0x14's layout is not documented: only the fields one client reads (docs/protocol.md)
    p = f.get("probable")
    if isinstance(p, dict):
        for key, attr in (("opening", "opening"), ("force", "force")):
            if p.get(key) is not None:
                changed[attr] = p[key]


_Fold = Callable[[dict[str, Any], dict[str, Any]], None]

_SERIAL_REQUESTS: Final[dict[int, _Fold]] = {
    Cmd.MOVE_CATCH_XG: lambda f, c: _catch(f, c, continuous=False),
    Cmd.MOVE_CATCH2_XG: lambda f, c: _catch(f, c, continuous=True),
    Cmd.MOVE_RELEASE: _release,
    Cmd.SEEKPOS: _seek,
    Cmd.SET_EG_PARA: _limits,
}
_SERIAL_RESPONSES: Final[dict[int, _Fold]] = {
    Cmd.READ_EG_PARA: _limits,
    Cmd.READ_ACTPOS: _position,
    Cmd.READ_EG_RUNSTATE: _run_state,
    Cmd.READ_EG_STATE: _probable_state,
}


def _serial(rec: Record, changed: dict[str, Any]) -> None:
    table = _SERIAL_REQUESTS if rec.direction == REQUEST else _SERIAL_RESPONSES
    fold = table.get(rec.code) if rec.code is not None else None
    if fold is not None:
        fold(rec.fields, changed)
