"""``OUTDIR/manifest.parquet``: one row per scene, the record of a batch and its restart point.

A row with status ``ok`` whose files exist and whose ``hash`` equals the content hash of the
scene text and the options (:meth:`clcsg.batching.options.Options.content_hash`) is
*complete*: a rerun reuses it (``skipped`` true) instead of computing it again.  So is an
error row of the same hash whose error follows from the scene and the options alone
(``error_code`` 3, bad input, or 5, a limit), unless ``redo_errors``.  Anything else (no row,
another hash, a file missing, a device error, a worker that died, an internal error) is run
again.

Durability: every row is appended to the *journal* ``OUTDIR/manifest.journal`` (one JSON
object per line, flushed and ``fsync`` ed) once its scene's files are written and synced but
before they get their final names (the store step of :mod:`clcsg.batching.api`), so a driver
killed at any moment (SIGKILL, a power cut) loses no finished scene and leaves no named file
without its row; a row whose files never got their names is not complete and is run again.
The Parquet file is rewritten atomically (temporary file, fsync, ``os.replace``) at most every
:data:`FLUSH_INTERVAL` seconds and at the end of the run, after which the journal is emptied;
a new run folds the journal into the rows it reads (later lines win; a last line cut short
by the kill is ignored).  Rows of scenes that are not in the current run are kept.
"""

from __future__ import annotations

import datetime
import io
import json
import os
import time
import warnings

from ..errors import OutputError
from .options import require
from .outputs import write_atomic

NAME = "manifest.parquet"
#: the append-only journal of finished rows beside the manifest
JOURNAL = "manifest.journal"
#: least seconds between two rewrites of the manifest during a run
FLUSH_INTERVAL = 2.0

#: exit codes of errors that the same scene text and options always give again
FINAL_ERRORS = (3, 5)

#: (column, pyarrow type name, meaning); the type names are pyarrow factory functions
COLUMNS = (
    ("name", "string", "the scene's name, the stem of its output files"),
    ("source", "string", "its file, or manifest:line"),
    ("status", "string", "ok or error"),
    ("error", "string", "the error message (one line) if status is error"),
    ("error_code", "int32", "the error's exit code: 3 bad input, 4 device, 5 limit, 1 anything else"),
    ("hash", "string", "sha256 of the scene text and the options that decide the outputs"),
    ("samples", "int64", "number of samples"),
    ("radius", "float64", "the sampling radius in scene units (NaN for an empty solid)"),
    ("diagonal", "float64", "diagonal of the scene's bound"),
    ("quadrics", "int32", "unique quadrics of the tape"),
    ("primitives", "int32", "primitive instances"),
    ("instructions", "int32", "tape instructions"),
    ("unresolved", "int64", "cells left unresolved at the floor"),
    ("levels", "int32", "subdivision levels"),
    ("clipped_samples", "int64", "samples whose splat is clipped (near a sharp edge)"),
    ("compile_s", "float64", "seconds compiling the tape"),
    ("sample_s", "float64", "seconds compiling and sampling"),
    ("render_s", "float64", "seconds framing and rendering the views"),
    ("seconds", "float64", "seconds of the whole task in its worker"),
    ("cpu_s", "float64", "CPU seconds of the task in its worker process (all its threads)"),
    ("views", "int32", "number of view images"),
    ("cameras", "string", "JSON list of the views' cameras: eye, target, up, fov, width, height"),
    ("query_points", "int64", "points queried (--points, --random-points)"),
    ("inside_fraction", "float64", "fraction of the query points inside the solid"),
    ("query_s", "float64", "seconds of the point queries"),
    ("samples_file", "string", "the samples file, relative to OUTDIR"),
    ("images", "list_string", "the view images, relative to OUTDIR"),
    ("queries_file", "string", "the point queries (x y z inside distance), relative to OUTDIR"),
    ("dependencies", "string", "JSON list of the other files a .scad program read (includes, uses); in the hash"),
    ("worker", "string", "host:pid of the worker that ran it"),
    ("attempts", "int32", "times it was started (local engine; null under Dask)"),
    ("skipped", "bool", "true: complete from an earlier run, not computed again"),
    ("warnings", "string", "warnings of the task, joined by '; '"),
    ("finished", "timestamp", "when its row was written (UTC)"),
)


def schema():
    """The manifest's ``pyarrow.Schema``."""
    pa = require("pyarrow", "the batch manifest")
    types = {"list_string": pa.list_(pa.string()), "timestamp": pa.timestamp("ms", tz="UTC"), "bool": pa.bool_()}
    return pa.schema([pa.field(name, types[t] if t in types else getattr(pa, t)()) for name, t, _ in COLUMNS])


def table(rows):
    """Rows (dicts; missing columns are null) as a ``pyarrow.Table`` with :func:`schema`."""
    pa = require("pyarrow", "the batch manifest")
    cols = [c[0] for c in COLUMNS]
    return pa.Table.from_pylist([{c: r.get(c) for c in cols} for r in rows], schema=schema())


def _json_value(v):
    if isinstance(v, datetime.datetime):
        return {"$time": v.isoformat()}
    if hasattr(v, "item"):
        return v.item()
    return str(v)


def _from_json(row: dict) -> dict:
    t = row.get("finished")
    if isinstance(t, dict) and "$time" in t:
        row["finished"] = datetime.datetime.fromisoformat(t["$time"])
    return row


def _valid_row(row) -> bool:
    """Is ``row`` (from a file) shaped like a manifest row?  A row that is not is dropped (its
    scene is run again)."""
    if not isinstance(row, dict) or not isinstance(row.get("name"), str) or not isinstance(row.get("hash"), str):
        return False
    strings = ("status", "samples_file", "queries_file", "dependencies", "error")
    if any(row.get(k) is not None and not isinstance(row[k], str) for k in strings):
        return False
    images = row.get("images")
    return images is None or (isinstance(images, list) and all(isinstance(x, str) for x in images))


class Manifest:
    """The manifest of ``outdir``: the rows read from an earlier run (the Parquet file and its
    journal), updated as scenes finish."""

    def __init__(self, outdir: str):
        self.outdir = outdir
        self.path = os.path.join(outdir, NAME)
        self.journal = os.path.join(outdir, JOURNAL)
        self.rows: dict[str, dict] = {}
        self._flushed = 0.0
        self._dirty = False
        self._journal_file = None
        if os.path.exists(self.path):
            self._read_parquet()
        self._read_journal()

    def _read_parquet(self) -> None:
        import pyarrow.parquet as pq

        try:
            rows = pq.read_table(self.path).to_pylist()
        except Exception as e:  # a damaged manifest: every scene is run again
            warnings.warn(f"{self.path}: cannot read the manifest of an earlier run ({type(e).__name__}: "
                          f"{' '.join(str(e).split())}); running every scene again", stacklevel=3)
            return
        self.rows = {r["name"]: r for r in rows if _valid_row(r)}

    def _read_journal(self) -> None:
        """Fold the journal's rows in (later ones win; a damaged line is skipped)."""
        try:
            with open(self.journal, encoding="utf-8", errors="replace") as f:
                lines = f.read().splitlines()
        except OSError:
            return
        for line in lines:
            try:
                row = json.loads(line)
            except ValueError:
                continue  # the last line of a driver killed while appending it
            if _valid_row(row):
                self.rows[row["name"]] = _from_json(row)
                self._dirty = True

    def complete(self, name: str, content_hash, redo_errors: bool = False) -> dict | None:
        """The earlier row of scene ``name`` if it is complete for ``content_hash`` (see the
        module docstring; a function of the row's recorded dependencies, a list of paths, or a
        string), else None."""
        row = self.rows.get(name)
        if row is None:
            return None
        if callable(content_hash):
            try:
                deps = json.loads(row.get("dependencies") or "[]")
            except ValueError:
                return None
            if not (isinstance(deps, list) and all(isinstance(d, str) for d in deps)):
                return None
            content_hash = content_hash(deps)
        if row.get("hash") != content_hash:
            return None
        if row.get("status") != "ok":
            return row if not redo_errors and row.get("error_code") in FINAL_ERRORS else None
        files = [row.get("samples_file")] + list(row.get("images") or [])
        files += [row["queries_file"]] if row.get("queries_file") else []
        if not all(f and os.path.isfile(os.path.join(self.outdir, f)) for f in files):
            return None
        return row

    def add(self, row: dict, durable: bool = False) -> None:
        """Record ``row``; with ``durable`` also append it to the journal (synced to disk)."""
        self.rows[row["name"]] = row
        self._dirty = True
        if durable:
            try:
                if self._journal_file is None:
                    self._journal_file = open(self.journal, "a", encoding="utf-8")
                self._journal_file.write(json.dumps(row, default=_json_value) + "\n")
                self._journal_file.flush()
                os.fsync(self._journal_file.fileno())
            except OSError as e:
                raise OutputError(f"{self.journal}: cannot append to the journal: {e.strerror or e}") from None

    def flush(self, force: bool = False) -> None:
        """Rewrite the file if rows changed (at most every FLUSH_INTERVAL s unless ``force``),
        then empty the journal (its rows are in the file now)."""
        now = time.monotonic()
        if not self._dirty or (not force and now - self._flushed < FLUSH_INTERVAL):
            return
        import pyarrow.parquet as pq

        buf = io.BytesIO()
        pq.write_table(table(self.rows.values()), buf)
        write_atomic(self.path, buf.getvalue())
        if self._journal_file is not None:
            self._journal_file.close()
            self._journal_file = None
        if os.path.exists(self.journal):
            os.unlink(self.journal)
        self._flushed = now
        self._dirty = False

    def table(self, names=None):
        """The rows of ``names`` (in that order; default all) as a table."""
        rows = self.rows.values() if names is None else [self.rows[n] for n in names if n in self.rows]
        return table(rows)
