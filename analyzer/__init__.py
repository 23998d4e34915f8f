"""eg2scope: the analyzer application (sources, pipeline, sinks, CLI, TUI, simulator)."""

__version__ = "0.1.0"
