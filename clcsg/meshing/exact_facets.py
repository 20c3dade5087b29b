"""Meshes from faceted primitives: manifold3d's Booleans, then vertices onto the exact surface.

1. :mod:`.facets`: each primitive instance as a closed mesh inscribed within its tolerance,
   every triangle tagged with the literal it lies on;
2. :mod:`.instance_booleans`: the solid from them by manifold3d's exact Booleans over the
   instance program; every triangle of the result keeps its instance and literal, so its
   quadric;
3. :mod:`.snap`: every vertex onto the quadrics of the triangles around it (the surface, an
   intersection curve, a corner); a vertex that lands beyond a corner, off the solid's
   surface, is moved onto the corner;
4. :mod:`.collapse`: zero-length edges (a corner reached from two vertices) collapsed;
5. per triangle its quadric (the nearest of those its vertices share), its primitive by the
   colour rule (:func:`.owners.primitives_of`: the first instance that bounds the solid
   there) and that primitive's colour.

The result is checked: a triangle farther than the tolerance from its quadric (centroid and
edge midpoints, to first order) or not on a quadric all its vertices lie on (spanning a sharp
edge) with a vertex more than :data:`SPAN_SLACK` tolerances off that quadric means that the
facets of the instances there met the wrong way round or missed a feature finer than them
(surfaces that graze: two cylinders tangent along a line).  Those instances are faceted again at half their tolerance and the Booleans
rerun, up to :data:`MAX_ROUNDS` times (the instances with a curved surface there: planes are
exact at any tolerance); what remains is counted in the stats.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from ..compile.interpret import contains
from ..compile.root_tapes import box_tapes
from ..model.csg import DEFAULT_COLOR
from . import refine
from .collapse import collapse_coincident
from .facets import KINDS
from .instance_booleans import boolean_mesh, common_frame, facets_of
from .owners import primitives_of, shared_nearest
from .planar import flat_quadrics
from .project import first_order_distance
from .snap import repair_off_surface, snap, vertex_sets

#: faceting rounds at most (each halves the tolerance of the instances of bad triangles)
MAX_ROUNDS = 5
#: a triangle across a sharp edge whose vertices all lie within this many tolerances of its
#: quadric spans a feature narrower than that (a fillet 0.01 mm off a face, a cone's end 0.01 mm
#: inside its bore): it is within the tolerance, counted (``spanning_triangles``), and faceting
#: finer is not tried for it (it would take rounds down to the feature's width)
SPAN_SLACK = 0.25


@dataclass
class Faceted:
    vertices: np.ndarray
    triangles: np.ndarray
    quadric: np.ndarray
    primitive: np.ndarray
    colors: np.ndarray
    sets: np.ndarray
    bad: np.ndarray  # per triangle: off its quadric by more than the tolerance, or spanning


def facetable(tape) -> bool:
    """Are all of ``tape``'s instances of a kind :mod:`.facets` builds?"""
    return all(inst.node.kind in KINDS for inst in tape.instances)


def timed(stats, stage, fn, *args):
    """``fn(*args)``, its process CPU time added to ``stats["stage_cpu_s"][stage]``."""
    t0 = time.process_time()
    out = fn(*args)
    stats["stage_cpu_s"][stage] = stats["stage_cpu_s"].get(stage, 0.0) + time.process_time() - t0
    return out


def _clip_planes(lo, hi) -> np.ndarray:
    """The planes of the clip box K as quadric matrices, in the order of its faces (+x, -x,
    +y, -y, +z, -z; solid x . n <= offset)."""
    out = np.zeros((6, 4, 4))
    for axis in range(3):
        for k, (sign, offset) in enumerate(((1.0, hi[axis]), (-1.0, -lo[axis]))):
            q = out[2 * axis + k]
            q[axis, 3] = q[3, axis] = 0.5 * sign
            q[3, 3] = -offset
    return out


def contains_around(tape, x, around) -> np.ndarray:
    """The solid's membership at ``around`` (N, k, 3), points near each of ``x`` (N, 3): the
    tape pruned per group of neighbouring points to the primitives whose boxes meet the group's
    (:func:`clcsg.compile.root_tapes.box_tapes`), so that the work is local, not the whole tape
    at every point."""
    n, k = around.shape[:2]
    lo, hi = around.min(axis=1), around.max(axis=1)
    group, tapes = box_tapes(tape, lo, hi, np.zeros(n, dtype=np.int64))
    out = np.zeros((n, k), dtype=bool)
    for g, ops in enumerate(tapes):
        rows = np.flatnonzero(group == g)
        if len(rows):
            out[rows] = contains(ops, tape.quadrics, around[rows].reshape(-1, 3)).reshape(len(rows), k)
    return out


def _deviation(tape, vertices, triangles, quad) -> np.ndarray:
    """Per triangle the largest first-order distance of its centroid and edge midpoints from
    its quadric (0 for a triangle on none)."""
    out = np.zeros(len(triangles))
    on = np.flatnonzero(quad >= 0)
    v = vertices[triangles[on]]
    q = tape.quadrics[quad[on]][:, None]
    for p in (v.mean(axis=1), 0.5 * (v[:, 0] + v[:, 1]), 0.5 * (v[:, 1] + v[:, 2]), 0.5 * (v[:, 2] + v[:, 0])):
        out[on] = np.maximum(out[on], np.nan_to_num(first_order_distance(q, p), nan=np.inf))
    return out


def _one_round(tape, facets, frame, tol: float, stats: dict) -> Faceted:
    got = timed(stats, "booleans", boolean_mesh, tape, facets, frame)
    n_inst, n_q = len(tape.instances), tape.n_quadrics
    table = np.full((n_inst + 1, 8), -1, dtype=np.int64)
    for inst in tape.instances:
        table[inst.index, :len(inst.literals)] = [q for q, _ in inst.literals]
    table[n_inst, :6] = n_q + np.arange(6)  # the clip box's planes, after the tape's quadrics
    tri_q = np.where(got.tag >= 0, table[got.instance, np.maximum(got.tag, 0)], -1)
    matrices = np.concatenate([tape.quadrics, _clip_planes(*got.clip)])
    sets = vertex_sets(len(got.vertices), got.triangles, tri_q)
    verts, kept, fallbacks = timed(stats, "snap", snap, got.vertices, sets, matrices, tol)
    off, fixed = timed(stats, "repair", repair_off_surface, verts, kept, got.triangles, matrices, tol,
                       lambda x, around: contains_around(tape, x, around))
    kept[kept >= n_q] = -1
    m = refine.Surface(tape, verts, refine._compact(kept), got.triangles, np.where(tri_q < n_q, tri_q, -1), wide=True)
    timed(stats, "collapse", collapse_coincident, m, stats, False)
    used = np.zeros(len(m.vertices), dtype=bool)
    used[m.triangles] = True
    index = np.cumsum(used) - 1
    quad = shared_nearest(tape, m.vertices, m.triangles, m.sets, m.faces)
    moved = np.flatnonzero(quad != m.faces)
    spanning = (quad >= 0) & ~(m.sets[m.triangles] == quad[:, None, None]).any(axis=2).all(axis=1)
    far = _deviation(tape, m.vertices, m.triangles, quad) > tol
    wide = spanning.copy()  # spanning a feature wider than SPAN_SLACK tolerances
    rows = np.flatnonzero(spanning)
    if len(rows):
        v = m.vertices[m.triangles[rows]]
        q = tape.quadrics[quad[rows]][:, None]
        miss = np.max([first_order_distance(q, v[:, k]) for k in range(3)], axis=0)
        wide[rows] = ~(miss <= SPAN_SLACK * tol)
    stats.update(snap_fallbacks=int(fallbacks), reassigned_triangles=int(len(moved)), off_surface=off,
                 off_surface_repaired=fixed, spanning_triangles=int(spanning.sum()),
                 spanning_wide_triangles=int(wide.sum()), far_triangles=int(far.sum()))
    return Faceted(m.vertices[used], index[m.triangles], quad, None, None, m.sets[used], wide | far)


def _coloured(tape, got: Faceted, tol: float, stats: dict) -> Faceted:
    """``got`` with each triangle's primitive (the colour rule) and colour."""
    prim = timed(stats, "owners", primitives_of, tape, got.quadric, got.vertices[got.triangles].mean(axis=1), tol)
    palette = np.array([inst.color for inst in tape.instances] + [DEFAULT_COLOR], dtype=np.float64)
    got.primitive = prim
    got.colors = palette[np.where(prim >= 0, prim, len(tape.instances))]
    return got


def _near_bad(tape, got, owners, flat, tol) -> np.ndarray:
    """The instances to facet finer: those with a curved quadric of a bad triangle or of its
    vertices as a literal, whose box (grown by the tolerance) holds the triangle's centroid
    (planes are exact at any tolerance)."""
    bad = np.flatnonzero(got.bad)
    centroid = got.vertices[got.triangles[bad]].mean(axis=1)
    quads = np.concatenate([got.quadric[bad, None], got.sets[got.triangles[bad]].reshape(len(bad), -1)], axis=1)
    out = set()
    for q in np.unique(quads[quads >= 0]).tolist():
        if q in flat:
            continue
        rows = (quads == q).any(axis=1)
        for i in owners[q]:
            box = tape.instances[i].box
            if box is None or i in out:
                continue
            if np.all((centroid[rows] >= box[0] - tol) & (centroid[rows] <= box[1] + tol), axis=1).any():
                out.add(i)
    return np.array(sorted(out), dtype=np.int64)


def mesh_by_facets(shape, tape, tol: float, stats: dict) -> Faceted:
    """The mesh of ``shape``'s solid (``tape``: its compiled tape) within ``tol`` (see the
    module docstring)."""
    tols = np.full(len(tape.instances), float(tol))
    owners = tape.owners()
    flat = set(flat_quadrics(tape.quadrics).tolist())
    rounds = 0
    frame = common_frame(shape, tape.instances)
    while True:
        facets = timed(stats, "facets", facets_of, tape, tols, frame)
        got = _one_round(tape, facets, frame[0], tol, stats)
        rounds += 1
        if not got.bad.any() or rounds >= MAX_ROUNDS:
            break
        finer = _near_bad(tape, got, owners, flat, tol)
        if not len(finer):
            break
        tols[finer] *= 0.5
    stats.update(method="facets", facet_rounds=rounds)
    return _coloured(tape, got, tol, stats)
