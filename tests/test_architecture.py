"""The layout's rules, read from the import graph grimp builds of ``analyzer`` and ``decoders``
(every import: at module level, inside functions and under ``if TYPE_CHECKING:``), as
docs/architecture.md states them: no import circle; only the CLI imports ``analyzer.commands``,
and only the CLI reads argparse (below it, options travel typed); the decoders import nothing of
the analyzer."""

from __future__ import annotations

from pathlib import Path

import grimp
import pytest

CLI = "analyzer.cli"
COMMANDS = "analyzer.commands"


@pytest.fixture(scope="module")
def graph() -> grimp.ImportGraph:
    # external packages too (the standard library among them), each as one module
    return grimp.build_graph("analyzer", "decoders", include_external_packages=True, cache_dir=None)


def _edges(graph: grimp.ImportGraph) -> list[tuple[str, str]]:
    return sorted(
        (importer, imported)
        for importer in graph.modules
        for imported in graph.find_modules_directly_imported_by(importer)
    )


def circles(graph: grimp.ImportGraph) -> list[tuple[str, ...]]:
    """Every import that closes a circle, as the circle: the importer, what it imports, and the
    shortest chain from there back to the importer."""
    found = []
    for importer, imported in _edges(graph):
        back = graph.find_shortest_chain(importer=imported, imported=importer)
        if back is not None:
            found.append((importer, *back))
    return found


def test_the_graph_holds_both_packages(graph: grimp.ImportGraph) -> None:
    # a graph of nothing would pass every rule below
    assert {"analyzer.session.session", "analyzer.cli", "decoders.eg2_can"} <= graph.modules
    assert len(_edges(graph)) > 300


def test_no_import_circle(graph: grimp.ImportGraph) -> None:
    assert circles(graph) == []


def test_only_the_cli_imports_the_commands(graph: grimp.ImportGraph) -> None:
    importers = graph.find_modules_that_directly_import(COMMANDS, as_package=True)
    below = {m for m in importers if m != CLI and not m.startswith(COMMANDS + ".")}
    assert below == set()


def test_only_the_cli_reads_argparse(graph: grimp.ImportGraph) -> None:
    importers = graph.find_modules_that_directly_import("argparse")
    assert importers  # the CLI does: a graph without argparse would pass the rule
    below = {m for m in importers if m != CLI and not m.startswith(COMMANDS + ".")}
    assert below == set()


def test_the_decoders_import_nothing_of_the_analyzer(graph: grimp.ImportGraph) -> None:
    imported = graph.find_modules_directly_imported_by("decoders", as_package=True)
    assert {m for m in imported if m.split(".")[0] == "analyzer"} == set()


def test_a_circle_is_found(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """The circle check finds a circle made of function-level imports (the kind the layout
    once had: a module below reaching back up inside a function)."""
    pkg = tmp_path / "roundabout"
    pkg.mkdir()
    (pkg / "__init__.py").write_text("")
    (pkg / "low.py").write_text("def f():\n    from .high import g\n    return g\n")
    (pkg / "high.py").write_text("from . import low\n\ndef g():\n    return low\n")
    (pkg / "apart.py").write_text("from . import low\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    found = circles(grimp.build_graph("roundabout", cache_dir=None))
    assert sorted(found) == [
        ("roundabout.high", "roundabout.low", "roundabout.high"),
        ("roundabout.low", "roundabout.high", "roundabout.low"),
    ]
