"""MF4 (ASAM MDF 4) captures, through python-can's ``MF4Reader`` and asammdf.

python-can imports asammdf, and pandas with it, as soon as ``can`` itself is imported, for its
MF4 classes alone: one to two seconds more at the start of every command that touches a CAN
bus. eg2scope defers that import to the first .mf4 file it reads: until then the import of
asammdf by ``can.io.mf4``'s own module code is refused (python-can then leaves its MF4 classes
as it does when asammdf is not installed), and ``mf4_reader()`` reloads ``can.io.mf4`` with
asammdf. Any other import of asammdf is left alone. ``defer()`` runs when ``analyzer`` is
imported, before anything imports ``can``; ``load()`` completes python-can's MF4 classes at
once (a program that writes .mf4 files through python-can after importing eg2scope).
"""

from __future__ import annotations

import importlib
import sys
from collections.abc import Sequence
from importlib.machinery import ModuleSpec
from types import FrameType, ModuleType
from typing import Any

_DEFERRED = "asammdf"
_IMPORTER = "can.io.mf4"
_state = {"wanted": False}


class _DeferAsammdf:
    """A meta path finder that refuses asammdf to ``can.io.mf4``'s module code."""

    def find_spec(
        self, fullname: str, path: Sequence[str] | None, target: ModuleType | None = None
    ) -> ModuleSpec | None:
        if fullname != _DEFERRED or _state["wanted"]:
            return None
        frame: FrameType | None = sys._getframe(1)
        while frame is not None:
            if frame.f_code.co_name == "<module>" and frame.f_globals.get("__name__") == _IMPORTER:
                raise ModuleNotFoundError("asammdf is imported when a .mf4 file is read",
                                          name=_DEFERRED)  # fmt: skip
            frame = frame.f_back
        return None


def defer() -> None:
    """Install the finder (once)."""
    if not any(isinstance(finder, _DeferAsammdf) for finder in sys.meta_path):
        sys.meta_path.insert(0, _DeferAsammdf())


def load() -> ModuleType:
    """python-can's ``can.io.mf4`` with asammdf loaded where it is installed: its MF4Reader
    and MF4Writer work from now on (call it before writing a .mf4 with python-can in a
    process that imported eg2scope first)."""
    _state["wanted"] = True
    module = importlib.import_module(_IMPORTER)
    if getattr(module, "asammdf", None) is None:
        module = importlib.reload(module)  # its classes look asammdf up when called
    return module


def mf4_reader() -> Any:
    """python-can's MF4Reader with asammdf loaded (its NotImplementedError when asammdf is not
    installed)."""
    return load().MF4Reader
