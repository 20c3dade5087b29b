"""One scene of a batch, run in a worker: load, sample, render the views, encode the files.

:func:`run_job` never raises for a bad scene: a :class:`~clcsg.errors.ClcsgError` (bad file,
limit hit, device problem) or any other exception becomes a row with ``status = "error"`` and
the message on one line.  It returns a :class:`Result`: the manifest row's fields computed
here and the output files as bytes (relative path -> contents), which the driver writes.

Each worker process opens its OpenCL device once (:func:`init_worker`, the process pool's
initializer or the Dask worker plugin) and runs one scene at a time (a lock: kernels and
queues of a context are not shared between threads).

Views: the camera ``clcsg render`` picks by default (the silhouette fitted at 90% from the
front right and above, 45 degree field of view, up +z), then ``views`` cameras on the orbit
through it (:func:`clcsg.orbit` at its elevation and distance, starting at its azimuth, so
view 0 is that camera); each is rendered like ``clcsg render`` renders it, so
``clcsg render SCENE -r R --eye E --target T --size WxH`` with a view's camera (manifest column
``cameras``) gives the same pixels.

Test hook: with ``CLCSG_BATCH_CRASH=NAME:MARKER`` in the environment, the worker that runs
scene NAME while the file MARKER does not exist creates MARKER and exits at once
(``os._exit``), as a crashing worker would; the tests use it to check that no scene is lost.
"""

from __future__ import annotations

import json
import math
import os
import socket
import threading
import time
import warnings
from dataclasses import dataclass, field

import numpy as np

from ..cl.device import get_context
from ..errors import ClcsgError, SceneError
from ..pipeline import Pipeline, bound_diagonal
from ..queries import distance, inside
from ..readers import scenes
from ..readers.openscad import parse_csg
from ..readers.scad import load_scad
from ..readers.scenefile import loads_json
from ..rendering.camera import orbit
from ..writers.output_files import png_bytes
from .inputs import Job
from .options import Options
from .outputs import parquet_bytes, queries_path, samples_bytes, samples_path, view_path

CRASH_HOOK = "CLCSG_BATCH_CRASH"
#: the background of the views (``clcsg render``'s default, white)
BACKGROUND = (1.0, 1.0, 1.0, 1.0)
#: the field of view of the views, degrees (``clcsg render``'s default)
FOV = 45.0
UP = (0.0, 0.0, 1.0)

_lock = threading.Lock()
_worker: dict = {"device": None, "error": None}


@dataclass
class Result:
    """A scene's manifest fields (``row``) and output files (relative path -> bytes)."""

    row: dict
    files: dict = field(default_factory=dict)


def init_worker(device=None) -> None:
    """Open the OpenCL device ``device`` in this process, once (a failure is kept and reported
    in the row of every scene this worker runs, so the pool itself stays usable)."""
    _worker["device"] = device
    try:
        get_context(device)
        _worker["error"] = None
    except ClcsgError as e:
        _worker["error"] = e


def worker_id() -> str:
    return f"{socket.gethostname()}:{os.getpid()}"


def _crash_hook(name: str) -> None:
    spec = os.environ.get(CRASH_HOOK, "")
    target, _, marker = spec.partition(":")
    if target and target == name and marker and not os.path.exists(marker):
        with open(marker, "w") as f:
            f.write(worker_id())
        os._exit(17)


def load_scene(job: Job):
    """(the Scene of a job, parsed from its text; the other files it read).  A ``.scad`` file
    is run through openscad, which lists the files it includes and uses (``openscad -d``);
    they go into the scene's content hash."""
    if job.error:
        raise SceneError(job.error)
    if job.kind == ".json":
        return loads_json(job.text, job.source), []
    if job.kind == ".csg":
        return parse_csg(job.text, job.source), []
    if job.kind == ".scad":
        scene, deps = load_scad(job.path, with_dependencies=True)
        own = os.path.abspath(job.path)
        return scene, [d for d in deps if d != own]
    return scenes.load(job.path), []


def cameras(pipe: Pipeline, samples, n: int, size) -> list:
    """The ``n`` view cameras of the module docstring."""
    w, h = size
    fitted = pipe.camera(w, h, fov=FOV, up=UP, tape=samples.tape)
    d = fitted.eye - fitted.target
    elevation = math.degrees(math.asin(float(np.clip(d @ np.asarray(UP) / np.linalg.norm(d), -1.0, 1.0))))
    return list(orbit(fitted, n=n, elevation=elevation))


def _camera_record(cam) -> dict:
    return {"eye": cam.eye.tolist(), "target": cam.target.tolist(), "up": list(UP), "fov": cam.fov,
            "width": cam.width, "height": cam.height}


def _one_line(text) -> str:
    return " ".join(str(text).split())


def _sample(pipe: Pipeline, options: Options, row: dict):
    """The scene's samples; its statistics into ``row``.  The radius is the pipeline's
    (``options.radius``, relative to the compiled bound's diagonal); the manifest shows an
    empty solid's relative radius as NaN (no bound, no diagonal)."""
    t0 = time.perf_counter()
    tape = pipe.tape
    compile_s = time.perf_counter() - t0
    diag = 0.0 if tape.empty else bound_diagonal(tape.bound)
    radius = pipe.radius(options.radius)
    s = pipe.samples(radius, floor=options.floor, progress=False, max_samples=options.max_samples)
    if tape.empty and options.radius.relative:
        radius = float("nan")
    st = s.stats
    row.update(samples=len(s), radius=radius, diagonal=diag, quadrics=int(st.get("tape_quadrics", tape.n_quadrics)),
               primitives=len(tape.instances), instructions=int(st.get("tape_instructions", len(tape.ops))),
               unresolved=int(st.get("unresolved", 0)), levels=int(st.get("levels", 0)),
               clipped_samples=int(st.get("clipped_samples", 0)), compile_s=compile_s,
               sample_s=time.perf_counter() - t0)
    return s


def query_points(job: Job, options: Options, tape) -> np.ndarray:
    """The scene's query points: ``options.points``, or ``options.random_points`` uniform in
    the bound grown by 5% of its diagonal, from a generator seeded by the scene's digest (an
    empty solid has no bound: none)."""
    if options.points is not None:
        return options.points
    if tape.empty:
        return np.zeros((0, 3))
    lo, hi = tape.bound
    pad = 0.05 * bound_diagonal(tape.bound)
    rng = np.random.default_rng(int(job.digest[:16], 16))
    return rng.uniform(lo - pad, hi + pad, (int(options.random_points), 3))


def _queries(job: Job, options: Options, tape, ctx, row: dict, files: dict) -> None:
    t0 = time.perf_counter()
    pts = query_points(job, options, tape)
    ins = inside(tape, pts, device=ctx)
    dist = distance(tape, pts, device=ctx)
    files[queries_path(job.name)] = parquet_bytes({"x": pts[:, 0], "y": pts[:, 1], "z": pts[:, 2], "inside": ins,
                                                   "distance": dist}, {"scene": job.name, "source": job.source})
    row.update(query_points=len(pts), inside_fraction=float(ins.mean()) if len(pts) else float("nan"),
               query_s=time.perf_counter() - t0)


def _sample_and_render(job: Job, options: Options, ctx, row: dict, files: dict) -> None:
    scene, deps = load_scene(job)
    row["dependencies"] = json.dumps(deps) if deps else None
    pipe = Pipeline(scene, ctx, options.normal_form)
    s = _sample(pipe, options, row)
    meta = {"scene": job.name, "source": job.source, "radius": repr(row["radius"])}
    files[samples_path(job.name, options.fmt)] = samples_bytes(s, options.fmt, meta)
    t1 = time.perf_counter()
    cams = cameras(pipe, s, options.views, options.size) if options.views and len(s) else []
    for k, cam in enumerate(cams):
        img = pipe.image(cam, s, background=BACKGROUND)
        files[view_path(job.name, k)] = png_bytes(img.rgba)
    row.update(views=len(cams), cameras=json.dumps([_camera_record(c) for c in cams]),
               render_s=time.perf_counter() - t1)
    if options.queries:
        _queries(job, options, s.tape, ctx, row, files)


def run_job(job: Job, options: Options) -> Result:
    """Run one scene (see the module docstring); never raises for a bad scene."""
    _crash_hook(job.name)
    row = {"name": job.name, "source": job.source, "status": "ok", "error": None, "worker": worker_id()}
    files: dict = {}
    t0, c0 = time.perf_counter(), time.process_time()
    with _lock, warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        try:
            if _worker["error"] is not None and _worker["device"] == options.device:
                raise _worker["error"]

            _sample_and_render(job, options, get_context(options.device), row, files)
        except ClcsgError as e:
            row.update(status="error", error=_one_line(e) or type(e).__name__, error_code=e.exit_code)
            files = {}
        except Exception as e:  # a bug or a driver failure: reported, the batch goes on
            row.update(status="error", error=f"{type(e).__name__}: {_one_line(e) or '(no message)'}",
                       error_code=1)
            files = {}
    msgs = list(dict.fromkeys(_one_line(w.message) for w in caught))
    row.update(warnings="; ".join(msgs) or None, seconds=time.perf_counter() - t0,
               cpu_s=time.process_time() - c0)
    return Result(row, files)
