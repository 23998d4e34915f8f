"""MCAP recordings: their layout (channels, schemas, topics), the writer, the recorder (a
listener), the reader and damage recovery, side by side as python-can keeps a format's reader
and writer."""
