"""Driver of the adaptive subdivision sampler (``sampler.cl``, ``finish.h``); paper sections 3-5
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
holds x, and the sides differ at x; a pruned value that no longer depends on q would make them
equal).  It is discarded by the discs only if x lies in a disc of
a corner p with d_q(p) > 0: the 2-D radius |d| / delta maps to a 3-D distance of at most |d|
(delta bounds |dp| / |dx| over the cell), and no point of q within |d| of p is on the surface
— contradiction.  Pruning keeps every tape exact where it is used: a leaf is replaced by a
constant only where it has one sign over the whole region (planes are tested exactly on the
patch box, other quadrics by their conservative distance), and the children's region (the
parent's patch grown by r) holds their patches and every splat ball of their samples.  The
per-cell decision prunes over the patch itself, which is all the cell's points of q: there a
leaf is also constant where the mean value form proves it (``leaf_over_patch`` in tape.h:
f = s Q(p(x, y)) lies in f(center) +- (max |f_x| h_x + max |f_y| h_y), the derivative bounds
from interval arithmetic over the cell, so a cell at distance D from a trimming curve is
decided once D exceeds O(h^2)).  That is what resolves edge cells at the size of a splat
instead of splitting them to the floor: a cell that crosses a trimming curve has a corner on
each side of it (a curve flat on the cell's scale separates its corners), so once the cell is
about r a corner with d_q < 0 gives the single sample below; a cell on the discarded side,
not crossing, is decided by the patch test.  Splits cut the longest edge at ``SPLIT_AT`` of
it (``SPLIT_AT_Y`` across y), not the middle: a cell edge lying exactly on a trimming curve
(features in the middle of a box are common) has corners with d_q = 0 that no bound can
separate from the curve, and so does a corner on a curve along the grid's diagonal (the
tricylinder's edges, in the planes y = +-z), which one fraction for both axes would put there.  A
roughly square cell larger than ``QUAD_SPLIT_DIAG`` radii is cut across both edges at once
(four children: a level saved, the children cover the cell just the same).  So the
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
the capacity without writing, the host sees it, grows the buffer (cells, samples, tape arena,
clip programs) and re-runs the level.  Levels run in chains of a few, launched back to back
with one read of their counters (:class:`_Subdivision`); a level after one that overran does
nothing, so the overrun level's inputs are intact when it runs again.

Scale
-----
A split counts the rows its children's pruned tape keeps (the forward pass of pruning, without
writing) and reserves exactly that many in the level's output arena, never the parent's
length.  Arenas ping-pong (:class:`_Subdivision`): a level reads its cells' tapes from one and
writes its children's into the other, whose counter starts at zero, so an arena holds the
tapes of one level's live cells.  A sample's clip program, sign, normal and primitive are
made as it is emitted (``finish.h``), from its cell's tape, into its record; a clip program
that an earlier launch stored already is not written again (``clip_table.h``: the level-3
Menger sponge at 0.1% of its diagonal writes 0.47M rows, not 14.3M).
"""

from __future__ import annotations

import math
import operator
import time
import warnings

import numpy as np

from ..cl import device as _device
from ..cl.constants import CLIP_ENTRY_WORDS, SAMPLER_COUNTERS
from ..cl.programs import build, kernel as program_kernel, launch, relaunch
from ..cl.buffer_pool import pool_of
from ..cl.memory import check_allocation, upload
from ..cl.records import SceneBuffers, cell_dtype, frame_dtype, pack, tape_rows, task_dtype
from ..compile.quadric_frames import principal_frame_list
from ..compile.contacts import contact_pairs, contact_root_tapes
from ..compile.root_tapes import prune_root_tapes
from ..compile.tape import leaf_quadrics
from ..errors import LimitError, UsageError
from ..readers.scenes import as_scene
from .samples import Samples
from .sample_columns import SampleColumns
from ..compile.bounds import estimates as guard
from ..progress import for_option
from .forecast import Forecast, level_bounds, peak_levels

#: fixed work-group size: PoCL compiles a kernel variant per local size, so letting the
#: runtime pick one per launch size would recompile at every level
WORK_GROUP = 64  # > the 16 statistics classify sums per work-group (sampler.cl)

#: counters summed over levels into the stats (the others are per-level positions)
SUMMED_STATS = _SUMMED = ("distance_queries", "leaf_distances", "unresolved", "discarded", "filled", "single", "split",
           "split_in_place", "prune_evaluations", "pruned_decided", "tapes_written", "finish_prune_evaluations")
_SLOT = {name: k for k, name in enumerate(SAMPLER_COUNTERS)}
#: argument indices of sampler.cl's classify that change between the launches of a chain
#: (each a buffer followed by its capacity)
_ARG_CELLS_IN, _ARG_CELLS_OUT, _ARG_ARENA_IN, _ARG_ARENA_OUT, _ARG_ROW, _ARG_LAUNCH = 3, 5, 10, 12, 15, 22
#: the counters of a cell's outcome: their sum is the cells a level classified
_OUTCOMES = ("discarded", "filled", "single", "split", "unresolved")
#: a level's counter row (a list) -> the counts of its outcomes, and (name, slot) of the summed
#: counters: the per-level bookkeeping indexes by slot (a call's 7 levels, 0.1 ms by name)
_outcome_counts = operator.itemgetter(*(_SLOT[k] for k in _OUTCOMES))
_SUMMED_SLOTS = tuple((name, _SLOT[name]) for name in _SUMMED)


def frame_records(frames, real) -> np.ndarray:
    """Principal frames as ``frame_rec`` records (``cl/include/layout.h``), with the per-axis
    quotients the kernels would otherwise divide out per cell: the height factor (-1 / lam,
    or -1 / (2 beta) where lam = 0), the vertex -beta / lam of lam z^2 + 2 beta z and its value."""
    rec = np.zeros(len(frames), dtype=frame_dtype(real))
    for i, f in enumerate(frames):
        rec["U"][i] = f.U.reshape(9)
        rec["center"][i] = f.center
        rec["lam"][i] = f.lam
        rec["beta"][i] = f.beta
        rec["gamma"][i] = f.gamma
    lam, beta = rec["lam"].astype(np.float64), rec["beta"].astype(np.float64)
    curved, sloped = lam != 0, beta != 0
    factor = np.zeros_like(lam)
    factor[curved] = -1.0 / lam[curved]
    flat = ~curved & sloped
    factor[flat] = -1.0 / (2.0 * beta[flat])
    vertex = np.zeros_like(lam)
    vertex[curved] = -beta[curved] / lam[curved]
    rec["height_factor"] = factor
    rec["vertex"] = vertex
    rec["vertex_value"] = lam * vertex * vertex + 2.0 * beta * vertex
    return rec


def quadric_boxes(tape) -> dict:
    """World box per sampled quadric: the union over the primitive instances that have it as a
    literal of the box of their face on it (their face boxes, which bound the part of their
    boundary on each literal; else their box), cut by the scene bound (no entry where that is
    empty).  A plane's face box is flat: the union per instance is padded by a relative 1e-9,
    so that cutting it by the scene bound (computed apart, and rounded) cannot empty it.
    One row per (instance, literal), unions by ``np.minimum.at`` (a loop per quadric took the
    2,500-hole plate 0.39 s)."""
    n_q = tape.n_quadrics
    inst_of, q_of, los, his, from_faces = [], [], [], [], []
    for inst in tape.instances:
        if inst.box is None or not inst.literals:
            continue
        qs = np.array([u for u, _ in inst.literals], dtype=np.int64)
        inst_of.append(np.full(len(qs), inst.index, dtype=np.int64))
        q_of.append(qs)
        if inst.face_boxes is not None:
            f = np.asarray(inst.face_boxes, dtype=np.float64).reshape(len(qs), 2, 3)
            los.append(f[:, 0])
            his.append(f[:, 1])
        else:
            los.append(np.broadcast_to(np.asarray(inst.box[0], dtype=np.float64), (len(qs), 3)))
            his.append(np.broadcast_to(np.asarray(inst.box[1], dtype=np.float64), (len(qs), 3)))
        from_faces.append(np.full(len(qs), inst.face_boxes is not None))
    if not inst_of:
        return {}
    inst_of, q_of, from_faces = np.concatenate(inst_of), np.concatenate(q_of), np.concatenate(from_faces)
    lo, hi = np.concatenate(los), np.concatenate(his)
    keep = ~from_faces | np.all(hi >= lo, axis=1)  # an empty face adds nothing
    inst_of, q_of, lo, hi, from_faces = inst_of[keep], q_of[keep], lo[keep], hi[keep], from_faces[keep]
    # the union per (instance, quadric), padded where made of face boxes
    pairs, pair = np.unique(inst_of * n_q + q_of, return_inverse=True)
    plo, phi = np.full((len(pairs), 3), np.inf), np.full((len(pairs), 3), -np.inf)
    np.minimum.at(plo, pair, lo)
    np.maximum.at(phi, pair, hi)
    padded = np.zeros(len(pairs), dtype=bool)
    padded[pair[from_faces]] = True
    with np.errstate(invalid="ignore"):
        size = np.abs(np.where(np.isfinite(plo), plo, 0.0)).max(axis=1) + np.abs(np.where(np.isfinite(phi), phi, 0.0)).max(axis=1)
    pad = np.where(padded, 1e-9 * (1.0 + size), 0.0)[:, None]
    quad = pairs % n_q
    qlo, qhi = np.full((n_q, 3), np.inf), np.full((n_q, 3), -np.inf)
    np.minimum.at(qlo, quad, plo - pad)
    np.maximum.at(qhi, quad, phi + pad)
    lo_b, hi_b = tape.bound
    qlo, qhi = np.maximum(qlo, lo_b), np.minimum(qhi, hi_b)
    used = leaf_quadrics(tape.ops)
    ok = np.zeros(n_q, dtype=bool)
    ok[quad] = True
    ok &= np.all(qhi >= qlo, axis=1)
    return {int(q): (qlo[q], qhi[q]) for q in used if ok[q]}


def root_tasks(tape, packed, frames, radius: float = 0.0):
    """One task per (quadric, plane, sheet) and its root cell, and the root tape rows.

    Returns (tasks, cells, rows): ``rows`` (TAPE_OP_DTYPE) start the tape arena; they begin
    with the full tape and continue with the quadrics' root tapes, pruned primitive by
    primitive to what can matter within ``radius`` of the patches of the quadrics' tasks
    (:mod:`clcsg.compile.root_tapes`), on the tree tape then with the leaves of the quadrics
    in contact with the sampled one folded (:mod:`clcsg.compile.contacts`); each root cell's
    ``tape_first`` / ``tape_count`` point at its quadric's tape."""
    scale = float(np.abs(tape.bound).max(initial=1.0))
    boxes = quadric_boxes(tape)
    qs = np.array(list(boxes), dtype=np.int64)
    lo = np.array([boxes[q][0] for q in qs.tolist()]).reshape(-1, 3) - packed.origin
    hi = np.array([boxes[q][1] for q in qs.tolist()]).reshape(-1, 3) - packed.origin
    pick = np.array([[(x, y, z) for x in (0, 1) for y in (0, 1) for z in (0, 1)]])  # (1, 8, 3): hi or lo
    corners = np.where(pick == 1, hi[:, None, :], lo[:, None, :])
    U = np.array([frames[q].U for q in qs.tolist()]).reshape(-1, 3, 3)
    center = np.array([frames[q].center for q in qs.tolist()]).reshape(-1, 3)
    z = np.matmul(corners - center[:, None, :], U)
    # pad by a relative epsilon: surface points on the box's faces (a box face is the
    # bound) must not be lost to rounding in the local coordinates
    pad = 1e-7 * (np.abs(z).max(axis=(1, 2), initial=0.0) + np.abs(hi - lo).max(axis=1, initial=0.0)) + 1e-12 * scale
    zlo, zhi = z.min(axis=1) - pad[:, None], z.max(axis=1) + pad[:, None]
    # per (quadric, plane k): sheets +1 and -1 where lam_k != 0, sheet 0 where only beta_k
    # (a plane's normal, a paraboloid's axis), none for a cylinder along u_k (plane k owns
    # no point)
    lam = np.array([frames[q].lam for q in qs.tolist()]).reshape(-1, 3)
    beta = np.array([frames[q].beta for q in qs.tolist()]).reshape(-1, 3)
    count = np.where(lam != 0.0, 2, np.where(beta != 0.0, 1, 0)).ravel()
    which = np.repeat(np.arange(count.size), count)  # (quadric index, plane) flattened
    first = np.repeat(np.cumsum(count) - count, count)
    nth = np.arange(len(which)) - first
    plane = which % 3
    t = np.zeros(len(which), dtype=task_dtype(packed.real))
    t["quadric"] = qs[which // 3]
    t["plane"] = plane
    t["sheet"] = np.where(count[which] == 2, 1 - 2 * nth, 0)
    t["zlo"], t["zhi"] = zlo[which // 3], zhi[which // 3]
    c = np.zeros(len(t), dtype=cell_dtype(packed.real))
    if not len(t):
        return t, c, tape_rows(tape.ops)
    zlo, zhi = t["zlo"].astype(np.float64), t["zhi"].astype(np.float64)
    i = np.where(t["plane"] == 0, 1, 0)
    j = np.where(t["plane"] == 2, 1, 2)
    rows = np.arange(len(t))
    c["x0"], c["y0"], c["x1"], c["y1"] = zlo[rows, i], zlo[rows, j], zhi[rows, i], zhi[rows, j]
    c["d"] = np.nan
    c["task"] = rows
    regions, oriented = _task_regions(t, frames, packed.origin, 1.01 * radius + 1e-6 * scale)
    spans, root_rows = prune_root_tapes(tape, regions, oriented)
    if tape.shape == "tree":  # the DNF stays the paper's
        grow = 1.01 * radius + 1e-6 * scale  # the patches (in the quadric's box) and their splat balls
        near = {q: (boxes[q][0] - grow, boxes[q][1] + grow) for q in regions}
        spans, root_rows = contact_root_tapes(tape, spans, root_rows, near)
    span = np.array([spans[int(q)] for q in t["quadric"]]).reshape(-1, 2)
    c["tape_first"], c["tape_count"] = span[:, 0], span[:, 1]
    return t, c, tape_rows(root_rows)


def _quadratic_ranges(lam, beta, a, b):
    """Range of lam x^2 + 2 beta x over [a, b] (arrays)."""
    fa, fb = lam * a * a + 2.0 * beta * a, lam * b * b + 2.0 * beta * b
    with np.errstate(divide="ignore", invalid="ignore"):
        v = np.where(lam != 0.0, -beta / np.where(lam != 0.0, lam, 1.0), np.nan)
    inside = (v > a) & (v < b)
    fv = np.where(inside, lam * v * v + 2.0 * beta * v, fa)
    return np.minimum(np.minimum(fa, fb), fv), np.maximum(np.maximum(fa, fb), fv)


def _task_regions(t, frames, origin, grow) -> tuple[dict, dict]:
    """Per quadric, a world box holding every point of its tasks' patches grown by ``grow``,
    and the same in the quadric's principal frame: (world origin of the frame, U, local lo,
    local hi), the local box of its patches grown by ``grow`` along each axis (a ball of that
    radius around a point of the box stays in it), which is much thinner than the world box
    for a tilted plane.

    Over task (plane k, sheet)'s root rectangle, R(x, y) = lam_i x^2 + 2 beta_i x + lam_j y^2
    + 2 beta_j y + gamma is separable, so its range is the sum of two 1-D ranges, and the height
    is t = +-sqrt(-R / lam_k) (eq. 7) or -R / (2 beta_k) (eq. 6): the patch lies in the local box
    of the rectangle and that height range."""
    n = len(t)
    q, k, sheet = t["quadric"], t["plane"], t["sheet"]
    lam = np.array([frames[int(u)].lam for u in q])
    beta = np.array([frames[int(u)].beta for u in q])
    gamma = np.array([frames[int(u)].gamma for u in q])
    zlo, zhi = t["zlo"].astype(np.float64), t["zhi"].astype(np.float64)
    r_lo, r_hi = gamma.copy(), gamma.copy()
    for axis in range(3):
        lo, hi = _quadratic_ranges(lam[:, axis], beta[:, axis], zlo[:, axis], zhi[:, axis])
        other = k != axis
        r_lo, r_hi = r_lo + np.where(other, lo, 0.0), r_hi + np.where(other, hi, 0.0)
    rows = np.arange(n)
    lk, bk = lam[rows, k], beta[rows, k]
    with np.errstate(divide="ignore", invalid="ignore"):
        safe_l = np.where(lk != 0.0, lk, 1.0)
        h1, h2 = -r_lo / safe_l, -r_hi / safe_l
        h_lo, h_hi = np.minimum(h1, h2), np.maximum(h1, h2)
        a, b = np.sqrt(np.maximum(h_lo, 0.0)), np.sqrt(np.maximum(h_hi, 0.0))
        t_lo = np.where(sheet > 0, a, -b)
        t_hi = np.where(sheet > 0, b, -a)
        safe_b = np.where(bk != 0.0, 2.0 * bk, 1.0)
        p1, p2 = -r_lo / safe_b, -r_hi / safe_b
    t_lo = np.where(lk != 0.0, t_lo, np.minimum(p1, p2))
    t_hi = np.where(lk != 0.0, t_hi, np.maximum(p1, p2))
    eps = 1e-9 * (1.0 + np.maximum(np.abs(t_lo), np.abs(t_hi)))
    lo, hi = zlo.copy(), zhi.copy()
    lo[rows, k], hi[rows, k] = t_lo - eps, t_hi + eps
    bits = np.array([[(c >> m) & 1 for m in range(3)] for c in range(8)], dtype=bool)
    corners = np.where(bits[None], hi[:, None, :], lo[:, None, :])  # (n, 8, 3) local
    U = np.array([frames[int(u)].U for u in q])
    center = np.array([frames[int(u)].center for u in q])
    world = center[:, None, :] + np.einsum("nij,ncj->nci", U, corners) + origin
    wlo, whi = world.min(axis=1) - grow, world.max(axis=1) + grow
    order = np.argsort(q, kind="stable")
    qs = q[order]
    starts = np.flatnonzero(np.concatenate([[True], qs[1:] != qs[:-1]]))
    lo_q = np.minimum.reduceat(wlo[order], starts, axis=0)
    hi_q = np.maximum.reduceat(whi[order], starts, axis=0)
    llo_q = np.minimum.reduceat(lo[order], starts, axis=0) - grow
    lhi_q = np.maximum.reduceat(hi[order], starts, axis=0) + grow
    first = order[starts]
    world = {int(u): (a, b) for u, a, b in zip(qs[starts], lo_q, hi_q)}
    local = {int(u): (center[f] + origin, U[f], a, b) for u, f, a, b in zip(qs[starts], first, llo_q, lhi_q)}
    return world, local


#: where a split cuts a cell's longest edge, as a fraction of it: SPLIT_AT across x, SPLIT_AT_Y
#: across y (the build options of sampler.cl, which says why they are not one half, and not
#: one fraction for both)
SPLIT_AT = 0.4871
SPLIT_AT_Y = 0.4913
#: the larger child's share of a split (at most)
SPLIT_LARGER = 1 - min(SPLIT_AT, SPLIT_AT_Y)
#: a roughly square cell whose diagonal exceeds this many radii is split into four, not two
#: (the build option QUAD_SPLIT_DIAG of sampler.cl).  3 rather than 8: 1-2 levels and 3-9% of
#: the cells fewer on the zoo, for 0.3-3% more samples (2.5 gave the gear 6% more)
QUAD_SPLIT_DIAG = 3.0
#: most children of a split
MAX_CHILDREN = 4
#: cells a work-item of the classify kernel holds for the small cells it splits in place (the
#: build option HERE_DEPTH of sampler.cl): its depth-first walk needs one more per level below
#: its first cell, and from a cell whose tape is handed on as it is (a diagonal under sqrt 8
#: radii) to the default floor (r / 10) are about 2 log2(sqrt 8 / 0.1) = 10 levels; 1: none
SPLIT_HERE_DEPTH = 16


class _Progress:
    """Progress of the level loop on the current reporter (:mod:`clcsg.progress`: a bar on
    a terminal, JSON lines with ``--progress json``, nothing in a pipe or with ``progress=False``).

    The seconds left are forecast by :class:`clcsg.sampling.forecast.Forecast` from the levels
    seen (cells per level up to the level where they reach the floor, seconds per level
    a + b (cells + samples), the expected sample count as the samples still to come while the
    emission grows).  The fraction shown is elapsed / (elapsed + forecast), elapsed counted
    from the start of the level loop, and the largest seen so far: it never goes back, and is
    100% when the last level is done.  The bar counts the cells classified (those a level read
    and the halves of those it split in place: the work of the levels they would have made);
    its total is done / fraction.
    Its ETA is the forecast itself, counting down between levels (``Step.update``'s
    ``forecast``): the rate so far times the cells left would be the forecast too, but not
    once the fraction is held (a forecast that grows would not show).  While the forecast
    extrapolates far beyond the cells seen (``Forecast.eta``: the first levels) no ETA is
    shown.  The samples so far
    and the expected count (:func:`clcsg.compile.bounds.estimates.expected_samples`) are
    shown next to the bar.
    """

    def __init__(self, enabled, estimate=0, roots=None, radius=None, max_levels=400, floor=None):
        self.reporter = for_option(enabled)
        self.estimate = int(estimate)
        peak = last = levels = None
        quad = 0.0
        self.visible = shown = self.reporter.mode != "none"  # else nothing is forecast (see chain)
        if shown and roots is not None and len(roots) and radius and floor:
            wx, wy = roots["x1"] - roots["x0"], roots["y1"] - roots["y0"]
            diag = np.hypot(wx, wy)
            if diag.max() > 0:
                # the deepest levels come from the largest root cell, the most cells of a
                # level from the root cells of its peak (Forecast.peak_at)
                quad, peak, last = level_bounds(float(diag.max()), radius, floor, SPLIT_LARGER, QUAD_SPLIT_DIAG)
                levels = (peak_levels(diag, radius, SPLIT_LARGER, QUAD_SPLIT_DIAG), wx * wy)
        self.forecast = Forecast(self.estimate, quad, peak, last, max_levels, levels) if shown else None
        outer = self.reporter.active()
        self.own = outer is None or outer.name != "sample"
        if not self.own:
            self.step = outer
        elif shown:
            self.step = self.reporter.step("sample", "sampling")
        else:  # a step of its own that nothing would show is not made (a call's 0.08 ms)
            self.step = None
        self.cells = 0
        self.fraction = 0.0
        self.shown = 0.0
        self.moved = False
        self.t0 = self.t_last = time.perf_counter()

    def restart(self):
        """Start the level loop's clock now (after one-off work the forecast must not see)."""
        self.t0 = self.t_last = time.perf_counter()

    def chain(self, levels):
        """The levels of one chain, (level, cells, samples so far, children) each, done at
        once: the chain's seconds are shared among them by their work as the forecast costs
        it (``Forecast.add_chain``), so that its time model sees each level's share, not the
        whole chain on its first level and nothing on the others.  The bar moves once, to the
        chain's last level: the forecasts after the levels before it would count levels
        already done."""
        self.cells += sum(lv[1] for lv in levels)
        if self.reporter.mode == "none":  # nothing is shown: no forecast to make
            return
        now = time.perf_counter()
        self.forecast.add_chain(levels, now - self.t_last)
        self.t_last = now
        self._show(*levels[-1])

    def level(self, level, cells, samples, children=0):
        """A level done on its own (a chain of one)."""
        self.chain([(level, cells, samples, children)])

    def _show(self, level, cells, samples, children):
        elapsed = time.perf_counter() - self.t0
        left = self.forecast.seconds_left(children)
        eta = self.forecast.eta(children, left)
        if not children:
            self.fraction = 1.0
        elif elapsed + left > 0:
            self.fraction = max(self.fraction, min(elapsed / (elapsed + left), 0.999))
        total = max(self.cells, math.ceil(self.cells / max(self.fraction, 1e-9)))
        if self.cells / total < self.shown:  # rounding must not take the bar back either
            total = max(self.cells, math.floor(self.cells / self.shown))
        self.shown = self.cells / total
        first, self.moved = not self.moved, True
        self.step.update(done=self.cells, total=total, label="sampling", unit="cells",
                         phase=self.t0 if first else False, forecast=math.nan if eta is None else eta, level=level + 1,
                         samples=samples, estimated=self.estimate,
                         note=f"level {level + 1}, {samples:,} samples (estimate {self.estimate:,})", always=True)

    def done(self):
        if self.step is None:
            return
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
    ``max_samples`` / ``max_memory``: limits of the resource guard (:mod:`clcsg.compile.bounds.tree.estimates`;
    None: 50 million samples / 80% of the device's global memory); past them
    :class:`~clcsg.errors.LimitError` is raised before anything is allocated.
    """
    radius, floor = checked_radius(radius, floor)
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
    est = _guarded(sc, tape, radius, ctx, real, normal_form, term_limit, distortion, max_samples, max_memory)
    t1 = time.perf_counter()
    packed, frames, frames_rec = _packed(tape, real)
    tasks, roots, root_rows = _root_tasks(tape, packed, frames, radius)
    timings["analyse_s"] = time.perf_counter() - t1
    stats = {"radius": radius, "floor": floor, "tasks": len(tasks), "normal_form": tape.shape,
             "contact_pairs": contact_pairs(tape),
             "estimated_samples": est.samples,
             **{f"tape_{k}": v for k, v in tape.stats.items()}}
    if len(roots) == 0 or tape.empty:
        warnings.warn(f"{sc.source}: the solid is empty; no samples", stacklevel=2)
        return _empty(radius, tape, packed, stats)

    stats["expected_samples"] = guard.expected_samples(tape, est)
    sub = _machinery(ctx, packed, real, distortion, frames_rec, tasks, roots, radius, floor, capacity,
                     stats["expected_samples"], progress, max_levels, root_rows)
    t_sub = time.perf_counter()
    sub.run()
    t2 = time.perf_counter()
    timings["subdivide_s"] = t2 - t_sub
    samples = sub.collect(tape, radius)
    sub.release()
    timings["finish_s"] = time.perf_counter() - t2
    timings["total_s"] = time.perf_counter() - t0
    if len(samples) == 0:
        warnings.warn(f"{sc.source}: no samples: no surface was found above the floor of {floor:.3g} "
                      f"({sub.totals['unresolved']} cells smaller than it were left unresolved)", stacklevel=2)
    stats.update(sub.totals)
    stats.update(_run_stats(sub, samples, ctx, timings))
    stats.update(samples.stats)
    samples.stats = stats
    return samples


def _packed(tape, real):
    """(packed scene, principal frames, frame records) of ``tape`` for precision ``real``: made
    once per tape and kept on it (as the scene keeps its compiled tape; nothing here depends on
    the radius)."""
    cache = tape.__dict__.setdefault("_sampler_packed", {})
    key = np.dtype(real).str
    if key not in cache:
        packed = pack(tape, real)
        frames = principal_frame_list(packed.local_matrices)
        cache[key] = (packed, frames, frame_records(frames, real))
    return cache[key]


#: radii whose root tasks are kept per tape and precision
_ROOT_TASKS_KEPT = 4


def _root_tasks(tape, packed, frames, radius):
    """:func:`root_tasks`, kept per tape, precision and radius for the last few radii (a
    viewer or a benchmark samples one scene at one radius again and again; the tasks, their
    root cells and root tapes depend on nothing else).  Copies are returned: the driver
    uploads them and must not see a caller's edits."""
    cache = tape.__dict__.setdefault("_sampler_roots", {})
    key = (np.dtype(packed.real).str, float(radius))
    hit = cache.get(key)
    if hit is None:
        hit = root_tasks(tape, packed, frames, radius)
        if len(cache) >= _ROOT_TASKS_KEPT:
            cache.pop(next(iter(cache)))
        cache[key] = hit
    return tuple(a.copy() for a in hit)


def _machinery(ctx, packed, real, distortion, frames_rec, tasks, roots, radius, floor, capacity, expected,
               progress, max_levels, root_rows=None):
    """The program, buffers and driver of one run (:class:`_Subdivision`)."""
    defines = {"WORST_CASE_DISTORTION": 0 if distortion else 1, "TAPE_REGS": packed.n_regs, "SPLIT_AT": SPLIT_AT,
               "SPLIT_AT_Y": SPLIT_AT_Y,
               "QUAD_SPLIT_DIAG": QUAD_SPLIT_DIAG, "WORK_GROUP": WORK_GROUP, "HERE_DEPTH": SPLIT_HERE_DEPTH}
    prg = build(ctx, "sampling/sampler.cl", defines, real)
    sub = _Subdivision(ctx, prg, SceneBuffers(ctx, packed), frames_rec, tasks, roots, radius, floor, capacity,
                       expected, progress, max_levels, root_rows)
    return sub


def checked_radius(radius, floor) -> tuple:
    """(radius, floor) as floats, or :class:`UsageError` naming the bad one."""
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
    return radius, floor


def _guarded(sc, tape, radius, ctx, real, normal_form, term_limit, distortion, max_samples, max_memory):
    """The resource guard's estimate, checked against the limits before anything is allocated.
    The estimate bounds the area from above: before refusing, measure (a run whose estimate is
    small) and refuse only if the extrapolated real count does not fit."""
    limits = dict(max_samples=max_samples, max_memory=max_memory, source=sc.source)
    est = guard.estimate_tape(tape, radius, real.itemsize)
    try:
        guard.check_estimate(est, ctx.info, **limits)
    except LimitError:
        r_probe = guard.probe_radius(est, guard.allowed_samples(est, ctx.info, max_samples=max_samples,
                                                                 max_memory=max_memory))
        if r_probe is None or not r_probe > radius:
            raise
        probe = sample(sc, r_probe, ctx, normal_form=normal_form, term_limit=term_limit, distortion=distortion,
                       progress=False, max_samples=max(4 * guard.PROBE_SAMPLES, 1e6))
        est = guard.check_estimate(guard.measured(est, len(probe), r_probe), ctx.info, **limits)
    return est


def _run_stats(sub, samples, ctx, timings) -> dict:
    """The statistics of a finished run: counts, per-level profiles, device, timings."""
    lv = sub.levels
    q = sub.totals["distance_queries"]
    return dict(
        samples=len(samples),
        clip_rows=int(len(samples.clip_ops)),
        clip_rows_written=int(sub.clip_used),
        clipped_samples=int(np.count_nonzero(samples.clip_count)),
        levels=len(lv),
        # every cell classified, the halves of cells split in place too (cells_per_level counts
        # the cells each level read from its buffer)
        cells=sum(sub.totals[k] for k in _OUTCOMES),
        cells_per_level=[v["cells"] for v in lv],
        tape_mean_per_level=[v["tape_mean"] for v in lv],
        tape_max_per_level=[v["tape_max"] for v in lv],
        arena_rows_per_level=[v["arena_rows"] for v in lv],
        leaf_distances_per_query=sub.totals["leaf_distances"] / q if q else 0.0,
        device=ctx.info.name,
        compute_units=ctx.info.compute_units,
        **timings,
    )


def scene_context(device):
    if device is not None and hasattr(device, "ctx"):
        return device
    return _device.get_context(device)


def _empty(radius, tape, packed, stats) -> Samples:
    stats.update({k: 0 for k in _SUMMED})
    stats.update(samples=0, clip_rows=0, clip_rows_written=0, clipped_samples=0, levels=0, cells=0, cells_per_level=[],
                 total_s=0.0)
    return Samples.empty(radius, tape, packed, stats)


def _grow(cap, needed):
    return int(max(2 * cap, needed + needed // 2))


#: most levels launched one after another before their counters are read: a read is a round
#: trip to the device's threads (about 40 us of the 2-core CPU's time per level, 13 levels on
#: the lens)
CHAIN_LEVELS = 4
#: most levels of a chain after the first while progress is shown: the bar moves, and its ETA
#: is forecast, once per chain, and a run long enough to watch has few levels after its first
#: chain (the lens at 0.03% of the diagonal, 0.4 s: two chains gave no ETA in the second half
#: of the run); a counter read costs about 0.1 ms
SHOWN_CHAIN_LEVELS = 1
#: the clip rows per cell a chain is given room for, over the most a level wrote lately
CLIP_MARGIN = 2
#: clip rows written so far up to which the clip buffer is grown for a whole chain (a copy of
#: them is cheap); past them a chain that does not fit is shortened
CLIP_CHEAP_ROWS = 1 << 20
#: a chain's later levels may write more than its first (up to MAX_CHILDREN times as many cells
#: per level): cell buffers and arenas are grown to their worst case up to these sizes (cells,
#: tape rows); levels that could need more run one per read
CHAIN_CELLS = 1 << 17
CHAIN_ARENA_ROWS = 1 << 18
#: work-groups of a chained level per compute unit, at least: its cells are counted on the
#: device, so it is launched for as many as it could have (up to this), and the work-groups
#: loop over them
CHAIN_GROUPS_PER_CU = 8
#: work-groups of a launch at most (they loop over the level's cells): PoCL builds a second
#: variant of a kernel the first time a launch has 65,536 work-items or more (0.75 s of the
#: classify kernel's build, once per register count, in the middle of a run with a cold cache)
LAUNCH_GROUPS = 1023
#: work-groups of a launch per compute unit at most on a CPU device, where a work-group runs on
#: one thread from start to end: more only add their set-up and their atomics on the level's
#: counters, and a chained level (launched for the most cells it could have) gets many empty
#: ones.  At 4 per compute unit the lens and the Steinmetz solid at 1/150 of the diagonal take
#: 6-9% less wall time, the flange 3%, the drilled die and the bracket within the noise, and
#: the same CPU time; 8 gained less, 2 slowed the die.  A GPU keeps LAUNCH_GROUPS (it needs
#: the work-items in flight).
CPU_GROUPS_PER_CU = 4


def launch_groups(info) -> int:
    """The most work-groups a launch of the classify kernel gets on the device ``info``."""
    if info.type == "cpu":
        return max(1, min(LAUNCH_GROUPS, CPU_GROUPS_PER_CU * int(info.compute_units)))
    return LAUNCH_GROUPS


#: entries of the device's clip program table (``clip_table.h``): one per this many expected
#: samples, a power of two in [CLIP_TABLE_MIN, CLIP_TABLE_MAX] (the sponge at 0.1%: 3.06M
#: samples, about 17k distinct programs)
SAMPLES_PER_CLIP_ENTRY = 16
CLIP_TABLE_MIN, CLIP_TABLE_MAX = 1 << 10, 1 << 18


class _Side:
    """One side of the ping-pong: a cell buffer and a tape arena, and their capacities (cells,
    tape rows).  A level reads one side and writes the other."""

    __slots__ = ("cells", "cap_cells", "arena", "cap_arena")

    def __init__(self, cells, cap_cells, arena, cap_arena):
        self.cells, self.cap_cells, self.arena, self.cap_arena = cells, int(cap_cells), arena, int(cap_arena)


class _Subdivision:
    """The level loop: buffers, chains of levels, the overflow protocol, per-level statistics.

    Cells and tape arenas ping-pong between two sides (:class:`_Side`): level L reads its
    cells and their tapes from one side and writes its children and their tapes (exactly the
    rows pruning keeps) into the other, whose counters start at zero, so an arena holds the
    tapes of one level's live cells and never the tapes of cells already done.  A sample is
    finished as it is emitted (``finish.h``) into the sample columns; its clip program goes to
    the clip buffer, whose rows are kept across levels.  A program that an earlier launch
    stored is not written again (a table of the run's programs, ``clip_table.h``, zeroed at the
    start and before a level runs again); equal programs still stored twice are merged at the
    end (:func:`dedupe_programs`).

    A work-item also classifies the halves of the small cells it splits in place (up to
    :data:`SPLIT_HERE_DEPTH` at a time, ``sampler.cl``): they never reach a buffer, so the
    bounds below, which count the cells a level writes, hold as they are; their outcomes are
    counted with the level's, and ``split_in_place`` counts such splits.

    Levels run in chains of up to :data:`CHAIN_LEVELS`, launched one after another, and their
    counters are read once per chain (``sampler.cl``).  Buffers are sized before a chain to
    what its levels can write at most, so a level runs once: a cell has at most
    :data:`MAX_CHILDREN` children, and a split writes its children's tape (at most its cell's
    rows + 1, ``tape_prune_rows``) once per two children, so the children's tapes take at most
    2 ((the rows of the level's cells' tapes) + (its cells)) rows; the rows of a level's cells
    are at most twice the rows the level before wrote (two cells to a tape).  The side a
    chain reads holds its first level's input and cannot be grown: a chain is as long as the
    worst case of its levels fits (growing the side it writes up to :data:`CHAIN_CELLS` /
    :data:`CHAIN_ARENA_ROWS`).  A bound past :data:`ARENA_BUDGET` of the device, and every
    buffer whose size the caller forces (``capacity``), is left to the overflow protocol: the
    levels after one that overran a buffer do nothing, the host sees the overrun in that
    level's counts, grows the buffer and runs it again; so are the samples and the clip
    programs, whose counts a level does not bound.
    """

    def __init__(self, ctx, prg, scene, frames_rec, tasks, roots, radius, floor, capacity, estimate, progress,
                 max_levels, root_rows=None):
        self.ctx, self.prg, self.scene = ctx, prg, scene
        self.real = np.dtype(scene.packed.real)
        self.radius, self.floor = radius, floor
        self.max_levels = max_levels
        self.frames = upload(ctx, frames_rec)
        self.tasks = upload(ctx, tasks)
        self.roots = roots
        # the arena starts with the root tapes (the full tape, then each quadric's)
        self.root_rows = scene.packed.tape if root_rows is None else root_rows
        self.cdt = cell_dtype(self.real)
        tape = scene.packed.tape
        cap = tuple(capacity or ())
        self.sized = {"cells": len(cap) < 1, "arena": len(cap) < 3, "clip": len(cap) < 4}
        self.cap_cells = max(2, int(cap[0])) if len(cap) > 0 else max(2 * len(roots), 4096)
        self.cap_samples = max(2, int(cap[1])) if len(cap) > 1 else max(int(2 * estimate), 4096)
        self.cap_arena = max(2, int(cap[2])) if len(cap) > 2 else max(8 * len(tape), 1 << 16)
        self.cap_clip = max(2, int(cap[3])) if len(cap) > 3 else max(int(estimate), 1 << 14)
        self.estimate = int(estimate)
        entries = max(CLIP_TABLE_MIN, min(CLIP_TABLE_MAX, self.estimate // SAMPLES_PER_CLIP_ENTRY))
        self.table_entries = 1 << (entries - 1).bit_length()
        self.launches = 0  # the run's launches so far (a launch's number tags what it publishes)
        self.clip_used = 0
        self.clip_per_cell = 0.0  # the most clip rows per cell a level wrote so far
        self.arena_budget = ARENA_BUDGET * min(ctx.info.max_mem_alloc, ctx.info.global_mem)
        self.max_groups = CHAIN_GROUPS_PER_CU * max(1, int(ctx.info.compute_units))
        self.launch_groups = launch_groups(ctx.info)
        self.zeroed = "oclgrind" in ctx.info.platform.lower()
        self.progress = _Progress(progress, estimate, roots, radius, max_levels, floor)
        self.levels = []
        self.chains = self.skipped = 0
        self.totals = {k: 0 for k in _SUMMED}
        self.grown = {"cells": 0, "samples": 0, "arena": 0, "clip": 0}
        self.arena_peak = 0
        # the events of host transfers not waited for yet: pyopencl waits for a transfer's
        # event when it is dropped (it holds the host array), a round trip to the device's
        # threads each (41-55 us of CPU time against 11 us kept); kept until the queue is
        # known to be done with them
        self.transfers = []
        self.gate = None

    def _buffer(self, nbytes, what):
        """A device buffer for a level's outputs (read by the next level).  On Oclgrind it is
        zeroed from host memory: its uninitialized-value checker only trusts host-initialized
        memory or bytes a kernel wrote, and a tape row's unused operand fields are never
        written (nor read for anything but copying the row).  Elsewhere zeroing would only cost
        time (a large arena is written through once per allocation)."""
        if not self.zeroed:
            return pool_of(self.ctx).take(nbytes, what)
        check_allocation(self.ctx, nbytes, what)
        return upload(self.ctx, np.zeros(max(int(nbytes), 16), dtype=np.uint8), writable=True, what=what)

    def _holding(self, records, capacity, what):
        """A buffer of ``capacity`` records (of ``records``' dtype) that starts with ``records``
        (from host memory in one piece where Oclgrind checks it, see :meth:`_buffer`)."""
        import pyopencl as cl

        capacity = max(int(capacity), len(records), 1)
        if self.zeroed:
            data = np.zeros(capacity, dtype=records.dtype)
            data[:len(records)] = records
            return upload(self.ctx, data, writable=True, what=what)
        buf = pool_of(self.ctx).take(capacity * records.dtype.itemsize, what)
        if len(records):
            self.transfers.append(cl.enqueue_copy(self.ctx.queue, buf, np.ascontiguousarray(records),
                                                  is_blocking=False, wait_for=self._behind_gate()))
        return buf

    def _replace(self, old, nbytes, what):
        """A new working buffer for ``old``, which goes back to the pool: the commands already
        enqueued on it run first (one in-order queue), and only later ones see its reuse."""
        if not self.zeroed:
            pool_of(self.ctx).give(old)
        return self._buffer(nbytes, what)

    def _grown_copy(self, old, used_bytes, new_bytes, what):
        """A larger buffer holding the first ``used_bytes`` of ``old`` (which goes back to the
        pool), copied on the device; on Oclgrind made from host memory (its
        uninitialized-value checker loses track of device-to-device copies)."""
        import pyopencl as cl

        if not self.zeroed:
            new = pool_of(self.ctx).take(new_bytes, what)
            if used_bytes:
                cl.enqueue_copy(self.ctx.queue, new, old, byte_count=int(used_bytes))
            pool_of(self.ctx).give(old)
            return new
        check_allocation(self.ctx, new_bytes, what)
        data = np.zeros(max(int(new_bytes), 16), dtype=np.uint8)
        if used_bytes:
            cl.enqueue_copy(self.ctx.queue, data[:used_bytes], old)
        return upload(self.ctx, data, writable=True)

    def _grow_side(self, side, cells, arena_rows):
        """Grow ``side`` (whose contents are dead) to ``cells`` cells and ``arena_rows`` tape rows
        where allowed (by half again at least)."""
        rows = self.scene.packed.tape.itemsize
        if self.sized["cells"] and cells > side.cap_cells:
            side.cap_cells = max(cells, side.cap_cells + side.cap_cells // 2)
            side.cells = self._replace(side.cells, side.cap_cells * self.cdt.itemsize, "cell")
        budget = self.arena_budget // rows
        if self.sized["arena"] and side.cap_arena < arena_rows <= budget:
            side.cap_arena = int(min(max(arena_rows, side.cap_arena + side.cap_arena // 2), budget))
            side.arena = self._replace(side.arena, side.cap_arena * rows, "tape arena")

    def _plan(self, n_in, n_samples, arena_bound, level) -> int:
        """Size the buffers for the next chain and return its length.  The j-th level from now
        (0-based) has at most MAX_CHILDREN^j ``n_in`` cells and writes at most its arena bound.
        The output side, whose contents are dead, is grown for the first level and, within the
        chain budgets, for the levels after it (it is written by this chain's even levels, and
        read by the next chain, whose second level writes it again); the input side holds the
        first level's input, so an odd level is chained only if it fits there.  The clip
        buffer, which nothing bounds, is sized by :meth:`_plan_clip`, which may shorten the
        chain."""
        rows = self.scene.packed.tape.itemsize
        cells_budget = CHAIN_CELLS if self.sized["cells"] else 0
        arena_budget = min(CHAIN_ARENA_ROWS, self.arena_budget // rows) if self.sized["arena"] else 0
        cells, arenas = [MAX_CHILDREN * n_in], [arena_bound]
        for _ in range(CHAIN_LEVELS):
            cells.append(MAX_CHILDREN * cells[-1])
            arenas.append(2 * (2 * arenas[-1] + cells[-2]))
        self._grow_side(self.out, max([cells[0]] + [c for c in cells if c <= cells_budget]),
                        max([arenas[0]] + [a for a in arenas if a <= arena_budget]))
        longest = CHAIN_LEVELS if level == 0 or not self.progress.visible else SHOWN_CHAIN_LEVELS
        k_max = max(1, min(longest, self.max_levels - level))
        k = 1
        while k < k_max:
            side = self.src if k % 2 else self.out
            if cells[k] > side.cap_cells or arenas[k] > side.cap_arena:
                break
            k += 1
        return self._plan_clip(n_in, n_samples, k)

    def _plan_clip(self, n_in, n_samples, k) -> int:
        """The clip buffer for a chain of ``k`` levels on ``n_in`` cells (``_plan``), and the
        chain's length that fits it.  A chain is to have room for CLIP_MARGIN times the most
        clip rows per cell a level wrote so far, for its levels' cells (doubling per level).
        The most of the run, not of the last chain: the rate jumps where cells start to be
        filled (the flange at 1/150: 1.3 rows per cell at level 5, 1.0 at level 6, 2.2 at
        level 7, which ran twice).  While the rows written are few (CLIP_CHEAP_ROWS) the buffer is grown for
        the whole chain; past them the chain is shortened to what fits, and only a single
        level that does not fit grows it (a level run again costs more than memory, but
        growing it for a chain of 15k cells copied the sponge's 14M rows at 0.1% into a new
        buffer, 0.1-0.4 s).  Once samples were written, it is also grown to hold
        CLIP_MARGIN times their clip rows per sample for the samples still expected (at most
        the arena budget): early, while the rows to copy are few (the sponge at 1% wrote 12
        rows per sample for the 1,858 samples of its first level of samples and 17 for the
        22,437 of the next, which ran twice when the room was the rows per cell)."""
        rows = self.scene.packed.tape.itemsize

        def need(k):  # the cells of a chain's levels double (not the worst case, four times)
            return self.clip_used + int(CLIP_MARGIN * self.clip_per_cell * n_in * (2 ** k - 1))

        want = need(k) if self.clip_used <= CLIP_CHEAP_ROWS else need(1)
        if n_samples and self.clip_used:
            per_sample = self.clip_used / n_samples
            expected = self.clip_used + int(CLIP_MARGIN * per_sample * max(0, self.estimate - n_samples))
            want = max(want, min(expected, self.arena_budget // rows))
        if self.sized["clip"] and want > self.cap_clip:
            new_cap = max(want, 2 * self.cap_clip)
            self.clip = self._grown_copy(self.clip, self.clip_used * rows, new_cap * rows, "clip")
            self.cap_clip = new_cap
        while k > 1 and need(k) > self.cap_clip:  # a shorter chain, not a copy of many clip rows
            k -= 1
        return k

    def _zeroed_table(self, old=None):
        """The clip program table with every entry empty: ``old`` zeroed, or a new one (on
        Oclgrind a new one from host memory, see :meth:`_buffer`)."""
        import pyopencl as cl

        nbytes = 4 * CLIP_ENTRY_WORDS * self.table_entries
        if self.zeroed:
            words = np.zeros(CLIP_ENTRY_WORDS * self.table_entries, dtype=np.uint32)
            return upload(self.ctx, words, writable=True, what="clip table")
        table = old if old is not None else pool_of(self.ctx).take(nbytes, "clip table")
        cl.enqueue_fill_buffer(self.ctx.queue, table, np.uint32(0), 0, nbytes, wait_for=self._behind_gate())
        return table

    def _behind_gate(self):
        """The events a transfer enqueued before a chain waits for: the gate its first launch
        also waits for (:meth:`_chain`), made here if there is none, so that the device's
        threads are woken once for all of them (woken for each, a call on a few cells took 7%
        more CPU time).  None on Oclgrind."""
        import pyopencl as cl

        if self.gate is None and not self.zeroed:
            self.gate = cl.UserEvent(self.ctx.ctx)
        return [self.gate] if self.gate is not None else None

    def _open_gate(self):
        """Let the commands behind the gate run (before anything waits for them)."""
        import pyopencl as cl

        if self.gate is not None:
            self.gate.set_status(cl.command_execution_status.COMPLETE)
            self.gate = None

    def _chain(self, kernel, n_in, n_samples, k):
        """Launch ``k`` levels, the first on ``n_in`` cells of the input side, and read their
        counters: a (k + 1, counters) array, row 0 the seed (``sampler.cl``)."""
        import pyopencl as cl

        counters = np.zeros((k + 1, len(SAMPLER_COUNTERS)), dtype=np.uint32)
        counters[0, _SLOT["cells"]] = n_in
        counters[0, _SLOT["samples"]] = n_samples
        counters[0, _SLOT["clip_rows"]] = self.clip_used
        # a fresh buffer from host memory each chain (Oclgrind's uninitialized-value checker
        # does not see host writes into an existing buffer)
        counters_buf = upload(self.ctx, counters, writable=True)
        src, out = self.src, self.out
        most = n_in
        # the first launch waits for the gate, opened once all are enqueued: enqueued while
        # the device's threads run the level before, a launch took twice the CPU (the lens:
        # 24 us, 13 us behind the gate)
        gate = self.gate if self.gate is not None else cl.UserEvent(self.ctx.ctx)
        self.gate = None
        try:
            for row in range(1, k + 1):
                self.launches += 1
                groups = -(-most // WORK_GROUP)
                if row > 1:
                    groups = min(groups, max(self.max_groups, -(-n_in // WORK_GROUP)))
                groups = max(1, min(groups, self.launch_groups))
                size = (groups * WORK_GROUP,), (WORK_GROUP,)
                if row == 1:
                    launch(kernel, self.ctx.queue, *size,
                           self.scene.quadrics, self.frames, self.tasks, src.cells, np.uint32(src.cap_cells),
                           out.cells, np.uint32(out.cap_cells), *self.samples.args(), src.arena,
                           np.uint32(src.cap_arena), out.arena, np.uint32(out.cap_arena), counters_buf, np.int32(row),
                           self.real.type(self.radius), self.real.type(self.floor), self.clip, np.uint32(self.cap_clip),
                           self.table, np.uint32(self.table_entries - 1), np.uint32(self.launches),
                           *self.scene.colour_args(), wait_for=[gate])
                else:  # the sides swapped, the next row and launch; nothing grows within a chain
                    relaunch(kernel, self.ctx.queue, *size, {
                        _ARG_CELLS_IN: src.cells, _ARG_CELLS_IN + 1: np.uint32(src.cap_cells),
                        _ARG_CELLS_OUT: out.cells, _ARG_CELLS_OUT + 1: np.uint32(out.cap_cells),
                        _ARG_ARENA_IN: src.arena, _ARG_ARENA_IN + 1: np.uint32(src.cap_arena),
                        _ARG_ARENA_OUT: out.arena, _ARG_ARENA_OUT + 1: np.uint32(out.cap_arena),
                        _ARG_ROW: np.int32(row), _ARG_LAUNCH: np.uint32(self.launches)})
                src, out = out, src
                most = min(MAX_CHILDREN * most, src.cap_cells)
        finally:
            gate.set_status(cl.command_execution_status.COMPLETE)
        self.chains += 1
        cl.enqueue_copy(self.ctx.queue, counters, counters_buf)
        return counters

    def _first_launch(self, kernel):
        """Launch ``kernel`` once on no cells and wait, then restart the progress clock: PoCL
        builds (or loads from its cache) the kernel's code at its first launch in a process,
        up to 0.9 s on a cold cache, which the forecast would take for the first level's cost
        per cell (the ETA 10^4x off on the first run after an install)."""
        import pyopencl as cl

        counters = np.zeros((2, len(SAMPLER_COUNTERS)), dtype=np.uint32)
        counters_buf = upload(self.ctx, counters, writable=True)
        src, out = self.src, self.out
        launch(kernel, self.ctx.queue, (WORK_GROUP,), (WORK_GROUP,),
               self.scene.quadrics, self.frames, self.tasks, src.cells, np.uint32(src.cap_cells), out.cells,
               np.uint32(out.cap_cells),
               *self.samples.args(), src.arena, np.uint32(src.cap_arena), out.arena, np.uint32(out.cap_arena),
               counters_buf, np.int32(1), self.real.type(self.radius), self.real.type(self.floor), self.clip,
               np.uint32(self.cap_clip), self.table, np.uint32(self.table_entries - 1), np.uint32(0),
               *self.scene.colour_args())
        cl.enqueue_copy(self.ctx.queue, counters, counters_buf)
        kernel._clcsg_launched = True
        self.progress.restart()

    def _overran(self, c, n_samples, n_in) -> bool:
        """Grow every buffer a level's counters ``c`` show it overran (keeping what the levels
        before wrote: ``n_samples`` samples, ``self.clip_used`` clip rows); True if any was.
        A level that overran the samples or the clip rows stopped taking cells (its
        work-groups that started after skipped theirs): what it wrote is scaled by its
        ``n_in`` cells over those it classified (a level of the sponge ran four times, the
        buffer doubled each time, when grown by what the counts said)."""
        out = self.out
        cells_over = c[_SLOT["cells"]] > out.cap_cells
        samples_over = n_samples + c[_SLOT["samples"]] > self.cap_samples
        arena_over = c[_SLOT["arena"]] > out.cap_arena
        clip_over = self.clip_used + c[_SLOT["clip_rows"]] > self.cap_clip
        if not (cells_over or samples_over or arena_over or clip_over or c[_SLOT["status"]]):
            return False
        rows = self.scene.packed.tape.itemsize
        over = False
        done = sum(_outcome_counts(c))
        done -= 2 * int(c[_SLOT["split_in_place"]])  # the halves of cells split in place
        scale = max(1.0, n_in / max(done, 1))
        if cells_over:
            out.cap_cells = _grow(out.cap_cells, int(c[_SLOT["cells"]]))
            out.cells = self._replace(out.cells, out.cap_cells * self.cdt.itemsize, "cell")
            self.grown["cells"] += 1
            over = True
        if samples_over:
            self.cap_samples = _grow(self.cap_samples, n_samples + int(scale * int(c[_SLOT["samples"]])))
            self.samples.grow(n_samples, self.cap_samples)
            self.grown["samples"] += 1
            over = True
        if arena_over:
            out.cap_arena = _grow(out.cap_arena, int(c[_SLOT["arena"]]))
            out.arena = self._replace(out.arena, out.cap_arena * rows, "tape arena")
            self.grown["arena"] += 1
            over = True
        if clip_over:
            new_cap = _grow(self.cap_clip, self.clip_used + int(scale * int(c[_SLOT["clip_rows"]])))
            self.clip = self._grown_copy(self.clip, self.clip_used * rows, new_cap * rows, "clip")
            self.cap_clip = new_cap
            self.grown["clip"] += 1
            over = True
        if not over and c[_SLOT["status"]]:
            raise RuntimeError("sampler: a level did nothing after one that overran no buffer")
        return over

    def _start(self):
        """The first level's buffers: the input side with the root cells and the root tapes,
        the output side, the samples and the clip rows; returns level 1's arena bound.  Sized
        arenas hold the default capacity, or exactly what level 1 reads and writes at most where
        that is more (a scene of thousands of primitives has long root tapes).

        Sized sides start with the chain budgets (:data:`CHAIN_CELLS` cells,
        :data:`CHAIN_ARENA_ROWS` rows): the input side is written by every chain's even levels
        but cannot be grown while it holds a chain's input, so at the default capacity it cut
        the chains short (at 1/150 of the diagonal the zoo's models took 3, 5, 4, 5, 4 and 9
        chains, now 2, 4, 3, 4, 4 and 8).  Not on Oclgrind, where every buffer is uploaded from
        host memory (:meth:`_buffer`)."""
        tape = self.scene.packed.tape
        bound = 2 * (int(self.roots["tape_count"].sum()) + len(self.roots))
        if not self.zeroed and self.sized["arena"]:
            self.cap_arena = max(self.cap_arena, min(CHAIN_ARENA_ROWS, self.arena_budget // tape.itemsize))
        cap_in = max(self.cap_arena, len(self.root_rows))
        cap_out = self.cap_arena
        if self.sized["arena"] and bound <= self.arena_budget / tape.itemsize:
            cap_out = max(bound, cap_out)
        cap_cells = max(self.cap_cells, MAX_CHILDREN * len(self.roots)) if self.sized["cells"] else self.cap_cells
        if not self.zeroed and self.sized["cells"]:
            cap_cells = max(cap_cells, CHAIN_CELLS)
        self.src = _Side(self._holding(self.roots, cap_cells, "cell"), max(cap_cells, len(self.roots)),
                         self._holding(np.ascontiguousarray(self.root_rows, dtype=tape.dtype), cap_in, "tape arena"),
                         cap_in)
        self.out = _Side(self._buffer(cap_cells * self.cdt.itemsize, "cell"), cap_cells,
                         self._buffer(cap_out * tape.itemsize, "tape arena"), cap_out)
        self.samples = SampleColumns(self.ctx, self.real, self.cap_samples, self._buffer, on_device=not self.zeroed)
        self.clip = self._buffer(self.cap_clip * tape.itemsize, "clip")
        self.table = self._zeroed_table()
        return bound

    def _accept(self, level, c, n_in, n_samples):
        """Record level ``level``, which ran on ``n_in`` cells with counters ``c`` and fit, and
        swap the sides; returns its children and the samples so far."""
        n_cells_out = int(c[_SLOT["cells"]])
        n_samples_out = n_samples + int(c[_SLOT["samples"]])
        totals = self.totals
        for name, slot in _SUMMED_SLOTS:
            totals[name] += c[slot]
        arena_rows = int(c[_SLOT["arena"]])
        self.levels.append({
            "cells": n_in, "children": n_cells_out, "samples": n_samples_out - n_samples,
            "tape_mean": int(c[_SLOT["tape_rows"]]) / max(n_in, 1), "tape_max": int(c[_SLOT["tape_max"]]),
            "arena_rows": arena_rows,
        })
        self.arena_peak = max(self.arena_peak, arena_rows)
        self.clip_per_cell = max(self.clip_per_cell, int(c[_SLOT["clip_rows"]]) / max(n_in, 1))
        self.clip_used += int(c[_SLOT["clip_rows"]])
        self.src, self.out = self.out, self.src
        return n_cells_out, n_samples_out

    def run(self):
        """The levels, then the samples' and clip programs' reads (:attr:`raw`,
        :attr:`clip_rows`); the gate is open however it ends."""
        try:
            self._levels()
        finally:
            self._open_gate()

    def _levels(self):
        import pyopencl as cl

        arena_bound = self._start()
        kernel = program_kernel(self.prg, "classify")
        if not getattr(kernel, "_clcsg_launched", False):
            self._open_gate()
            self._first_launch(kernel)
        n_in, n_samples, level = len(self.roots), 0, 0
        while n_in > 0:
            if level >= self.max_levels:
                raise RuntimeError(f"sampler did not finish in {self.max_levels} levels ({n_in} cells left)")
            k = self._plan(n_in, n_samples, arena_bound, level)
            counters = self._chain(kernel, n_in, n_samples, k)
            self.transfers.clear()  # done: the counters were read after them on an in-order queue
            rows = counters.tolist()  # Python ints: a numpy scalar per counter read costs 10x more
            done = []
            for row in range(1, k + 1):
                c = rows[row]
                if self._overran(c, n_samples, n_in):
                    self.skipped += sum(r[_SLOT["status"]] for r in rows[row + 1:])
                    self.table = self._zeroed_table(self.table)  # its entries may name rows run again
                    break
                # the progress counts every cell the level classified: the halves of the cells
                # it split in place are the work the levels after it would have had
                cells = sum(_outcome_counts(c))
                n_in, n_samples = self._accept(level, c, n_in, n_samples)
                done.append((level, cells, n_samples, n_in))
                arena_bound = 2 * (2 * c[_SLOT["arena"]] + n_in)
                level += 1
                if n_in == 0 or level >= self.max_levels:
                    break
            if done:
                self.progress.chain(done)
        self.progress.done()
        self._open_gate()
        self.n_samples = n_samples
        # the reads are waited for at once (each blocking read is a round trip to the
        # device's threads)
        self.raw = self.samples.read(n_samples, self.transfers)
        self.clip_rows = np.zeros(self.clip_used, dtype=self.scene.packed.tape.dtype)
        if self.clip_used:
            self.transfers.append(cl.enqueue_copy(self.ctx.queue, self.clip_rows, self.clip, is_blocking=False))
        self.ctx.queue.finish()
        self.transfers.clear()
        self.totals["buffer_growths"] = {k: v for k, v in self.grown.items() if k != "clip"}
        self.totals["chains"] = self.chains
        self.totals["levels_skipped"] = self.skipped
        self.totals["arena_rows"] = self.arena_peak

    def collect(self, tape, radius) -> Samples:
        """The samples of the run as :class:`Samples` (equal clip programs stored once)."""
        packed = self.scene.packed
        raw = self.raw
        if not len(raw["pos"]):
            return Samples.empty(radius, tape, packed, {})
        clip_ops = self.clip_rows.view(np.int32).reshape(-1, 4)
        first, count, ops = dedupe_programs(clip_ops, raw["clip_first"], raw["clip_count"])
        positions = raw["pos"].astype(np.float64, copy=False)
        for k in range(3):  # by column: numpy broadcasts the (3,) origin row by row (4x slower)
            if packed.origin[k] != 0:  # a centred scene's (the lens: 0.1 ms of a 5 ms call)
                positions[:, k] += packed.origin[k]
        return Samples(
            positions=positions,
            normals=raw["normal"].astype(np.float64, copy=False),
            radii=raw["radius"].astype(np.float64, copy=False),
            quadrics=raw["quadric"],
            signs=raw["sign"],
            primitives=raw["primitive"],
            clip_first=first,
            clip_count=count,
            clip_ops=ops,
            radius=radius,
            tape=tape,
            packed=packed,
            stats={"finish_prune_evaluations": self.totals["finish_prune_evaluations"],
                   "clip_buffer_growths": self.grown["clip"]},
        )

    def release(self) -> None:
        """Hand the working buffers to the context's pool (all commands on them are done)."""
        if not self.zeroed:
            pool_of(self.ctx).give(self.src.cells, self.out.cells, self.src.arena, self.out.arena,
                                   *self.samples.buffers(), self.clip, self.table)


#: the share of the device's largest allocation (or global memory, if smaller) that a tape
#: arena may take when it is sized to its bound ahead of a level; a larger bound falls back to
#: the overflow protocol
ARENA_BUDGET = 1 / 8

#: the odd multipliers of :func:`program_keys`, one per 64-bit word of a program (grown on demand)
_KEY_MULTIPLIERS = np.zeros(0, dtype=np.uint64)


def program_keys(words: np.ndarray) -> np.ndarray:
    """A 64-bit key per program (rows of ``words``, uint64): sum_j w_j M_j mod 2^64 with fixed
    odd random multipliers M_j.  Equal programs have equal keys; :func:`dedupe_programs` checks
    the words of the programs that share one."""
    k = words.shape[1]
    _multipliers(k)
    h = words[:, 0] * _KEY_MULTIPLIERS[0]
    for j in range(1, k):
        h += words[:, j] * _KEY_MULTIPLIERS[j]
    return h


def program_keys_flat(words: np.ndarray, pos: np.ndarray, starts: np.ndarray) -> np.ndarray:
    """:func:`program_keys` of programs stored one after another: ``words`` (rows, 2) the 64-bit
    words of every program's rows, ``pos`` each row's place in its program, ``starts`` each
    program's first row.  The sum of the rows' terms w_j M_j per program (mod 2^64), with the
    multipliers of the words' places in the program, so a program gets the key
    :func:`program_keys` gives it."""
    _multipliers(2 * (int(pos.max()) + 1))
    h = words[:, 0] * _KEY_MULTIPLIERS[2 * pos] + words[:, 1] * _KEY_MULTIPLIERS[2 * pos + 1]
    return np.add.reduceat(h, starts)


#: distinct first rows up to which :func:`dedupe_programs` merges programs by their bytes in a
#: dict (the zoo at 1/150 of the diagonal: 10-60 programs, where dedupe_spans's twenty-odd
#: numpy passes cost the lens 0.2 ms of its 5.5 ms call)
FEW_PROGRAMS = 256


def dedupe_programs(rows, first, count):
    """Equal clip programs stored once: (first, count, rows) over a compact row buffer.

    Samples that share a program (a filled cell's samples take its program as it is; the device
    stores a program once where it can, ``clip_table.h``) share its first row: the programs are
    taken once per distinct first row (a scatter over the rows, no sort) and merged, by their
    bytes if they are few (:data:`FEW_PROGRAMS`), else by :func:`dedupe_spans`; rows that no
    sample names are dropped."""
    first = np.asarray(first)
    count = np.asarray(count)
    live = count > 0
    shared = first[live].astype(np.int64)
    at = np.zeros(len(rows) + 1, dtype=bool)
    at[shared] = True
    starts = np.flatnonzero(at)
    if len(starts) == len(shared) and len(starts) > FEW_PROGRAMS:
        return dedupe_spans(rows, first, count)
    rows_at = np.zeros(len(rows) + 1, dtype=np.int32)
    rows_at[shared] = count[live]
    if len(starts) <= FEW_PROGRAMS:
        new_at, out = _dedupe_few(rows, starts, rows_at[starts])
    else:
        new_at, _, out = dedupe_spans(rows, starts, rows_at[starts])
    moved = np.zeros(len(rows) + 1, dtype=np.int32)
    moved[starts] = new_at
    new_first = np.zeros(len(first), dtype=np.int32)
    new_first[live] = moved[shared]
    return new_first, count.astype(np.int32, copy=False), out


def _dedupe_few(rows, starts, counts):
    """(first row in the output of each program (``starts``, ``counts``), the output rows): the
    programs merged by their bytes, each distinct one stored once."""
    rows = np.ascontiguousarray(rows, dtype=np.int32)
    seen: dict = {}
    kept, used = [], 0
    new_at = np.empty(len(starts), dtype=np.int32)
    for i, (s, c) in enumerate(zip(starts.tolist(), counts.tolist())):
        key = rows[s:s + c].tobytes()
        at = seen.get(key)
        if at is None:
            seen[key] = at = used
            kept.append(rows[s:s + c])
            used += c
        new_at[i] = at
    return new_at, np.concatenate(kept) if kept else np.zeros((0, 4), dtype=np.int32)


def dedupe_spans(rows, first, count):
    """:func:`dedupe_programs` of programs (``first``, ``count``) over ``rows``, one per entry.

    Every program's rows are gathered as whole rows in one pass (a row's 16 bytes as one array
    element, which ``np.take`` copies three times faster than fancy indexing over columns),
    keyed (:func:`program_keys_flat`, the length folded in, 32 bits: :func:`_key32`), grouped
    by key and checked row for row (and for length) against the first program of their group;
    each group's rows are stored once.  If a key is shared by
    programs that differ, the programs are grouped length by length instead
    (:func:`dedupe_by_length`, which falls back to their bytes).  One pass over all lengths: the
    loop over lengths cost the gear 2.7 ms a call (21 lengths)."""
    first = np.asarray(first)
    count = np.asarray(count)
    rows = np.ascontiguousarray(rows, dtype=np.int32)
    live = np.flatnonzero(count > 0)
    if not len(live):
        return np.zeros_like(first, dtype=np.int32), count.astype(np.int32), np.zeros((0, 4), dtype=np.int32)
    as_elements = rows.view(np.complex128).ravel()  # only copied, never compared as numbers
    c = count[live].astype(np.int64)
    f = first[live].astype(np.int64)
    starts = np.cumsum(c) - c
    pos = np.arange(int(c.sum())) - np.repeat(starts, c)
    gathered = np.take(as_elements, np.repeat(f, c) + pos)
    words = gathered.view(np.uint64).reshape(-1, 2)
    k32 = _key32(program_keys_flat(words, pos, starts), c)
    # two stable sorts of 16-bit halves (numpy sorts those by radix: a tenth of a sort of
    # random 64-bit keys)
    order = np.argsort(k32.astype(np.uint16), kind="stable")
    order = order[np.argsort((k32[order] >> 16).astype(np.uint16), kind="stable")]
    ranked = k32[order]
    new_group = np.concatenate([[True], ranked[1:] != ranked[:-1]])
    group = np.empty(len(live), dtype=np.int64)
    group[order] = np.cumsum(new_group) - 1
    rep = order[new_group]
    rep_rows = np.take(as_elements, np.repeat(f[rep[group]], c) + pos)
    if not (np.array_equal(c[rep[group]], c) and np.array_equal(rep_rows.view(np.uint64), words.ravel())):
        return dedupe_by_length(rows, first, count)  # a key collision
    rc = c[rep]
    out_starts = np.cumsum(rc) - rc
    out = np.take(as_elements, np.repeat(f[rep], rc) + np.arange(int(rc.sum())) - np.repeat(out_starts, rc))
    new_first = np.zeros(len(first), dtype=np.int32)
    new_first[live] = out_starts[group]
    return new_first, count.astype(np.int32), out.view(np.int32).reshape(-1, 4)


def _key32(keys: np.ndarray, lengths: np.ndarray) -> np.ndarray:
    """32-bit keys from 64-bit program keys and the programs' lengths (equal programs, equal
    keys; programs that share a key but differ are found by the check after grouping)."""
    k = keys ^ (lengths.astype(np.uint64) * np.uint64(0x9E3779B97F4A7C15))
    return (k >> np.uint64(32)).astype(np.uint32) ^ k.astype(np.uint32)


def _multipliers(k: int) -> None:
    """Grow the odd multipliers of :func:`program_keys` to at least ``k``."""
    global _KEY_MULTIPLIERS
    if len(_KEY_MULTIPLIERS) < k:
        _KEY_MULTIPLIERS = _splitmix64(np.arange(max(k, 2 * len(_KEY_MULTIPLIERS), 64), dtype=np.uint64)) | np.uint64(1)


def _splitmix64(i: np.ndarray) -> np.ndarray:
    """SplitMix64 of the integers ``i``: well-mixed 64-bit words, the same on every run (not
    numpy.random, whose import costs a short CLI run 5 ms)."""
    z = (i + np.uint64(1)) * np.uint64(0x9E3779B97F4A7C15)
    z = (z ^ (z >> np.uint64(30))) * np.uint64(0xBF58476D1CE4E5B9)
    z = (z ^ (z >> np.uint64(27))) * np.uint64(0x94D049BB133111EB)
    return z ^ (z >> np.uint64(31))


def dedupe_by_length(rows, first, count):
    """:func:`dedupe_programs` length by length: programs of one length are grouped by their
    64-bit keys (:func:`program_keys`: one sort of integers), and each checked against its
    group's first program; if a key is shared by programs that differ, that length is grouped
    by the programs' bytes instead (a void view of its rows, sorted as byte strings)."""
    first = first.copy()
    count = count.copy()
    rows = np.ascontiguousarray(rows, dtype=np.int32)
    as_elements = rows.view(np.complex128).ravel()  # only copied, never compared as numbers
    out = [np.zeros((0, 4), dtype=np.int32)]
    used = 0
    # the lengths in use from a bincount: np.unique of a plain array imports numpy.ma (about
    # 20 ms, a tenth of a small run's start)
    for c in np.flatnonzero(np.bincount(count[count > 0].astype(np.int64))):
        sel = np.flatnonzero(count == c)
        idx = first[sel, None] + np.arange(c)[None, :]
        progs = np.take(as_elements, idx).view(np.uint64).reshape(len(sel), 2 * int(c))
        keys = program_keys(progs)
        order = np.argsort(keys, kind="stable")
        ranked = keys[order]
        starts = np.concatenate([[True], ranked[1:] != ranked[:-1]])
        keep = order[starts]
        inverse = np.empty(len(sel), dtype=np.int64)
        inverse[order] = np.cumsum(starts) - 1
        if not np.array_equal(np.take(progs, keep[inverse], axis=0), progs):  # a key collision
            void = progs.view(np.dtype((np.void, progs.itemsize * progs.shape[1]))).ravel()
            _, keep, inverse = np.unique(void, return_index=True, return_inverse=True)
            inverse = np.asarray(inverse).reshape(-1)
        out.append(np.take(progs, keep, axis=0).view(np.int32).reshape(-1, 4))
        first[sel] = used + c * inverse
        used += len(keep) * c
    first[count == 0] = 0
    return first.astype(np.int32), count.astype(np.int32), np.concatenate(out).astype(np.int32)
