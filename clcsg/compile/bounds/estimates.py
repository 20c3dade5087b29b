"""Resource guard: estimate the work of sampling a DNF at a radius before allocating anything.

:func:`estimate` bounds the area of the CSG surface from the DNF alone (no device work) and
turns it into a sample count and a memory size; :func:`estimate_regions` does the same from
per-quadric regions computed on the CSG tree (:func:`clcsg.compile.bounds.regions.quadric_regions`:
the boxes of the faces of the primitive instances holding each quadric, within the instances'
boxes and the scene bound).  :func:`check` (for a DNF or an :class:`Estimate`) and
:func:`check_estimate` raise :class:`~clcsg.errors.LimitError` (exit code 5) when a limit is
passed, with the estimate and how to proceed.  :func:`clcsg.host.sampler.sample` calls :func:`check` right after
normalization, before it builds a kernel or allocates a buffer, so a radius that is far too
small for the scene fails in milliseconds instead of exhausting memory.

The estimate (documented in ``docs/robustness.md``)
---------------------------------------------------
Area.  Every point of the CSG surface lies on a quadric Q of some term t, inside that term's
bound B_t and inside the box of Q's surface (the box of the literal's solid, intersected for
both polarities: a sphere's surface lies in the sphere's box even when it is a hole in a big
block).  So the area is at most the sum over unique quadrics Q of an upper bound of
area(Q ∩ R) over the regions R = B_t ∩ box(Q) of the terms holding Q (taken once per term,
or once for the box around all of them, whichever is smaller).  Per region box with face
areas F_x, F_y, F_z and surface S = 2 (F_x + F_y + F_z):

* plane with unit normal n: area <= min(sqrt(F_x^2 + F_y^2 + F_z^2), min_k F_k / |n_k|)
  (the section projects onto each coordinate plane with area A |n_k| <= F_k);
* quadric with a semidefinite quadratic part (ellipsoids, cylinders, paraboloids: one side is
  convex): area <= S (a convex body's surface is at most that of any convex set containing it;
  the patch is part of the boundary of (convex side ∩ box));
* indefinite quadratic part (cones, hyperboloids, saddles): area <= sqrt(3) S (the part of the
  surface whose normal is closest to axis k has |n_k| >= 1/sqrt(3) and projects at most 2-to-1
  onto the k-face, a line meeting a quadric in at most two points).

These are upper bounds, never under-estimates.  The curvature slack (sqrt 3 for saddles and
cones) is the price of not knowing the shape inside the box: a sphere in its bounding box
gets 6 / pi = 1.9 times its area.

Samples.  A fill sample covers at most pi r^2 of surface and the sampler's covering is within
a small factor of that (tests/test_sampler.py: at most 4x on smooth scenes), so

    samples ~= AREA_FACTOR * area / (pi r^2) + EDGE_FACTOR * (sum of region box edges) / r
               + TASK_SAMPLES * tasks

where the second term accounts for the partial cells along patch borders (proportional to
their length, bounded by the box edges) and the third for the few single samples every task
(literal group x sampling plane x sheet) emits even when it is tiny.  The constants are
calibrated on the test scenes (tests/test_robustness.py checks that the estimate is never
below a quarter of the real count and not absurdly above it).

Memory.  Per sample the device holds its record (position, normal, radius, sign, primitive,
clip program; grown by 1.5x and copied, so up to twice its size while growing), and the
cells of a level (bounded by a few per sample); the host holds the Samples arrays.  The byte
counts per sample are in :data:`DEVICE_BYTES_PER_SAMPLE` / :data:`HOST_BYTES_PER_SAMPLE`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np

from ...cl.constants import SAMPLE_INT_COLUMNS, SAMPLE_REAL_COLUMNS
from ...errors import LimitError, UsageError
from ...model.quadric import Quadric
from .term_boxes import literal_box
from ..interpret import minmax_program, surface_in_boxes
from ..root_tapes import box_tapes
from .regions import quadric_regions
from .surface_area import surface_areas
from .surface_boxes import CONVEX, PLANE, SADDLE, quadric_kinds, surface_boxes, surface_meets

__all__ = [
    "DEFAULT_MAX_SAMPLES",
    "HARD_MAX_SAMPLES",
    "Estimate",
    "check",
    "check_estimate",
    "estimate",
    "estimate_regions",
    "memory_limit",
    "quadric_area_bound",
]

#: default limit of ``clcsg.sample(..., max_samples=)`` and ``--max-samples``
DEFAULT_MAX_SAMPLES = 50_000_000

#: hard limit whatever ``max_samples`` says: the kernels count samples and size buffers with
#: 32-bit integers (``int`` capacities, ``uint`` counters, a 32-bit sample index in the splat
#: framebuffer key); half of 2^31 leaves room for the estimate being low by 2x
HARD_MAX_SAMPLES = 2**30

#: fraction of the device's global memory the sampler may plan to use (default ``max_memory``)
MEMORY_FRACTION = 0.8

#: calibration of the sample estimate (see the module docstring)
AREA_FACTOR = 1.0
EDGE_FACTOR = 0.5
TASK_SAMPLES = 4

#: bytes per sample: device buffers of the sampler (the sample columns of ``finish.h``, twice
#: while growing; cells) and host arrays (Samples arrays, PLY record)
_REALS = sum(w for _, w in SAMPLE_REAL_COLUMNS)
_INTS = 4 * sum(w for _, w in SAMPLE_INT_COLUMNS)
DEVICE_BYTES_PER_SAMPLE = {8: 2 * (8 * _REALS + _INTS) + 108, 4: 2 * (4 * _REALS + _INTS) + 60}
HOST_BYTES_PER_SAMPLE = 24 + 24 + 24 + 8 + 5 * 4 + 8 + 32

SQRT3 = math.sqrt(3.0)


@dataclass(frozen=True)
class Estimate:
    """What sampling a DNF at ``radius`` is expected to cost (upper-bound style estimates)."""

    radius: float
    area: float  # upper bound of the CSG surface area
    samples: float  # estimated sample count (float: inf for absurd radii)
    device_bytes: float
    host_bytes: float
    largest_buffer: float  # bytes of the largest single device buffer (raw samples)
    edges: float = 0.0  # total length of the patch border bound
    tasks: int = 0
    real_itemsize: int = 8
    quadric_areas: tuple = field(default=(), repr=False)  # per unique quadric
    measured_at: float | None = None  # radius of the probe run this estimate was scaled to

    @property
    def finite(self) -> bool:
        return math.isfinite(self.samples) and math.isfinite(self.device_bytes)

    def at(self, radius: float) -> "Estimate":
        """The same estimate at another radius (no new pass over the DNF)."""
        return _make_estimate(float(radius), self.area, self.edges, self.tasks, self.real_itemsize,
                              self.quadric_areas)

    def radius_for(self, samples: float) -> float:
        """The smallest radius whose estimate is at most ``samples`` (inf if none is)."""
        c = samples - TASK_SAMPLES * self.tasks
        if c <= 0:
            return math.inf
        a = AREA_FACTOR * self.area / math.pi
        b = EDGE_FACTOR * self.edges
        if a <= 0 and b <= 0:
            return 0.0
        # a x^2 + b x = c with x = 1 / r
        x = (2 * c) / (b + math.sqrt(b * b + 4 * a * c)) if a > 0 else c / b
        return (1.0 / x) * (1 + 1e-9)

    def as_dict(self) -> dict:
        return {
            "radius": self.radius,
            "area_bound": self.area,
            "samples": self.samples,
            "device_bytes": self.device_bytes,
            "host_bytes": self.host_bytes,
            "largest_buffer": self.largest_buffer,
        }


def _make_estimate(r, area, edges, tasks, itemsize, per_quadric=()) -> Estimate:
    samples = AREA_FACTOR * _div(area, math.pi * r * r) + EDGE_FACTOR * _div(edges, r) + TASK_SAMPLES * tasks
    key = 8 if itemsize == 8 else 4
    raw = 40 if key == 8 else 24
    return Estimate(r, float(area), float(samples), float(samples * DEVICE_BYTES_PER_SAMPLE[key]),
                    float(samples * HOST_BYTES_PER_SAMPLE), float(1.5 * raw * samples), float(edges),
                    int(tasks), key, tuple(per_quadric))


# -- area bounds --------------------------------------------------------------------------------


def _kind(matrix):
    """("plane", |unit normal|), ("convex", None) or ("saddle", None) for a quadric matrix."""
    m = np.asarray(matrix, dtype=np.float64)
    A = m[:3, :3]
    scale = np.abs(m).max()
    if np.abs(A).max() <= 1e-14 * scale:  # a plane: Q = 2 b.x + c
        b = m[:3, 3]
        nb = np.linalg.norm(b)
        return ("plane", np.abs(b) / nb if nb > 0 else None)
    lam = np.linalg.eigvalsh(0.5 * (A + A.T))
    tol = 1e-12 * np.abs(lam).max()
    if np.all(lam >= -tol) or np.all(lam <= tol):
        return ("convex", None)
    return ("saddle", None)


def _area_bounds(kind, lo, hi) -> np.ndarray:
    """Upper bounds of the area of a quadric of ``kind`` inside each box (lo, hi: (N, 3))."""
    e = np.maximum(np.asarray(hi, float) - np.asarray(lo, float), 0.0)
    F = np.stack([e[:, 1] * e[:, 2], e[:, 0] * e[:, 2], e[:, 0] * e[:, 1]], axis=1)
    S = 2.0 * F.sum(axis=1)
    what, n = kind
    if what == "plane":
        if n is None:
            return np.zeros(len(e))
        best = np.sqrt((F * F).sum(axis=1))
        for k in range(3):
            if n[k] > 1e-12:
                best = np.minimum(best, F[:, k] / n[k])
        return best
    return S if what == "convex" else SQRT3 * S


def quadric_area_bound(matrix, lo, hi) -> float:
    """Upper bound of the area of the quadric surface ``x^T Q x = 0`` inside the box [lo, hi]."""
    lo = np.asarray(lo, float).reshape(1, 3)
    hi = np.asarray(hi, float).reshape(1, 3)
    return float(_area_bounds(_kind(matrix), lo, hi)[0])


def _div(a: float, b: float) -> float:
    """a / b for a >= 0, b >= 0 without ZeroDivisionError or OverflowError (inf instead)."""
    if a == 0.0:
        return 0.0
    try:
        out = a / b
    except (ZeroDivisionError, OverflowError):
        return math.inf
    return out if math.isfinite(out) else math.inf


def _surface_box(q, lit_box):
    """Box of the surface of quadric ``q``: the intersection of the boxes of its two literals."""
    lo = np.full(3, -np.inf)
    hi = np.full(3, np.inf)
    for s in (1, -1):
        b = lit_box(q, s)
        if b is None:  # one side empty: the surface is empty too (e.g. x^2 + 1 = 0)
            return None
        lo = np.maximum(lo, b[0])
        hi = np.minimum(hi, b[1])
    return lo, hi


def estimate(dnf, radius: float, real_itemsize: int = 8) -> Estimate:
    """The :class:`Estimate` of sampling ``dnf`` at ``radius`` (host only, no device needed).

    ``real_itemsize``: 8 for the fp64 path, 4 for float32 (device buffer sizes).
    """
    r = float(radius)
    if not (math.isfinite(r) and r > 0):
        raise UsageError(f"radius must be a positive finite number, got {radius}")
    if not dnf.n_terms:
        return _make_estimate(r, 0.0, 0.0, 0, real_itemsize)
    boxes = np.asarray(dnf.term_bounds, dtype=np.float64)
    holders: dict[int, list[int]] = {}
    signs: dict[int, set] = {}
    for t, term in enumerate(dnf.terms):
        for qi, s in term:
            holders.setdefault(qi, []).append(t)
            signs.setdefault(qi, set()).add(s)
    area = 0.0
    edges = 0.0
    per_quadric = []
    tasks = 0
    for qi in range(dnf.n_quadrics):
        terms = holders.get(qi)
        if not terms:
            per_quadric.append(0.0)
            continue
        q = Quadric(dnf.quadrics[qi])
        sb = _surface_box(q, literal_box)
        if sb is None:
            per_quadric.append(0.0)
            continue
        lo = np.maximum(boxes[terms, 0], sb[0])
        hi = np.minimum(boxes[terms, 1], sb[1])
        ok = np.all(hi >= lo, axis=1)
        if not ok.any():
            per_quadric.append(0.0)
            continue
        lo, hi = lo[ok], hi[ok]
        kind = _kind(q.matrix)
        ulo, uhi = lo.min(axis=0, keepdims=True), hi.max(axis=0, keepdims=True)
        separate = float(_area_bounds(kind, lo, hi).sum())
        together = float(_area_bounds(kind, ulo, uhi)[0])
        a = min(separate, together)
        per_quadric.append(a)
        area += a
        # patch borders: at most the edges of the region boxes (the cheaper of the two ways)
        edges += min(4.0 * float(np.sum(hi - lo)), 4.0 * float(np.sum(uhi - ulo)))
        # tasks: one per literal polarity present x 3 planes x up to 2 sheets
        tasks += 6 * len(signs[qi])
    return _make_estimate(r, area, edges, tasks, real_itemsize, per_quadric)


def estimate_regions(quadric_matrices, regions, radius: float, real_itemsize: int = 8, tasks=None) -> Estimate:
    """The :class:`Estimate` of sampling the surface at ``radius`` from per-quadric regions.

    ``quadric_matrices``: (U, 4, 4) the unique quadrics; ``regions``: U arrays (k_u, 2, 3), the
    boxes where quadric u can carry CSG surface (:func:`clcsg.compile.bounds.regions.quadric_regions`:
    the faces of the primitive instances holding u, within their boxes and the scene bound).
    The area of u is bounded as in :func:`estimate`: per region box (intersected with the box
    of u's surface, dropped where the surface misses it) by the plane / convex / saddle rules,
    summed over the boxes or taken once for the box around all of them, whichever is smaller.
    ``tasks``: the number of sampling tasks; None for 6 per quadric that carries surface
    (3 sampling planes x 2 sheets).  All quadrics and boxes are treated in one pass
    (:mod:`clcsg.compile.bounds.surface_boxes`).
    """
    r = float(radius)
    if not (math.isfinite(r) and r > 0):
        raise UsageError(f"radius must be a positive finite number, got {radius}")
    mats = np.asarray(quadric_matrices, dtype=np.float64).reshape(-1, 4, 4)
    if len(regions) != len(mats):
        raise ValueError(f"{len(regions)} region lists for {len(mats)} quadrics")
    reg = [np.asarray(g, dtype=np.float64).reshape(-1, 2, 3) for g in regions]
    q = np.repeat(np.arange(len(reg)), [len(g) for g in reg])
    boxes = np.concatenate(reg) if len(q) else np.zeros((0, 2, 3))
    slo, shi, empty = surface_boxes(mats)
    live = ~empty[q]
    q, boxes = q[live], boxes[live]
    lo, hi = np.maximum(boxes[:, 0], slo[q]), np.minimum(boxes[:, 1], shi[q])
    ok = np.all(hi >= lo, axis=1)
    q, lo, hi = q[ok], lo[ok], hi[ok]
    ok = surface_meets(mats, q, lo, hi)
    q, lo, hi = q[ok], lo[ok], hi[ok]
    per_quadric = np.zeros(len(mats))
    n_tasks = 0
    edges = 0.0
    if len(q):
        kind, normal = quadric_kinds(mats)
        starts = np.flatnonzero(np.r_[True, q[1:] != q[:-1]])
        held = q[starts]
        ulo, uhi = np.minimum.reduceat(lo, starts, axis=0), np.maximum.reduceat(hi, starts, axis=0)
        separate = np.add.reduceat(_area_bounds_by_kind(kind[q], normal[q], lo, hi), starts)
        together = _area_bounds_by_kind(kind[held], normal[held], ulo, uhi)
        per_quadric[held] = np.minimum(separate, together)
        edge_sep = np.add.reduceat(np.sum(hi - lo, axis=1), starts)
        edges = float(np.sum(np.minimum(4.0 * edge_sep, 4.0 * np.sum(uhi - ulo, axis=1))))
        n_tasks = 6 * len(held)
    if tasks is not None:
        n_tasks = int(tasks)
    return _make_estimate(r, float(per_quadric.sum()), edges, n_tasks, real_itemsize, per_quadric.tolist())


def _area_bounds_by_kind(kind, normal, lo, hi) -> np.ndarray:
    """:func:`_area_bounds` per box for boxes of mixed kinds (``kind`` and ``normal`` per box,
    from :func:`~clcsg.compile.bounds.surface_boxes.quadric_kinds`)."""
    e = np.maximum(hi - lo, 0.0)
    F = np.stack([e[:, 1] * e[:, 2], e[:, 0] * e[:, 2], e[:, 0] * e[:, 1]], axis=1)
    S = 2.0 * F.sum(axis=1)
    out = np.where(kind == SADDLE, SQRT3 * S, S)
    p = kind == PLANE
    if p.any():
        best = np.sqrt((F[p] * F[p]).sum(axis=1))
        n = normal[p]
        with np.errstate(divide="ignore", invalid="ignore"):
            best = np.minimum(best, np.where(n > 1e-12, F[p] / np.where(n > 1e-12, n, 1.0), np.inf).min(axis=1))
        out[p] = np.where(np.isnan(n[:, 0]), 0.0, best)
    return out


# -- the check ------------------------------------------------------------------------------------


def memory_limit(info) -> tuple[float, float]:
    """(planned device bytes, largest single buffer) a device allows by default."""
    if info is None:
        return math.inf, math.inf
    return MEMORY_FRACTION * float(info.global_mem), float(info.max_mem_alloc)


def _size(n: float) -> str:
    if not math.isfinite(n):
        return "an unbounded amount"
    for unit in ("bytes", "KiB", "MiB", "GiB", "TiB", "PiB"):
        if n < 1024 or unit == "PiB":
            return f"{n:.0f} {unit}" if unit == "bytes" else f"{n:.3g} {unit}"
        n /= 1024.0
    return f"{n:.3g} PiB"  # pragma: no cover


def _count(n: float) -> str:
    if n >= 1e12:
        return f"{n:.3g}"
    return f"{int(round(n)):,}"


def _round_up(x: float) -> float:
    """``x`` rounded up to 3 significant digits (so the printed radius passes the guard)."""
    if not (math.isfinite(x) and x > 0):
        return x
    step = 10.0 ** (math.floor(math.log10(x)) - 2)
    return math.ceil(x / step * (1 - 1e-12)) * step


def _limit_value(value, name: str):
    if value is None:
        return None
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise UsageError(f"{name} must be a positive number, got {value!r}") from None
    if math.isnan(v) or v <= 0:
        raise UsageError(f"{name} must be a positive number, got {value!r}")
    return v


def check(dnf, radius: float, info=None, *, max_samples=None, max_memory=None, source: str = "scene",
          real_itemsize: int = 8) -> Estimate:
    """Estimate the cost of sampling ``dnf`` at ``radius`` and raise :class:`LimitError` past a limit.

    ``dnf``: a :class:`~clcsg.compile.dnf.Dnf` (estimated with :func:`estimate`) or an
    :class:`Estimate` (taken at ``radius``, e.g. from :func:`estimate_regions`).
    ``info``: the device's :class:`~clcsg.host.device.DeviceInfo` (None: no memory limit).
    ``max_samples``: None for :data:`DEFAULT_MAX_SAMPLES`; ``math.inf`` disables the count
    limit.  ``max_memory``: bytes of device memory the run may plan to use; None for
    :data:`MEMORY_FRACTION` of the device's global memory.  Returns the :class:`Estimate`.
    """
    _limit_value(max_samples, "max_samples")
    _limit_value(max_memory, "max_memory")
    if isinstance(dnf, Estimate):
        r = float(radius)
        if not (math.isfinite(r) and r > 0):
            raise UsageError(f"radius must be a positive finite number, got {radius}")
        est = dnf if r == dnf.radius else dnf.at(r)
    else:
        est = estimate(dnf, radius, real_itemsize)
    return check_estimate(est, info, max_samples=max_samples, max_memory=max_memory, source=source)


def _limits(est: Estimate, info, max_samples, max_memory):
    """(sample limit, past the hard limit?, max_memory or None, memory cap, largest allocation,
    the largest sample count every limit allows)."""
    ms = _limit_value(max_samples, "max_samples")
    mm = _limit_value(max_memory, "max_memory")
    ms = DEFAULT_MAX_SAMPLES if ms is None else ms
    hard = ms > HARD_MAX_SAMPLES
    ms = min(ms, HARD_MAX_SAMPLES)
    default_mem, max_alloc = memory_limit(info)
    mem_cap = default_mem if mm is None else mm
    allowed = min(ms, mem_cap / DEVICE_BYTES_PER_SAMPLE[est.real_itemsize],
                  max_alloc / est.largest_buffer * est.samples if est.largest_buffer > 0 else math.inf)
    return ms, hard, mm, mem_cap, max_alloc, allowed


def allowed_samples(est: Estimate, info=None, *, max_samples=None, max_memory=None) -> float:
    """The largest sample count that every limit allows."""
    return _limits(est, info, max_samples, max_memory)[-1]


def check_estimate(est: Estimate, info=None, *, max_samples=None, max_memory=None,
                   source: str = "scene") -> Estimate:
    """Raise :class:`LimitError` if the estimate ``est`` passes a limit (see :func:`check` for
    ``info``, ``max_samples``, ``max_memory``); returns ``est``.  The message names ``source``,
    the estimate and the radius that would fit."""
    ms, hard, mm, mem_cap, max_alloc, allowed = _limits(est, info, max_samples, max_memory)
    if est.finite and est.samples <= ms and est.device_bytes <= mem_cap and est.largest_buffer <= max_alloc:
        return est  # within every limit: no message to word (a sampling call's 0.05 ms)
    where = "" if info is None else f" on {info.describe()}"
    fit = _round_up(est.radius_for(allowed))
    how = (f"use a larger --radius (about {fit:.3g} fits)" if math.isfinite(fit)
           else f"no radius fits (the estimate never falls below {_count(TASK_SAMPLES * est.tasks)} samples)")
    if not est.finite:
        raise LimitError(f"{source}: radius {est.radius:.6g} is too small for a surface of area up to "
                         f"{est.area:.4g}: the sample count overflows; {how}")
    basis = (f"measured by sampling at radius {est.measured_at:.3g}" if est.measured_at
             else f"surface area <= {est.area:.4g}")
    head = (f"{source}: sampling at radius {est.radius:.6g} needs about {_count(est.samples)} samples "
            f"({basis}, about {_size(est.device_bytes)} of device memory)")
    if est.samples > ms:
        if hard:
            raise LimitError(f"{head}, past the {_count(ms)} samples the 32-bit kernels can index; {how}")
        raise LimitError(f"{head}, past the limit of {_count(ms)} samples; {how} or raise --max-samples")
    if est.device_bytes > mem_cap:
        what = "max_memory" if mm is not None else f"{MEMORY_FRACTION:.0%} of the device's global memory"
        raise LimitError(f"{head}, past {what} ({_size(mem_cap)}{where}); {how} "
                         "or a device with more memory (--device)")
    if est.largest_buffer > max_alloc:
        raise LimitError(f"{head}; its sample buffer ({_size(est.largest_buffer)}) is past the largest "
                         f"allocation the device allows ({_size(max_alloc)}{where}); {how} "
                         "or a device with more memory (--device)")
    return est


#: levels of octree refinement of the quadrics' regions by tape pruning, the most boxes the
#: refinement may hold at once, and the estimate past which it is worth its time (50-250 ms)
REFINE_LEVELS = 3
REFINE_BOXES = 20_000
REFINE_FROM = 1e6
#: a tape longer than this keeps the first estimate (an upper bound of the refined one): its
#: host pruning per group of boxes would cost minutes (a mesh of 80,000 face planes: 155 s),
#: and such tapes are large meshes, whose face boxes already follow their surface
REFINE_MAX_ROWS = 100_000

#: a refusal is checked by sampling at a radius whose estimate is this many samples ...
PROBE_SAMPLES = 2e5
#: ... and extrapolating the real count as (probe radius / radius)^2 times this margin; only
#: estimates at most PROBE_MAX_OVER times the limit are probed (the area bound is seldom
#: looser than 20x)
PROBE_MARGIN = 1.5
PROBE_MAX_OVER = 30.0


def refine_regions(tape, regions, levels: int = REFINE_LEVELS, max_boxes: int = REFINE_BOXES) -> list:
    """The regions with the boxes dropped where quadric u carries no CSG surface: the tape,
    pruned over the box with u substituted, gives the same constant on u's two sides
    (:func:`clcsg.compile.interpret.surface_in_boxes`).  Kept boxes are split in 8 and tested
    again, ``levels`` times (while the boxes number at most ``max_boxes``), so the regions
    follow the CSG surface instead of the primitives' boxes.  Neighbouring boxes are tested
    on their group's tape pruned to the primitives near the group
    (:func:`clcsg.compile.root_tapes.box_tapes`: exact over the group's boxes and the boxes
    split from them), not on the whole tape."""
    boxes = [np.asarray(r, dtype=np.float64).reshape(-1, 2, 3) for r in regions]
    q = np.concatenate([np.full(len(b), u) for u, b in enumerate(boxes)]) if boxes else np.zeros(0, int)
    if not len(q):
        return boxes
    lo = np.concatenate([b[:, 0] for b in boxes])
    hi = np.concatenate([b[:, 1] for b in boxes])
    group, tapes = box_tapes(tape, lo, hi, q)
    corners = np.array([[(k >> i) & 1 for i in range(3)] for k in range(8)], dtype=np.float64)
    programs: dict = {}  # the groups' tapes are often the same rows (a convex mesh: one group of planes)
    for level in range(levels + 1):
        keep = np.zeros(len(q), dtype=bool)
        order = np.argsort(group, kind="stable")
        cuts = np.searchsorted(group[order], np.arange(len(tapes) + 1))
        for k, ops in enumerate(tapes):
            sel = order[cuts[k]:cuts[k + 1]]
            if len(sel):
                key = np.ascontiguousarray(ops).tobytes()
                if key not in programs:
                    programs[key] = minmax_program(ops)
                keep[sel] = surface_in_boxes(ops, tape.quadrics, lo[sel], hi[sel], q[sel], program=programs[key])
        lo, hi, q, group = lo[keep], hi[keep], q[keep], group[keep]
        if level == levels or 8 * len(q) > max_boxes:
            break
        half = 0.5 * (hi - lo)
        lo = (lo[:, None, :] + corners[None] * half[:, None, :]).reshape(-1, 3)
        hi = lo + np.repeat(half, 8, axis=0)
        q, group = np.repeat(q, 8), np.repeat(group, 8)
    order = np.argsort(q, kind="stable")
    cuts = np.cumsum(np.bincount(q, minlength=len(boxes)))[:-1]
    return [np.stack([a, b], axis=1) for a, b in zip(np.split(lo[order], cuts), np.split(hi[order], cuts))]


def estimate_tape(tape, radius: float, real_itemsize: int = 8) -> Estimate:
    """The :class:`Estimate` of sampling a compiled tape: the regions of its quadrics are the
    face boxes of the primitive instances holding them, within the scene bound
    (:func:`clcsg.compile.bounds.regions.quadric_regions`), refined by tape pruning
    (:func:`refine_regions`) when the first estimate is past :data:`REFINE_FROM` samples and the
    tape has at most :data:`REFINE_MAX_ROWS` rows."""
    if tape.empty:
        return _make_estimate(float(radius), 0.0, 0.0, 0, real_itemsize)
    est = _tape_estimate(tape, "regions", radius, real_itemsize)
    if est.finite and est.samples > REFINE_FROM and len(tape.ops) <= REFINE_MAX_ROWS:
        est = _tape_estimate(tape, "refined", radius, real_itemsize)
    return est


def _tape_estimate(tape, which: str, radius: float, real_itemsize: int) -> Estimate:
    """The estimate from the tape's ``"regions"`` or ``"refined"`` regions at ``radius``.  The
    regions, the areas and the edges do not depend on the radius, so they are computed once per
    tape (kept on it, as the scene keeps its compiled tape) and only rescaled
    (:meth:`Estimate.at`) for another radius."""
    cache = tape.__dict__.setdefault("_guard_estimates", {})
    key = (which, int(real_itemsize))
    est = cache.get(key)
    if est is None:
        regions = cache.get("regions")
        if regions is None:
            regions = cache["regions"] = quadric_regions(tape.quadrics, tape.instances, tape.bound)
        if which == "refined":
            regions = refine_regions(tape, regions)
        est = cache[key] = estimate_regions(tape.quadrics, regions, radius, real_itemsize)
    return est if est.radius == float(radius) else est.at(radius)


#: the expected sample count's weights, per (area bound of the kind) / (pi r^2) and per
#: (patch border bound) / r: the ratios of the real counts to those bounds, fitted (least squares
#: on the log ratio) on the examples and the zoo at r = 1% of the diagonal; used for scenes too
#: large for a measured area
EXPECTED_WEIGHTS = {"plane": 0.7, "convex": 0.58, "saddle": 0.27, "edge": 0.7}
#: with the measured area (:mod:`clcsg.compile.bounds.surface_area`): samples per
#: (area / (pi r^2)) and per (sum over quadrics of sqrt(area) / r), fitted (least squares on the
#: log ratio) on the examples and the zoo at r = 2%, 1%, 0.2% and 0.05% of the diagonal (the
#: sponge at the first two; 94 runs; the fit is within 0.55-1.44x of every one, 0.81-1.17x at
#: 0.05%, where a fit at 1-2% alone expected 1.1-1.6x the real count)
EXPECTED_AREA = 1.8
EXPECTED_PERIMETER = 14.9


def measured_areas(tape):
    """Per quadric the measured CSG surface area (:func:`~clcsg.compile.bounds.surface_area.surface_areas`),
    or None for a scene too large to measure; computed once per tape and kept on it."""
    cache = tape.__dict__.setdefault("_guard_estimates", {})
    if "measured_areas" not in cache:
        regions = cache.get("regions")
        if regions is None:
            regions = cache["regions"] = quadric_regions(tape.quadrics, tape.instances, tape.bound)
        cache["measured_areas"] = surface_areas(tape, regions)
    return cache["measured_areas"]


def expected_samples(tape, est: Estimate) -> float:
    """The sample count to expect (not a bound: the guard keeps :attr:`Estimate.samples` for
    its limits).  With the CSG surface area A_u measured on each quadric u
    (:func:`measured_areas`): fill samples grow with the area and partial cells with the
    length of the patches' borders, taken as sqrt(A_u) per quadric:

        expected = EXPECTED_AREA sum_u A_u / (pi r^2) + EXPECTED_PERIMETER sum_u sqrt(A_u) / r

    For scenes too large to measure, the area bounds (which overshoot by a factor that depends
    on the kind of quadric: a sphere in its box gets 6 / pi = 1.9 times its area, a saddle
    sqrt 3 times more) are weighted per kind by :data:`EXPECTED_WEIGHTS`:

        expected = sum_kind w_kind area_kind / (pi r^2) + w_edge edges / r

    An estimate rescaled from a probe run (:func:`measured`) expects the probe's count scaled
    as 1 / r^2, without :data:`PROBE_MARGIN`.
    """
    if est.measured_at is not None:  # rescaled from a probe run: without the guard's margin
        return est.samples / PROBE_MARGIN
    if not est.finite or not est.quadric_areas:
        return est.samples
    r = est.radius
    areas = None if tape.empty else measured_areas(tape)
    if areas is not None:
        n = EXPECTED_AREA * float(areas.sum()) / (math.pi * r * r) + EXPECTED_PERIMETER * float(np.sqrt(areas).sum()) / r
        return max(1.0, n)
    kind, _ = quadric_kinds(tape.quadrics)
    areas = np.asarray(est.quadric_areas, dtype=np.float64)
    by_kind = {name: float(areas[kind == k].sum()) for name, k in (("plane", PLANE), ("convex", CONVEX), ("saddle", SADDLE))}
    w = EXPECTED_WEIGHTS
    n = sum(w[k] * a for k, a in by_kind.items()) / (math.pi * r * r) + w["edge"] * est.edges / r
    return max(1.0, n)


def probe_radius(est: Estimate, allowed: float) -> float | None:
    """The radius at which a probe run checks a refusal of ``est`` under a limit of
    ``allowed`` samples (None: no probe; the estimate is not finite, already small, or so far
    past the limit that no looseness of the area bound explains it)."""
    if not est.finite or est.samples <= PROBE_SAMPLES or est.samples > PROBE_MAX_OVER * allowed:
        return None
    return est.radius_for(PROBE_SAMPLES)


def measured(est: Estimate, probe_samples: int, probe_radius: float) -> Estimate:
    """``est`` rescaled to a probe's real sample count: samples grow as 1 / r^2, so the run
    at ``est.radius`` is expected to give probe_samples (probe_radius / radius)^2, times
    :data:`PROBE_MARGIN`; the area and edge terms are scaled alike, and ``measured_at``
    records the probe."""
    fixed = TASK_SAMPLES * est.tasks
    want = PROBE_MARGIN * probe_samples * (probe_radius / est.radius) ** 2
    k = max(want - fixed, 0.0) / max(est.samples - fixed, 1e-300)
    out = _make_estimate(est.radius, est.area * k, est.edges * k, est.tasks, est.real_itemsize,
                         tuple(a * k for a in est.quadric_areas))
    return replace(out, measured_at=float(probe_radius))


def check_tape(tape, radius: float, info=None, *, max_samples=None, max_memory=None, source: str = "scene",
               real_itemsize: int = 8) -> Estimate:
    """:func:`estimate_tape`, then the limits of :func:`check_estimate`."""
    est = estimate_tape(tape, radius, real_itemsize)
    return check_estimate(est, info, max_samples=max_samples, max_memory=max_memory, source=source)
