"""CLI subcommands: one module each, with ``add_subparser`` (as cantools does) and ``run(args)``,
which turns the arguments into typed options and calls one function below the command line.

Listed by name and imported when the parser is built, so importing one command's helpers does
not import every command (the simulator, the TUI ...)."""

from __future__ import annotations

SUBCOMMANDS: tuple[str, ...] = (
    "decode",
    "stats",
    "cycles",
    "live",
    "record",
    "bridge",
    "sim",
    "demo",
    "plot",
    "tui",
    "batch",
)
