"""The Rerun entity contract (docs/rerun.md): entity paths, timelines, series names and colours,
the state lanes' configuration. The listener (``analyzer/plot/listener.py``) logs these entities and
the blueprint (``analyzer/plot/blueprint.py``) lays them out; both read them from here only.

```
/<bus>/<device>/opening_mm/measured   /opening_mm/target       scalars (mm)
/<bus>/<device>/force/measured        /force/limit             scalars; /force/faults: red marks
/<bus>/<device>/current               /temperature_c           scalars
/<bus>/<device>/state                 /fault                   state lanes
/<bus>/<device>/commands                                       text log
/<bus>/<device>/cycles                /cycles/log              cycle lane (by outcome), its log
/<bus>/errors                                                  text log, levels from the flags
/<bus>/health/load_pct  frames_per_s  errors_per_s  unanswered_per_s  latency_ms
/<bus>/health/state                                            CAN controller state lane
/session/errors                                                text log: events of no bus
```
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Final

import numpy as np
import rerun as rr

from decoders.registers import STATE_TEXT, fault_text, opening_mm

from ..cycles.looks import LOOKS
from ..health.seconds import STATES as CONTROLLER_STATES

CAPTURE_TIME: Final = "capture_time"  # the records' own timestamps
FRAME: Final = "frame"  # the record's seq: the same number the TUI and the MCAP recording show

COMMANDS: Final = "commands"
ERRORS: Final = "errors"
HEALTH: Final = "health"
FORCE: Final = "force"  # the force plot's entities: measured, limit and the fault marks
OPENING: Final = "opening_mm"  # the opening plot's: measured and target
CURRENT: Final = "current"
TEMPERATURE: Final = "temperature_c"
FAULT_MARKS: Final = f"{FORCE}/faults"
STATE: Final = "state"
FAULT: Final = "fault"
SESSION: Final = "session"  # where events that belong to no bus go (drops, a failed output)
SESSION_ERRORS: Final = f"/{SESSION}/{ERRORS}"
CYCLES: Final = "cycles"  # a gripper's cycle lane
CYCLE_LOG: Final = f"{CYCLES}/log"  # ... and its log
# under /<bus>/health/: the load, the rates, the latencies, the CAN controller's state
LOAD: Final = "load_pct"
FRAMES_PER_S: Final = "frames_per_s"
ERRORS_PER_S: Final = "errors_per_s"
UNANSWERED_PER_S: Final = "unanswered_per_s"
RATES: Final = (FRAMES_PER_S, ERRORS_PER_S, UNANSWERED_PER_S)
LATENCY: Final = "latency_ms"
CONTROLLER: Final = "state"

FAULT_MARK_COLOR: Final = 0xE3000BFF


def bus_path(bus: str) -> str:
    """``/<bus>``: a bus name as one entity path part (``/dev/ttyUSB0`` stays one part)."""
    return "/" + rr.escape_entity_path_part(bus)


def gripper_path(bus: str, device: int) -> str:
    return f"{bus_path(bus)}/{device}"


_MM: Final = np.array([opening_mm(v) for v in range(1001)])


def opening_mm_column(openings: np.ndarray) -> np.ndarray:
    """``opening_mm`` of a column of openings (0-1000 by table; anything else one by one)."""
    whole = openings.astype(np.int64)
    if len(whole) and (whole == openings).all() and whole.min() >= 0 and whole.max() <= 1000:
        return np.asarray(_MM[whole])
    return np.array([opening_mm(v) for v in openings.tolist()], dtype=np.float64)


@dataclass(frozen=True)
class Series:
    """One plotted quantity: which state field feeds it, where it goes, how it looks."""

    field: str  # the StateSample field
    entity: str  # under /<bus>/<device>/
    name: str  # the legend
    color: int  # 0xRRGGBBAA
    convert: Callable[[np.ndarray], np.ndarray] | None = None  # readings -> plotted values
    step: bool = False  # a setting holds until the next one: drawn as steps


SERIES: Final = (
    Series("opening", f"{OPENING}/measured", "opening (mm)", 0x1F77B4FF, opening_mm_column),
    Series(
        "target_opening", f"{OPENING}/target", "target (mm)", 0x9EC9E8FF, opening_mm_column, True
    ),
    Series("force", f"{FORCE}/measured", "force", 0xFF7F0EFF),
    Series("force_setting", f"{FORCE}/limit", "force limit", 0x8C8C8CFF, step=True),
    Series("current", CURRENT, "current", 0x2CA02CFF),
    Series("temperature_c", TEMPERATURE, "temperature (°C)", 0x9467BDFF),
)
# what each plot of a gripper shows, in legend order
FORCE_ENTITIES: Final = (
    *(s.entity for s in SERIES if s.entity.startswith(f"{FORCE}/")),
    FAULT_MARKS,
)
OPENING_ENTITIES: Final = tuple(s.entity for s in SERIES if s.entity.startswith(f"{OPENING}/"))

# the state lanes: field -> entity
LANES: Final = {"state": STATE, "fault": FAULT}

# per-bus health: entity under /<bus>/health/ -> (legend after the bus's name, one colour per
# bus, in the order the buses appear): a view shows one unit of every bus at once
BUS_COLORS: Final = (0x1F77B4FF, 0x2CA02CFF, 0x9467BDFF, 0x8C564BFF, 0x17BECFFF, 0x7F7F7FFF)
HEALTH_SERIES: Final = {
    LOAD: ("load %", BUS_COLORS),
    FRAMES_PER_S: ("frames/s", BUS_COLORS),
    ERRORS_PER_S: ("errors/s", (0xE3000BFF, 0xF46D43FF, 0xA50026FF, 0xFDAE61FF)),
    UNANSWERED_PER_S: ("unanswered/s", (0xFF7F0EFF, 0xFDB863FF, 0xB35806FF, 0xFEE0B6FF)),
    LATENCY: ("latency (ms)", BUS_COLORS),
}
# the CAN controller's states (health.seconds.STATES), the worst last
CONTROLLER_COLORS: Final = (0x2CA02CFF, 0xFFB000FF, 0xFF7F0EFF, 0xE3000BFF)

# the manual's run states (1-6), coloured by what they mean for a grip
STATE_COLORS: Final = {
    1: 0x9EC9E8FF,  # fully open, idle
    2: 0x1F77B4FF,  # fully closed, idle
    3: 0xBCBD22FF,  # stopped, idle
    4: 0xFF7F0EFF,  # closing
    5: 0x17BECFFF,  # opening
    6: 0x2CA02CFF,  # stopped by the force limit: holding a part
}
FAULT_VALUES: Final = range(32)  # the five documented fault bits, every combination
NO_FAULT_COLOR: Final = 0x2CA02CFF


def state_configuration() -> rr.StateConfiguration:
    """The run state lane: the manual's states by name and colour (values are the numbers)."""
    return rr.StateConfiguration(
        values=[str(n) for n in STATE_TEXT],
        labels=list(STATE_TEXT.values()),
        colors=[STATE_COLORS[n] for n in STATE_TEXT],
    )


def fault_configuration() -> rr.StateConfiguration:
    """The fault lane: every combination of the documented fault bits, named; any fault red."""
    return rr.StateConfiguration(
        values=[str(v) for v in FAULT_VALUES],
        labels=[", ".join(fault_text(v)) or "no fault" for v in FAULT_VALUES],
        colors=[NO_FAULT_COLOR if v == 0 else FAULT_MARK_COLOR for v in FAULT_VALUES],
    )


def series_style(series: Series) -> rr.SeriesLines:
    """A gripper's series, named and coloured (logged static, once)."""
    step = rr.components.InterpolationMode.StepAfter if series.step else None
    return rr.SeriesLines(names=series.name, colors=series.color, interpolation_mode=step)


def fault_marks_style() -> rr.SeriesPoints:
    """The red crosses on the force plot where a record has an error or a fault."""
    return rr.SeriesPoints(
        names="error or fault", colors=FAULT_MARK_COLOR, markers="cross", marker_sizes=6.0
    )


def health_style(entity: str, bus: str, index: int) -> rr.SeriesLines:
    """A bus's health series, named after the bus, coloured by the bus's place (``index``)."""
    name, colors = HEALTH_SERIES[entity]
    return rr.SeriesLines(names=f"{bus} {name}", colors=colors[index % len(colors)])


def controller_configuration() -> rr.StateConfiguration:
    """The CAN controller's state lane: error active green, warning amber, passive orange,
    bus-off red."""
    return rr.StateConfiguration(
        values=list(CONTROLLER_STATES),
        labels=[s.replace("_", " ") for s in CONTROLLER_STATES],
        colors=np.array(CONTROLLER_COLORS, dtype=np.uint32),  # 4 ints: not one RGBA colour
    )


def cycles_configuration() -> rr.StateConfiguration:
    """A gripper's cycle lane: each outcome by name and colour (``cycles/looks.py``)."""
    return rr.StateConfiguration(
        values=list(LOOKS),
        labels=[look.label for look in LOOKS.values()],
        colors=np.array([look.color for look in LOOKS.values()], dtype=np.uint32),
    )
