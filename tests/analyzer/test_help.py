"""Every subcommand's ``--help`` explains itself: a description wrapped to the terminal, an
epilog that ends with the exit statuses, and a help text for every option; and a protocol
name ``--protocol`` does not know is answered with every name it does, ``auto`` too."""

from __future__ import annotations

import argparse
import subprocess
import sys
from pathlib import Path

import pytest

from analyzer import cli
from analyzer.commands import SUBCOMMANDS

ROOT = Path(__file__).resolve().parents[2]


def subparsers() -> dict[str, argparse.ArgumentParser]:
    parser = cli.build_parser()
    (action,) = [a for a in parser._actions if isinstance(a, argparse._SubParsersAction)]
    return dict(action.choices)


@pytest.mark.parametrize("name", SUBCOMMANDS)
def test_every_subcommand_has_a_description_an_exit_status_and_help_for_every_option(
    name: str,
) -> None:
    parser = subparsers()[name]
    assert parser.description and len(parser.description) > 40
    assert parser.epilog and "exit status: 0 " in parser.epilog
    assert "2 usage error" in parser.epilog
    for action in parser._actions:
        assert action.help and action.help != argparse.SUPPRESS, (name, action.option_strings)


@pytest.mark.parametrize("name", SUBCOMMANDS)
def test_help_is_wrapped_to_the_terminal(name: str) -> None:
    """Run as a user runs it, in an 80-column terminal: the description and the exit status
    are prose wrapped to it; the examples keep their lines."""
    result = subprocess.run(
        [sys.executable, "-m", "analyzer", name, "--help"],
        capture_output=True,
        text=True,
        cwd=ROOT,
        env={"COLUMNS": "80", "PATH": "/usr/bin:/bin"},
        check=True,
    )
    parser = subparsers()[name]
    text = result.stdout
    description = text.split("\n\n")[1]  # after the usage
    assert " ".join(description.split()) == " ".join(parser.description.split("\n\n")[0].split())
    assert max(len(line) for line in description.splitlines()) <= 80
    status = text[text.index("exit status:") :].split("\n\n")[0]
    assert len(status.splitlines()) > 1
    assert max(len(line) for line in status.splitlines()) <= 80
    for line in text.splitlines():
        if line.startswith("  eg2scope "):  # an example, as written
            assert f"\n{line}\n" in f"\n{parser.epilog}\n" or line in parser.epilog


def test_the_top_level_help_ends_with_the_exit_statuses() -> None:
    epilog = cli.build_parser().epilog
    assert epilog is not None and "130 a file job" in epilog


@pytest.mark.parametrize(
    "argv",
    [
        ["decode", "x.log"],
        ["stats", "x.log"],
        ["batch", "x.log", "-o", "d"],
        ["live", "--serial", "/dev/null"],
        ["tui", "x.log"],
    ],
)
def test_an_unknown_protocol_lists_auto_too(
    argv: list[str], capsys: pytest.CaptureFixture[str]
) -> None:
    with pytest.raises(SystemExit) as exc:
        cli.main([*argv, "--protocol", "foo"])
    assert exc.value.code == 2
    err = capsys.readouterr().err
    assert "unknown protocol 'foo'; choose one of: " in err
    assert err.rstrip().endswith(", or auto (detected)")


def test_bridge_bus_help_is_about_its_serial_line() -> None:
    bus = next(a for a in subparsers()["bridge"]._actions if "--bus" in a.option_strings)
    assert bus.help is not None and "CAN" not in bus.help and "rs485" in bus.help
    live = next(a for a in subparsers()["live"]._actions if "--bus" in a.option_strings)
    assert live.help is not None and "CAN channel" in live.help


def test_plot_takes_the_captures_decode_reads() -> None:
    plot = next(a for a in subparsers()["plot"]._actions if a.dest == "file")
    decode = next(a for a in subparsers()["decode"]._actions if a.dest == "file")
    assert plot.help is not None and decode.help is not None
    assert plot.help.startswith(decode.help)
    assert "PCAN trace (.trc, 1.0-2.1)" in plot.help and "candump -L" not in plot.help


def test_a_command_imports_only_its_own_module() -> None:
    """``eg2scope decode`` builds the parser of decode alone (the TUI, the simulator, Rerun are
    not imported); ``eg2scope --help`` and an unknown command still list every command."""
    script = (
        "import sys; from analyzer import cli; "
        "code = cli.main(sys.argv[1:]); "
        "print(sorted(m for m in sys.modules if m.startswith('analyzer.commands.')), "
        "file=sys.stderr); sys.exit(code)"
    )
    capture = str(ROOT / "captures" / "can_pick_place.log")
    proc = subprocess.run(
        [sys.executable, "-c", script, "decode", "-f", "jsonl", capture],
        capture_output=True,
        text=True,
        cwd=ROOT,
    )
    assert proc.returncode == 0, proc.stderr
    loaded = proc.stderr.strip().splitlines()[-1]
    assert "analyzer.commands.decode" in loaded
    for other in ("tui", "sim", "demo", "plot", "batch"):
        assert f"analyzer.commands.{other}'" not in loaded, loaded
    wrong = subprocess.run(
        [sys.executable, "-m", "analyzer", "decod"], capture_output=True, text=True, cwd=ROOT
    )
    assert wrong.returncode == 2
    assert all(name in wrong.stderr for name in SUBCOMMANDS), wrong.stderr
