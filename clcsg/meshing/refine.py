"""Sharp features and chord error: splitting edges onto the exact surface, keeping the mesh
closed and manifold.

Every vertex knows the quadrics it lies on (one on a patch, two on an intersection curve,
three at a corner).  An edge is split at a new vertex when

* its ends share no quadric (it spans a sharp edge): the new vertex is the corner of the
  ends' three quadrics if Newton (:func:`~.project.newton`) finds one on the solid within
  reach, else the point where the intersection curve of one quadric of each end crosses the
  edge's plane (the plane through the edge that holds the mesh normal there: Newton on the two
  quadrics and that plane), the closest converged candidate on the solid's surface within
  :data:`REACH` edge lengths (a curve running almost along the edge, or the apex of a thin
  wedge, still crosses that plane near the edge); a curve point counts only where both its
  quadrics bound the solid (:func:`on_curve`), and where the ends' quadrics meet off the
  surface the edge goes through a third quadric (:func:`_through_third`);
* its ends share quadrics (it runs on a patch or along a curve) and its midpoint is farther
  than :data:`CHORD_FRACTION` of the tolerance from them (the chord error): the new vertex is
  the midpoint projected onto them, or onto the face's rim where that point is off the face
  (:func:`_onto_rim`).

Splits are keyed by edge, so both triangles of an edge split at the same vertex; a triangle
with one, two or three split edges becomes two, three or four (the red-green patterns), which
keeps the mesh conforming, closed and 2-manifold.  A triangle whose vertices pairwise share a
quadric but have none in common surrounds a corner: the corner of the three quadrics, solved
from its centroid, splits it in three.  After the splits every triangle lies on one quadric
(its vertices share it) unless Newton found no intersection near an edge (counted).
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass

import numpy as np

from ..compile.interpret import contains, member, member_per_point
from .project import first_order_distance, newton, residuals

#: an edge is split when its midpoint is farther than this fraction of the tolerance from its
#: quadric (a triangle's interior sags about 4/3 as far as its edges' midpoints)
CHORD_FRACTION = 0.7
#: rounds of splitting
MAX_PASSES = 16
#: edges shorter than this fraction of the tolerance are never split
MIN_EDGE = 1e-3
#: the probe distance of :func:`on_boundary`, relative to the coordinates' scale
PROBE = 1e-7
#: the probe distances of :func:`on_curve`: from this times the coordinates' scale, by factors
#: of :data:`CURVE_PROBE_STEP`, below :data:`CURVE_PROBE_MAX` times the scale and half the
#: tolerance.  Small: a quadric's extension a step below the tolerance away from its face (a
#: 0.01 rim where a cone stands on a cylinder) is no edge; the faces on both sides of the step
#: are found instead (:func:`_through_third`)
CURVE_PROBE = 1e-6
CURVE_PROBE_STEP = 10.0
CURVE_PROBE_MAX = 1e-4
#: (edge, quadric) pairs of :func:`_through_third` evaluated at a time
NEAR_ENTRIES = 1 << 20
#: two quadrics whose normals at a curve point make an angle with a sine below this touch
#: there (a fillet's cylinder tangent to a face): Newton's point is off the contact line by
#: about the square root of the rounding, so :func:`on_curve` probes the solid around it
#: (:func:`on_boundary`) instead of across a curve that is not there
TANGENT_SINE = 1e-3
#: a curve point up to this many edge lengths from the edge's midpoint may split it (a thin
#: wedge's apex projects beyond the chord that crosses it)
REACH = 3.0
#: a curve point this close to an edge's end (a fraction of the tolerance) moves that end
SNAP = 0.05


@dataclass
class Surface:
    """The mesh being refined: vertices, per vertex its quadrics (V, 3) -1 padded, triangles,
    and optionally per triangle a row of data that follows the triangles it belongs to when
    some are removed (:mod:`.collapse`); ``wide``: the sets may grow past three columns."""

    tape: object
    vertices: np.ndarray
    sets: np.ndarray
    triangles: np.ndarray
    faces: np.ndarray | None = None
    wide: bool = False


def edges_of(tri):
    """(edges (E, 2) sorted, per triangle the index of edge k = (v_k, v_k+1) (T, 3))."""
    a = tri
    b = np.roll(tri, -1, axis=1)
    n = np.int64(tri.max(initial=0) + 1)
    keys = (np.minimum(a, b).astype(np.int64) * n + np.maximum(a, b)).ravel()
    uniq, inv = np.unique(keys, return_inverse=True)
    return np.stack([uniq // n, uniq % n], axis=1), inv.reshape(-1, 3)


def common(sa, sb):
    """Per row the quadrics of set ``sa`` also in ``sb`` ((N, 3) -1 padded, in sa's order)."""
    hit = np.stack([(sa[:, i] == sb[:, 0]) | (sa[:, i] == sb[:, 1]) | (sa[:, i] == sb[:, 2]) for i in range(3)], 1)
    return np.where(hit & (sa >= 0), sa, -1)


def spanning(sets, triangles) -> np.ndarray:
    """Per triangle whether its vertices (quadric ``sets`` (V, 3), -1 padded) share no quadric:
    it spans a sharp edge."""
    s = sets[triangles]
    return ~(common(common(s[:, 0], s[:, 1]), s[:, 2]) >= 0).any(axis=1)


def _compact(sets):
    """Sets with their quadrics first and -1 after (stable)."""
    order = np.argsort(sets < 0, axis=1, kind="stable")
    return np.take_along_axis(sets, order, axis=1)


def _candidates(sa, sb):
    """Target quadric sets for edges spanning two patches: each pair (one quadric of each
    end) and, if the ends' union has three, their corner.  (edge row, set (3,) -1 padded)."""
    rows, sets = [], []
    for i, j in itertools.product(range(3), range(3)):
        ok = (sa[:, i] >= 0) & (sb[:, j] >= 0) & (sa[:, i] != sb[:, j])
        r = np.flatnonzero(ok)
        rows.append(r)
        sets.append(np.stack([sa[r, i], sb[r, j], np.full(len(r), -1)], axis=1))
    union = np.concatenate([sa, sb], axis=1)
    srt = np.sort(union, axis=1)
    distinct = np.where(np.diff(srt, axis=1, prepend=-1) != 0, srt, -1)
    distinct = np.where(distinct >= 0, distinct, -1)
    count = (distinct >= 0).sum(axis=1)
    r = np.flatnonzero(count == 3)
    rows.append(r)
    sets.append(np.sort(distinct[r], axis=1)[:, -3:])
    return np.concatenate(rows), np.concatenate(sets)


def _onto_rim(tape, tol, rows, sets, x, ok, mid, length):
    """Chord splits on one quadric whose midpoint, moved onto it, is off the solid's face on
    it (an edge along the face's rim, its ends just inside): the split goes onto the rim, the
    curve of that quadric and another near the midpoint (:func:`_through_third`'s candidates,
    Newton from the midpoint), the nearest on the surface within one edge length.  ``sets``,
    ``x`` and ``ok`` (rows of the chord edges) are updated in place."""
    if not len(rows):
        return
    none = np.full((len(rows), 3), -1)
    cand, csets = _through_third(tape, sets[rows], none, mid[rows], length[rows])
    cx, cok = _solve(tape, csets, mid[rows[cand]])
    dist = np.where(cok, np.linalg.norm(cx - mid[rows[cand]], axis=1), np.inf)
    dist[dist > length[rows[cand]]] = np.inf
    pick = _nearest_on_surface(tape, cand, len(rows), cx, csets, tol, dist)
    found = pick >= 0
    r = rows[found]
    x[r], sets[r], ok[r] = cx[pick[found]], csets[pick[found]], True


def _through_third(tape, sa, sb, mid, length):
    """Candidates for edges spanning two patches that no curve of theirs joins on the surface
    (their quadrics' own curve lies off the solid): the surface between the ends is on a third
    quadric C (the annulus on a plane between two near-parallel cones), so each curve of one
    end's quadric and a C whose first-order distance from the edge's middle is within one
    edge length.  (rows into the edges, sets (3,) -1 padded)."""
    quadrics = np.asarray(tape.quadrics)
    near = np.zeros((len(mid), len(quadrics)), dtype=bool)
    step = max(1, NEAR_ENTRIES // max(len(quadrics), 1))
    for s in range(0, len(mid), step):  # (rows, U, 4) values at a time: bounded memory
        f, j = residuals(quadrics[None], mid[s:s + step])
        with np.errstate(divide="ignore", invalid="ignore"):
            near[s:s + step] = np.abs(f) <= length[s:s + step, None] * np.linalg.norm(j, axis=2)
    ends = np.concatenate([sa, sb], axis=1)
    for k in range(6):
        valid = ends[:, k] >= 0
        near[np.flatnonzero(valid), ends[valid, k]] = False
    rows, third = np.nonzero(near)
    out_rows, out_sets = [], []
    for k in range(6):
        own = ends[rows, k]
        sel = own >= 0
        out_rows.append(rows[sel])
        out_sets.append(np.stack([own[sel], third[sel], np.full(sel.sum(), -1)], axis=1))
    return np.concatenate(out_rows), np.concatenate(out_sets)


def _nearest_on_surface(tape, rows, n, x, sets, tol, dist):
    """Per row (0..n-1) the candidate (index into ``x``, on the quadrics of ``sets``) of lowest
    ``dist`` among those with a finite ``dist`` that lie on the solid's surface through their
    quadrics (:func:`on_surface`, its probe radius from all of them), -1 if none.  The same
    pick as testing every candidate, but the surface test (the costly part) runs on each row's
    best remaining candidate only, round after round."""
    best = np.full(n, -1)
    alive = np.isfinite(dist)
    scale = max(1.0, float(np.abs(x[alive]).max())) if alive.any() else 1.0  # the probes' of all
    while alive.any():
        cand = np.flatnonzero(alive)
        order = cand[np.lexsort((dist[cand], rows[cand]))]
        first = np.ones(len(order), dtype=bool)
        first[1:] = rows[order][1:] != rows[order][:-1]
        pick = order[first]
        ok = on_surface(tape, x[pick], sets[pick], tol, scale)
        best[rows[pick[ok]]] = pick[ok]
        alive[pick] = False
        alive &= best[rows] < 0
    return best


def _solve(tape, sets, x0, planes=None):
    """Newton onto the quadrics of ``sets`` (N, 3) from ``x0``, grouped by how many there are.
    With ``planes`` (N, 4, 4), a point on two quadrics is also held to its row's plane (the
    curve's crossing with that plane, not the curve point nearest to ``x0``)."""
    x = np.full_like(x0, np.nan)
    ok = np.zeros(len(x0), dtype=bool)
    k = (sets >= 0).sum(axis=1)
    for n in (1, 2, 3):
        sel = np.flatnonzero(k == n)
        if len(sel):
            mats = tape.quadrics[sets[sel, :n]]
            if n == 2 and planes is not None:
                mats = np.concatenate([mats, planes[sel][:, None]], axis=1)
            x[sel], ok[sel] = newton(mats, x0[sel])
    return x, ok


def plane_matrix(normal, point):
    """The plane through ``point`` (N, 3) with ``normal`` (N, 3) as a quadric (N, 4, 4): its
    value at homogeneous x is n . x - n . p (the normal halved into the symmetric last row and
    column), its gradient n."""
    out = np.zeros((len(normal), 4, 4))
    out[:, :3, 3] = out[:, 3, :3] = 0.5 * normal
    out[:, 3, 3] = -np.einsum("ni,ni->n", normal, point)
    return out


def edge_planes(m, edges, tri_edge):
    """Per edge the plane through it that contains the mesh normal there (the sum of its two
    triangles' unit normals), as quadric matrices (E, 4, 4).  A sharp edge crossing the mesh
    edge crosses this plane near it, even when the curve runs almost along the edge."""
    v, t = m.vertices, m.triangles
    tn = np.cross(v[t[:, 1]] - v[t[:, 0]], v[t[:, 2]] - v[t[:, 0]])
    ln = np.linalg.norm(tn, axis=1, keepdims=True)
    tn = np.divide(tn, ln, out=np.zeros_like(tn), where=ln > 0)
    en = np.zeros((len(edges), 3))
    np.add.at(en, tri_edge.ravel(), np.repeat(tn, 3, axis=0))
    pn = np.cross(v[edges[:, 1]] - v[edges[:, 0]], en)
    ln = np.linalg.norm(pn, axis=1, keepdims=True)
    pn = np.divide(pn, ln, out=np.zeros_like(pn), where=ln > 0)
    return plane_matrix(pn, 0.5 * (v[edges[:, 0]] + v[edges[:, 1]]))


def _on_csg(tape, x, q):
    """Points on quadric ``q`` (N,) where the CSG surface is (the substituted sides differ)."""
    out = np.zeros(len(x), dtype=bool)
    for u in np.unique(q):
        sel = np.flatnonzero(q == u)
        neg, pos = member(tape.ops, tape.quadrics, x[sel], int(u))
        out[sel] = neg != pos
    return out


def _probe_directions(n: int = 64):
    """``n`` unit directions spread evenly over the sphere (a Fibonacci lattice, turned off
    the axes), so that a wedge of the solid as narrow as a box corner holds some of them and
    none lies on an axis-aligned face through the point."""
    k = np.arange(n) + 0.5
    z = 1.0 - 2.0 * k / n
    phi = k * np.pi * (3.0 - np.sqrt(5.0)) + 0.1234
    r = np.sqrt(1.0 - z * z)
    d = np.stack([r * np.cos(phi), r * np.sin(phi), z + 1e-3 * np.sin(7 * k)], axis=1)
    return d / np.linalg.norm(d, axis=1, keepdims=True)


PROBES = _probe_directions()


def straddles(tape, x, radius, directions) -> np.ndarray:
    """Points (N, 3) with some probes ``x + radius d`` inside the solid and some outside."""
    if not len(x):
        return np.zeros(0, dtype=bool)
    pts = (x[:, None, :] + radius * directions[None]).reshape(-1, 3)
    ins = contains(tape.ops, tape.quadrics, pts).reshape(len(x), -1)
    return ins.any(axis=1) & ~ins.all(axis=1)


def on_boundary(tape, x, scale=None) -> np.ndarray:
    """Points (N, 3) on the solid's boundary to rounding: among the points at distance
    :data:`PROBE` x scale (:func:`_probe_directions`) some are inside and some outside, and
    likewise at 100 times that distance.  Used for points on curves and corners, where
    substituting one quadric is ambiguous.  Every fourth direction first: the points those
    already decide (most: an edge's wedge is wide) need no others, so the answer is that of
    all directions at a quarter of the evaluations."""
    if not len(x):
        return np.zeros(0, dtype=bool)
    scale = max(1.0, float(np.abs(x).max())) if scale is None else scale
    out = np.ones(len(x), dtype=bool)
    for r in (PROBE, 100 * PROBE):  # two radii: a rounding-level disagreement of one probe is not enough
        sel = np.flatnonzero(out)
        got = straddles(tape, x[sel], r * scale, PROBES[::4])
        rest = sel[~got]
        if len(rest):
            out[rest] = straddles(tape, x[rest], r * scale, PROBES)
    return out


def on_curve(tape, x, qa, qb, tol, scale=None) -> np.ndarray:
    """Points ``x`` (N, 3) on the intersection curve of quadrics ``qa`` and ``qb`` (N,) where
    both bound the solid: for each of the two, on one side of the curve within its tangent
    plane (direction d = t x n, t = n_a x n_b the curve's tangent) switching its membership
    switches the solid's (the quadric substituted at x + r d or x - r d).  A curve point where
    one of them does not bound the solid (a quadric's extension beyond the face it contributes,
    inside or outside the solid) is no sharp edge of it, though :func:`on_boundary` holds there
    through the other quadric.  Probed at r from :data:`CURVE_PROBE` x scale up (below half the
    tolerance ``tol``), the smallest first, so that a corner close by does not hide the edge."""
    n = len(x)
    if not n:
        return np.zeros(0, dtype=bool)
    scale = max(1.0, float(np.abs(x).max())) if scale is None else scale
    _, j = residuals(tape.quadrics[np.stack([qa, qb], axis=1)], x)  # (N, 2, 3) gradients
    t = np.cross(j[:, 0], j[:, 1])
    radii = [CURVE_PROBE * scale]
    while radii[-1] * CURVE_PROBE_STEP < min(0.5 * tol, CURVE_PROBE_MAX * scale):
        radii.append(radii[-1] * CURVE_PROBE_STEP)
    g = np.linalg.norm(j, axis=2)
    tangent = np.linalg.norm(t, axis=1) <= TANGENT_SINE * g[:, 0] * g[:, 1]  # no side within the tangent planes
    bounds = np.zeros((n, 2), dtype=bool)
    bounds[tangent] = on_boundary(tape, x[tangent], scale)[:, None]
    for k, q in enumerate((qa, qb)):
        d = np.cross(t, j[:, k])
        ln = np.linalg.norm(d, axis=1, keepdims=True)
        d = np.divide(d, ln, out=np.zeros_like(d), where=ln > 0)
        for r in radii:
            sel = np.flatnonzero(~bounds[:, k] & ~tangent)
            if not len(sel):
                break
            probes = np.concatenate([x[sel] + r * d[sel], x[sel] - r * d[sel]])
            neg, pos = member_per_point(tape.ops, tape.quadrics, probes, np.concatenate([q[sel], q[sel]]))
            switch = (neg != pos).reshape(2, -1).any(axis=0)
            bounds[sel[switch], k] = True
    return bounds.all(axis=1)


def on_surface(tape, x, sets, tol, scale=None) -> np.ndarray:
    """Points ``x`` (N, 3) on the quadrics of ``sets`` (N, 3), -1 padded, that lie on the
    solid's surface through them: on one quadric, its substituted sides differ; on two, both
    bound the solid (:func:`on_curve`); at a corner of three, :func:`on_boundary`."""
    out = np.zeros(len(x), dtype=bool)
    k = (sets >= 0).sum(axis=1)
    one, two, three = (np.flatnonzero(k == c) for c in (1, 2, 3))
    out[one] = _on_csg(tape, x[one], sets[one, 0])
    out[two] = on_curve(tape, x[two], sets[two, 0], sets[two, 1], tol, scale)
    out[three] = on_boundary(tape, x[three], scale)
    return out


def _edge_splits(m, tol, edges, tri_edge):
    """New vertices for the edges to split: (edge indices, points, sets), plus the count of
    edges that needed a split but got none."""
    v, s = m.vertices, m.sets
    a, b = edges[:, 0], edges[:, 1]
    mid = 0.5 * (v[a] + v[b])
    length = np.linalg.norm(v[a] - v[b], axis=1)
    shared = _compact(common(s[a], s[b]))
    n_shared = (shared >= 0).sum(axis=1)
    shared[:, 2] = -1  # a curve at most: two shared quadrics
    long_enough = length > MIN_EDGE * tol
    chord = np.flatnonzero((n_shared > 0) & long_enough)
    err = first_order_distance(m.tape.quadrics[np.where(shared[chord] >= 0, shared[chord], shared[chord, :1])], mid[chord])
    chord = chord[err > CHORD_FRACTION * tol]
    cx, cok = _solve(m.tape, shared[chord], mid[chord])
    cok &= np.linalg.norm(cx - mid[chord], axis=1) <= length[chord]
    single = (shared[chord, 1] < 0) & cok
    if single.any():
        cok[single] = _on_csg(m.tape, cx[single], shared[chord[single], 0])
    curve = ~single & cok
    cok[curve] = on_curve(m.tape, cx[curve], shared[chord[curve], 0], shared[chord[curve], 1], tol)
    cset = shared[chord].copy()
    _onto_rim(m.tape, tol, np.flatnonzero((shared[chord, 1] < 0) & ~cok), cset, cx, cok, mid[chord], length[chord])
    span = np.flatnonzero((n_shared == 0) & long_enough)
    planes = edge_planes(m, edges, tri_edge)[span]
    rows, sets = _candidates(s[a[span]], s[b[span]])
    sx, sok = _solve(m.tape, sets, mid[span[rows]], planes[rows])
    dist = np.where(sok, np.linalg.norm(sx - mid[span[rows]], axis=1), np.inf)
    dist[dist > REACH * length[span[rows]]] = np.inf
    # a corner on the surface ends the edge's chain of splits: the only choice where there is
    # one; where the three quadrics meet off the surface or not at all, a curve of two
    corner = sets[:, 2] >= 0
    best = _nearest_on_surface(m.tape, rows, len(span), sx, sets, tol, np.where(corner, dist, np.inf))
    rest = (best[rows] < 0) & ~corner
    if rest.any():
        best_pair = _nearest_on_surface(m.tape, rows, len(span), sx, sets, tol, np.where(rest, dist, np.inf))
        best = np.where(best >= 0, best, best_pair)
    lost = np.flatnonzero(best < 0)
    if len(lost):
        rows3, sets3 = _through_third(m.tape, s[a[span[lost]]], s[b[span[lost]]], mid[span[lost]], length[span[lost]])
        r3 = lost[rows3]
        x3, ok3 = _solve(m.tape, sets3, mid[span[r3]], planes[r3])
        d3 = np.where(ok3, np.linalg.norm(x3 - mid[span[r3]], axis=1), np.inf)
        d3[d3 > length[span[r3]]] = np.inf  # between the ends: a curve farther off is another edge's
        pick = _nearest_on_surface(m.tape, np.searchsorted(lost, r3), len(lost), x3, sets3, tol, d3)
        found = pick >= 0
        best[lost[found]] = len(sx) + np.arange(found.sum())
        sx = np.concatenate([sx, x3[pick[found]]])
        sets = np.concatenate([sets, sets3[pick[found]]])
    got = best >= 0
    _upgrade_ends(m, tol, edges[span[got]], sx[best[got]], sets[best[got]], got, np.flatnonzero(got))
    e_idx = np.concatenate([chord[cok], span[got]])
    pts = np.concatenate([cx[cok], sx[best[got]]])
    new_sets = np.concatenate([cset[cok], sets[best[got]]])
    missed = int((~cok).sum() + (~got).sum())
    return e_idx, pts, new_sets, missed


def _upgrade_ends(m, tol, ends, x, sets, got, rows):
    """A curve point within :data:`SNAP` tolerances of an edge's end is no new vertex: when
    the curve's quadrics include the end's own, the end moves onto the curve point (still on
    its quadrics, exactly) and takes the curve's quadrics (``got[rows]`` cleared for those).
    This stops splits from creeping towards a curve in ever shorter steps."""
    for k in (0, 1):
        d = np.linalg.norm(m.vertices[ends[:, k]] - x, axis=1)
        hit = np.flatnonzero((d <= SNAP * tol) & got[rows])
        for i in hit:
            v = ends[i, k]
            own = [q for q in m.sets[v] if q >= 0]
            target = [q for q in sets[i] if q >= 0]
            if all(q in target for q in own):
                m.vertices[v] = x[i]
                m.sets[v] = (target + [-1, -1, -1])[:3]
                got[rows[i]] = False


def split_triangles(tri, tri_edge, mid_vertex, vertices, with_parents: bool = False):
    """The red-green split: a triangle with 1, 2, 3 split edges (``mid_vertex`` per edge, -1
    if not split) becomes 2, 3, 4 triangles of the same orientation.  With ``with_parents``
    also, per new triangle, the index of the triangle it came from."""
    mids = mid_vertex[tri_edge]  # (T, 3), mids[:, k] on edge (v_k, v_k+1)
    marked = mids >= 0
    c = marked.sum(axis=1)
    sel = np.flatnonzero(c == 0)
    out, parents = [tri[sel]], [sel]
    sel = np.flatnonzero(c == 1)
    r = np.argmax(marked[sel], axis=1)
    v, mm = _rolled(tri[sel], r), _rolled(mids[sel], r)
    out += [np.stack([v[:, 0], mm[:, 0], v[:, 2]], 1), np.stack([mm[:, 0], v[:, 1], v[:, 2]], 1)]
    parents += [sel, sel]
    sel = np.flatnonzero(c == 2)
    r = (np.argmin(marked[sel], axis=1) + 1) % 3
    v, mm = _rolled(tri[sel], r), _rolled(mids[sel], r)
    out.append(np.stack([mm[:, 0], v[:, 1], mm[:, 1]], 1))
    short = np.linalg.norm(vertices[v[:, 0]] - vertices[mm[:, 1]], axis=1) <= np.linalg.norm(
        vertices[mm[:, 0]] - vertices[v[:, 2]], axis=1)
    q1 = np.where(short[:, None], np.stack([v[:, 0], mm[:, 0], mm[:, 1]], 1), np.stack([mm[:, 0], mm[:, 1], v[:, 2]], 1))
    q2 = np.where(short[:, None], np.stack([v[:, 0], mm[:, 1], v[:, 2]], 1), np.stack([v[:, 0], mm[:, 0], v[:, 2]], 1))
    out += [q1, q2]
    parents += [sel, sel, sel]
    sel = np.flatnonzero(c == 3)
    v, mm = tri[sel], mids[sel]
    out += [np.stack([v[:, 0], mm[:, 0], mm[:, 2]], 1), np.stack([mm[:, 0], v[:, 1], mm[:, 1]], 1),
            np.stack([mm[:, 2], mm[:, 1], v[:, 2]], 1), np.stack([mm[:, 0], mm[:, 1], mm[:, 2]], 1)]
    parents += [sel] * 4
    if with_parents:
        return np.concatenate(out), np.concatenate(parents)
    return np.concatenate(out)


def _rolled(a, r):
    idx = (np.arange(3)[None, :] + r[:, None]) % 3
    return np.take_along_axis(a, idx, axis=1)


def _corner_splits(m):
    """Triangles around a corner (pairwise shared quadrics, none common to all three): split in
    three at the corner of their three quadrics.  Returns how many were split."""
    s = m.sets[m.triangles]  # (T, 3 verts, 3)
    ab, bc, ca = (common(s[:, i], s[:, (i + 1) % 3]) for i in range(3))
    pair = (ab >= 0).any(1) & (bc >= 0).any(1) & (ca >= 0).any(1)
    none = ~(common(ab, s[:, 2]) >= 0).any(1)
    sel = np.flatnonzero(pair & none)
    if not len(sel):
        return 0
    corner = np.stack([_compact(ab[sel])[:, 0], _compact(bc[sel])[:, 0], _compact(ca[sel])[:, 0]], 1)
    distinct = (corner[:, 0] != corner[:, 1]) & (corner[:, 1] != corner[:, 2]) & (corner[:, 0] != corner[:, 2])
    sel, corner = sel[distinct], corner[distinct]
    x0 = m.vertices[m.triangles[sel]].mean(axis=1)
    x, ok = _solve(m.tape, corner, x0)
    reach = np.linalg.norm(m.vertices[m.triangles[sel]] - x0[:, None], axis=2).max(axis=1)
    ok &= np.linalg.norm(x - x0, axis=1) <= 2.0 * reach
    ok[ok] = on_boundary(m.tape, x[ok])
    sel, x, corner = sel[ok], x[ok], corner[ok]
    if not len(sel):
        return 0
    c = len(m.vertices) + np.arange(len(sel))
    m.vertices = np.concatenate([m.vertices, x])
    m.sets = np.concatenate([m.sets, corner])
    t = m.triangles[sel]
    keep = np.ones(len(m.triangles), dtype=bool)
    keep[sel] = False
    m.triangles = np.concatenate([m.triangles[keep], np.stack([t[:, 0], t[:, 1], c], 1),
                                  np.stack([t[:, 1], t[:, 2], c], 1), np.stack([t[:, 2], t[:, 0], c], 1)])
    return len(sel)


def refine(m: Surface, tol: float, stats: dict) -> None:
    """Split until no edge spans a sharp edge or exceeds the chord error (or MAX_PASSES)."""
    splits = corners = 0
    missed = 0
    per_pass = []
    for _ in range(MAX_PASSES):
        edges, tri_edge = edges_of(m.triangles)
        e_idx, pts, sets, missed = _edge_splits(m, tol, edges, tri_edge)
        if not len(e_idx):
            n = _corner_splits(m)
            corners += n
            if n:
                continue
            break
        mid_vertex = np.full(len(edges), -1, dtype=np.int64)
        mid_vertex[e_idx] = len(m.vertices) + np.arange(len(e_idx))
        m.vertices = np.concatenate([m.vertices, pts])
        m.sets = np.concatenate([m.sets, sets])
        m.triangles = split_triangles(m.triangles, tri_edge, mid_vertex, m.vertices)
        splits += len(e_idx)
        per_pass.append(int(len(e_idx)))
    no_common = spanning(m.sets, m.triangles)
    stats.update(splits_per_pass=per_pass, edge_splits=int(splits), corner_splits=int(corners), unsplit_edges=int(missed),
                 spanning_after_refine=int(no_common.sum()))
