"""Fleet-scale batch decoding (``eg2scope batch``): a folder of captures into one Parquet dataset.

- ``inputs``: which files a run takes (globs, folders, files) and their content hash;
- ``layout``: the dataset's folders and file names, atomic writes, what is done already;
- ``tables``: the ``states/`` and ``captures/`` columns;
- ``capture_task``: one capture decoded into its partitions (what a Dask worker runs);
- ``runner``: the captures run in one loop or on Dask, with a progress bar and a summary.

docs/fleet.md describes the dataset and how to query it.
"""
