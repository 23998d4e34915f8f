"""The native core's extension module (``analyzer._native``, built from native/), loaded once:
the module, or None and why not. A leaf below every package, so that a module the session's
engine imports (the capture sniffer) may use the core too; analyzer/session/engine.py says when
its decode applies."""

from __future__ import annotations

import importlib
from types import ModuleType

CORE = "analyzer._native"  # the extension's name (pyproject.toml: setuptools-rust target)
_native: ModuleType | None
try:
    _native = importlib.import_module(CORE)
except ModuleNotFoundError as exc:
    _native = None
    if exc.name == CORE:
        WHY_NOT = "not built: no Rust toolchain at install time, or its build failed"
    else:
        WHY_NOT = f"not loadable: {exc}"
except ImportError as exc:  # built, but for another platform, or damaged
    _native = None
    WHY_NOT = f"not loadable: {exc}"
else:
    WHY_NOT = ""
