"""Where records go: text, JSONL, CSV, MCAP, Rerun."""
