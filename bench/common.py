"""Shared benchmark plumbing: machine/device description, result files, timing helpers, the
manifold3d translation of a clcsg shape (:class:`Translator`), the surface error
(:func:`surface_error`) that the peer and mesh benchmarks both measure with and the distance to
the CSG surface itself (:func:`csg_surface_error`), and the command and
environment of fresh ``clcsg`` processes (:func:`clcsg_command`, :func:`environment_for_runs`).

Every other bench module may import this one and :mod:`bench.zoo`; neither imports another
bench module, so there are no import cycles.
"""

from __future__ import annotations

import contextlib
import json
import math
import os
import platform
import subprocess
import sys
import time
import warnings

import numpy as np

from clcsg.model.csg import Complement, Difference, Intersection, Primitive, Transformed, Union
from clcsg.model.quadric import frame_z_to

RESULTS = os.path.join(os.path.dirname(__file__), "results")
#: the default result directory (the gallery is written only with it)
DEFAULT_RESULTS = RESULTS


def git_commit() -> str:
    try:
        return subprocess.check_output(["git", "rev-parse", "--short", "HEAD"], text=True,
                                       cwd=os.path.dirname(__file__), stderr=subprocess.DEVNULL).strip()
    except Exception:
        return "unknown"


def git_dirty() -> bool | None:
    """True if the work tree differs from HEAD (other engineers edit the package meanwhile)."""
    try:
        out = subprocess.check_output(["git", "status", "--porcelain", "--untracked-files=no"], text=True,
                                      cwd=os.path.dirname(__file__), stderr=subprocess.DEVNULL)
        return bool(out.strip())
    except Exception:
        return None


def environment(ctx) -> dict:
    import numpy
    import pyopencl

    import clcsg

    return {
        "date": time.strftime("%Y-%m-%dT%H:%M:%S"),
        "machine": platform.machine(),
        "processor": platform.processor() or platform.machine(),
        "cpus": os.cpu_count(),
        "python": platform.python_version(),
        "numpy": numpy.__version__,
        "pyopencl": pyopencl.VERSION_TEXT,
        "clcsg": clcsg.__version__,
        "git_commit": git_commit(),
        "git_dirty": git_dirty(),
        "device": ctx.info.name,
        "platform": ctx.info.platform,
        "compute_units": ctx.info.compute_units,
    }


class Load:
    """The load average at the start and at the end of a part (the machine is shared)."""

    def __init__(self):
        self.start = os.getloadavg()[0]

    def into(self, env: dict) -> dict:
        env["loadavg_start"] = round(self.start, 2)
        env["loadavg_end"] = round(os.getloadavg()[0], 2)
        return env


def write(part: str, payload: dict) -> str:
    os.makedirs(RESULTS, exist_ok=True)
    path = os.path.join(RESULTS, f"{part}.json")
    with open(path, "w") as f:
        json.dump(payload, f, indent=2, default=_json_default)
    return path


def _json_default(x):
    if isinstance(x, np.generic):
        return x.item()
    if isinstance(x, np.ndarray):
        return x.tolist()
    raise TypeError(f"not JSON serializable: {type(x).__name__}")


def best_of(fn, repeats: int):
    """(best wall time in seconds, last result) over ``repeats`` runs (noisy 2-core machines)."""
    best, out = float("inf"), None
    for _ in range(repeats):
        t = time.perf_counter()
        out = fn()
        best = min(best, time.perf_counter() - t)
    return best, out


def fmt(x, spec=".1f", scale=1.0, suffix="", none="-") -> str:
    """``x * scale`` formatted, or ``none`` for None / NaN / inf."""
    if x is None or (isinstance(x, float) and not math.isfinite(x)):
        return none
    return f"{(x * scale if scale != 1.0 else x):{spec}}{suffix}"


# -- OpenCL profiling -----------------------------------------------------------------------------


def event_seconds(ev) -> float:
    ev.wait()
    return 1e-9 * (ev.profile.end - ev.profile.start)


@contextlib.contextmanager
def kernel_events():
    """Record the profiling event of every kernel launched through ``pyopencl.Kernel.__call__``
    inside the block: yields a list of (kernel name, event)."""
    import pyopencl as cl

    log = []
    original = cl.Kernel.__call__

    def traced(self, *args, **kwargs):
        ev = original(self, *args, **kwargs)
        log.append((self.function_name, ev))
        return ev

    cl.Kernel.__call__ = traced
    try:
        yield log
    finally:
        cl.Kernel.__call__ = original


def kernel_seconds(log, name=None) -> float:
    return sum(event_seconds(ev) for n, ev in log if name is None or n == name)


# -- scenes ---------------------------------------------------------------------------------------


def diagonal(bound) -> float:
    b = np.asarray(bound, dtype=np.float64)
    return float(np.linalg.norm(b[1] - b[0]))


def summarize_levels(values) -> dict:
    """mean / max / last of a per-level list (tape lengths)."""
    v = [float(x) for x in values or []]
    if not v:
        return {"mean": None, "max": None, "first": None, "last": None}
    return {"mean": float(np.mean(v)), "max": float(np.max(v)), "first": v[0], "last": v[-1]}


def time_sampling(scene, radius, ctx, repeats=3, budget=20.0, normal_form="tree", warm=True, **kw) -> dict:
    """Warm timing of ``clcsg.sample``: one run first (it builds the kernels for this tape's
    register count and precision; programs are cached per process), then up to ``repeats`` runs
    (fewer once ``budget`` seconds are spent).  The dict has ``seconds`` (the least wall time of
    the whole call), ``cpu_s`` (the least process CPU time of a call: on a noisy machine the
    least of each is the closest to the call's own cost, and the two may come from different
    runs), the ``classify`` kernel's time in the fastest run (samples are finished in it),
    ``first_s`` (the warm-up run, kernel builds included), ``runs`` and ``samples`` (the Samples
    of the fastest run).  ``cpu_p10_s`` is the 10th percentile of the calls' CPU times (the
    least of 10 calls or fewer): a rare call is counted far below its work on this virtual
    machine (the lens in 2.7 ms of CPU on one PoCL thread, where its kernels alone take 3.5 ms
    and 4,500 other calls took 4.7 ms or more), and the least takes such a call for the cost."""
    import clcsg

    warnings.simplefilter("ignore")
    first_s = None
    if warm:
        t0 = time.perf_counter()
        clcsg.sample(scene, radius, device=ctx, normal_form=normal_form, progress=False, **kw)
        first_s = time.perf_counter() - t0
    best = None
    cpu_times = []
    spent = 0.0
    runs = 0
    for _ in range(max(1, repeats)):
        with kernel_events() as log:
            c0, t0 = time.process_time(), time.perf_counter()
            s = clcsg.sample(scene, radius, device=ctx, normal_form=normal_form, progress=False, **kw)
            wall, cpu = time.perf_counter() - t0, time.process_time() - c0
        runs += 1
        cpu_times.append(cpu)
        if best is None or wall < best["seconds"]:
            best = {"seconds": wall, "classify_kernel_s": kernel_seconds(log, "classify"), "samples": s}
        spent += wall
        if spent > budget:
            break
    cpu_times.sort()
    best["cpu_s"] = cpu_times[0]
    best["cpu_p10_s"] = cpu_times[len(cpu_times) // 10]
    best["runs"] = runs
    best["first_s"] = first_s
    return best


def sampling_record(ts: dict, cu: int) -> dict:
    """The JSON fields of a :func:`time_sampling` result (its Samples' stats summarized)."""
    st = ts["samples"].stats
    tm = summarize_levels(st.get("tape_mean_per_level"))
    tx = summarize_levels(st.get("tape_max_per_level"))
    q = st.get("distance_queries", 0)
    return {
        "samples": st.get("samples"),
        "sampling_s": ts["seconds"],
        "sampling_cpu_s": ts["cpu_s"],
        "sampling_cpu_p10_s": ts["cpu_p10_s"],
        "sampling_s_times_cu": ts["seconds"] * cu,
        "first_run_s": ts["first_s"],
        "runs": ts["runs"],
        "compile_s": st.get("compile_s"),
        "analyse_s": st.get("analyse_s"),
        "subdivide_s": st.get("subdivide_s"),
        "finish_s": st.get("finish_s"),
        "classify_kernel_s": ts["classify_kernel_s"],
        "distance_queries": q,
        "leaf_distances": st.get("leaf_distances"),
        "leaf_distances_per_query": st.get("leaf_distances_per_query"),
        "prune_evaluations": st.get("prune_evaluations"),
        "prune_evaluations_per_cell": st.get("prune_evaluations", 0) / max(1, st.get("cells") or 1),
        "pruned_decided": st.get("pruned_decided"),
        "unresolved": st.get("unresolved"),
        "discarded": st.get("discarded"),
        "filled": st.get("filled"),
        "single": st.get("single"),
        "split": st.get("split"),
        "split_in_place": st.get("split_in_place"),
        "cells": st.get("cells"),
        "levels": st.get("levels"),
        "chains": st.get("chains"),
        "tapes_written": st.get("tapes_written"),
        "arena_rows": st.get("arena_rows"),
        "tape_instructions": st.get("tape_instructions"),
        "tape_leaves": st.get("tape_leaves"),
        "tape_registers": st.get("tape_registers"),
        "tape_mean": tm,
        "tape_max": tx,
        "tape_mean_per_level": st.get("tape_mean_per_level"),
        "tape_max_per_level": st.get("tape_max_per_level"),
        "clip_rows": st.get("clip_rows"),
        "clip_rows_written": st.get("clip_rows_written"),
        "clipped_samples": st.get("clipped_samples"),
        "us_per_query_kernel_per_cu": 1e6 * ts["classify_kernel_s"] * cu / q if q else None,
    }


# -- cameras --------------------------------------------------------------------------------------


def fit_camera(bound, width, height, direction, fill=0.9):
    """A camera looking at the bound's center from ``direction``, at the distance where the
    projection of the bound's corners spans ``fill`` of the image (width or height)."""
    from clcsg.rendering.camera import Camera

    b = np.asarray(bound, dtype=np.float64)
    cam = Camera.fit(b, width, height, direction=direction)
    corners = np.array([[x, y, z] for x in b[:, 0] for y in b[:, 1] for z in b[:, 2]])
    for _ in range(6):
        xy, _z = cam.project(corners)
        span = max(np.abs(xy[:, 0] - width / 2).max() / (width / 2), np.abs(xy[:, 1] - height / 2).max() / (height / 2))
        if not math.isfinite(span) or abs(span / fill - 1) < 0.01:
            break
        d = cam.eye - cam.target
        cam = Camera.look_at(cam.target + d * (span / fill), cam.target, up=(0, 0, 1), fov=cam.fov,
                             width=width, height=height)
    return cam


def fit_to_silhouette(tape, width, height, direction, fill=0.9, ctx=None):
    """:func:`fit_camera`, then moved along the view direction until the solid's silhouette
    (found with a low-resolution exact ray tracing of ``tape``) spans ``fill`` of the image."""
    import clcsg
    from clcsg.rendering.camera import Camera

    cam = fit_camera(tape.bound, width, height, direction, fill)
    small_w = 96
    small_h = max(2, round(small_w * height / width))
    for _ in range(3):
        ids = clcsg.raytrace(tape, cam.resized(small_w, small_h), device=ctx).ids
        ys, xs = np.nonzero(ids >= 0)
        if len(xs) == 0:
            break
        span = max(np.abs(xs + 0.5 - small_w / 2).max() / (small_w / 2),
                   np.abs(ys + 0.5 - small_h / 2).max() / (small_h / 2))
        if abs(span / fill - 1) < 0.03:
            break
        d = cam.eye - cam.target
        cam = Camera.look_at(cam.target + d * (span / fill), cam.target, up=(0, 0, 1), fov=cam.fov,
                             width=width, height=height)
    return cam


def least_cpu(fn, repeats):
    """(the least process time of ``repeats`` calls of ``fn``, its last result)."""
    best, out = math.inf, None
    for _ in range(repeats):
        t = time.process_time()
        out = fn()
        best = min(best, time.process_time() - t)
    return best, out


# -- manifold3d translation and the surface error (bench.peers, bench.mesh) -----------------------

class Unsupported(Exception):
    pass


def _frame_to(axis):
    """3x3 rotation taking +z to ``axis``."""
    return frame_z_to(np.asarray(axis, dtype=float))


def _place(m, rot, center):
    """Rotate ``m`` by the 3x3 ``rot`` about the origin, then translate it to ``center``."""
    M = np.zeros((3, 4))
    M[:, :3] = rot
    M[:, 3] = center
    return m.transform(M)


class Translator:
    def __init__(self, manifold3d, segments, bound):
        self.mf = manifold3d
        self.n = int(segments)
        b = np.asarray(bound, dtype=float)
        self.center = 0.5 * (b[0] + b[1])
        self.big = 4.0 * float(np.linalg.norm(b[1] - b[0])) + 1.0

    def build(self, shape):
        M = self.mf.Manifold
        if isinstance(shape, Primitive):
            return self.primitive(shape)
        if isinstance(shape, Union):
            return M.batch_boolean([self.build(s) for s in shape.operands], self.mf.OpType.Add) \
                if shape.operands else M()
        if isinstance(shape, Intersection):
            pos = [s for s in shape.operands if not isinstance(s, Complement)]
            neg = [s.operand for s in shape.operands if isinstance(s, Complement)]
            if not pos:
                raise Unsupported("an intersection of complements only")
            out = M.batch_boolean([self.build(s) for s in pos], self.mf.OpType.Intersect) if len(pos) > 1 \
                else self.build(pos[0])
            for s in neg:
                out = out - self.build(s)
            return out
        if isinstance(shape, Difference):
            first = self.build(shape.operands[0])
            rest = [self.build(s) for s in shape.operands[1:]]
            if not rest:
                return first
            return first - (M.batch_boolean(rest, self.mf.OpType.Add) if len(rest) > 1 else rest[0])
        if isinstance(shape, Transformed):
            return self.build(shape.operand).transform(np.asarray(shape.matrix)[:3, :4])
        raise Unsupported(f"{type(shape).__name__} outside an intersection")

    def halfspace(self, normal, offset):
        """normal . x <= offset, as a cube of side `big` with one face on the plane."""
        n = np.asarray(normal, dtype=float)
        ln = np.linalg.norm(n)
        w, o = n / ln, offset / ln
        p0 = self.center - (w @ self.center - o) * w  # the scene center projected onto the plane
        L = self.big
        cube = self.mf.Manifold.cube((L, L, L), True)
        return _place(cube, _frame_to(w), p0 - 0.5 * L * w)

    def primitive(self, p: Primitive):
        M = self.mf.Manifold
        k, a, n = p.kind, p.params, self.n
        if k == "box":
            size = np.broadcast_to(np.asarray(a.get("size", 1.0), dtype=float), (3,))
            return M.cube(tuple(size), True).translate(tuple(np.asarray(a.get("center", (0, 0, 0)), dtype=float)))
        if k in ("cylinder", "cone"):
            h = float(a.get("height", 1.0))
            if k == "cylinder":
                r1 = r2 = float(a.get("radius", 1.0))
            else:
                r1, r2 = float(a.get("r1", 1.0)), float(a.get("r2", 0.0))
            m = M.cylinder(h, r1, r2, n, True)
            return _place(m, _frame_to(a.get("axis", (0, 0, 1))), np.asarray(a.get("center", (0, 0, 0)), float))
        if k == "sphere":
            return M.sphere(float(a.get("radius", 1.0)), n).translate(tuple(np.asarray(a.get("center", (0, 0, 0)), float)))
        if k == "ellipsoid":
            r = np.broadcast_to(np.asarray(a.get("radii", (1, 1, 1)), dtype=float), (3,))
            return M.sphere(1.0, n).scale(tuple(r)).translate(tuple(np.asarray(a.get("center", (0, 0, 0)), float)))
        if k == "halfspace":
            return self.halfspace(a.get("normal", (0, 0, 1)), float(a.get("offset", 0.0)))
        if k == "slab":
            nrm = np.asarray(a.get("normal", (0, 0, 1)), dtype=float)
            return self.halfspace(nrm, float(a.get("hi", 0.5))) ^ self.halfspace(-nrm, -float(a.get("lo", -0.5)))
        if k == "infinite_cylinder":
            m = M.cylinder(self.big, float(a.get("radius", 1.0)), -1.0, n, True)
            axis = np.asarray(a.get("axis", (0, 0, 1)), dtype=float)
            c = np.asarray(a.get("center", (0, 0, 0)), dtype=float)
            w = axis / np.linalg.norm(axis)
            c = c + (w @ (self.center - c)) * w  # centered on the scene along its axis
            return _place(m, _frame_to(w), c)
        raise Unsupported(f"primitive {k!r}")


def surface_error(tape, points, chunk=20000):
    """Distance to the nearest unique quadric of ``tape`` (a compiled scene, or anything with
    ``quadrics`` (U, 4, 4)) along each quadric's gradient line: min_u of the root of
    Q_u(x + t n) nearest to 0 (n the unit gradient; exact for a quadric, the distance itself for
    spheres, cylinders and planes, an upper bound elsewhere), first order (|Q_u| / |grad Q_u|)
    where the line misses Q_u.  The first-order value alone overstates the sag of a chord
    inside a circle of radius R by about s / 2R, for every mesher alike."""
    return nearest_quadric(tape, points, chunk)[0]


def nearest_quadric(tape, points, chunk=20000):
    """(:func:`surface_error`, the index of that nearest quadric, the point where its gradient
    line meets it (the point itself where the line misses))."""
    Qs = np.asarray(tape.quadrics)  # (U, 4, 4)
    chunk = max(16, min(chunk, 2_000_000 // max(len(Qs), 1)))  # (chunk, U, 4) values: at most 64 MB
    points = np.asarray(points, dtype=np.float64)
    dist, which, foot = np.empty(len(points)), np.zeros(len(points), dtype=np.int64), points.copy()
    for s in range(0, len(points), chunk):
        x = points[s:s + chunk]
        xh = np.concatenate([x, np.ones((len(x), 1))], axis=1)
        mx = np.einsum("uij,nj->nui", Qs, xh)  # (N, U, 4): Q_u xh
        val = np.einsum("nui,ni->nu", mx, xh)
        grad = 2.0 * mx[:, :, :3]
        g = np.linalg.norm(grad, axis=-1)
        with np.errstate(divide="ignore", invalid="ignore"):
            n = grad / g[..., None]
            bend = np.einsum("nui,uij,nuj->nu", n, Qs[:, :3, :3], n)
            disc = g * g - 4.0 * val * bend
            t = np.where(disc >= 0, -2.0 * val / (g + np.sqrt(np.maximum(disc, 0.0))), np.nan)
            d = np.where(disc >= 0, np.abs(t), np.abs(val) / g)
            d = np.where(g > 0, d, np.where(val == 0, 0.0, np.inf))
        k = np.argmin(d, axis=1)
        rows = np.arange(len(x))
        dist[s:s + chunk], which[s:s + chunk] = d[rows, k], k
        step = np.nan_to_num(t[rows, k])[:, None] * np.nan_to_num(n[rows, k])
        foot[s:s + chunk] = x + step
    return dist, which, foot


def _sphere_directions(n):
    k = np.arange(n) + 0.5
    z = 1.0 - 2.0 * k / n
    phi = k * np.pi * (3.0 - np.sqrt(5.0)) + 0.1234
    r = np.sqrt(1.0 - z * z)
    return np.stack([r * np.cos(phi), r * np.sin(phi), z], axis=1)


#: directions and growth of :func:`csg_surface_error`'s probe spheres
CSG_ERROR_DIRECTIONS = _sphere_directions(256)
CSG_ERROR_STEP = 1.05


def csg_surface_error(tape, points, floor, reach=None):
    """Distance (an upper bound) from each point to the CSG surface itself, not to the nearest
    quadric.  Where the nearest quadric's gradient line meets it at a point of the CSG surface
    (the solid's membership differs on the quadric's two sides there: substitution, exact), the
    distance to that point (:func:`nearest_quadric`).  Elsewhere (a triangle on a quadric's
    extension, across a gap that quadric does not bound, is near its quadric and far from the
    solid) the smallest radius, growing by :data:`CSG_ERROR_STEP` from that distance and at
    least ``floor``, at which some of 256 points on the sphere round the point are inside the
    solid and some outside (the boundary then passes within the radius), the largest of those
    tightened by bisection with denser probes (:func:`_tightened`); inf past ``reach``
    (default: the bound's diagonal)."""
    from clcsg.compile.interpret import contains, member

    points = np.asarray(points, dtype=np.float64)
    d, which, foot = nearest_quadric(tape, points)
    out = np.full(len(points), np.inf)
    for q in np.unique(which):
        rows = np.flatnonzero((which == q) & np.isfinite(d))
        neg, pos = member(tape.ops, tape.quadrics, foot[rows], int(q))
        out[rows[neg != pos]] = d[rows[neg != pos]]
    exact = np.isfinite(out)
    r = np.maximum(d, floor)
    alive = np.flatnonzero(~exact)
    reach = diagonal(tape.bound) if reach is None else reach
    while len(alive):
        probes = (points[alive, None] + r[alive, None, None] * CSG_ERROR_DIRECTIONS[None]).reshape(-1, 3)
        ins = contains(tape.ops, tape.quadrics, probes).reshape(len(alive), -1)
        hit = ins.any(axis=1) & ~ins.all(axis=1)
        out[alive[hit]] = r[alive[hit]]
        alive = alive[~hit]
        r[alive] *= CSG_ERROR_STEP
        alive = alive[r[alive] <= reach * CSG_ERROR_STEP]
    return _tightened(tape, points, out, ~exact, floor)


#: directions and bisection steps of :func:`_tightened`
TIGHT_DIRECTIONS = _sphere_directions(4096)
TIGHT_STEPS = 8
TIGHT_POINTS = 256


def _tightened(tape, points, out, probed, floor):
    """``out`` where the probes set it (``probed``) above every other value: at most
    :data:`TIGHT_POINTS` of the largest, each the smallest radius between it /
    :data:`CSG_ERROR_STEP` and it at which :data:`TIGHT_DIRECTIONS` straddle (bisection; still
    an upper bound, now within a fraction of a per cent)."""
    from clcsg.compile.interpret import contains

    finite = np.isfinite(out)
    rest = out[finite & ~probed]
    base = max(float(rest.max()) if len(rest) else 0.0, floor)
    top = np.flatnonzero(finite & probed & (out > base))
    top = top[np.argsort(out[top])[-TIGHT_POINTS:]]
    if not len(top):
        return out
    hi = out[top].copy()
    lo = hi / CSG_ERROR_STEP
    for _ in range(TIGHT_STEPS):
        mid = 0.5 * (lo + hi)
        probes = (points[top, None] + mid[:, None, None] * TIGHT_DIRECTIONS[None]).reshape(-1, 3)
        ins = contains(tape.ops, tape.quadrics, probes).reshape(len(top), -1)
        hit = ins.any(axis=1) & ~ins.all(axis=1)
        hi = np.where(hit, mid, hi)
        lo = np.where(hit, lo, mid)
    out = out.copy()
    out[top] = np.minimum(out[top], hi)
    return out


# -- fresh clcsg processes (startup, peers, progress) -------------------------------------------
def clcsg_command() -> list[str]:
    """The ``clcsg`` console script beside this Python, else ``python -m clcsg``."""
    script = os.path.join(os.path.dirname(sys.executable), "clcsg")
    return [script] if os.path.exists(script) else [sys.executable, "-m", "clcsg"]


def package_root() -> str:
    """The folder holding the ``clcsg`` package this benchmark imported."""
    import clcsg

    return os.path.dirname(os.path.dirname(os.path.abspath(clcsg.__file__)))


def environment_for_runs() -> dict:
    """The caller's environment with Python's bytecode cache on (as a user has it), and this
    ``clcsg`` first on the path (the console script would otherwise load the installed one)."""
    env = dict(os.environ)
    env.pop("PYTHONDONTWRITEBYTECODE", None)
    env.pop("CLCSG_NO_CACHE", None)
    env["PYTHONPATH"] = os.pathsep.join([package_root()] + [p for p in [env.get("PYTHONPATH")] if p])
    return env
