"""Driver of the adaptive subdivision sampler (``kernels/sampler.cl``); paper sections 3-5.

Decomposition
-------------
Every literal b of every DNF term a is sampled on its quadric Q from each of the three
sampling planes of Q's principal frame (``analysis.py``) and, for two-sheet heightfields,
from both sheets.  A *task* is one (term, literal, plane, sheet); its root cell is the
term's bound projected into the plane's local (x, y) coordinates.  Cells are axis-aligned
rectangles of that plane (the design note's "simpler cells") instead of the paper's basic
regions; the kernel bounds every quantity exactly over a cell, because R(x, y) is separable.

Guarantee
---------
*Every sample lies on the CSG surface*: a sample is emitted at a point p of a cell only when
the cell was proven to lie on the CSG surface (fill) or p is a corner with d_Q(S, p) < 0
(single sample), and eq. 22 is negative only on the surface.

*Every point x of the CSG surface, on literal b of term a, with a non-zero normal, has a sample
on the same quadric within r*: let k be the plane whose axis has the largest |n_k| at x.  x
projects into the root cell of task (a, b, k, sheet of x) because the term's bound contains x.
Follow the chain of cells that contain the projection.  A cell in the chain is never dropped as
"no surface" (the heightfield is defined at x), nor as "not owned" (at x no in-plane
component exceeds |n_k|), nor as outside the term bound (x is inside it).  It is discarded by
the discs only if x lies in a disc of a corner p with d_Q(S, p) > 0: the 2-D radius
|d| / delta maps to a 3-D distance of at most |d| along the straight segment inside the cell
(delta = sqrt(max n_i^2 + max n_j^2 + max n_k^2) / min |n_k| bounds |dp| / |dx| over the
cell), and eq. 22 says no point of Q within |d| of p is on the surface — contradiction.  So
the chain ends in (i) a fill, which puts every cell point within r of a sample (see below),
(ii) a single sample whose radius covers the patch's whole 3-D box, or (iii) the
floor: cells whose 3-D box is smaller than the floor (default r / 10) and still unresolved are
dropped and counted as ``unresolved`` in the stats; the guarantee holds for every feature wider
than the floor.  The paper makes the same trade (section 4.2).

Fill (beyond the paper's isotropic distortion bound): a cell on the surface is covered by
rows of sub-rectangles with half-sizes (a, b), a sample at each center.  For two points of a
sub-rectangle p2 - p1 = (dx, dy, t2 - t1) and, by the mean value theorem,
|t2 - t1| <= mx |dx| + my |dy| with the slope bounds mx = max|n_i| / min|n_k|,
my = max|n_j| / min|n_k| over the sub-rectangle.  So every point is within
sqrt(a^2 + b^2 + (mx a + my b)^2) of the center, and (a, b) are chosen with that <= r and the
area a b as large as possible: on a steep patch only the steep direction shrinks.  On a
sphere this needs 37% fewer samples than the isotropic sqrt 3 bound (paper Fig. 14: 36% for
its distortion estimate).

Shared surfaces (design note, "Coincident and shared surfaces") are handled inside eq. 22:
terms that hold the sampled quadric with the same polarity are left out, terms holding it with
the opposite polarity enter without that literal.

Nothing is lost: each level runs with buffers sized from an estimate; the kernel counts past
the capacity without writing, the host sees it, grows the buffer and re-runs the level.
"""

from __future__ import annotations

import math
import sys
import time
import warnings

import numpy as np

from ..errors import UsageError
from .samples import Samples
from ..model.scene import as_scene
from ..cl import device as _device
from ..compile.frames import principal_frame
from ..cl.records import PackedScene, SceneBuffers, pack
from ..compile.dnf import Dnf
from ..cl.programs import build

COUNTERS = ("cells", "samples", "distance_queries", "unresolved", "discarded", "filled", "single", "split",
            "box_tests", "box_resolved")


#: fixed work-group size: PoCL compiles a kernel variant per local size, so letting the
#: runtime pick one per launch size would recompile at every level
WORK_GROUP = 64


def launch_size(n: int) -> tuple[int]:
    return (max(1, -(-n // WORK_GROUP)) * WORK_GROUP,)


def frame_dtype(real) -> np.dtype:
    return np.dtype(
        [("U", real, 9), ("center", real, 3), ("lam", real, 3), ("beta", real, 3), ("gamma", real)],
        align=True,
    )


def task_dtype(real) -> np.dtype:
    return np.dtype(
        [
            ("group_first", np.int32), ("group_count", np.int32), ("terms_first", np.int32),
            ("terms_count", np.int32), ("quadric", np.int32), ("sign", np.int32), ("plane", np.int32),
            ("sheet", np.int32), ("far_other", real), ("zlo", real, 3), ("zhi", real, 3),
        ],
        align=True,
    )


GROUP_LITERAL_DTYPE = np.dtype([("term", np.int32), ("literal", np.int32)], align=True)


def cell_dtype(real) -> np.dtype:
    return np.dtype(
        [("x0", real), ("y0", real), ("x1", real), ("y1", real), ("d", real, 4), ("task", np.int32), ("level", np.int32)],
        align=True,
    )


def raw_sample_dtype(real) -> np.dtype:
    return np.dtype([("pos", real, 3), ("radius", real), ("task", np.int32), ("pad", np.int32)], align=True)


def frame_records(frames, real) -> np.ndarray:
    """Principal frames as ``frame_rec`` records (``kernels/layout.h``)."""
    rec = np.zeros(len(frames), dtype=frame_dtype(real))
    for i, f in enumerate(frames):
        rec["U"][i] = f.U.reshape(9)
        rec["center"][i] = f.center
        rec["lam"][i] = f.lam
        rec["beta"][i] = f.beta
        rec["gamma"][i] = f.gamma
    return rec


def analyse(packed: PackedScene) -> tuple[np.ndarray, list]:
    """Principal frames of all quadrics (device coordinates) as ``frame_rec`` records."""
    frames = [principal_frame_of(m) for m in packed.local_matrices]
    return frame_records(frames, packed.real), frames


def principal_frame_of(matrix):
    from ..model.quadric import Quadric

    return principal_frame(Quadric(matrix))


def literal_groups(dnf: Dnf) -> dict:
    """(quadric, sign) -> the terms holding that literal, in term order."""
    groups: dict = {}
    for a, term in enumerate(dnf.terms):
        for lit in term:
            groups.setdefault(lit, []).append(a)
    return groups


def root_tasks(dnf: Dnf, packed: PackedScene, frames: list):
    """One task per (literal group, plane, sheet), its root cell, and the group-literal table.

    A literal shared by several terms is sampled once for all of them (see
    ``kernels/sampler.cl:csg_distance``); its root cell covers the union of their bounds.
    """
    offsets = np.concatenate([[0], np.cumsum([len(t) for t in dnf.terms])]).astype(int)
    tasks, cells, glits, task_terms = [], [], [], []
    lo_all = packed.terms["lo"].astype(np.float64)
    hi_all = packed.terms["hi"].astype(np.float64)
    scale = float(np.abs(np.concatenate([lo_all.ravel(), hi_all.ravel()])).max(initial=1.0))
    for (qi, s), members in literal_groups(dnf).items():
        first = len(glits)
        for a in members:
            others = [(a, offsets[a] + j) for j, (q2, _) in enumerate(dnf.terms[a]) if q2 != qi]
            glits.extend(others or [(a, -1)])  # -1: the term is the literal alone
        lo = lo_all[members].min(0)
        hi = hi_all[members].max(0)
        # other terms whose bound misses the group's: out of the queries, their distance to
        # the group's bound stands in (a lower bound for every point of the group's patches)
        gap = np.linalg.norm(np.maximum(0.0, np.maximum(lo_all - hi, lo - hi_all)), axis=1)
        near = gap <= 1e-9 * scale
        near[members] = False
        far = ~near
        far[members] = False
        far_other = float(gap[far].min()) if far.any() else np.inf
        terms_first = len(task_terms)
        task_terms.extend(~np.int64(a) for a in members)
        task_terms.extend(np.flatnonzero(near).tolist())
        terms_count = len(task_terms) - terms_first
        corners = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])])
        f = frames[qi]
        z = (corners - f.center) @ f.U
        # pad by a relative epsilon: surface points on the bound's faces (a box face is the
        # bound) must not be lost to rounding in the local coordinates
        pad = 1e-7 * (np.abs(z).max() + np.abs(hi - lo).max())
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
                tasks.append((first, len(glits) - first, terms_first, terms_count, qi, s, k, sheet,
                              far_other, zlo, zhi))
                cells.append((zlo[i], zlo[j], zhi[i], zhi[j], (np.nan,) * 4, len(tasks) - 1, 0))
    t = np.zeros(len(tasks), dtype=task_dtype(packed.real))
    for n, row in enumerate(tasks):
        t[n] = row
    c = np.array(cells, dtype=cell_dtype(packed.real)) if cells else np.zeros(0, cell_dtype(packed.real))
    g = np.array(glits, dtype=GROUP_LITERAL_DTYPE) if glits else np.zeros(1, GROUP_LITERAL_DTYPE)
    tt = np.array(task_terms, dtype=np.int32) if task_terms else np.zeros(1, np.int32)
    return t, c, g, tt


def estimate_samples(dnf: Dnf, radius: float) -> int:
    """Rough sample count: surface area of the term boxes over the area of a splat."""
    if not dnf.n_terms:
        return 0
    ext = dnf.term_bounds[:, 1] - dnf.term_bounds[:, 0]
    area = 2 * (ext[:, 0] * ext[:, 1] + ext[:, 1] * ext[:, 2] + ext[:, 0] * ext[:, 2]).sum()
    return int(area / (math.pi * radius * radius)) + 1


class _Progress:
    """A one-line progress display on stderr for long runs (only on a terminal)."""

    def __init__(self, enabled):
        self.enabled = enabled if enabled is not None else sys.stderr.isatty()
        self.t0 = time.perf_counter()
        self.shown = False

    def level(self, level, cells, samples):
        if not self.enabled or time.perf_counter() - self.t0 < 0.5:
            return
        self.shown = True
        sys.stderr.write(f"\rsampling: level {level:3d}  {cells:10,d} cells  {samples:12,d} samples")
        sys.stderr.flush()

    def done(self):
        if self.shown:
            sys.stderr.write("\n")


def sample(
    scene,
    radius: float,
    device=None,
    *,
    floor: float | None = None,
    term_limit: int | None = None,
    bound=None,
    distortion: bool = True,
    capacity: tuple[int, int] | None = None,
    progress: bool | None = None,
    max_levels: int = 200,
    max_samples: float | None = None,
    max_memory: float | None = None,
) -> Samples:
    """Samples on the CSG surface of ``scene`` with the coverage guarantee for ``radius``.

    ``scene``: a Shape, Scene or scene file path.  ``device``: None (default selection),
    'cpu', 'gpu', 'P:D' or a context from :func:`clcsg.host.device.get_context`.  ``floor``:
    size below which unresolved cells are dropped (default radius / 10).  ``distortion``:
    use the interval distortion bound (True) or the worst case max(sqrt 3, bound) (False).
    ``capacity``: initial (cells, samples) buffer sizes (tests force tiny ones).
    ``max_samples`` / ``max_memory``: limits of the resource guard (:mod:`clcsg.host.guard`;
    None: 50 million samples / 80% of the device's global memory); past them
    :class:`~clcsg.errors.LimitError` is raised before anything is allocated.
    """
    try:
        radius = float(radius)
    except (TypeError, ValueError):
        raise UsageError(f"radius must be a number, got {radius!r}") from None
    if not (math.isfinite(radius) and radius > 0):
        raise UsageError(f"radius must be a positive finite number, got {radius}")
    floor = radius / 10 if floor is None else float(floor)
    if not (math.isfinite(floor) and floor > 0):
        raise UsageError(f"floor must be a positive finite number, got {floor}")
    timings = {}
    t0 = time.perf_counter()
    sc = as_scene(scene, bound)
    dnf = sc.normalize(term_limit)
    timings["normalize_s"] = time.perf_counter() - t0

    ctx = scene_context(device)
    real = _device.real_dtype(ctx)
    from .guard import check as _guard  # resource guard: LimitError before any allocation

    _guard(dnf, radius, ctx.info, max_samples=max_samples, max_memory=max_memory, source=sc.source,
           real_itemsize=np.dtype(real).itemsize)
    t1 = time.perf_counter()
    packed = pack(dnf, real)
    frames_rec, frames = analyse(packed)
    tasks, roots, glits, task_terms = root_tasks(dnf, packed, frames)
    timings["analyse_s"] = time.perf_counter() - t1
    stats = {"radius": radius, "floor": floor, "tasks": len(tasks), **{f"dnf_{k}": v for k, v in dnf.stats.items()}}
    if len(roots) == 0:
        warnings.warn(f"{sc.source}: the solid has no surface; no samples", stacklevel=2)
        return _empty(radius, dnf, packed, stats)

    mask_words = max(1, (int(tasks["group_count"].max(initial=1)) + 31) // 32)
    defines = {"WORST_CASE_DISTORTION": 0 if distortion else 1, "MASK_WORDS": mask_words}
    prg = build(ctx, "sampling/sampler.cl", defines, real)
    raw, raw_buf, level_stats, totals = _subdivide(ctx, prg, packed, frames_rec, tasks, task_terms, roots, radius, floor,
                                          capacity, estimate_samples(dnf, radius), progress, max_levels)
    t2 = time.perf_counter()
    timings["subdivide_s"] = t2 - t1 - timings["analyse_s"]
    normals, terms, masks = _finish(ctx, prg, packed, frames_rec, tasks, glits, raw_buf, len(raw), mask_words)
    samples = _assemble(raw, normals, terms, masks, tasks, glits, dnf, packed, radius)
    if len(samples) == 0:
        warnings.warn(f"{sc.source}: the solid has no surface; no samples", stacklevel=2)
    timings["finish_s"] = time.perf_counter() - t2
    timings["total_s"] = time.perf_counter() - t0
    stats.update(totals)
    stats.update(
        samples=len(samples.positions),
        clip_indices=int(len(samples.clip_literals)),
        levels=len(level_stats),
        cells_per_level=[ls["cells"] for ls in level_stats],
        device=ctx.info.name,
        compute_units=ctx.info.compute_units,
        **timings,
    )
    samples.stats = stats
    return samples


def scene_context(device):
    if device is not None and hasattr(device, "ctx"):
        return device
    return _device.get_context(device)


def _empty(radius, dnf, packed, stats) -> Samples:
    z3 = np.zeros((0, 3))
    zi = np.zeros(0, dtype=np.int32)
    stats.update({k: 0 for k in COUNTERS if k != "cells"})
    stats.update(samples=0, clip_indices=0, levels=0, cells_per_level=[], total_s=0.0)
    return Samples(z3, z3.copy(), np.zeros(0), zi, zi.copy(), zi.copy(), zi.copy(), zi.copy(),
                   np.zeros((0, 2), dtype=np.int32), radius, dnf, packed, stats)


def _subdivide(ctx, prg, packed, frames_rec, tasks, task_terms, roots, radius, floor, capacity, estimate, progress,
               max_levels):
    import pyopencl as cl

    mf = cl.mem_flags
    queue = ctx.queue
    real = packed.real
    scene = SceneBuffers(ctx, packed)
    frames_buf = cl.Buffer(ctx.ctx, mf.READ_ONLY | mf.COPY_HOST_PTR, hostbuf=frames_rec)
    tasks_buf = cl.Buffer(ctx.ctx, mf.READ_ONLY | mf.COPY_HOST_PTR, hostbuf=tasks)
    task_terms_buf = cl.Buffer(ctx.ctx, mf.READ_ONLY | mf.COPY_HOST_PTR, hostbuf=task_terms)
    cdt = cell_dtype(real)
    sdt = raw_sample_dtype(real)
    if capacity is None:
        cap_cells = max(4 * len(roots), 4096)
        cap_samples = max(2 * estimate, 4096)
    else:
        cap_cells, cap_samples = (max(2, int(c)) for c in capacity)
    cells_in = cl.Buffer(ctx.ctx, mf.READ_WRITE | mf.COPY_HOST_PTR, hostbuf=roots)
    n_in = len(roots)
    cells_out = cl.Buffer(ctx.ctx, mf.READ_WRITE, cap_cells * cdt.itemsize)
    samples_buf = cl.Buffer(ctx.ctx, mf.READ_WRITE, cap_samples * sdt.itemsize)
    counters = np.zeros(len(COUNTERS), dtype=np.uint32)
    counters_buf = cl.Buffer(ctx.ctx, mf.READ_WRITE, counters.nbytes)
    totals = {k: 0 for k in COUNTERS if k != "cells"}
    n_samples = 0
    levels = []
    prog = _Progress(progress)
    kernel = cl.Kernel(prg, "classify")
    level = 0
    grown = {"cells": 0, "samples": 0}
    while n_in > 0:
        if level >= max_levels:
            raise RuntimeError(f"sampler did not finish in {max_levels} levels ({n_in} cells left)")
        while True:
            counters[:] = 0
            counters[1] = n_samples
            cl.enqueue_copy(queue, counters_buf, counters)
            kernel(queue, launch_size(n_in), (WORK_GROUP,),
                   scene.quadrics, scene.literals, scene.terms, task_terms_buf,
                   frames_buf, tasks_buf, cells_in, np.int32(n_in), cells_out, np.int32(cap_cells),
                   samples_buf, np.int32(cap_samples), counters_buf,
                   real.type(radius), real.type(floor))
            cl.enqueue_copy(queue, counters, counters_buf)
            n_cells_out, n_samples_out = int(counters[0]), int(counters[1])
            ok = True
            if n_cells_out > cap_cells:
                cap_cells = _grow(cap_cells, n_cells_out)
                cells_out = cl.Buffer(ctx.ctx, mf.READ_WRITE, cap_cells * cdt.itemsize)
                grown["cells"] += 1
                ok = False
            if n_samples_out > cap_samples:
                new_cap = _grow(cap_samples, n_samples_out)
                bigger = cl.Buffer(ctx.ctx, mf.READ_WRITE, new_cap * sdt.itemsize)
                if n_samples:
                    cl.enqueue_copy(queue, bigger, samples_buf, byte_count=n_samples * sdt.itemsize)
                samples_buf, cap_samples = bigger, new_cap
                grown["samples"] += 1
                ok = False
            if ok:
                break
        for k, name in enumerate(COUNTERS):
            if name not in ("cells", "samples"):
                totals[name] += int(counters[k])
        levels.append({"cells": n_in, "children": n_cells_out, "samples": n_samples_out - n_samples})
        n_samples = n_samples_out
        prog.level(level, n_in, n_samples)
        cells_in, cells_out = cells_out, cells_in
        # the old input buffer becomes the next output: make sure it is large enough
        if cap_cells * cdt.itemsize > cells_out.size:
            cells_out = cl.Buffer(ctx.ctx, mf.READ_WRITE, cap_cells * cdt.itemsize)
        n_in = n_cells_out
        level += 1
    prog.done()
    raw = np.zeros(n_samples, dtype=sdt)
    if n_samples:
        cl.enqueue_copy(queue, raw, samples_buf)
    totals["buffer_growths"] = grown
    return raw, samples_buf, levels, totals


def _grow(cap, needed):
    return int(max(2 * cap, needed + needed // 2))


def _finish(ctx, prg, packed, frames_rec, tasks, glits, raw_buf, n, mask_words):
    """Normals, terms and clip masks, computed on the device from the samples still there."""
    import pyopencl as cl

    mf = cl.mem_flags
    real = packed.real
    normals = np.zeros((n, 3), dtype=real)
    terms = np.zeros(n, dtype=np.int32)
    masks = np.zeros((n, mask_words + 1), dtype=np.uint32)
    if n == 0:
        return normals, terms, masks
    scene = SceneBuffers(ctx, packed)

    def up(a):
        return cl.Buffer(ctx.ctx, mf.READ_ONLY | mf.COPY_HOST_PTR, hostbuf=a)

    nb = cl.Buffer(ctx.ctx, mf.WRITE_ONLY, normals.nbytes)
    tb = cl.Buffer(ctx.ctx, mf.WRITE_ONLY, terms.nbytes)
    mb = cl.Buffer(ctx.ctx, mf.WRITE_ONLY, masks.nbytes)
    cl.Kernel(prg, "finish")(ctx.queue, launch_size(n), (WORK_GROUP,), scene.quadrics, scene.literals,
                             scene.terms, up(frames_rec), up(tasks), up(glits), raw_buf, np.int32(n),
                             nb, tb, mb)
    cl.enqueue_copy(ctx.queue, normals, nb)
    cl.enqueue_copy(ctx.queue, terms, tb)
    cl.enqueue_copy(ctx.queue, masks, mb)
    return normals, terms, masks


#: separates the terms of a clip set in the clip buffer (a splat fragment is kept if all
#: literals of some block hold)
CLIP_SEPARATOR = (-1, 0)


def _assemble(raw, normals, terms, masks, tasks, glits, dnf, packed, radius) -> Samples:
    """Host arrays in world coordinates; clip sets deduplicated (sort, then unique).

    A clip set is a list of blocks, one per group term that neither holds nor fails over the
    whole splat ball, separated by ``CLIP_SEPARATOR``; empty when some group term holds over
    the whole ball.  Most samples have an empty clip set; only the others are sorted."""
    tid = raw["task"]
    n = len(raw)
    clip_first = np.zeros(n, dtype=np.int32)
    clip_count = np.zeros(n, dtype=np.int32)
    clip = []
    some = np.flatnonzero((masks[:, 0] == 0) & masks[:, 1:].any(axis=1))
    if len(some):
        gfirst = tasks["group_first"][tid[some]].astype(np.int64)
        key = np.column_stack([gfirst, masks[some, 1:].astype(np.int64)])
        uniq, inverse = np.unique(key, axis=0, return_inverse=True)
        inverse = np.asarray(inverse).reshape(-1)
        firsts = np.zeros(len(uniq), dtype=np.int32)
        counts = np.zeros(len(uniq), dtype=np.int32)
        for u, row in enumerate(uniq):
            g0 = int(row[0])
            words = row[1:]
            blocks: dict = {}
            for j in range(32 * len(words)):
                if (int(words[j // 32]) >> (j % 32)) & 1:
                    term, lit = glits[g0 + j]
                    blocks.setdefault(int(term), []).append(tuple(packed.literals[lit][["quadric", "sign"]].tolist()))
            sel = []
            for b, lits in enumerate(blocks.values()):
                if b:
                    sel.append(CLIP_SEPARATOR)
                sel.extend(lits)
            firsts[u] = len(clip)
            counts[u] = len(sel)
            clip.extend(sel)
        clip_first[some] = firsts[inverse]
        clip_count[some] = counts[inverse]
    return Samples(
        positions=np.add(raw["pos"], packed.origin, dtype=np.float64),
        normals=np.asarray(normals, dtype=np.float64),
        radii=np.array(raw["radius"], dtype=np.float64),
        quadrics=tasks["quadric"][tid],
        signs=tasks["sign"][tid],
        terms=terms,
        clip_first=clip_first,
        clip_count=clip_count,
        clip_literals=np.array(clip, dtype=np.int32).reshape(-1, 2),
        radius=radius,
        dnf=dnf,
        packed=packed,
    )
