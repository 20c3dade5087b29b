"""Batches: sample (and render) thousands of scenes into a folder, restartably.

The data flow: ``inputs`` turns paths, globs, directories and manifest files into jobs (one
scene each, its text read once, with a content hash); ``api.batch`` (the driver) skips the
scenes an earlier run completed (``manifest``), hands the others to an engine — ``local``
(a process pool, one OpenCL context per worker) or ``dask_engine`` (a Dask distributed
cluster) — and writes each result's files (``outputs``: Parquet or PLY samples, PNG views,
atomic writes) and manifest row as it arrives.  ``task`` is what a worker does with one scene;
``options`` what it does to every scene.  Needs the ``batch`` extra (pyarrow, dask).

:func:`batch` is ``clcsg.batch``.
"""

from .api import batch
from .options import DependencyError, Options

__all__ = ["batch", "DependencyError", "Options"]
