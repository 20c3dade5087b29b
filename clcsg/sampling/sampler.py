"""Driver of the adaptive subdivision sampler (``sampler.cl``, ``finish.cl``); paper sections 3-5
on the CSG tape.

Decomposition
-------------
Every unique quadric q that a leaf of the tape uses is sampled from each of the three sampling
planes of its principal frame (:mod:`clcsg.compile.quadric_frames`) and, for two-sheet heightfields,
from both sheets.  A *task* is one (quadric, plane, sheet); its root cell is the box of the
primitive instances that have q as a literal (the CSG surface lies on the union of the
primitives' boundaries), cut by the scene bound, projected into the plane's local (x, y).
Cells are axis-aligned rectangles of that plane with exact interval bounds (R(x, y) is
separable); each carries a tape pruned over its parent's patch grown by the radius.

Guarantee
---------
*Every sample lies on the CSG surface*: a sample is emitted at a point p of a cell only if the
cell's pruned tape decides the whole patch as surface (both substituted sides constant and
different), the corner discs prove it (fill), or p has d_q(p) < 0 (single sample); d_q is
negative only on the surface (see :mod:`clcsg.compile.interpret`).

*Every point x of the CSG surface, on quadric q, with a non-zero normal, has a sample on q
within r*: let k be the plane whose axis has the largest |n_k| at x.  x projects into the root
cell of task (q, k, sheet of x): x lies on the boundary of a primitive instance holding q, so
in that instance's box and in the scene bound.  Follow the chain of cells that contain the
projection.  A cell in the chain is never dropped as "no surface" (the heightfield is defined
at x), nor as "not owned" (at x no in-plane component exceeds |n_k|), nor as outside the task
box; it is not decided "no surface" by pruning (the pruned tape is exact over the patch, which
holds x, and the sides differ at x).  It is discarded by the discs only if x lies in a disc of
a corner p with d_q(p) > 0: the 2-D radius |d| / delta maps to a 3-D distance of at most |d|
(delta bounds |dp| / |dx| over the cell), and no point of q within |d| of p is on the surface
— contradiction.  Pruning keeps every tape exact where it is used: a leaf is replaced by a
constant only where it has one sign over the whole region (planes are tested exactly on the
patch box, other quadrics by their conservative distance), and the children's region (the
parent's patch grown by r) holds their patches and every splat ball of their samples.  So the
chain ends in (i) a fill, which puts every cell point within r of a sample (the anisotropic
slope bound in ``fill.h``), (ii) a single sample whose radius covers the patch's whole 3-D
box, or (iii) the floor: cells whose 3-D box is smaller than the floor and still unresolved
are dropped and counted as ``unresolved`` (the paper makes the same trade with r / 10,
section 4.2); the guarantee holds for every feature wider than the floor.  The default floor
is min(r / 10, 1e-3 of the scene's diagonal): a radius far larger than a feature does not
raise the floor past the feature, so a bore much narrower than r still gets its samples (one
single sample per small patch is enough for the guarantee).

The substitution is per quadric, not per leaf, so coincident faces of different solids,
surfaces shared by several parts of the tree and shared sub-graphs need no special rule.

Nothing is lost: each level runs with buffers sized from an estimate; the kernel counts past
the capacity without writing, the host sees it, grows the buffer (cells, samples, tape arena)
and re-runs the level; the finish pass does the same with the clip buffer.
"""

from __future__ import annotations

import math
import time
import warnings

import numpy as np

from ..cl import device as _device
from ..cl.constants import SAMPLER_COUNTERS
from ..cl.programs import build
from ..cl.memory import check_allocation, device_buffer, upload
from ..cl.records import SceneBuffers, cell_dtype, frame_dtype, pack, raw_sample_dtype, task_dtype
from ..compile.quadric_frames import principal_frame
from ..cl.constants import OP_LEAF
from ..errors import LimitError, UsageError
from ..model.quadric import Quadric
from ..readers.scenes import as_scene
from .samples import Samples
from ..compile.bounds import estimates as guard
from ..progress import for_option

#: fixed work-group size: PoCL compiles a kernel variant per local size, so letting the
#: runtime pick one per launch size would recompile at every level
WORK_GROUP = 64

#: counters summed over levels into the stats (the others are per-level positions)
_SUMMED = ("distance_queries", "leaf_distances", "unresolved", "discarded", "filled", "single", "split",
           "prune_evaluations", "pruned_decided", "tapes_written")
_SLOT = {name: k for k, name in enumerate(SAMPLER_COUNTERS)}


def launch_size(n: int) -> tuple[int]:
    return (max(1, -(-n // WORK_GROUP)) * WORK_GROUP,)


def frame_records(frames, real) -> np.ndarray:
    """Principal frames as ``frame_rec`` records (``cl/include/layout.h``)."""
    rec = np.zeros(len(frames), dtype=frame_dtype(real))
    for i, f in enumerate(frames):
        rec["U"][i] = f.U.reshape(9)
        rec["center"][i] = f.center
        rec["lam"][i] = f.lam
        rec["beta"][i] = f.beta
        rec["gamma"][i] = f.gamma
    return rec


def quadric_boxes(tape) -> dict:
    """World box per sampled quadric: the union of the boxes of the primitive instances that
    have it as a literal, cut by the scene bound (None where that is empty)."""
    used = set(int(q) for q in tape.ops[tape.ops[:, 0] == OP_LEAF, 2])
    owners = tape.owners()
    lo_b, hi_b = tape.bound
    out = {}
    for q in sorted(used):
        boxes = [tape.instances[i].box for i in owners[q] if tape.instances[i].box is not None]
        if not boxes:
            continue
        lo = np.maximum(np.min([b[0] for b in boxes], axis=0), lo_b)
        hi = np.minimum(np.max([b[1] for b in boxes], axis=0), hi_b)
        if np.all(hi >= lo):
            out[q] = (lo, hi)
    return out


def root_tasks(tape, packed, frames):
    """One task per (quadric, plane, sheet) and its root cell (holding the root tape)."""
    tasks, cells = [], []
    scale = float(np.abs(tape.bound).max(initial=1.0))
    for q, (lo, hi) in quadric_boxes(tape).items():
        lo, hi = lo - packed.origin, hi - packed.origin
        corners = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])])
        f = frames[q]
        z = (corners - f.center) @ f.U
        # pad by a relative epsilon: surface points on the box's faces (a box face is the
        # bound) must not be lost to rounding in the local coordinates
        pad = 1e-7 * (np.abs(z).max() + np.abs(hi - lo).max()) + 1e-12 * scale
        zlo, zhi = z.min(0) - pad, z.max(0) + pad
        for k in range(3):
            if f.lam[k] != 0.0:
                sheets = (1, -1)
            elif f.beta[k] != 0.0:
                sheets = (0,)
            else:
                continue  # a cylinder along u_k: plane k owns no point
            i, j = [m for m in range(3) if m != k]
            for sheet in sheets:
                tasks.append((q, k, sheet, 0, zlo, zhi))
                cells.append((zlo[i], zlo[j], zhi[i], zhi[j], (np.nan,) * 4, len(tasks) - 1, 0, 0, len(tape.ops)))
    t = np.zeros(len(tasks), dtype=task_dtype(packed.real))
    for n, row in enumerate(tasks):
        t[n] = row
    c = np.array(cells, dtype=cell_dtype(packed.real)) if cells else np.zeros(0, cell_dtype(packed.real))
    return t, c


def estimate_samples(tape, radius: float) -> int:
    """Rough sample count for the first buffer sizes: box areas of the sampled quadrics."""
    area = 0.0
    for lo, hi in quadric_boxes(tape).values():
        e = hi - lo
        area += 2 * (e[0] * e[1] + e[1] * e[2] + e[0] * e[2])
    return int(area / (math.pi * radius * radius)) + 1


class _Progress:
    """Progress of the level loop on the current reporter (:mod:`clcsg.progress`: a bar on
    a terminal, JSON lines with ``--progress json``, nothing in a pipe or with ``progress=False``).

    Done / total count cells: the work of a level is its cells.  The total is a forecast,
    refined as levels finish: the cells classified so far, plus the next level's cells (known
    exactly), growing by the ratio seen over the last two levels (cells split in two, along x
    and y in turn) until the expected last level, about 2 log2(largest root cell / floor)
    (cells are dropped as unresolved below the floor).  The ETA is the rate of the levels so
    far times the cells left.  Samples so far and the first estimate (``estimate_samples``, an
    area bound) are shown next to the bar.
    """

    def __init__(self, enabled, estimate=0, roots=None, floor=None, max_levels=400):
        self.reporter = for_option(enabled)
        self.estimate = int(estimate)
        self.levels_expected = max_levels
        if roots is not None and len(roots) and floor:
            extent = float(np.max(np.maximum(roots["x1"] - roots["x0"], roots["y1"] - roots["y0"])))
            if extent > floor:
                self.levels_expected = min(max_levels, round(2 * math.log2(extent / floor)) + 2)
        outer = self.reporter.active()
        self.own = outer is None or outer.name != "sample"
        self.step = self.reporter.step("sample", "sampling") if self.own else outer
        self.cells = 0
        self.history: list[int] = []

    def level(self, level, cells, samples, children=0):
        self.cells += cells
        self.history.append(cells)
        prev = self.history[-2] if len(self.history) > 1 else cells
        growth = (children / prev) ** 0.5 if len(self.history) > 1 else children / max(cells, 1)
        growth = min(max(growth, 0.5), 1.8)
        remaining = max(1, self.levels_expected - level - 1)
        ahead = children * sum(growth ** k for k in range(remaining)) if children else 0
        self.step.update(done=self.cells, total=int(self.cells + ahead), label="sampling", unit="cells",
                         phase=level == 0, level=level + 1, samples=samples, estimated=self.estimate,
                         note=f"level {level + 1}, {samples:,} samples (estimate {self.estimate:,})", always=True)

    def done(self):
        self.step.update(total=self.cells, label="sampling: clip programs", note="")
        if self.own:
            self.step.close()


def sample(
    scene,
    radius: float,
    device=None,
    *,
    normal_form: str = "tree",
    floor: float | None = None,
    term_limit: int | None = None,
    bound=None,
    distortion: bool = True,
    capacity: tuple | None = None,
    progress: bool | None = None,
    max_levels: int = 400,
    max_samples: float | None = None,
    max_memory: float | None = None,
) -> Samples:
    """Samples on the CSG surface of ``scene`` with the coverage guarantee for ``radius``.

    ``scene``: a Shape, Scene or scene file path.  ``device``: None (default selection),
    'cpu', 'gpu', 'P:D' or a context from :func:`clcsg.cl.device.get_context`.
    ``normal_form``: ``"tree"`` (the CSG tape, default) or ``"dnf"`` (the paper's disjunctive
    normal form as an OR of ANDs, with its term limit ``term_limit``).  ``floor``: size below
    which unresolved cells are dropped (default min(radius / 10, 1e-3 of the bound's
    diagonal)).  ``distortion``: use the interval
    distortion bound (True) or the worst case max(sqrt 3, bound) (False).  ``capacity``: initial
    (cells, samples[, arena[, clip]]) buffer sizes (tests force tiny ones).
    ``max_samples`` / ``max_memory``: limits of the resource guard (:mod:`clcsg.compile.bounds.estimates`;
    None: 50 million samples / 80% of the device's global memory); past them
    :class:`~clcsg.errors.LimitError` is raised before anything is allocated.
    """
    try:
        radius = float(radius)
    except (TypeError, ValueError):
        raise UsageError(f"radius must be a number, got {radius!r}") from None
    if not (math.isfinite(radius) and radius > 0):
        raise UsageError(f"radius must be a positive finite number, got {radius}")
    if floor is not None:
        floor = float(floor)
        if not (math.isfinite(floor) and floor > 0):
            raise UsageError(f"floor must be a positive finite number, got {floor}")
    timings = {}
    t0 = time.perf_counter()
    sc = as_scene(scene, bound)
    tape = sc.compile(normal_form, term_limit)
    timings["compile_s"] = time.perf_counter() - t0
    if floor is None:
        diag = float(np.linalg.norm(tape.bound[1] - tape.bound[0]))
        floor = min(radius / 10, 1e-3 * diag) if diag > 0 else radius / 10

    ctx = scene_context(device)
    real = np.dtype(_device.real_dtype(ctx))

    limits = dict(max_samples=max_samples, max_memory=max_memory, source=sc.source)
    est = guard.estimate_tape(tape, radius, real.itemsize)
    try:
        guard.check_estimate(est, ctx.info, **limits)
    except LimitError:
        # the estimate bounds the area from above: before refusing, measure (a run whose
        # estimate is small) and refuse only if the extrapolated real count does not fit
        r_probe = guard.probe_radius(est, guard.allowed_samples(est, ctx.info, max_samples=max_samples,
                                                                 max_memory=max_memory))
        if r_probe is None or not r_probe > radius:
            raise
        probe = sample(sc, r_probe, ctx, normal_form=normal_form, term_limit=term_limit, distortion=distortion,
                       progress=False, max_samples=max(4 * guard.PROBE_SAMPLES, 1e6))
        est = guard.check_estimate(guard.measured(est, len(probe), r_probe), ctx.info, **limits)
    t1 = time.perf_counter()
    packed = pack(tape, real)
    frames = [principal_frame(Quadric(m)) for m in packed.local_matrices]
    frames_rec = frame_records(frames, real)
    tasks, roots = root_tasks(tape, packed, frames)
    timings["analyse_s"] = time.perf_counter() - t1
    stats = {"radius": radius, "floor": floor, "tasks": len(tasks), "normal_form": tape.shape,
             "estimated_samples": est.samples,
             **{f"tape_{k}": v for k, v in tape.stats.items()}}
    if len(roots) == 0 or tape.empty:
        warnings.warn(f"{sc.source}: the solid is empty; no samples", stacklevel=2)
        return _empty(radius, tape, packed, stats)

    defines = {"WORST_CASE_DISTORTION": 0 if distortion else 1, "TAPE_REGS": packed.n_regs}
    prg = build(ctx, "sampling/sampler.cl", defines, real)
    scene_buf = SceneBuffers(ctx, packed)
    sub = _Subdivision(ctx, prg, scene_buf, frames_rec, tasks, roots, radius, floor, capacity,
                       estimate_samples(tape, radius), progress, max_levels)
    sub.run()
    t2 = time.perf_counter()
    timings["subdivide_s"] = t2 - t1 - timings["analyse_s"]
    fin = build(ctx, "sampling/finish.cl", {"TAPE_REGS": packed.n_regs}, real)
    samples = _finish(ctx, fin, scene_buf, frames_rec, tasks, sub, tape, packed, radius, capacity)
    timings["finish_s"] = time.perf_counter() - t2
    timings["total_s"] = time.perf_counter() - t0
    if len(samples) == 0:
        warnings.warn(f"{sc.source}: no samples: no surface was found above the floor of {floor:.3g} "
                      f"({sub.totals['unresolved']} cells smaller than it were left unresolved)", stacklevel=2)
    stats.update(sub.totals)
    stats.update(
        samples=len(samples),
        clip_rows=int(len(samples.clip_ops)),
        clipped_samples=int((samples.clip_count > 0).sum()),
        levels=len(sub.levels),
        cells_per_level=[lv["cells"] for lv in sub.levels],
        tape_mean_per_level=[lv["tape_mean"] for lv in sub.levels],
        tape_max_per_level=[lv["tape_max"] for lv in sub.levels],
        leaf_distances_per_query=(sub.totals["leaf_distances"] / sub.totals["distance_queries"]
                                  if sub.totals["distance_queries"] else 0.0),
        device=ctx.info.name,
        compute_units=ctx.info.compute_units,
        **timings,
    )
    stats.update(samples.stats)
    samples.stats = stats
    return samples


def scene_context(device):
    if device is not None and hasattr(device, "ctx"):
        return device
    return _device.get_context(device)


def _empty(radius, tape, packed, stats) -> Samples:
    stats.update({k: 0 for k in _SUMMED})
    stats.update(samples=0, clip_rows=0, clipped_samples=0, levels=0, cells_per_level=[], total_s=0.0)
    return Samples.empty(radius, tape, packed, stats)


def _grow(cap, needed):
    return int(max(2 * cap, needed + needed // 2))


class _Subdivision:
    """The level loop: buffers, the overflow protocol, per-level statistics."""

    def __init__(self, ctx, prg, scene, frames_rec, tasks, roots, radius, floor, capacity, estimate, progress,
                 max_levels):
        self.ctx, self.prg, self.scene = ctx, prg, scene
        self.real = np.dtype(scene.packed.real)
        self.radius, self.floor = radius, floor
        self.max_levels = max_levels
        self.frames = upload(ctx, frames_rec)
        self.tasks = upload(ctx, tasks)
        self.roots = roots
        self.cdt = cell_dtype(self.real)
        self.sdt = raw_sample_dtype(self.real)
        tape = scene.packed.tape
        cap = tuple(capacity or ())
        self.cap_cells = max(2, int(cap[0])) if len(cap) > 0 else max(4 * len(roots), 4096)
        self.cap_samples = max(2, int(cap[1])) if len(cap) > 1 else max(2 * estimate, 4096)
        self.cap_arena = max(len(tape) + 2, int(cap[2])) if len(cap) > 2 else max(64 * len(tape), 1 << 16)
        self.progress = _Progress(progress, estimate, roots, floor, max_levels)
        self.levels = []
        self.totals = {k: 0 for k in _SUMMED}
        self.grown = {"cells": 0, "samples": 0, "arena": 0}

    def _buffer(self, nbytes, what):
        return device_buffer(self.ctx, nbytes, what)

    def _grown_copy(self, old, used_bytes, new_bytes, what):
        """A larger buffer holding the first ``used_bytes`` of ``old``, made from host memory (a
        device-to-device copy would do, but Oclgrind's uninitialized-value checker loses track
        of such copies; growing is rare)."""
        import pyopencl as cl

        check_allocation(self.ctx, new_bytes, what)
        data = np.zeros(max(int(new_bytes), 16), dtype=np.uint8)
        if used_bytes:
            cl.enqueue_copy(self.ctx.queue, data[:used_bytes], old)
        return upload(self.ctx, data, writable=True)

    def run(self):
        import pyopencl as cl

        queue = self.ctx.queue
        tape = self.scene.packed.tape
        check_allocation(self.ctx, self.cap_arena * tape.itemsize, "tape arena")
        arena = np.zeros(self.cap_arena, dtype=tape.dtype)
        arena[:len(tape)] = tape
        self.arena = upload(self.ctx, arena, writable=True)
        arena_used = len(tape)
        cells_in = upload(self.ctx, self.roots, writable=True)
        n_in = len(self.roots)
        cells_out = self._buffer(self.cap_cells * self.cdt.itemsize, "cell")
        self.samples = self._buffer(self.cap_samples * self.sdt.itemsize, "sample")
        counters = np.zeros(len(SAMPLER_COUNTERS), dtype=np.uint32)
        kernel = cl.Kernel(self.prg, "classify")
        n_samples = 0
        level = 0
        while n_in > 0:
            if level >= self.max_levels:
                raise RuntimeError(f"sampler did not finish in {self.max_levels} levels ({n_in} cells left)")
            while True:
                counters[:] = 0
                counters[_SLOT["samples"]] = n_samples
                counters[_SLOT["arena"]] = arena_used
                # a fresh buffer from host memory each run (Oclgrind's uninitialized-value
                # checker does not see host writes into an existing buffer)
                counters_buf = upload(self.ctx, counters, writable=True)
                kernel(queue, launch_size(n_in), (WORK_GROUP,),
                       self.scene.quadrics, self.frames, self.tasks, cells_in, np.int32(n_in),
                       cells_out, np.uint32(self.cap_cells), self.samples, np.uint32(self.cap_samples),
                       self.arena, np.uint32(self.cap_arena), counters_buf,
                       self.real.type(self.radius), self.real.type(self.floor))
                cl.enqueue_copy(queue, counters, counters_buf)
                n_cells_out = int(counters[_SLOT["cells"]])
                n_samples_out = int(counters[_SLOT["samples"]])
                arena_out = int(counters[_SLOT["arena"]])
                ok = True
                if n_cells_out > self.cap_cells:
                    self.cap_cells = _grow(self.cap_cells, n_cells_out)
                    cells_out = self._buffer(self.cap_cells * self.cdt.itemsize, "cell")
                    self.grown["cells"] += 1
                    ok = False
                if n_samples_out > self.cap_samples:
                    new_cap = _grow(self.cap_samples, n_samples_out)
                    self.samples = self._grown_copy(self.samples, n_samples * self.sdt.itemsize,
                                                    new_cap * self.sdt.itemsize, "sample")
                    self.cap_samples = new_cap
                    self.grown["samples"] += 1
                    ok = False
                if arena_out > self.cap_arena:
                    new_cap = _grow(self.cap_arena, arena_out)
                    self.arena = self._grown_copy(self.arena, arena_used * tape.itemsize,
                                                  new_cap * tape.itemsize, "tape arena")
                    self.cap_arena = new_cap
                    self.grown["arena"] += 1
                    ok = False
                if ok:
                    break
            for name in _SUMMED:
                self.totals[name] += int(counters[_SLOT[name]])
            self.levels.append({
                "cells": n_in, "children": n_cells_out, "samples": n_samples_out - n_samples,
                "tape_mean": int(counters[_SLOT["tape_rows"]]) / n_in, "tape_max": int(counters[_SLOT["tape_max"]]),
            })
            n_samples = n_samples_out
            arena_used = arena_out
            self.progress.level(level, n_in, n_samples, n_cells_out)
            cells_in, cells_out = cells_out, cells_in
            # the old input buffer becomes the next output: make sure it is large enough
            if self.cap_cells * self.cdt.itemsize > cells_out.size:
                cells_out = self._buffer(self.cap_cells * self.cdt.itemsize, "cell")
            n_in = n_cells_out
            level += 1
        self.progress.done()
        self.n_samples = n_samples
        self.arena_used = arena_used
        self.raw = np.zeros(n_samples, dtype=self.sdt)
        if n_samples:
            cl.enqueue_copy(queue, self.raw, self.samples)
        self.totals["buffer_growths"] = dict(self.grown)
        self.totals["arena_rows"] = arena_used


def _finish(ctx, prg, scene, frames_rec, tasks, sub, tape, packed, radius, capacity) -> Samples:
    """Clip programs, signs, normals and primitives on the device; clip programs deduplicated."""
    import pyopencl as cl

    n = sub.n_samples
    real = np.dtype(packed.real)
    if n == 0:
        return Samples.empty(radius, tape, packed, {})
    q = ctx.queue
    normals = np.zeros((n, 3), dtype=real)
    ints = {k: np.zeros(n, dtype=np.int32) for k in ("signs", "primitives", "clip_first", "clip_count")}
    bufs = {k: sub._buffer(a.nbytes, "sample output") for k, a in ints.items()}
    nb = sub._buffer(normals.nbytes, "normal")
    cap = tuple(capacity or ())
    rows = scene.packed.tape.itemsize
    cap_clip = max(2 * len(packed.tape), int(cap[3])) if len(cap) > 3 else max(n, 1 << 14)
    counters = np.zeros(2, dtype=np.uint32)
    kernel = cl.Kernel(prg, "finish")
    grown = 0
    while True:
        clip_buf = sub._buffer(cap_clip * rows, "clip")
        counters[:] = 0
        counters_buf = upload(ctx, counters, writable=True)
        kernel(q, launch_size(n), (WORK_GROUP,), scene.quadrics, upload(ctx, frames_rec), upload(ctx, tasks),
               sub.samples, np.int32(n), sub.arena, clip_buf, np.uint32(cap_clip), counters_buf,
               *scene.colour_args(), nb, bufs["signs"], bufs["primitives"], bufs["clip_first"], bufs["clip_count"])
        cl.enqueue_copy(q, counters, counters_buf)
        if int(counters[0]) <= cap_clip:
            break
        cap_clip = _grow(cap_clip, int(counters[0]))
        grown += 1
    cl.enqueue_copy(q, normals, nb)
    for k, a in ints.items():
        cl.enqueue_copy(q, a, bufs[k])
    used = int(counters[0])
    clip = np.zeros(used, dtype=packed.tape.dtype)
    if used:
        cl.enqueue_copy(q, clip, clip_buf)
    clip_ops = np.asarray(clip.view(np.int32).reshape(-1, 4))
    first, count, ops = dedupe_programs(clip_ops, ints["clip_first"], ints["clip_count"])
    raw = sub.raw
    return Samples(
        positions=np.add(raw["pos"], packed.origin, dtype=np.float64),
        normals=np.asarray(normals, dtype=np.float64),
        radii=np.array(raw["radius"], dtype=np.float64),
        quadrics=tasks["quadric"][raw["task"]].astype(np.int32),
        signs=ints["signs"],
        primitives=ints["primitives"],
        clip_first=first,
        clip_count=count,
        clip_ops=ops,
        radius=radius,
        tape=tape,
        packed=packed,
        stats={"finish_prune_evaluations": int(counters[1]), "clip_buffer_growths": grown},
    )


def dedupe_programs(rows, first, count):
    """Equal clip programs stored once: (first, count, rows) over a compact row buffer."""
    first = first.copy()
    count = count.copy()
    out = [np.zeros((0, 4), dtype=np.int32)]
    used = 0
    for c in np.unique(count[count > 0]):
        sel = np.flatnonzero(count == c)
        idx = first[sel, None] + np.arange(c)[None, :]
        progs = rows[idx].reshape(len(sel), 4 * c)
        uniq, inverse = np.unique(progs, axis=0, return_inverse=True)
        out.append(uniq.reshape(-1, 4))
        first[sel] = used + c * np.asarray(inverse).reshape(-1)
        used += len(uniq) * c
    first[count == 0] = 0
    return first.astype(np.int32), count.astype(np.int32), np.concatenate(out).astype(np.int32)
