"""The catalogue of error and warning texts (decoders/messages.py): every text the decoders
write on the project's captures is one of its messages, said with its flag code, so a text
written outside the catalogue fails here; and every message is one both engines write alike."""

from __future__ import annotations

import ast
import importlib.util
import io
import re
import string
from collections.abc import Iterator
from contextlib import redirect_stderr
from pathlib import Path
from types import ModuleType
from typing import Any

import orjson
import pytest
from protocol_vectors import load

from analyzer import cli
from decoders import messages as M
from decoders import modbus_rtu

ROOT = Path(__file__).resolve().parents[2]
DATA = ROOT / "tests" / "data"


def _codegen() -> ModuleType:
    """native/codegen.py, which writes the crate's copy of the catalogue."""
    spec = importlib.util.spec_from_file_location("codegen", ROOT / "native" / "codegen.py")
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


codegen = _codegen()
MESSAGES = {name: m for name, m in vars(M).items() if isinstance(m, M.Message)}


def _captures() -> list[Path]:
    """The sample captures, and every capture under tests/data with its expectation beside it
    (``FILE.json``: a file the tests decode)."""
    samples = [p for p in (ROOT / "captures").iterdir() if p.suffix in (".bin", ".log")]
    data = [p for p in DATA.rglob("*") if p.with_name(p.name + ".json").is_file()]
    return sorted(samples + data)


def _manual_captures(folder: Path) -> list[Path]:
    """The manual's frames (tests/data/manual_frames.json) as capture files, one per protocol."""
    serial = b"".join(
        bytes.fromhex(v["request"]) + bytes.fromhex(v["response"]) for v in load("eg2_serial")
    )
    serial += b"".join(bytes.fromhex(v["bytes"]) for v in load("eg2_serial_bad"))
    modbus = b"".join(
        bytes.fromhex(v["wire"]) + bytes.fromhex(v["manual_prints"]) for v in load("modbus_rtu")
    )
    lines = []
    for v in load("eg2_can"):
        for part in (v, v.get("response")):
            if part:
                t = 1_700_000_000 + len(lines) / 1000
                lines.append(f"({t:.6f}) can0 {part['id']}#{part['data'].replace(' ', '')}\n")
    files = {"manual-serial.bin": serial, "manual-modbus.bin": modbus}
    files["manual-can.log"] = "".join(lines).encode()
    for name, content in files.items():
        (folder / name).write_bytes(content)
    return [folder / name for name in files]


def _records(capture: Path, options: list[str], out: Path) -> Iterator[dict[str, Any]]:
    """The records of ``eg2scope decode`` (the Python engine: the decoders, pairing, linter)."""
    argv = ["decode", str(capture), "-f", "jsonl", "-o", str(out), "--no-progress"]
    with redirect_stderr(io.StringIO()):
        cli.main([*argv, *options, "--engine", "python", "--jobs", "1"])
    for line in out.read_bytes().splitlines():
        yield orjson.loads(line)


def _pattern(message: M.Message) -> re.Pattern[str]:
    """The texts a message can be: its words, anything in place of a field."""
    parts = []
    for literal, name, _, _ in string.Formatter().parse(message.template):
        parts.append(re.escape(literal))
        if name is not None:
            parts.append("(.+)")
    return re.compile("".join(parts))


PATTERNS = {name: _pattern(m) for name, m in MESSAGES.items()}


def _unexplained(rec: dict[str, Any]) -> list[str]:
    """The record's errors and warnings that no message of the catalogue says with a code the
    record has."""
    flags = rec.get("flags") or []
    texts = (rec.get("errors") or []) + (rec.get("warnings") or [])
    return [
        text
        for text in texts
        if not any(
            MESSAGES[name].code in flags and pattern.fullmatch(text)
            for name, pattern in PATTERNS.items()
        )
    ]


def test_every_text_on_the_captures_is_a_catalogue_message(tmp_path: Path) -> None:
    captures = _captures() + _manual_captures(tmp_path)
    assert len(captures) > 20
    outside: dict[str, str] = {}
    said: set[str] = set()
    for capture in captures:
        # -p modbus: the serial capture's bytes read as Modbus (no frame: garbage, truncation)
        for options in ([], ["-p", "modbus"]) if capture.suffix == ".bin" else ([],):
            for rec in _records(capture, options, tmp_path / "out.jsonl"):
                for text in _unexplained(rec):
                    outside.setdefault(text, capture.name)
                for text in (rec.get("errors") or []) + (rec.get("warnings") or []):
                    said.update(n for n, p in PATTERNS.items() if p.fullmatch(text))
    assert not outside, f"texts outside decoders/messages.py (or without their code): {outside}"
    assert len(said) > 25  # the captures show most kinds of problem


def test_a_text_outside_the_catalogue_is_found() -> None:
    rec = {
        "errors": [M.SERIAL_CHECKSUM.text(expected=0xC8, got=0x74)],
        "warnings": ["speed out of range (10-1000): 5000", "a new text"],
        "flags": [M.SERIAL_CHECKSUM.code, M.VALUE_OUT_OF_RANGE.code],
    }
    assert _unexplained(rec) == ["a new text"]
    rec["flags"] = [M.SERIAL_CHECKSUM.code]  # a text without its code
    assert _unexplained(rec) == ["speed out of range (10-1000): 5000", "a new text"]


@pytest.mark.parametrize("name", sorted(MESSAGES))
def test_a_message_is_one_the_crate_can_write(name: str) -> None:
    """Named fields only, with format specs that Rust's format! writes as Python does."""
    message = MESSAGES[name]
    assert name.split("_")[0] in {"VALUE", "FRAMING", "SERIAL", "MODBUS", "CAN", "PAIRING", "LINT"}
    codegen.rust_format(message.template, name)  # raises on a spec without a Rust twin
    assert message.text(**{f: 1 for f in message.fields})


def test_specs_map_to_rust() -> None:
    f = codegen.rust_format
    assert f("0x{a:02X} {b:#x} {c:.2f} {d} {{x}}") == "0x{a:02X} {b:#x} {c:.2} {d} {{x}}"
    for bad in ("{a:g}", "{a!r}", "{a.b}", "{a[0]}", "{a:>5}"):
        with pytest.raises(ValueError):
            f(bad)


def test_short_numbering_prefix_starts_both_messages() -> None:
    """The decoder finds the numbering warning by its start (to say it once per device)."""
    for message in (M.MODBUS_SHORT_NUMBER, M.MODBUS_SHORT_NUMBERS):
        assert message.template.startswith(modbus_rtu._SHORT)


# -- no text written outside the catalogue, on any path (the captures reach only some) -------

DECODERS = ROOT / "decoders"
CRATE_DECODERS = ROOT / "native" / "src" / "decoders"


def _literal(node: ast.expr) -> bool:
    return isinstance(node, ast.JoinedStr) or (
        isinstance(node, ast.Constant) and isinstance(node.value, str)
    )


def _texts_written(tree: ast.AST) -> Iterator[ast.expr]:
    """The texts a module hands to Notes.warn/error, appends to a record's warnings/errors or
    gives a Record's errors=/warnings=."""
    for node in ast.walk(tree):
        if not isinstance(node, ast.Call):
            continue
        func = node.func
        if isinstance(func, ast.Attribute):
            if func.attr in ("warn", "error") and len(node.args) == 2:
                yield node.args[1]
            owner = func.value
            if (
                func.attr == "append"
                and isinstance(owner, ast.Attribute)
                and owner.attr in ("warnings", "errors")
            ):
                yield from node.args
        for kw in node.keywords:
            if kw.arg in ("warnings", "errors") and isinstance(kw.value, ast.List | ast.Tuple):
                yield from kw.value.elts


@pytest.mark.parametrize("path", sorted(DECODERS.glob("*.py")), ids=lambda p: p.name)
def test_python_decoders_write_no_text_of_their_own(path: Path) -> None:
    tree = ast.parse(path.read_text(encoding="utf-8"))
    own = [ast.unparse(t) for t in _texts_written(tree) if _literal(t)]
    assert not own, f"{path.name} writes texts outside decoders/messages.py: {own}"


# a flag code and then a text made here (a literal or format!), or a literal or format! pushed
RUST_OWN_TEXT = re.compile(
    r"\.(?:warn|error|warning)\(\s*[\w:]+,\s*(?:format!|\")"
    r"|\.(?:warnings|errors)\.push\(\s*(?:format!|\")"
)


@pytest.mark.parametrize("path", sorted(CRATE_DECODERS.glob("*.rs")), ids=lambda p: p.name)
def test_crate_decoders_write_no_text_of_their_own(path: Path) -> None:
    code = path.read_text(encoding="utf-8").split("#[cfg(test)]")[0]
    own = [m.group(0) for m in RUST_OWN_TEXT.finditer(code)]
    assert not own, f"{path.name} writes texts outside generated::messages: {own}"


def test_the_checks_see_a_text_of_its_own() -> None:
    tree = ast.parse(
        'notes.warn(F.X, f"a {b}")\nrec.warnings.append("c")\nRecord(errors=[f"d{e}"])\n'
        "notes.warn(M.X.code, text)\nnotes.warn_of(M.X, a=1)\n"
    )
    assert [ast.unparse(t) for t in _texts_written(tree) if _literal(t)] == [
        "f'a {b}'",
        "'c'",
        "f'd{e}'",
    ]
    rust = 'notes.warn(\n    F::X,\n    format!("a {b}"),\n);\nrec.warnings.push("c".into());'
    assert len(RUST_OWN_TEXT.findall(rust)) == 2
    assert not RUST_OWN_TEXT.search("notes.warn_of(M::x!(a = 1));\nnotes.warn(F::X, text);")
