"""The files of a batch: samples as Parquet (or PLY) and view images as PNG, encoded to bytes
where they are computed (a worker) and written by the driver atomically (a temporary file in
the same folder, then ``os.replace``), so a file under its final name is always complete.

Layout of OUTDIR: ``samples/NAME.parquet`` (or ``.ply``), ``views/NAME.K.png`` for view K,
``queries/NAME.parquet`` with point queries (columns x, y, z, inside, distance: membership of
the closed solid and the conservative signed distance, :mod:`clcsg.queries`),
``manifest.parquet`` (:mod:`clcsg.batching.manifest`).

Parquet columns of the samples (one row per sample, world coordinates):

=============  =======  =====================================================================
x, y, z        float64  position, on the CSG surface
nx, ny, nz     float64  outward unit normal
quadric        int32    index of its quadric in the scene's tape (``tape.quadrics``)
primitive      int32    the primitive instance (tree order) whose boundary holds it
radius         float64  its splat radius (at most the batch radius)
clipped        bool     its splat is clipped: it has a non-empty clip program, i.e. another
                        surface passes within its radius (near a sharp edge)
=============  =======  =====================================================================

The schema's metadata holds ``clcsg.scene`` (the name), ``clcsg.radius`` and ``clcsg.hash``.
"""

from __future__ import annotations

import contextlib
import os
import tempfile

import numpy as np

from ..errors import OutputError
from ..atomic import stage, write_bytes
from ..writers import ply
from .options import FORMATS, require

SAMPLES_DIR = "samples"
VIEWS_DIR = "views"
QUERIES_DIR = "queries"


def samples_path(name: str, fmt: str) -> str:
    """Relative path of a scene's samples file."""
    return f"{SAMPLES_DIR}/{name}{FORMATS[fmt]}"


def view_path(name: str, k: int) -> str:
    """Relative path of a scene's view image ``k``."""
    return f"{VIEWS_DIR}/{name}.{k}.png"


def queries_path(name: str) -> str:
    """Relative path of a scene's point queries."""
    return f"{QUERIES_DIR}/{name}.parquet"


def parquet_bytes(columns: dict, metadata: dict | None = None) -> bytes:
    """A Parquet file (zstd) of numpy ``columns``, with ``clcsg.*`` schema metadata."""
    pa = require("pyarrow", "batch output")
    import pyarrow.parquet as pq

    table = pa.table({k: pa.array(np.ascontiguousarray(v)) for k, v in columns.items()})
    if metadata:
        table = table.replace_schema_metadata({f"clcsg.{k}": str(v) for k, v in metadata.items()})
    sink = pa.BufferOutputStream()
    pq.write_table(table, sink, compression="zstd")
    return sink.getvalue().to_pybytes()


def samples_columns(samples) -> dict:
    """The samples' columns (the module docstring) as numpy arrays."""
    p, n = samples.positions, samples.normals
    return {
        "x": p[:, 0], "y": p[:, 1], "z": p[:, 2], "nx": n[:, 0], "ny": n[:, 1], "nz": n[:, 2],
        "quadric": np.asarray(samples.quadrics, dtype=np.int32),
        "primitive": np.asarray(samples.primitives, dtype=np.int32),
        "radius": np.asarray(samples.radii, dtype=np.float64),
        "clipped": np.asarray(samples.clip_count) > 0,
    }


def samples_bytes(samples, fmt: str, metadata: dict | None = None) -> bytes:
    """The samples file's contents: Parquet (zstd-compressed) or binary PLY."""
    if fmt == "parquet":
        return parquet_bytes(samples_columns(samples), metadata)
    fd, tmp = tempfile.mkstemp(suffix=".ply")
    os.close(fd)
    try:
        ply.write_samples(samples, tmp)
        with open(tmp, "rb") as f:
            return f.read()
    finally:
        os.unlink(tmp)


def write_atomic(path: str, data: bytes) -> None:
    """Write ``data`` to ``path`` atomically and durably (:func:`clcsg.atomic.write_bytes`:
    a temporary in its folder, fsync, ``os.replace``): a process that dies leaves the old file
    or none, never a partial one.  :class:`~clcsg.errors.OutputError` if it cannot."""
    folder = os.path.dirname(path) or "."
    try:
        os.makedirs(folder, exist_ok=True)
    except OSError as e:
        raise OutputError(f"{folder}: cannot create the folder: {e.strerror or e}") from None
    write_bytes(path, data, "batch output")


def stage_files(outdir: str, files: dict) -> list:
    """Every (relative path -> bytes) of a scene's result written and synced under ``outdir``
    but not yet named (:class:`clcsg.atomic.Staged`): the caller journals the scene's row,
    then publishes them, so a scene's file under its final name always has its row."""
    staged = []
    try:
        for rel, data in files.items():
            path = os.path.join(outdir, rel)
            folder = os.path.dirname(path)
            try:
                os.makedirs(folder, exist_ok=True)
            except OSError as e:
                raise OutputError(f"{folder}: cannot create the folder: {e.strerror or e}") from None
            staged.append(stage(path, data, "batch output"))
    except BaseException:
        discard_files(staged)
        raise
    return staged


def remove_files(outdir: str, rels) -> None:
    """Remove an earlier run's files of a scene (before its new row is journaled, so that a
    new row never names an old file)."""
    for rel in rels:
        with contextlib.suppress(FileNotFoundError):
            os.unlink(os.path.join(outdir, rel))


def publish_files(staged: list) -> None:
    try:
        for st in staged:
            st.publish()
    finally:
        discard_files(staged)


def discard_files(staged: list) -> None:
    for st in staged:
        st.discard()
