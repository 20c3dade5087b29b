"""``clcsg.batch``: sample (and render) many scenes into a folder, on a process pool or Dask.

The driver: expand the inputs into jobs, reuse the scenes an earlier run completed (same
content hash, files present), run the others on an engine, write each result's files and
manifest row as it arrives, and show progress (scenes done, failed, samples per second).
"""

from __future__ import annotations

import datetime
import json
import os
import time

from ..errors import OutputError, UsageError
from ..progress import for_option
from . import dask_engine, local
from . import inputs as _inputs
from .dask_engine import parse_local
from .manifest import Manifest
from .options import Options, Radius, file_digests, require
from .outputs import discard_files, publish_files, queries_path, remove_files, samples_path, stage_files, view_path


class _Tally:
    """Counts of the run for the progress bar and the summary."""

    def __init__(self, total: int):
        self.total = total
        self.ok = self.failed = self.skipped = self.samples = 0
        self.t0 = time.perf_counter()

    @property
    def done(self) -> int:
        return self.ok + self.failed

    @property
    def rate(self) -> float:
        dt = time.perf_counter() - self.t0
        return self.samples / dt if dt > 0 else 0.0

    def note(self) -> str:
        return f"{self.ok} ok, {self.failed} failed ({self.skipped} done before), {self.rate:,.0f} samples/s"

    def count(self, row: dict) -> None:
        """Count a finished row: ok or failed, and skipped (from an earlier run) or computed."""
        ok = row.get("status") == "ok"
        self.ok += ok
        self.failed += not ok
        if row.get("skipped"):
            self.skipped += 1
        elif ok:
            self.samples += int(row.get("samples") or 0)


def _hash(job, options: Options, deps) -> str:
    """The content hash of a job whose scene read the files ``deps`` (a list of paths)."""
    return options.content_hash(job.digest, file_digests(deps))


def _finish_row(row: dict, job, options: Options, attempts) -> dict:
    ok = row.get("status") == "ok"
    deps = json.loads(row["dependencies"]) if row.get("dependencies") else []
    row.update(hash=_hash(job, options, deps), attempts=attempts, skipped=False,
               samples_file=samples_path(job.name, options.fmt) if ok else None,
               images=[view_path(job.name, k) for k in range(int(row.get("views") or 0))] if ok else [],
               queries_file=queries_path(job.name) if ok and options.queries else None,
               finished=datetime.datetime.now(datetime.timezone.utc))
    return row


def _error(row: dict, e: OutputError) -> dict:
    return {**row, "status": "error", "error": str(e), "error_code": e.exit_code,
            "samples_file": None, "images": [], "queries_file": None}


def _store(result, job, options: Options, outdir: str, attempts, manifest: Manifest) -> dict:
    """Write a result's files and journal its finished manifest row, in the order that keeps
    the journal ahead of the files: the files are written and synced without names, this
    scene's earlier files are removed, the row is journaled, and only then are the files
    named.  A driver killed at any point leaves no file whose row is not journaled, and no
    journaled row that names an older run's file."""
    row = _finish_row(dict(result.row), job, options, attempts)
    if row.get("status") != "ok":
        manifest.add(row, durable=True)
        return row
    try:
        staged = stage_files(outdir, result.files)
    except OutputError as e:
        row = _error(row, e)
        manifest.add(row, durable=True)
        return row
    try:
        remove_files(outdir, result.files)
        manifest.add(row, durable=True)
        publish_files(staged)
    except OutputError as e:
        row = _error(row, e)
        manifest.add(row, durable=True)
    finally:
        discard_files(staged)
    return row


def dask_address(scheduler, dask) -> str | None:
    """The Dask engine's address (``tcp://...`` or ``local:N``), None for the local engine."""
    if scheduler is not None and dask is not None:
        raise UsageError("give either a scheduler address or a local Dask cluster (local:N), not both")
    if scheduler is None and dask is None:
        return None

    if scheduler is None:
        address = f"local:{dask}" if isinstance(dask, int) else str(dask)
        if parse_local(address) is None:
            raise UsageError(f"--dask: expected local:N, got {dask!r} (a scheduler address goes to --scheduler)")
        return address
    address = str(scheduler).strip()
    return address if "://" in address or parse_local(address) is not None else f"tcp://{address}"


def _engine(todo, options, workers, address, retries):
    if address is not None:
        return dask_engine.run(todo, options, address, retries)

    return local.run(todo, options, workers, retries)


def _output_folder(outdir) -> str:
    outdir = os.fspath(outdir)
    try:
        os.makedirs(outdir, exist_ok=True)
    except OSError as e:
        raise UsageError(f"{outdir}: cannot create the output folder: {e.strerror or e}") from None
    return outdir


def _not_done(jobs, manifest, options: Options, redo_errors: bool, tally) -> list:
    """The jobs an earlier run did not complete; the others go into the manifest as skipped.

    A ``.scad`` program's error may come from a file it includes, so it is never final."""
    todo = []
    for job in jobs:
        old = manifest.complete(job.name, lambda deps, job=job: _hash(job, options, deps),
                                redo_errors or job.kind == ".scad")
        if old is None:
            todo.append(job)
        else:
            manifest.add({**old, "skipped": True})
            tally.count({**old, "skipped": True})
    return todo


def batch(scenes, radius, outdir, *, fmt: str = "parquet", views: int = 0, size=(640, 480), points=None,
          random_points: int = 0, workers=None,
          scheduler: str | None = None, dask=None, device=None, normal_form: str = "tree", floor=None,
          max_samples=None, retries: int = 2, redo_errors: bool = False, progress=None,
          as_pandas: bool = False):
    """Sample every scene of ``scenes`` into ``outdir`` and return the manifest of these scenes.

    ``scenes``: paths, globs, directories, manifest files (one path or one-line JSON scene per
    line), Shapes or Scenes (:mod:`clcsg.batching.inputs`).  ``radius``: a number in scene units or
    a percentage of each scene's bound diagonal (``"1%"``).  Per scene: ``samples/NAME.parquet``
    (``fmt="ply"``: ``.ply``), ``views`` PNG images ``views/NAME.K.png`` of ``size`` on an
    orbit through ``clcsg render``'s default camera, with ``points`` (an (N, 3) array or a
    ``.npy`` file; the same points for every scene) or ``random_points`` (N uniform points in
    each scene's bound, grown by 5% of its diagonal) ``queries/NAME.parquet`` (x, y, z,
    inside, distance: :func:`clcsg.inside`, :func:`clcsg.distance`), and a row of
    ``manifest.parquet`` (:mod:`clcsg.batching.manifest`).  Scenes complete from an earlier run with the same options
    are not computed again (``skipped``), nor are scenes whose bad input or limit failed them
    then (unless ``redo_errors``); a scene that fails gets ``status = "error"`` and its
    message, and the run goes on.

    Engine: a local process pool of ``workers`` processes (default: one per CPU), or with
    ``scheduler`` (an address, ``tcp://host:8786``) or ``dask`` (N or ``"local:N"``: a
    LocalCluster of N processes) a Dask cluster.  ``retries``: extra attempts for a scene whose
    worker died.  ``device``: every worker's OpenCL device (default: each worker's default,
    e.g. its ``PYOPENCL_CTX``).  ``progress`` as in :func:`clcsg.sample`.

    Returns a ``pyarrow.Table`` (a pandas DataFrame with ``as_pandas=True``), one row per scene
    in input order.  Needs pyarrow (and dask for the Dask engine): ``pip install 'clcsg[batch]'``.
    """
    require("pyarrow", "clcsg batch")
    address = dask_address(scheduler, dask)
    if address is not None:
        require("distributed", "the Dask engine")
    if as_pandas:
        require("pandas", "as_pandas=True")
    options = Options(Radius.parse(radius), fmt=fmt, views=int(views), size=tuple(int(v) for v in size),
                      normal_form=normal_form, floor=None if floor is None else float(floor),
                      max_samples=None if max_samples is None else int(max_samples),
                      device=None if device is None else str(device), points=points,
                      random_points=int(random_points))
    if workers is not None and int(workers) < 1:
        raise UsageError(f"workers must be >= 1, got {workers}")
    if int(retries) < 0:
        raise UsageError(f"retries must be >= 0, got {retries}")
    jobs = _inputs.jobs(scenes)
    outdir = _output_folder(outdir)
    manifest = Manifest(outdir)
    tally = _Tally(len(jobs))
    todo = _not_done(jobs, manifest, options, redo_errors, tally)
    with for_option(progress).step("batch", "batch", total=len(jobs), unit="scenes") as st:
        st.update(done=tally.done, note=tally.note())
        try:
            if todo:
                for job, result, attempts in _engine(todo, options, workers, address, retries):
                    row = _store(result, job, options, outdir, attempts, manifest)
                    manifest.flush()
                    tally.count(row)
                    st.update(done=tally.done, note=tally.note(), ok=tally.ok, failed=tally.failed,
                              skipped=tally.skipped, samples_per_s=round(tally.rate, 1))
        finally:
            manifest.flush(force=True)
    out = manifest.table([job.name for job in jobs])
    out = out.replace_schema_metadata({"clcsg.outdir": os.path.abspath(outdir),
                                       "clcsg.seconds": f"{time.perf_counter() - tally.t0:.3f}"})
    return out.to_pandas() if as_pandas else out
