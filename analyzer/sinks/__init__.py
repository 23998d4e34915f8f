"""Where records go, as session listeners: text, JSONL, CSV, Parquet, statistics and Rerun
(the MCAP recorder is ``analyzer/recording/reader.py``)."""
