"""Fleet-scale batch decoding (``eg2scope batch``): a folder of captures into one Parquet dataset.

- ``inputs``: which files a run takes (globs, folders, files) and their content hash;
- ``layout``: the dataset's folders and file names, atomic writes, what is done already;
- ``tables``: the ``states/`` and ``captures/`` columns;
- ``cycle_tables``, ``health_tables``: the ``cycles/`` and ``health/`` columns and rows;
- ``arrow_sequences``: the native core's columns read as the sequences a cycles listener reads;
- ``listeners``: what fills one capture's tables, from the native core's columns or a session;
- ``summary``: a capture's ``captures/`` counts, gathered from its columns;
- ``partitions``: one capture's rows written into its day and bus partitions, then committed;
- ``capture_task``: one capture decoded into its partitions (what a Dask worker runs);
- ``runner``: the captures run in one loop or on Dask;
- ``progress``: the progress bar, the lines of captures that went wrong, the summary table.

docs/fleet.md describes the dataset and how to query it.
"""
