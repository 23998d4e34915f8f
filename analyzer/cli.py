"""The ``eg2scope`` command line: one module per subcommand (as cantools does)."""

from __future__ import annotations

import argparse
import os
import sys
from collections.abc import Sequence

from . import __version__
from .commands import SUBCOMMANDS


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="eg2scope",
        description=(
            "Passive bus sniffer and protocol analyzer for the Inspire EG2-4XX electric "
            "gripper: the regular serial protocol (RS232), Modbus RTU (RS485) and the CAN "
            "register protocol. Decodes captures and live buses into words."
        ),
        epilog="Run 'eg2scope COMMAND --help' for the options of one command.",
    )
    parser.add_argument("--version", action="version", version=f"eg2scope {__version__}")
    sub = parser.add_subparsers(title="commands", dest="command", metavar="COMMAND")
    for module in SUBCOMMANDS:
        module.add_subparser(sub)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    if not getattr(args, "func", None):
        parser.print_help()
        return 2
    try:
        return int(args.func(args) or 0)
    except KeyboardInterrupt:
        return 130
    except BrokenPipeError:
        # output piped into `head` and the like: stop quietly, as Unix tools do
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
        return 0
    except (OSError, ValueError) as exc:
        print(f"eg2scope: error: {exc}", file=sys.stderr)
        return 1
