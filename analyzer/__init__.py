"""eg2scope: the analyzer application (sources, session, sinks, recording, parquet, plot, CLI,
TUI, simulator)."""

from .sources.mf4 import defer as _defer_asammdf

__version__ = "0.1.0"

_defer_asammdf()  # python-can would import asammdf (1-2 s) for .mf4 files at `import can`
