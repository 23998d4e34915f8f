"""The Parquet columns of decoded records (docs/contracts.md, "Parquet"): one schema for every
capture, derived from the register map and the decoders' field tables.

- The record columns: the JSONL keys except ``fields``, with the same names and in the same order.
- One column per register of the map (``registers.REGISTERS``), named as the manual names it
  (``CMD_OPENLEN_ACT``, the key of ``fields.values`` in JSONL): every register value a Modbus or
  CAN frame carries, whichever way it carries it. An opening register (0-1000 of the stroke) has a
  ``_mm`` twin in millimetres, as the decoders give openings in ``fields``.
- ``fields`` flattened per protocol family: ``serial_<key>`` (eg2-serial), ``modbus_<key>``
  (modbus-rtu), ``can_<key>`` (eg2-can and foreign ``can`` frames); a nested object's keys are
  joined with ``_`` (``serial_probable_opening``). The families name the same key differently
  (``id`` is the gripper's number on serial, the identifier's hex on CAN), hence the prefixes.
- ``other_fields``: the JSON text of whatever else a record's ``fields`` held (a register
  outside the map, a key a newer decoder added), null when nothing: no value is ever dropped.

Units are in each column's field metadata (``unit``), with the register's meaning
(``description``) where the register map gives one.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass
from typing import Final

import pyarrow as pa
import pyarrow.compute as pc

from decoders import eg2_serial
from decoders.model import EG2_CAN, EG2_SERIAL, FOREIGN_CAN, MODBUS_RTU
from decoders.registers import REGISTERS, opening_mm

INT: Final = pa.int64()
FLOAT: Final = pa.float64()
STR: Final = pa.string()
BOOL: Final = pa.bool_()
STR_LIST: Final = pa.list_(STR)
INT_LIST: Final = pa.list_(INT)

MM: Final = "mm"
MM_SUFFIX: Final = "_mm"  # an opening's twin in millimetres, as the decoders name it
STROKE: Final = "1/1000 of the stroke"  # the unit of an opening 0-1000 (1000 = 70 mm)
UNITS: Final = {"mm": STROKE, "g": "g", "°C": "°C"}  # decoder/register unit -> column unit

# the JSONL keys of a record (Record.to_dict), in order, with their column types and units;
# ``fields`` is flattened into the columns below
RECORD_COLUMNS: Final[tuple[tuple[str, pa.DataType, str], ...]] = (
    ("t", FLOAT, "s"),
    ("bus", STR, ""),
    ("protocol", STR, ""),
    ("kind", STR, ""),
    ("offset", INT, ""),
    ("index", INT, ""),
    ("length", INT, ""),
    ("direction", STR, ""),
    ("device", INT, ""),
    ("code", INT, ""),
    ("name", STR, ""),
    ("raw", STR, ""),
    ("errors", STR_LIST, ""),
    ("warnings", STR_LIST, ""),
    ("flags", STR_LIST, ""),
    ("summary", STR, ""),
    ("seq", INT, ""),
    ("pair", INT, ""),
    ("latency_ms", FLOAT, "ms"),
)

# protocol -> the family whose columns hold its fields
FAMILY: Final = {EG2_SERIAL: "serial", MODBUS_RTU: "modbus", EG2_CAN: "can", FOREIGN_CAN: "can"}


@dataclass(frozen=True, slots=True)
class FieldColumn:
    """One key of ``fields`` in one family: its JSON key, its type, its unit."""

    key: str
    type: pa.DataType
    unit: str = ""


def _serial_table_fields() -> list[FieldColumn]:
    """The keys of the serial decoder's declarative layouts, with their millimetre twins."""
    found: dict[str, FieldColumn] = {}
    for cmd in eg2_serial.COMMANDS.values():
        for layout in (cmd.request, cmd.response):
            if callable(layout):
                continue
            for f in layout:
                found[f.key] = FieldColumn(f.key, INT, UNITS.get(f.unit, f.unit))
                if f.unit == "mm":
                    found[f.key + MM_SUFFIX] = FieldColumn(f.key + MM_SUFFIX, FLOAT, MM)
    return list(found.values())


PROBABLE: Final = pa.struct([("opening", INT), ("force", INT), ("force_threshold", INT)])
PARTIAL: Final = pa.list_(
    pa.struct([("address", INT), ("byte", STR), ("register", STR), ("half", STR)])
)

# the keys of ``fields`` per family: the serial layouts' own, then what the decoders' custom
# payloads, headers and fallbacks add (decoders/eg2_serial.py, modbus_pdu.py, eg2_can.py)
FAMILY_FIELDS: Final[dict[str, tuple[FieldColumn, ...]]] = {
    "serial": (
        FieldColumn("id", INT),
        *_serial_table_fields(),
        FieldColumn("status", STR),
        FieldColumn("new_id", INT),
        FieldColumn("id_width", INT),
        FieldColumn("state", INT),
        FieldColumn("state_text", STR),
        FieldColumn("fault", INT),
        FieldColumn("fault_text", STR_LIST),
        FieldColumn("temperature_c", INT, "°C"),
        FieldColumn("force_setting_g", INT, "g"),
        FieldColumn("probable", PROBABLE),
        FieldColumn("values", INT_LIST),
        FieldColumn("data", STR),
        FieldColumn("extra", STR),
        FieldColumn("alias", STR),
    ),
    "modbus": (
        FieldColumn("slave", INT),
        FieldColumn("function", INT),
        FieldColumn("start", INT),
        FieldColumn("count", INT),
        FieldColumn("byte_count", INT),
        FieldColumn("registers", STR_LIST),
        FieldColumn("register", INT),
        FieldColumn("name", STR),
        FieldColumn("value", INT),
        FieldColumn("numbering", STR),
        FieldColumn("address", INT),
        FieldColumn("coil", INT),
        FieldColumn("bits", INT_LIST),
        FieldColumn("values_raw", INT_LIST),
        FieldColumn("exception_code", INT),
        FieldColumn("exception_text", STR),
    ),
    "can": (
        FieldColumn("op", STR),
        FieldColumn("address", INT),
        FieldColumn("id", STR),
        FieldColumn("dlc", INT),
        FieldColumn("length", INT),
        FieldColumn("registers", STR_LIST),
        FieldColumn("written_bytes", INT),
        FieldColumn("padded", BOOL),
        FieldColumn("broadcast", BOOL),
        FieldColumn("partial", PARTIAL),
        FieldColumn("state_text", STR),
        FieldColumn("fault_text", STR_LIST),
        FieldColumn("data", STR),
        FieldColumn("extended", BOOL),
        FieldColumn("error_class", INT),
        FieldColumn("fd", BOOL),
        FieldColumn("eg2_device", INT),
    ),
}

# ``fields.values`` (Modbus and CAN) and the Modbus single write's ``name``/``value``: by name
VALUES_KEY: Final = "values"
REGISTER_VALUES: Final = pa.struct([(r.name, INT) for r in REGISTERS])
OTHER_FIELDS: Final = "other_fields"


@functools.cache
def mm_table() -> pa.Array:
    """An opening register's value (0-65535) -> millimetres, as ``opening_mm`` rounds it."""
    return pa.array([opening_mm(v) for v in range(1 << 16)], FLOAT)


# typed once: pyarrow infers a Python value's type at every call (and tries to import dateutil)
_LOWEST: Final = pa.scalar(0, INT)
_BEYOND: Final = pa.scalar(1 << 16, INT)
_NO_OPENING: Final = pa.scalar(None, INT)


def millimetres(opening: pa.Array | pa.ChunkedArray) -> pa.Array | pa.ChunkedArray:
    """Opening values in millimetres, as ``opening_mm`` gives them (null outside 0-65535)."""
    inside = pc.and_(pc.greater_equal(opening, _LOWEST), pc.less(opening, _BEYOND))
    return pc.take(mm_table(), pc.if_else(inside, opening, _NO_OPENING))


def described_field(
    name: str, type_: pa.DataType, unit: str = "", description: str = ""
) -> pa.Field:
    """A column with its unit and meaning in the field's metadata (``unit``, ``description``)."""
    meta = {}
    if unit:
        meta[b"unit"] = unit.encode()
    if description:
        meta[b"description"] = description.encode()
    return pa.field(name, type_, metadata=meta or None)


Path = tuple[str, ...]  # a value's place in a parsed record: ("fields_can", "values", "CMD_TEMP")


def parse_key(family: str) -> str:
    """The key ``fields`` is renamed to in a family's records before parsing."""
    return f"fields_{family}"


def _family_columns() -> list[tuple[pa.Field, Path]]:
    """The columns of ``fields`` with where each is parsed from; a nested object's keys are
    columns of their own."""
    out: list[tuple[pa.Field, Path]] = []
    for family, columns in FAMILY_FIELDS.items():
        for col in columns:
            path = (parse_key(family), col.key)
            if pa.types.is_struct(col.type):
                out += [
                    (described_field(f"{family}_{col.key}_{c.name}", c.type), (*path, c.name))
                    for c in col.type.fields
                ]
            else:
                out.append((described_field(f"{family}_{col.key}", col.type, col.unit), path))
    return out


def _register_fields() -> list[pa.Field]:
    out = []
    for r in REGISTERS:
        unit = UNITS.get(r.unit, r.unit)
        out.append(described_field(r.name, INT, unit, f"{r.number} {r.key}: {r.meaning}"))
        if r.unit == "mm":
            out.append(described_field(r.name + MM_SUFFIX, FLOAT, MM, f"{r.number} {r.key} in mm"))
    return out


_RECORD: Final = [(described_field(name, t, unit), (name,)) for name, t, unit in RECORD_COLUMNS]
_FAMILY: Final = _family_columns()
_OTHER: Final = (described_field(OTHER_FIELDS, STR, description="JSON: fields held by no column"),)

#: the columns of every Parquet file ``eg2scope decode --format parquet`` writes
SCHEMA: Final = pa.schema(
    [f for f, _ in _RECORD] + _register_fields() + [f for f, _ in _FAMILY] + list(_OTHER),
    metadata={b"eg2scope": b"records"},
)
#: column -> the path of its value in a parsed record (the register columns excepted)
PATHS: Final[dict[str, Path]] = {
    f.name: path for f, path in (*_RECORD, *_FAMILY, (_OTHER[0], (OTHER_FIELDS,)))
}
#: register -> where its value may be: a Modbus or CAN frame's ``values``
REGISTER_PATHS: Final[dict[str, tuple[Path, ...]]] = {
    r.name: tuple((parse_key(f), VALUES_KEY, r.name) for f in ("modbus", "can")) for r in REGISTERS
}
#: an opening register's millimetre twin -> the register
MM_TWINS: Final = {r.name + MM_SUFFIX: r.name for r in REGISTERS if r.unit == "mm"}
#: a Modbus single write names its register and gives its value
SINGLE_WRITE: Final[tuple[Path, Path]] = (
    (parse_key("modbus"), "name"),
    (parse_key("modbus"), "value"),
)

#: every path a parsed record may hold a value at
KNOWN_PATHS: Final = frozenset(PATHS.values()).union(*REGISTER_PATHS.values())


def family_struct(family: str) -> pa.StructType:
    """The type ``fields`` of a family parses as (JSON keys, nested objects kept)."""
    children = [pa.field(c.key, c.type) for c in FAMILY_FIELDS[family]]
    if family != "serial":
        children.append(pa.field(VALUES_KEY, REGISTER_VALUES))
    return pa.struct(children)


def parse_schema() -> pa.Schema:
    """What a JSONL record parses as: its keys with ``fields`` renamed per family, and
    ``other_fields`` for what no column holds."""
    fields = [pa.field(name, type_) for name, type_, _ in RECORD_COLUMNS]
    fields += [pa.field(parse_key(family), family_struct(family)) for family in FAMILY_FIELDS]
    fields.append(pa.field(OTHER_FIELDS, STR))
    return pa.schema(fields)


PARSE_SCHEMA: Final = parse_schema()
