"""The one register table of the EG2-4XX, shared by the Modbus RTU and CAN decoders.

Modbus counts 16-bit registers (1001 ... 1065, or 1 ... 65 as some hosts send them, reference
section 4); CAN counts bytes: ``CAN address = 1000 + 2 * (register - 1000)`` (section 3.1).
Run-state and fault-bit texts (section 1.3) live here too: all three protocols use them.
"""

from __future__ import annotations

from dataclasses import dataclass

from .messages import VALUE_OUT_OF_RANGE

STROKE_MM = 70.0  # 1000 = 70 mm (section 0)

STATE_TEXT: dict[int, str] = {
    1: "fully open, idle",
    2: "fully closed, idle",
    3: "stopped, idle",
    4: "closing",
    5: "opening",
    6: "stopped by the force limit while closing",
}

FAULT_BITS: tuple[str, ...] = (
    "stall",
    "over-temperature",
    "over-current",
    "driver fault",
    "internal communication fault",
)


def opening_mm(value: int) -> float:
    """Opening 0-1000 to millimetres (linear; 1000 = 70 mm)."""
    return round(value * STROKE_MM / 1000.0, 2)


def state_text(state: int) -> str:
    return STATE_TEXT.get(state, f"unknown state {state}")


def fault_text(bits: int) -> list[str]:
    """Fault bits in words; reserved bits 5-7 are named as such."""
    if not bits:  # the usual case, on every state sample a recording writes
        return []
    words = [name for i, name in enumerate(FAULT_BITS) if bits & (1 << i)]
    words += [f"reserved bit {i}" for i in range(5, 8) if bits & (1 << i)]
    words += [f"bit {i}" for i in range(8, 16) if bits & (1 << i)]
    return words


@dataclass(frozen=True, slots=True)
class Register:
    number: int  # Modbus register number, 1001 ... 1065
    name: str  # the manual's identifier
    key: str  # short snake_case name for device state and plots
    access: str  # "rw" or "ro"
    lo: int | None  # documented range, None where the manual gives none
    hi: int | None
    unit: str = ""
    signed: bool = False
    meaning: str = ""
    documented: bool = True

    @property
    def can_address(self) -> int:
        return 1000 + 2 * (self.number - 1000)

    def value(self, raw: int) -> int:
        """A 16-bit wire value as this register's integer (two's complement if signed)."""
        if self.signed and raw & 0x8000:
            return raw - 0x10000
        return raw

    def range_warning(self, value: int) -> str | None:
        if self.lo is None or self.hi is None or self.lo <= value <= self.hi:
            return None
        return VALUE_OUT_OF_RANGE.text(label=self.key, lo=self.lo, hi=self.hi, value=value)

    def describe(self, value: int) -> str:
        """``target_opening=500 (35.0 mm)``, ``temperature_c=37 °C``, ``state=1 (fully open,
        idle)``."""
        text = f"{self.key}={value}"
        if self.unit == "mm":
            return f"{text} ({opening_mm(value)} mm)"
        if self.unit:
            return f"{text} {self.unit}"
        if self.key == "state":
            return f"{text} ({state_text(value)})"
        if self.key == "fault":
            return f"{text} ({', '.join(fault_text(value)) or 'no fault'})"
        return text


# unit "mm" means the value is 0-1000 of the stroke and is also shown in millimetres
REGISTERS: tuple[Register, ...] = (
    Register(1001, "CMD_SAVE", "save", "rw", 0, 1, meaning="1 = save parameters to flash"),
    Register(1002, "CMD_SETDEFAULT", "set_default", "rw", 0, 1, meaning="1 = restore factory"),
    Register(1003, "CMD_ID", "id", "rw", 0, 254, meaning="device ID"),
    Register(1004, "CMD_BAUD", "baud", "rw", 0, 2, meaning="0 = 115200, 1 = 57600, 2 = 19200"),
    Register(1005, "CMD_CATCH_MOD", "catch_mode", "rw", 0, 1, meaning="0 single, 1 continuous"),
    Register(1006, "CMD_STOP", "stop", "rw", 0, 1, meaning="1 = stop"),
    Register(1007, "CMD_FAULTACK", "fault_clear", "rw", 0, 1, meaning="1 = clear faults"),
    Register(1010, "CMD_OPENLEN_SET", "target_opening", "rw", 0, 1000, "mm", meaning="target"),
    Register(1011, "CMD_SPEED_SET", "speed", "rw", 10, 1000, meaning="speed"),
    Register(1012, "CMD_FORCE_SET", "force", "rw", 100, 1000, "g", meaning="grip force"),
    Register(1016, "CMD_MAX_OPENLEN", "max_opening", "rw", 0, 1000, "mm", meaning="upper limit"),
    Register(1017, "CMD_MIN_OPENLEN", "min_opening", "rw", 0, 1000, "mm", meaning="lower limit"),
    Register(1060, "CMD_FORCE_ACT", "measured_force", "ro", None, None, meaning="measured force"),
    Register(1061, "CMD_OPENLEN_ACT", "measured_opening", "ro", 0, 1000, "mm", meaning="opening"),
    Register(1062, "CMD_CURRENT", "current", "ro", -2000, 2000, signed=True, meaning="current"),
    Register(1063, "CMD_TEMP", "temperature_c", "ro", 0, 100, "°C", meaning="temperature"),
    Register(1064, "CMD_ERRORCODE", "fault", "ro", 0, 0x1F, meaning="fault bits"),
    Register(1065, "CMD_STATUS", "state", "ro", 1, 6, meaning="run state"),
)

BY_NUMBER: dict[int, Register] = {r.number: r for r in REGISTERS}
BY_NAME: dict[str, Register] = {r.name: r for r in REGISTERS}
BY_KEY: dict[str, Register] = {r.key: r for r in REGISTERS}
BY_CAN_ADDRESS: dict[int, Register] = {r.can_address: r for r in REGISTERS}

FIRST, LAST = 1001, 1065
SAVE_REGISTERS = frozenset({1001, 1002})  # writes of 1 here make the gripper pause ~850 ms


def undocumented(number: int, meaning: str | None = None) -> Register:
    """A placeholder for a register the manual does not describe (flagged): inside the map's
    span by default, or anywhere else with its own ``meaning``."""
    return Register(
        number,
        f"REG_{number}",
        f"reg_{number}",
        "?",
        None,
        None,
        documented=False,
        meaning=meaning or f"undocumented register {number}",
    )


@dataclass(frozen=True, slots=True)
class Lookup:
    register: Register
    short: bool  # the host used the short numbering (10 for 1010, section 4)


def by_modbus(number: int) -> Lookup | None:
    """Resolve a Modbus register number in either numbering.

    Returns None outside the gripper's map (neither N nor 1000 + N falls in 1001-1065).
    Numbers inside the span that the manual does not document resolve to a flagged
    placeholder register.
    """
    reg = BY_NUMBER.get(number)
    if reg is not None:
        return Lookup(reg, False)
    if FIRST <= number <= LAST:
        return Lookup(undocumented(number), False)
    if 1 <= number <= LAST - 1000:
        full = number + 1000
        reg = BY_NUMBER.get(full)
        return Lookup(reg if reg is not None else undocumented(full), True)
    return None


def by_can_address(address: int) -> Register | None:
    """The register at a CAN byte address (even addresses 1002-1130), else None."""
    reg = BY_CAN_ADDRESS.get(address)
    if reg is not None:
        return reg
    if address % 2 == 0 and 1002 <= address <= 1130:
        return undocumented(1000 + (address - 1000) // 2)
    return None
