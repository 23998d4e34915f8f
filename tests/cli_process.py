"""eg2scope run as a user runs it: a real process, ``python -m analyzer``, from the project's
root unless told, without colour and without a display (no viewer or browser opens)."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
ENV = {**os.environ, "PYTHONPATH": str(ROOT), "NO_COLOR": "1"}
ENV.pop("DISPLAY", None)
ENV.pop("WAYLAND_DISPLAY", None)


def eg2scope(
    *args: str, cwd: Path = ROOT, timeout: float = 90, **kw: Any
) -> subprocess.CompletedProcess[str]:
    """Run ``eg2scope ARGS`` to its end; its exit status, stdout and stderr as text."""
    return subprocess.run(
        [sys.executable, "-m", "analyzer", *args],
        capture_output=True,
        text=True,
        timeout=timeout,
        env=kw.pop("env", ENV),
        cwd=cwd,
        **kw,
    )
