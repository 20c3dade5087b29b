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

The result is checked.  A triangle is bad if
* it is farther than the tolerance from its quadric (centroid and edge midpoints, along the
  gradient line), or one of its crease edges sags off both of its surfaces beyond it
  (:func:`_far_chords`) and its midpoint is not proven within the tolerance of the solid (the
  straddle test at the tolerance: inside and outside points that far round it);
* a vertex of it moved more than :data:`SHIFTED` tolerances in its solve and it is not within
  the tolerance of the solid itself (the straddle test, :func:`_near_solid`);
* it spans a sharp edge (not on a quadric all its vertices lie on) with a vertex more than
  :data:`SPAN_SLACK` tolerances off its quadric where the surfaces meet at more than
  :data:`SHARP_DEGREES`, or more than the tolerance off it.
Bad triangles mean that the facets met the wrong way round where surfaces graze (two cylinders
tangent along a line) or were too coarse for a curve.  Where the only faults are chords that
sag too far (off a curve or off the quadric), those edges are split at points solved onto it
(:mod:`.chord_splits`, up to :data:`SPLIT_PASSES` times).  Otherwise, or where a split is
refused, the curved instances round the bad triangles (planes are exact at any tolerance) are
faceted again at half their tolerance and the Booleans rerun, up to :data:`MAX_ROUNDS` times;
what remains is counted in the stats.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from functools import partial

import numpy as np

from ..compile.interpret import contains_around
from ..compile.root_tapes import local_instances, primitive_dag
from ..model.bvh import morton_order
from ..model.csg import DEFAULT_COLOR
from . import refine
from .chord_splits import edge_sides, edges_to_split, split_far
from .collapse import collapse_coincident
from .facets import KINDS
from .instance_booleans import boolean_mesh, common_frame, facets_of
from .owners import primitives_of, shared_nearest
from .planar import flat_quadrics
from .project import line_distance, line_steps, residuals
from .snap import fibonacci_directions, repair_off_surface, snap, straddles, vertex_sets

#: faceting rounds at most (each halves the tolerance of the instances of bad triangles)
MAX_ROUNDS = 5
#: a triangle across a sharp edge whose vertices all lie within this many tolerances of its
#: quadric spans a feature narrower than that (a fillet 0.01 mm off a face, a cone's end 0.01 mm
#: inside its bore): it is within the tolerance, counted (``spanning_triangles``), and faceting
#: finer is not tried for it (it would take rounds down to the feature's width)
SPAN_SLACK = 0.25
#: surfaces that meet at less than this angle (degrees) make no sharp edge
SHARP_DEGREES = 15.0
#: passes of local chord splits (:mod:`.chord_splits`) before the instances are faceted again
SPLIT_PASSES = 3
#: a vertex its solve moved farther than this many tolerances (farther than a point of the
#: facets lies from its own surface) has its triangles checked against the solid, not only
#: against their quadric
SHIFTED = 1.0
#: the radius (tolerances) and directions of that check
NEAR_REACH = 1.1
NEAR_DIRECTIONS = fibonacci_directions(64)
COARSE_DIRECTIONS = fibonacci_directions(12)


@dataclass
class SnappedMesh:
    """A round's mesh: vertices on their quadrics (``sets``), per triangle its quadric, primitive
    and colour (set on the final round), and whether it is bad (see the module docstring)."""

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


def contains_near(tape, x, eps: float, directions) -> np.ndarray:
    """The solid's membership at the points x_i + eps d_j as (N, k) bool
    (:func:`~clcsg.compile.interpret.contains_around`): per group of :data:`GROUP`
    neighbouring points (along a Morton curve) the tape pruned to what can matter in the
    group's box G grown by ``eps``
    (:class:`clcsg.compile.root_tapes.PrimitiveDag`: the instances whose boxes meet G and the
    half-spaces whose plane crosses it kept, the half-spaces that miss G false, the rest at
    their defaults), so that the work is local; a short tape runs whole."""
    n = len(x)
    dag = primitive_dag(tape)
    if dag is None or n <= GROUP or len(tape.ops) <= WHOLE_TAPE:
        step = max(1, CHUNK_ENTRIES // max(1, tape.n_quadrics * len(directions)))
        return np.concatenate([contains_around(tape.ops, tape.quadrics, x[a:a + step], eps, directions)
                               for a in range(0, n, step)]) if n else np.zeros((0, len(directions)), dtype=bool)
    order = morton_order(x)
    starts = np.arange(0, n, GROUP)
    glo = np.minimum.reduceat(x[order], starts, axis=0) - eps
    ghi = np.maximum.reduceat(x[order], starts, axis=0) + eps
    near, outside = local_instances(tape, glo, ghi)
    out = np.zeros((n, len(directions)), dtype=bool)
    for g, a in enumerate(starts):
        rows = order[a:a + GROUP]
        ops, regs = dag.pruned(frozenset(near[g]), outside[g], registers=tape.n_regs)
        if regs > tape.n_regs:
            ops = tape.ops
        out[rows] = contains_around(ops, tape.quadrics, x[rows], eps, directions)
    return out


#: points whose membership is evaluated on one pruned tape
GROUP = 64
#: a tape of at most this many rows is run whole over all the points (pruning would cost more)
WHOLE_TAPE = 512
#: leaf values (quadrics x points x directions) evaluated at once
CHUNK_ENTRIES = 1 << 21


def _near_solid(tape, vertices, triangles, tol) -> np.ndarray:
    """Per triangle whether its centroid and edge midpoints lie within about ``tol`` of the
    solid's surface: of :data:`NEAR_DIRECTIONS` points at :data:`NEAR_REACH` tolerances round
    each, some inside and some outside (the straddle test; a point at 0.97 tolerances from a
    flat face sees it in a cap of 28 degrees round the normal, which 64 directions, 25 degrees
    apart, hit).  Each distinct point is tested once, first with :data:`COARSE_DIRECTIONS`
    (most lie well within the tolerance, where a few directions find both sides)."""
    v = vertices[triangles]
    pts = np.concatenate([v.mean(axis=1), 0.5 * (v + np.roll(v, -1, axis=1)).reshape(-1, 3)])
    uniq, which = np.unique(pts, axis=0, return_inverse=True)
    near = partial(contains_near, tape)
    ok = straddles(uniq, near, NEAR_REACH * tol, COARSE_DIRECTIONS)
    rest = np.flatnonzero(~ok)
    ok[rest] = straddles(uniq[rest], near, NEAR_REACH * tol, NEAR_DIRECTIONS)
    ok = ok[which.ravel()]
    return ok[:len(v)] & ok[len(v):].reshape(-1, 3).all(axis=1)


def _on_surface(tape, tol, points) -> np.ndarray:
    """Per point whether the solid has points inside and outside within a quarter of ``tol``
    round it (the straddle test with :data:`COARSE_DIRECTIONS`): it lies on the surface."""
    return straddles(points, partial(contains_near, tape), 0.25 * tol, COARSE_DIRECTIONS)


def _foot_on_solid(tape, x, quads, tol) -> np.ndarray:
    """Per point of ``x`` whether one of its quadrics ``quads`` (N, 2) is met along its
    gradient line within ``tol`` (less :data:`FOOT_REACH` tolerances) at a point on the solid's
    surface (the straddle test that close round it): then ``x`` is within ``tol`` of the
    surface.  A rim chord lies the sag times cos(alpha) from a cone, a distance the straddle
    test at the whole tolerance only sees through a narrow cap of directions."""
    t, n = line_steps(tape.quadrics[quads], x)
    reach = FOOT_REACH * tol
    cand = np.argwhere(np.abs(t) <= tol - reach)
    out = np.zeros(len(x), dtype=bool)
    if len(cand):
        foot = x[cand[:, 0]] + t[cand[:, 0], cand[:, 1], None] * n[cand[:, 0], cand[:, 1]]
        on = straddles(foot, partial(contains_near, tape), reach, COARSE_DIRECTIONS)
        out[cand[on, 0]] = True
    return out


#: the straddle test's radius round a foot point (:func:`_foot_on_solid`), in tolerances
FOOT_REACH = 1e-3


def _far_chords(tape, vertices, edges, side, tol) -> np.ndarray:
    """Per edge whether it is a crease (``side``: the quadrics of its two triangles differ: the
    edge runs along their curve) whose midpoint is farther than ``tol`` from the curve, to
    first order: with signed distances d1, d2 to the two tangent planes and c the cosine
    between their normals, the distance to the planes' line is
    sqrt((d1^2 + d2^2 - 2 c d1 d2) / (1 - c^2)), with the angle taken as at least 30 degrees
    (where surfaces graze the line is ill-posed, and the facets' own check covers them).  A
    chord of a rim sags off both surfaces at once (a hole through a slope), so it can be
    farther from the solid than from either."""
    qa, qb = side[:, 0], side[:, 1]
    crease = np.flatnonzero((qa >= 0) & (qb >= 0) & (qa != qb))
    far_edge = np.zeros(len(edges), dtype=bool)
    if len(crease):
        mid = 0.5 * (vertices[edges[crease, 0]] + vertices[edges[crease, 1]])
        fa, ja = residuals(tape.quadrics[qa[crease]][:, None], mid)
        fb, jb = residuals(tape.quadrics[qb[crease]][:, None], mid)
        na, nb = np.linalg.norm(ja[:, 0], axis=1), np.linalg.norm(jb[:, 0], axis=1)
        with np.errstate(divide="ignore", invalid="ignore"):
            d1, d2 = fa[:, 0] / na, fb[:, 0] / nb
            c = np.einsum("ij,ij->i", ja[:, 0], jb[:, 0]) / (na * nb)
            s2 = np.maximum(1.0 - c * c, 0.25)  # below 30 degrees taken as 30: grazing surfaces
            dist = np.sqrt(np.maximum(d1 * d1 + d2 * d2 - 2.0 * c * d1 * d2, 0.0) / s2)
        far_edge[crease] = np.nan_to_num(dist, nan=0.0) > tol
    return far_edge


def _deviation(tape, vertices, triangles, quad) -> np.ndarray:
    """Per triangle the largest distance of its centroid and edge midpoints from its quadric
    along the gradient line (:func:`~.project.line_distance`; 0 for a triangle on none)."""
    out = np.zeros(len(triangles))
    on = np.flatnonzero(quad >= 0)
    v = vertices[triangles[on]]
    q = tape.quadrics[quad[on]][:, None]
    for p in (v.mean(axis=1), 0.5 * (v[:, 0] + v[:, 1]), 0.5 * (v[:, 1] + v[:, 2]), 0.5 * (v[:, 2] + v[:, 0])):
        out[on] = np.maximum(out[on], np.nan_to_num(line_distance(q, p), nan=np.inf))
    return out


def _one_round(tape, facets, frame, tol: float, stats: dict) -> SnappedMesh:
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
                       partial(contains_near, tape))
    kept[kept >= n_q] = -1
    m = refine.Surface(tape, verts, refine._compact(kept), got.triangles, np.where(tri_q < n_q, tri_q, -1), wide=True)
    timed(stats, "collapse", collapse_coincident, m, stats, False)
    used = np.zeros(len(m.vertices), dtype=bool)
    used[m.triangles] = True
    index = np.cumsum(used) - 1
    tri = index[m.triangles]
    quad = shared_nearest(tape, m.vertices[used], tri, m.sets[used], m.faces)
    stats.update(snap_fallbacks=int(fallbacks), reassigned_triangles=int((quad != m.faces).sum()), off_surface=off,
                 off_surface_repaired=fixed)
    mesh = SnappedMesh(m.vertices[used], tri, quad, None, None, m.sets[used], None)
    return _split_to_tolerance(tape, mesh, got.vertices[used], tol, stats)


def _split_to_tolerance(tape, mesh: SnappedMesh, before, tol: float, stats: dict) -> SnappedMesh:
    """``mesh`` checked, and where only chords sag too far, split locally
    (:mod:`.chord_splits`) and checked again, up to :data:`SPLIT_PASSES` times."""
    near_ok = np.ones(len(mesh.triangles), dtype=bool)
    fresh = near_ok.copy()
    for passes in range(SPLIT_PASSES + 1):
        edges, tri_edge, far_edge, off_quadric = timed(stats, "check", _check, tape, mesh, before, fresh, near_ok,
                                                        tol, stats)
        if not mesh.bad.any() or passes == SPLIT_PASSES or stats["spanning_wide_triangles"] or not near_ok.all():
            break
        want = edges_to_split(tape, mesh.vertices, mesh.triangles, mesh.quadric, tri_edge, far_edge, off_quadric, tol)
        got = timed(stats, "split", split_far, tape, mesh.vertices, mesh.triangles, mesh.sets, mesh.quadric, before,
                    edges, tri_edge, want, partial(contains_near, tape))
        if got is None:
            break
        stats["chord_splits"] = stats.get("chord_splits", 0) + int(want.sum())
        quad = shared_nearest(tape, got.vertices, got.triangles, got.sets, got.quadric)
        mesh = SnappedMesh(got.vertices, got.triangles, quad, None, None, got.sets, None)
        before, fresh, near_ok = got.before, got.fresh, near_ok[got.parent] | got.fresh
    return mesh


def _check(tape, mesh: SnappedMesh, before, fresh, near_ok, tol: float, stats: dict):
    """Sets ``mesh.bad`` (see the module docstring; the solid itself checked round the
    ``fresh`` triangles' vertices moved more than :data:`SHIFTED` tolerances from ``before``,
    ``near_ok`` updated in place); returns (edges, per triangle its edges, far crease edges,
    triangles off their quadric)."""
    v, t, quad = mesh.vertices, mesh.triangles, mesh.quadric
    edges, tri_edge = refine.edges_of(t)
    side = edge_sides(edges, tri_edge, quad)
    far_edge = _far_chords(tape, v, edges, side, tol)
    rows = np.flatnonzero(far_edge)
    if len(rows):  # far from the curve, but within the tolerance of the solid (a cone's rim): fine
        mid = 0.5 * (v[edges[rows, 0]] + v[edges[rows, 1]])
        near = _foot_on_solid(tape, mid, side[rows], tol)
        far_edge[rows[near]] = False
        rows, mid = rows[~near], mid[~near]
        far_edge[rows[straddles(mid, partial(contains_near, tape), tol, NEAR_DIRECTIONS)]] = False
    off_quadric = _deviation(tape, v, t, quad) > tol
    far = off_quadric | far_edge[tri_edge].any(axis=1)
    # a vertex moved far by its solve (a corner where two curves meet at a shallow angle) may
    # drag its triangles across a curve: those are checked against the solid itself
    shifted = np.linalg.norm(v - before, axis=1) > SHIFTED * tol
    check = np.flatnonzero(fresh & shifted[t].any(axis=1) & ~far)
    if len(check):
        near_ok[check] = _near_solid(tape, v, t[check], tol)
    stats["checked_triangles"] = stats.get("checked_triangles", 0) + int(len(check))
    spanning = (quad >= 0) & ~(mesh.sets[t] == quad[:, None, None]).any(axis=2).all(axis=1)
    wide = spanning.copy()
    rows = np.flatnonzero(spanning)
    if len(rows):
        wide[rows] = _spans_a_sharp_edge(tape, v, t[rows], quad[rows], mesh.sets, tol)
    mesh.bad = wide | far | ~near_ok
    stats.update(spanning_triangles=int(spanning.sum()), spanning_wide_triangles=int(wide.sum()),
                 far_triangles=int((far | ~near_ok).sum()))
    return edges, tri_edge, far_edge, off_quadric


def _spans_a_sharp_edge(tape, v, tri, quad, sets, tol: float) -> np.ndarray:
    """Per triangle spanning a sharp edge (its vertices share no quadric with it) whether that
    matters: a vertex more than the tolerance off the triangle's quadric, or more than
    :data:`SPAN_SLACK` tolerances off it where one of the vertex's own quadrics meets the
    triangle's at more than :data:`SHARP_DEGREES` (a narrower step is within the tolerance; a
    flatter crossing is no sharp edge: two cylinders tangent at a point of the tricylinder)."""
    out = np.zeros(len(tri), dtype=bool)
    cos_sharp = np.cos(np.radians(SHARP_DEGREES))
    for k in range(3):
        x = v[tri[:, k]]
        f, g = residuals(tape.quadrics[quad][:, None], x)
        g = g[:, 0]
        miss = np.abs(f[:, 0]) / np.linalg.norm(g, axis=1)
        out |= ~(miss <= tol)
        sharp = np.zeros(len(tri), dtype=bool)
        own = sets[tri[:, k]]
        for c in range(own.shape[1]):
            sel = np.flatnonzero((own[:, c] >= 0) & (miss > SPAN_SLACK * tol))
            if len(sel):
                _, h = residuals(tape.quadrics[own[sel, c]][:, None], x[sel])
                h = h[:, 0]
                cos = np.abs(np.einsum("ij,ij->i", g[sel], h))
                cos /= np.linalg.norm(g[sel], axis=1) * np.linalg.norm(h, axis=1)
                sharp[sel] |= ~(cos >= cos_sharp)
        out |= sharp & (miss > SPAN_SLACK * tol)
    return out


def _coloured(tape, got: SnappedMesh, tol: float, stats: dict) -> SnappedMesh:
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


def mesh_by_facets(shape, tape, tol: float, stats: dict) -> SnappedMesh:
    """The mesh of ``shape``'s solid (``tape``: its compiled tape) within ``tol`` (see the
    module docstring)."""
    tols = np.full(len(tape.instances), float(tol))
    owners = tape.owners()
    flat = set(flat_quadrics(tape.quadrics).tolist())
    rounds = 0
    frame = common_frame(shape, tape.instances)
    while True:
        facets = timed(stats, "facets", facets_of, tape, tols, frame, partial(_on_surface, tape, tol))
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
