"""CLI subcommands: one module each, with ``add_subparser`` (as cantools does)."""

from __future__ import annotations

from types import ModuleType

from . import bridge, decode, demo, live, record, sim, stats

SUBCOMMANDS: tuple[ModuleType, ...] = (decode, stats, live, record, bridge, sim, demo)
