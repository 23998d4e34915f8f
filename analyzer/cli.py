"""The ``eg2scope`` command line: one module per subcommand (as cantools does)."""

from __future__ import annotations

import argparse
import importlib
import os
import sys
from collections.abc import Sequence

from . import __version__
from .commands import SUBCOMMANDS
from .commands.helptext import EXIT_STATUS, HelpFormatter, epilog
from .errors import EXIT_ERROR, EXIT_INTERRUPTED, EXIT_USAGE, UsageError, stop_status
from .session import engine
from .session.session import signals_as_interrupt


def build_parser(command: str | None = None) -> argparse.ArgumentParser:
    """The parser of every subcommand, or of ``command`` alone: a run imports only the module
    of the command it runs (the others' imports would cost a decode a fifth of its CPU)."""
    parser = argparse.ArgumentParser(
        prog="eg2scope",
        description=(
            "Passive bus sniffer and protocol analyzer for the Inspire EG2-4XX electric "
            "gripper: the regular serial protocol (RS232), Modbus RTU (RS485) and the CAN "
            "register protocol. Decodes captures and live buses into words."
        ),
        epilog=epilog("Run 'eg2scope COMMAND --help' for the options of one command.", EXIT_STATUS),
        formatter_class=HelpFormatter,
    )
    parser.add_argument(
        "--version", action="version", version=f"eg2scope {__version__} ({engine.status()})"
    )
    sub = parser.add_subparsers(title="commands", dest="command", metavar="COMMAND")
    for name in (command,) if command in SUBCOMMANDS else SUBCOMMANDS:
        importlib.import_module(f"{__package__}.commands.{name}").add_subparser(sub)
    return parser


def command_named(argv: Sequence[str]) -> str | None:
    """The subcommand the command line names: its first word that is not an option (the
    top-level options take no value), or None (help, a typo: every command is listed)."""
    word = next((arg for arg in argv if not arg.startswith("-")), None)
    return word if word in SUBCOMMANDS else None


def runs_until_stopped(args: argparse.Namespace) -> bool:
    """Whether the command runs until the user stops it: a live source, the demo or the
    simulator (its parser sets ``until_stopped``), and not a capture file (``file``)."""
    return bool(getattr(args, "until_stopped", False)) and not getattr(args, "file", None)


def main(argv: Sequence[str] | None = None) -> int:
    try:  # the subcommands' imports take a moment: a Ctrl-C then ends it without a traceback
        parser = build_parser(command_named(sys.argv[1:] if argv is None else argv))
    except KeyboardInterrupt:
        print("eg2scope: interrupted before it began", file=sys.stderr)
        return EXIT_INTERRUPTED
    args = parser.parse_args(argv)
    if not getattr(args, "func", None):
        parser.print_help()
        return 2
    try:
        # SIGTERM and SIGHUP end a command as Ctrl-C does, at any moment: a session finishes
        # its recording, a live command stopped before its session began just ends
        with signals_as_interrupt():
            code = int(args.func(args) or 0)
        sys.stdout.flush()  # a pipe closed early shows here, not at interpreter exit
        return code
    except KeyboardInterrupt:
        code = stop_status(runs_until_stopped(args))
        print(f"eg2scope: {'interrupted' if code else 'stopped'}", file=sys.stderr)
        return code
    except BrokenPipeError:
        # output piped into `head` and the like: stop quietly, as Unix tools do
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
        return 0
    except UsageError as exc:
        parser.exit(EXIT_USAGE, f"eg2scope: error: {exc}\n")
    except (OSError, ValueError) as exc:
        print(f"eg2scope: error: {exc}", file=sys.stderr)
        return EXIT_ERROR
    return EXIT_ERROR  # not reached: parser.exit raises SystemExit
