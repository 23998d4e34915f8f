"""A simulated EG2-4XX gripper: jaw motion, grip force, temperature, faults and parameters.

Pure and single-threaded: no clocks, no threads, no I/O. Every method takes the current time
(seconds, any monotonic clock) and first advances the simulation to it, so the same calls at the
same times give the same gripper. The protocol servers (``endpoints.py``) own the clock and the
locking.

The behaviour follows the reference (``protocol/EG2-4XX.md``):

- opening 0-1000 (1000 = 70 mm) moves toward a target at a rate set by the speed: speed 1000
  covers the full stroke in ``FULL_STROKE_S`` (0.7 s), speed 1 a thousand times slower;
- an object between the jaws (``place_object``) stops a closing motion at its width; the force
  then rises to the force limit and the state becomes 6 (stopped by the force limit);
- an obstruction (``place_jam``) stalls a closing jaw where it meets it: fault bit 0 (stall);
- continuous catch (CMD 0x18, or catch mode 1 for Modbus/CAN moves) closes again when the grip
  is lost (the object slips or shrinks); a single catch just stops;
- the driver warms while moving and holding and cools toward ambient; above 80 °C the
  over-temperature fault (bit 1) trips and stops the jaw, below 60 °C it clears by itself;
- fault bits 0, 2, 3, 4 are cleared by command, unless injected as permanent (they come straight
  back); while any fault is set the jaw does not move and motion commands fail;
- a parameter save or factory reset pauses the gripper for ``SAVE_PAUSE_S`` (~850 ms): it
  answers nothing meanwhile (``busy``) and its save response comes after the pause.

State codes (section 1.3): 1 fully open and idle, 2 fully closed and idle, 3 stopped and idle,
4 closing, 5 opening, 6 stopped by the force limit while closing.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Final

from decoders.registers import BY_NUMBER

# state codes (section 1.3)
FULLY_OPEN: Final = 1
FULLY_CLOSED: Final = 2
STOPPED: Final = 3
CLOSING: Final = 4
OPENING: Final = 5
GRIPPING: Final = 6

# fault bits (section 1.3)
FAULT_STALL: Final = 0x01
FAULT_OVER_TEMPERATURE: Final = 0x02
FAULT_OVER_CURRENT: Final = 0x04
FAULT_DRIVER: Final = 0x08
FAULT_COMMUNICATION: Final = 0x10
CLEARABLE: Final = FAULT_STALL | FAULT_OVER_CURRENT | FAULT_DRIVER | FAULT_COMMUNICATION
FAULT_NAMES: Final[dict[str, int]] = {
    "stall": FAULT_STALL,
    "over_temperature": FAULT_OVER_TEMPERATURE,
    "over-temperature": FAULT_OVER_TEMPERATURE,
    "over_current": FAULT_OVER_CURRENT,
    "over-current": FAULT_OVER_CURRENT,
    "driver": FAULT_DRIVER,
    "communication": FAULT_COMMUNICATION,
}

FULL_STROKE_S: Final = 0.7  # speed 1000: 0 -> 1000 in 0.7 s
SAVE_PAUSE_S: Final = 0.85  # flash erase and write (section 1.4)
FORCE_RATE_G_S: Final = 5000.0  # grip force build-up after contact (100 g in 20 ms)
OVER_TEMP_TRIP_C: Final = 80.0
OVER_TEMP_CLEAR_C: Final = 60.0
MAX_SUBSTEP_S: Final = 0.005  # integration step while something changes
REST_CURRENT: Final = -2  # the manual's example reads -2 at rest

# Modbus exception codes returned by the register interface
OK: Final = 0
ILLEGAL_FUNCTION: Final = 1
ILLEGAL_ADDRESS: Final = 2
ILLEGAL_VALUE: Final = 3
DEVICE_FAILURE: Final = 4

# jaw activity
_IDLE, _CLOSING, _OPENING, _SQUEEZING, _HOLDING = (
    "idle",
    "closing",
    "opening",
    "squeezing",
    "holding",
)


@dataclass(slots=True)
class Params:
    """What a save writes to flash and a power cycle reads back."""

    device_id: int = 1
    baud: int = 0
    catch_mode: int = 0
    speed: int = 500
    force: int = 100
    max_opening: int = 1000
    min_opening: int = 0


FACTORY: Final = Params()


class GripperModel:
    """One simulated gripper. Construct it, then call its actions with the current time.

    Parameters are public attributes (``device_id``, ``speed``, ``force``, ``catch_mode``,
    ``max_opening``, ``min_opening``, ``baud``); readings are properties (``state``,
    ``position``, ``measured_force``, ``current``, ``temperature_c``, ``fault``).
    Action methods return True on success, False where the gripper answers failure (0x55).
    """

    def __init__(
        self,
        device_id: int = 1,
        *,
        now: float = 0.0,
        opening: float = 1000.0,
        object_width: float | None = None,
        ambient_c: float = 35.0,
        temperature_c: float | None = None,
        thermal_tau_s: float = 120.0,
        heat_moving_c: float = 70.0,
        heat_holding_c: float = 25.0,
        speed: int = 500,
        force: int = 100,
        pace: float = 1.0,
    ) -> None:
        self.device_id = device_id
        self.pace = pace  # the jaw moves and squeezes this many times faster (demos, tests)
        self.id_max = 254  # serial and Modbus IDs are 1-254; CAN IDs 1-16382
        self.baud = 0
        self.catch_mode = 0
        self.speed = speed
        self.force = force
        self.max_opening = 1000
        self.min_opening = 0
        self.t = now
        self.opening = float(opening)
        self.target = self.opening
        self.object_width = object_width
        self.jam_at: float | None = None  # an obstruction the closing jaw stalls on
        self.ambient_c = ambient_c
        self.temperature = ambient_c if temperature_c is None else temperature_c
        self.thermal_tau_s = thermal_tau_s
        self.heat_moving_c = heat_moving_c  # rise above ambient when moving all the time at 1000
        self.heat_holding_c = heat_holding_c  # rise above ambient when holding 1000 g
        self.busy_until = -math.inf
        self._fault = 0
        self._permanent = 0  # injected faults that come straight back after a clear
        self._force = 0.0  # measured grip force, g
        self._activity = _IDLE
        self._continuous = False  # the current close re-closes when the grip is lost
        self._state = FULLY_OPEN if self.opening >= self.max_opening else STOPPED
        self._saved = self.params()
        self.saves = 0  # how many saves the flash has seen (for tests)

    # -- readings ---------------------------------------------------------------------------

    @property
    def state(self) -> int:
        return self._state

    @property
    def fault(self) -> int:
        return self._fault

    @property
    def position(self) -> int:
        return round(self.opening)

    @property
    def measured_force(self) -> int:
        return round(self._force)

    @property
    def temperature_c(self) -> int:
        return round(self.temperature)

    @property
    def current(self) -> int:
        """Motor current, signed: positive closing and squeezing, negative opening."""
        activity = self._activity
        if activity in (_CLOSING, _OPENING):
            amps = 120 + 0.25 * self.speed
            return int(amps) if activity == _CLOSING else -int(amps)
        if activity in (_SQUEEZING, _HOLDING) and self._force > 0:
            return min(2000, int(30 + 0.9 * self._force))
        return REST_CURRENT

    @property
    def moving(self) -> bool:
        return self._activity in (_CLOSING, _OPENING, _SQUEEZING)

    def busy(self, now: float) -> bool:
        """True during a save or factory-reset pause: the gripper answers nothing."""
        return now < self.busy_until

    def params(self) -> Params:
        return Params(
            self.device_id,
            self.baud,
            self.catch_mode,
            self.speed,
            self.force,
            self.max_opening,
            self.min_opening,
        )

    def snapshot(self) -> dict[str, Any]:
        """Everything a test or a status display wants, as plain values."""
        return {
            "device_id": self.device_id,
            "state": self.state,
            "fault": self.fault,
            "position": self.position,
            "target": round(self.target),
            "measured_force": self.measured_force,
            "current": self.current,
            "temperature_c": self.temperature_c,
            "speed": self.speed,
            "force": self.force,
            "catch_mode": self.catch_mode,
            "max_opening": self.max_opening,
            "min_opening": self.min_opening,
            "object_width": self.object_width,
            "jam_at": self.jam_at,
        }

    # -- test and demo knobs ----------------------------------------------------------------

    def place_object(self, width: float | None, now: float | None = None) -> None:
        """Put an object of this opening width (0-1000) between the jaws, or None to take it
        away. Narrowing or removing a held object loses the grip: a continuous catch closes
        again, a single catch stops."""
        if now is not None:
            self.step(now)
        self.object_width = width
        if self._activity in (_SQUEEZING, _HOLDING) and (width is None or width < self.opening):
            self._force = 0.0
            if self._continuous and self._fault == 0:
                self._activity = _CLOSING
                self._state = CLOSING
            else:
                self._activity = _IDLE
                self._state = STOPPED

    def place_jam(self, at: float | None, now: float | None = None) -> None:
        """Put an obstruction at this opening (0-1000), or None to take it away: a closing jaw
        that meets it stalls there (fault bit 0, the jaw stops)."""
        if now is not None:
            self.step(now)
        self.jam_at = at

    def inject_fault(self, kind: str, now: float | None = None, permanent: bool = False) -> None:
        """Raise a fault: "stall", "over_temperature" (heats the driver to 85 °C; it clears
        below 60 °C as it cools), "over_current", "driver" or "communication". A permanent fault
        comes straight back after a clear."""
        if now is not None:
            self.step(now)
        try:
            bit = FAULT_NAMES[kind]
        except KeyError:
            raise ValueError(
                f"unknown fault {kind!r}; choose one of {sorted(FAULT_NAMES)}"
            ) from None
        if bit == FAULT_OVER_TEMPERATURE:
            self.temperature = max(self.temperature, OVER_TEMP_TRIP_C + 5.0)
        elif permanent:
            self._permanent |= bit
        self._raise(bit)

    def power_cycle(self, now: float) -> None:
        """Switch off and on: the saved parameters come back, the jaw stands still."""
        self.step(now)
        self._apply(self._saved)
        self._halt(STOPPED)
        self._fault &= FAULT_OVER_TEMPERATURE
        self._fault |= self._permanent
        self.busy_until = -math.inf

    # -- the simulation ---------------------------------------------------------------------

    def step(self, now: float) -> None:
        """Advance the simulation to now (never backwards)."""
        while self.t < now:
            active = self._activity in (_CLOSING, _OPENING, _SQUEEZING) or (
                self._activity == _HOLDING and self._force != self.force
            )
            dt = min(now - self.t, MAX_SUBSTEP_S) if active else now - self.t
            self._advance(dt)
            self.t += dt

    def _rate(self) -> float:
        """Opening units per second at the current speed setting."""
        return max(1, self.speed) * (1000.0 / FULL_STROKE_S) / 1000.0 * self.pace

    def _advance(self, dt: float) -> None:
        activity = self._activity
        if activity == _CLOSING:
            new = self.opening - self._rate() * dt
            width, jam = self.object_width, self.jam_at
            if width is not None and self.target < width <= self.opening + 1e-9 and new <= width:
                self.opening = float(width)
                self._activity = _SQUEEZING
            elif jam is not None and self.target < jam <= self.opening + 1e-9 and new <= jam:
                self.opening = float(jam)
                self._raise(FAULT_STALL)
            elif new <= self.target:
                self.opening = self.target
                self._halt(FULLY_CLOSED if self.target <= self.min_opening else STOPPED)
            else:
                self.opening = new
        elif activity == _OPENING:
            new = self.opening + self._rate() * dt
            if new >= self.target:
                self.opening = self.target
                self._halt(FULLY_OPEN if self.target >= self.max_opening else STOPPED)
            else:
                self.opening = new
        elif activity == _SQUEEZING:
            self._force = min(float(self.force), self._force + FORCE_RATE_G_S * self.pace * dt)
            if self._force >= self.force:
                self._activity = _HOLDING
                self._state = GRIPPING
        elif activity == _HOLDING and self._force != self.force:
            self._regrip()
        self._heat(dt)

    def _heat(self, dt: float) -> None:
        activity = self._activity
        rise = 0.0
        if activity in (_CLOSING, _OPENING):
            rise = self.heat_moving_c * max(1, self.speed) / 1000.0
        elif activity in (_SQUEEZING, _HOLDING):
            rise = self.heat_holding_c * self._force / 1000.0
        equilibrium = self.ambient_c + rise
        self.temperature = equilibrium + (self.temperature - equilibrium) * math.exp(
            -dt / self.thermal_tau_s
        )
        if self.temperature > OVER_TEMP_TRIP_C and not self._fault & FAULT_OVER_TEMPERATURE:
            self._raise(FAULT_OVER_TEMPERATURE)
        elif self.temperature < OVER_TEMP_CLEAR_C and self._fault & FAULT_OVER_TEMPERATURE:
            self._fault &= ~FAULT_OVER_TEMPERATURE

    def _raise(self, bit: int) -> None:
        self._fault |= bit
        if self._activity != _IDLE:
            self._halt(STOPPED)  # a fault stops the jaw where it is

    def _halt(self, state: int) -> None:
        """The jaw stands still (not on an object): no grip force."""
        self._activity = _IDLE
        self._state = state
        self.target = self.opening
        self._force = 0.0

    def _regrip(self) -> None:
        """On the object with a (new) force setting: squeeze up to it, or ease off to it."""
        if self._force < self.force:
            self._activity = _SQUEEZING
            self._state = CLOSING
        else:
            self._force = float(self.force)
            self._activity = _HOLDING
            self._state = GRIPPING

    def _go(self, target: float, continuous: bool) -> bool:
        """Move the jaw toward target (clamped to the opening limits)."""
        if self._fault:
            return False
        target = float(min(max(target, self.min_opening), self.max_opening))
        self._continuous = continuous
        self.target = target
        holding = self._activity in (_SQUEEZING, _HOLDING)
        if target < self.opening - 1e-9:
            width = self.object_width
            if holding and width is not None and target < width:
                self._regrip()  # already on the object: keep the grip
                return True
            self._force = 0.0
            self._activity = _CLOSING
            self._state = CLOSING
        elif target > self.opening + 1e-9:
            self._force = 0.0
            self._activity = _OPENING
            self._state = OPENING
        else:
            if holding:
                self._regrip()
                return True
            self._halt(
                FULLY_CLOSED
                if target <= self.min_opening
                else FULLY_OPEN
                if target >= self.max_opening
                else STOPPED
            )
        return True

    # -- actions (serial commands; Modbus and CAN map onto them) ----------------------------

    def catch(self, speed: int, force: int, now: float, continuous: bool = False) -> bool:
        """CMD 0x10 (single) / 0x18 (continuous): close with speed 1-1000 and force 50-1000 g,
        stopping when the force limit is reached."""
        self.step(now)
        if not (1 <= speed <= 1000 and 50 <= force <= 1000):
            return False
        if self._fault:
            return False
        self.speed, self.force = speed, force
        return self._go(self.min_opening, continuous)

    def release(self, speed: int, now: float) -> bool:
        """CMD 0x11: open fully at speed 1-1000."""
        self.step(now)
        if not 1 <= speed <= 1000 or self._fault:
            return False
        self.speed = speed
        return self._go(self.max_opening, False)

    def seek(self, position: int, now: float) -> bool:
        """CMD 0x54: go to an opening 1-1000 (closing with the force limit)."""
        self.step(now)
        if not 1 <= position <= 1000:
            return False
        return self._go(position, False)

    def move_to(self, target: int, now: float, continuous: bool | None = None) -> bool:
        """Modbus 1010 / CAN 1020: go to an opening 0-1000 with the speed and force settings;
        closes in the catch mode set by register 1005 unless told otherwise."""
        self.step(now)
        if not 0 <= target <= 1000:
            return False
        return self._go(target, bool(self.catch_mode) if continuous is None else continuous)

    def stop(self, now: float) -> bool:
        """CMD 0x16: stop where the jaw is; a grip at the force limit is held."""
        self.step(now)
        if self._activity in (_CLOSING, _OPENING, _SQUEEZING):
            self._halt(STOPPED)  # (stopped before the force limit: the motor lets go)
        self._continuous = False
        return True

    def set_limits(self, max_opening: int, min_opening: int, now: float) -> bool:
        """CMD 0x12: opening limits, both 0-1000 and max >= min."""
        self.step(now)
        if not (0 <= min_opening <= max_opening <= 1000):
            return False
        self.max_opening, self.min_opening = max_opening, min_opening
        return True

    def set_speed(self, speed: int, now: float, lo: int = 1) -> bool:
        self.step(now)
        if not lo <= speed <= 1000:
            return False
        self.speed = speed
        return True

    def set_force(self, force: int, now: float, lo: int = 50) -> bool:
        self.step(now)
        if not lo <= force <= 1000:
            return False
        self.force = force
        if self._activity in (_SQUEEZING, _HOLDING):
            self._regrip()
        return True

    def clear_faults(self, now: float) -> bool:
        """CMD 0x17: clear bits 0, 2, 3, 4 (over-temperature clears only by cooling); a
        permanent fault comes straight back."""
        self.step(now)
        self._fault = (self._fault & ~CLEARABLE) | self._permanent
        return True

    def set_id(self, new_id: int, now: float) -> bool:
        """CMD 0x04: a new ID 1-254 (CAN 1-16382; 0 is never one), in effect at once (the
        response still carries the old)."""
        self.step(now)
        if not 1 <= new_id <= self.id_max:
            return False
        self.device_id = new_id
        return True

    def save(self, now: float) -> bool:
        """CMD 0x01: write the parameters to flash; the gripper then pauses SAVE_PAUSE_S."""
        self.step(now)
        self._saved = self.params()
        self.saves += 1
        self.busy_until = now + SAVE_PAUSE_S
        return True

    def restore_defaults(self, now: float) -> bool:
        """Modbus 1002 / CAN 1004: factory parameters, saved (the same pause as a save)."""
        self.step(now)
        self._apply(FACTORY)
        self._saved = self.params()
        self.busy_until = now + SAVE_PAUSE_S
        return True

    def _apply(self, p: Params) -> None:
        self.device_id, self.baud, self.catch_mode = p.device_id, p.baud, p.catch_mode
        self.speed, self.force = p.speed, p.force
        self.max_opening, self.min_opening = p.max_opening, p.min_opening

    # -- the Modbus register map (CAN addresses map onto it) -------------------------------

    def read_register(self, number: int, now: float) -> int | None:
        """The 16-bit wire value of a register 1001-1065, None if the map has no such register.
        Command registers (save, stop, ...) read 0."""
        self.step(now)
        getter = _READERS.get(number)
        if getter is None:
            return None
        return getter(self) & 0xFFFF

    def check_write(self, number: int, value: int) -> int:
        """0 if the value may be written to the register, else the Modbus exception code."""
        reg = BY_NUMBER.get(number)
        if reg is None or reg.access != "rw" or number not in _WRITERS:
            return ILLEGAL_ADDRESS
        lo, hi = (1, self.id_max) if number == 1003 else (reg.lo, reg.hi)
        if lo is not None and hi is not None and not lo <= value <= hi:
            return ILLEGAL_VALUE
        return OK

    def write_registers(self, start: int, values: list[int], now: float) -> int:
        """Write consecutive registers from start: all or nothing. Returns 0 or the Modbus
        exception code (2 unknown or read-only register, 3 bad value, 4 the gripper refused,
        e.g. a move while faulted)."""
        self.step(now)
        for i, v in enumerate(values):
            code = self.check_write(start + i, v)
            if code:
                return code
        # limits are checked as a pair against what they will be after the write
        new = dict(zip(range(start, start + len(values)), values, strict=True))
        hi, lo = new.get(1016, self.max_opening), new.get(1017, self.min_opening)
        if (1016 in new or 1017 in new) and hi < lo:
            return ILLEGAL_VALUE
        result = OK
        for number, v in new.items():
            if not _WRITERS[number](self, v, now):
                result = DEVICE_FAILURE
        return result

    def write_register(self, number: int, value: int, now: float) -> int:
        return self.write_registers(number, [value], now)


def _w_save(m: GripperModel, v: int, now: float) -> bool:
    return m.save(now) if v == 1 else True


def _w_default(m: GripperModel, v: int, now: float) -> bool:
    return m.restore_defaults(now) if v == 1 else True


def _w_id(m: GripperModel, v: int, now: float) -> bool:
    return m.set_id(v, now)


def _w_baud(m: GripperModel, v: int, now: float) -> bool:
    m.baud = v  # takes effect after a save and a power cycle (the simulator ignores it)
    return True


def _w_catch_mode(m: GripperModel, v: int, now: float) -> bool:
    m.catch_mode = v
    return True


def _w_stop(m: GripperModel, v: int, now: float) -> bool:
    return m.stop(now) if v == 1 else True


def _w_fault_ack(m: GripperModel, v: int, now: float) -> bool:
    return m.clear_faults(now) if v == 1 else True


def _w_target(m: GripperModel, v: int, now: float) -> bool:
    return m.move_to(v, now)


def _w_speed(m: GripperModel, v: int, now: float) -> bool:
    return m.set_speed(v, now, lo=10)


def _w_force(m: GripperModel, v: int, now: float) -> bool:
    return m.set_force(v, now, lo=100)


def _w_max(m: GripperModel, v: int, now: float) -> bool:
    m.max_opening = v
    return True


def _w_min(m: GripperModel, v: int, now: float) -> bool:
    m.min_opening = v
    return True


_WRITERS: Final = {
    1001: _w_save,
    1002: _w_default,
    1003: _w_id,
    1004: _w_baud,
    1005: _w_catch_mode,
    1006: _w_stop,
    1007: _w_fault_ack,
    1010: _w_target,
    1011: _w_speed,
    1012: _w_force,
    1016: _w_max,
    1017: _w_min,
}
_READERS: Final = {
    1001: lambda m: 0,
    1002: lambda m: 0,
    1003: lambda m: m.device_id,
    1004: lambda m: m.baud,
    1005: lambda m: m.catch_mode,
    1006: lambda m: 0,
    1007: lambda m: 0,
    1010: lambda m: round(m.target),
    1011: lambda m: m.speed,
    1012: lambda m: m.force,
    1016: lambda m: m.max_opening,
    1017: lambda m: m.min_opening,
    1060: lambda m: m.measured_force,
    1061: lambda m: m.position,
    1062: lambda m: m.current,
    1063: lambda m: m.temperature_c,
    1064: lambda m: m.fault,
    1065: lambda m: m.state,
}
