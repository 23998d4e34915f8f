"""Rerun plots: the entities, the blueprint, the log rows, where a plot goes (targets) and the
listener that logs a session."""
