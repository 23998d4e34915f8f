"""The documentation says what the code does: docs/ against the code's own tables, and every link
inside the repository.

docs/ restates facts that live in the code (flag codes, JSONL keys, CSV columns, exit codes, the
register map, the command table) for people; these tests keep the two from drifting apart.
"""

from __future__ import annotations

import json
import re
import subprocess
import sys
import unicodedata
from pathlib import Path

import pytest

from analyzer import errors
from analyzer.model import SourceEvent
from decoders import flags, registers
from decoders.eg2_serial import COMMANDS
from decoders.model import Record

ROOT = Path(__file__).resolve().parents[2]
DOCS = ROOT / "docs"
PROTOCOL = DOCS / "protocol.md"
CONTRACTS = DOCS / "contracts.md"
MANUAL_FRAMES = ROOT / "tests" / "data" / "manual_frames.json"
MARKDOWN = sorted(
    [ROOT / "README.md", ROOT / "captures" / "README.md", *DOCS.glob("*.md")], key=str
)

LINK = re.compile(r"\[[^\]]*\]\(([^)\s]+)\)")
HEADING = re.compile(r"^(#{1,6})\s+(.*?)\s*$", re.MULTILINE)


def slug(heading: str) -> str:
    """GitHub's anchor for a heading: lower case, punctuation dropped, spaces to hyphens."""
    text = heading.strip().lower()
    kept = "".join(c for c in text if c in " -_" or unicodedata.category(c)[0] in "LN")
    return kept.replace(" ", "-")


def anchors(path: Path) -> set[str]:
    return {slug(m.group(2)) for m in HEADING.finditer(path.read_text(encoding="utf-8"))}


def section(path: Path, heading: str) -> str:
    """The text under a heading, up to the next heading of the same or a higher level."""
    text = path.read_text(encoding="utf-8")
    for m in HEADING.finditer(text):
        if m.group(2) == heading:
            level = len(m.group(1))
            rest = text[m.end() :]
            nxt = re.search(rf"^#{{1,{level}}}\s", rest, re.MULTILINE)
            return rest[: nxt.start()] if nxt else rest
    raise AssertionError(f"{path.name} has no heading {heading!r}")


def table(text: str, first: int = 0) -> list[list[str]]:
    """The rows (cells stripped) of the ``first``-th pipe table in text, without its header."""
    tables: list[list[list[str]]] = []
    current: list[list[str]] = []
    for line in [*text.splitlines(), ""]:
        if line.startswith("|"):
            current.append([c.strip() for c in line.strip().strip("|").split("|")])
        elif current:
            tables.append(current)
            current = []
    rows = tables[first]
    assert set(rows[1][0]) <= set("-: "), "second line of a table is its rule"
    return rows[2:]


def code_in(cell: str) -> str:
    """The first `code` span of a cell."""
    m = re.search(r"`([^`]+)`", cell)
    assert m, cell
    return m.group(1)


# -- the project stands on its own -------------------------------------------------------


@pytest.mark.parametrize("path", MARKDOWN, ids=lambda p: str(p.relative_to(ROOT)))
def test_links_stay_inside_the_repository_and_resolve(path: Path) -> None:
    for target in LINK.findall(path.read_text(encoding="utf-8")):
        if re.match(r"[a-z]+://", target):
            continue  # a web page, not a file
        file_part, _, anchor = target.partition("#")
        dest = (path.parent / file_part).resolve() if file_part else path
        assert dest.is_relative_to(ROOT), f"{target} leaves the repository"
        assert dest.exists(), f"{target}: no such file"
        if anchor:
            assert anchor in anchors(dest), f"{target}: no such heading"


def test_nothing_points_beside_the_checkout() -> None:
    """The team's notes are not shipped: no project file may send a reader or a test there."""
    outside = ["../" + "shared", "shared/" + "protocol", "shared/" + "DESIGN"]
    places = ["README.md", "docs", "analyzer", "decoders", "tests", "captures", "Makefile"]
    places += ["pyproject.toml", ".ci"]
    for place in places:
        root = ROOT / place
        for path in [root] if root.is_file() else root.rglob("*"):
            if not path.is_file() or path.suffix in {".pyc", ".bin", ".log", ".mcap"}:
                continue
            text = path.read_text(encoding="utf-8", errors="replace")
            for needle in outside:
                assert needle not in text, f"{path.relative_to(ROOT)} mentions {needle}"


# -- docs/contracts.md against the code -----------------------------------------------------


def test_jsonl_keys_are_documented_in_order() -> None:
    keys = list(Record(None, "can0", "eg2-can", "frame", 0, b"").to_dict())
    documented = [code_in(row[0]) for row in table(section(CONTRACTS, "JSONL records"))]
    assert documented == keys


def test_jsonl_examples_are_what_decode_writes() -> None:
    """The examples are real: ``decode`` writes them, byte for byte, for the sample capture."""
    examples = re.findall(r"^\{.*\}$", section(CONTRACTS, "JSONL records"), re.MULTILINE)
    assert examples
    capture = ROOT / "captures" / "serial_session.bin"
    out = subprocess.run(
        [sys.executable, "-m", "analyzer", "decode", str(capture), "-f", "jsonl"],
        capture_output=True,
        text=True,
        check=True,
        cwd=ROOT,
    ).stdout.splitlines()
    for example in examples:
        assert example in out


def test_event_record_keys_are_documented_in_order() -> None:
    keys = list(SourceEvent(0.0, "can0", 2, "opened").to_dict())
    rows = table(section(CONTRACTS, "Source events in live streams"))
    assert [code_in(row[0]) for row in rows] == keys


def test_every_flag_code_is_documented_once() -> None:
    codes = [code_in(row[0]) for row in table(section(CONTRACTS, "Flags"))]
    assert len(codes) == len(set(codes))
    assert set(codes) == flags.ALL


def test_csv_columns_are_documented() -> None:
    from analyzer.sinks.csv import COLUMNS

    block = re.search(r"```\n(seq,.*)\n```", section(CONTRACTS, "CSV"))
    assert block, "the CSV section shows its header line"
    assert block.group(1).split(",") == list(COLUMNS)


def test_exit_codes_are_documented() -> None:
    codes = {int(row[0]) for row in table(section(CONTRACTS, "Exit codes"))}
    defined = {getattr(errors, name) for name in dir(errors) if name.startswith("EXIT_")}
    assert codes == defined


# -- docs/protocol.md against the decoders' tables ------------------------------------------


def test_register_map_matches_the_register_table() -> None:
    rows = table(section(PROTOCOL, "2.1 Register map"))
    documented = {int(r[0]): (int(r[1]), int(r[2]), r[3], code_in(r[4]), r[7]) for r in rows}
    actual = {
        reg.number: (reg.number - 1000, reg.can_address, reg.name, reg.key, reg.access)
        for reg in registers.REGISTERS
    }
    assert documented == actual


@pytest.mark.parametrize("reg", registers.REGISTERS, ids=lambda r: r.name)
def test_register_ranges_match(reg: registers.Register) -> None:
    rows = table(section(PROTOCOL, "2.1 Register map"))
    cell = next(r[5] for r in rows if int(r[0]) == reg.number)
    if reg.lo is None or reg.hi is None:
        assert cell == "none given"
    elif reg.signed:
        assert cell.startswith(f"±{reg.hi}") and -reg.lo == reg.hi
    elif reg.key == "fault":
        assert cell == f"bits 0-{reg.hi.bit_length() - 1}"
    else:
        assert cell == f"{reg.lo}-{reg.hi}"


def test_serial_command_tables_match_the_decoder() -> None:
    text = section(PROTOCOL, "1.2 Commands")
    documented: dict[int, set[str]] = {}
    for first in (0, 1):  # the gripper's table, then the hand-compatible one
        for row in table(text, first):
            documented.setdefault(int(code_in(row[0]), 16), set()).add(row[1])
    actual: dict[int, set[str]] = {}
    for code, cmd in COMMANDS.items():
        actual[code] = {cmd.name} | ({cmd.alias} if cmd.alias else set())
    assert documented == actual


def _manual_frames() -> list[str]:
    data = json.loads(MANUAL_FRAMES.read_text(encoding="utf-8"))
    frames = [e[side] for e in data["eg2_serial"] for side in ("request", "response")]
    frames += [e["bytes"] for e in data["eg2_serial_bad"]]
    frames += [e[form] for e in data["modbus_rtu"] for form in ("manual_prints", "wire")]
    for e in data["eg2_can"]:
        frames += [e["id"], e["data"], e["response"]["data"], e.get("alt_data_padded", "")]
    return [f for f in frames if f]


@pytest.mark.parametrize("frame", _manual_frames())
def test_every_manual_frame_is_explained(frame: str) -> None:
    assert f"`{frame}`" in PROTOCOL.read_text(encoding="utf-8")


# -- docs/architecture.md against the tree ---------------------------------------------------

ARCHITECTURE = DOCS / "architecture.md"


def _layout() -> str:
    block = re.search(r"```\n(decoders/.*?)```", section(ARCHITECTURE, "Package layout"), re.S)
    assert block, "the layout is a code block starting with decoders/"
    return block.group(1)


def _modules() -> list[str]:
    names = [p.name for p in (ROOT / "decoders").glob("*.py")]
    names += [p.name for p in (ROOT / "analyzer").glob("*.py")]
    for folder in ("sources", "session", "recording", "parquet", "plot"):
        names += [p.name for p in (ROOT / "analyzer" / folder).glob("*.py")]
    names += [p.parent.name + "/" for p in (ROOT / "analyzer").glob("*/__init__.py")]
    return sorted(set(names) - {"__init__.py", "__main__.py"})


@pytest.mark.parametrize("module", _modules())
def test_layout_names_every_module(module: str) -> None:
    assert re.search(rf"(?<![\w/]){re.escape(module)}", _layout())


def test_every_registered_listener_is_named() -> None:
    from analyzer.session.listener import LISTENERS

    text = section(ARCHITECTURE, "The listener contract")
    for name in LISTENERS:
        assert f"`{name}`" in text, name


# -- docs/contracts.md's grip cycles against the code ----------------------------------------


def test_cycle_keys_are_documented_in_order() -> None:
    from analyzer.cycles.model import KEYS

    rows = table(section(CONTRACTS, "Grip cycles"))
    assert [code_in(row[0]) for row in rows] == list(KEYS)


def test_every_outcome_is_documented_once() -> None:
    from analyzer.cycles.model import OUTCOMES

    rows = table(section(CONTRACTS, "Grip cycles"), first=1)
    assert sorted(code_in(row[0]) for row in rows) == sorted(OUTCOMES)


def test_what_a_cycle_may_not_know_is_documented() -> None:
    from analyzer.cycles.model import QUANTITIES

    rows = table(section(CONTRACTS, "Grip cycles"))
    unknown = next(row[2] for row in rows if code_in(row[0]) == "unknown")
    assert all(f"`{q}`" in unknown for q in QUANTITIES)


def test_cycles_csv_header_is_documented() -> None:
    from analyzer.cycles.model import KEYS

    block = re.search(r"```\n(bus,device,.*)\n```", section(CONTRACTS, "Grip cycles"))
    assert block, "the section shows the CSV header line"
    assert block.group(1).split(",") == list(KEYS)


def test_the_cycle_example_is_what_cycles_writes() -> None:
    examples = re.findall(r"^\{.*\}$", section(CONTRACTS, "Grip cycles"), re.MULTILINE)
    assert examples
    capture = ROOT / "captures" / "can_pick_place.log"
    out = subprocess.run(
        [sys.executable, "-m", "analyzer", "cycles", str(capture), "-f", "jsonl"],
        capture_output=True,
        text=True,
        check=True,
        cwd=ROOT,
    ).stdout.splitlines()
    for example in examples:
        assert example in out
