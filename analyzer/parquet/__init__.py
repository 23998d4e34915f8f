"""Parquet output: the records' columns, the writer (a listener) and the native core's Arrow
columns."""
