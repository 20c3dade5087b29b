"""Vertices of a faceted Boolean result moved onto the exact surface, curves and corners.

Every triangle of :func:`clcsg.meshing.instance_booleans.boolean_mesh` lies on one quadric's
facets; a vertex's *set* is the quadrics of the triangles around it.  A vertex with one
quadric is projected onto it, with two onto their intersection curve, with three onto the
corner (Newton's method in float64, :func:`clcsg.meshing.project.newton`: the minimum-norm
step, quadratic near a transversal intersection).  Of more than three quadrics (four planes
through a pyramid's apex, a corner where coincident faces meet) the three with the most
independent normals are used.

Newton may fail where surfaces meet at a grazing angle (a fillet tangent to a face): it does
not converge, or converges to a point farther than :data:`MAX_MOVE` tolerances away (another
branch of the curve).  Such a vertex is solved for each subset of one quadric fewer, the
solution that moves least taken, down to single quadrics; one that no single quadric takes
within the limit (a cone's apex, where the gradient vanishes) stays where the facets put it,
on its first quadric to their accuracy.  The counts are kept in the stats.

The topology is the Boolean result's, untouched: the mesh stays closed, oriented and
2-manifold.  Faceted curved surfaces are inscribed and their vertices move outward onto the
surface, so a triangle's deviation from its quadric stays the chord sag the facets were made
for (:mod:`.facets`).
"""

from __future__ import annotations

from itertools import combinations

import numpy as np

from .project import REL, first_order_distance, newton

#: a solved vertex may move at most this many tolerances (else a grazing intersection's far
#: branch: the vertex keeps fewer quadrics)
MAX_MOVE = 8.0


def vertex_sets(n_vertices: int, triangles, tri_quadric) -> np.ndarray:
    """(V, k) the distinct quadrics of the triangles around each vertex, -1 padded, in
    ascending order (``tri_quadric`` < 0: none)."""
    v = triangles.reshape(-1)
    q = np.repeat(tri_quadric, 3)
    keep = q >= 0
    pairs = _unique_pairs(v[keep], q[keep])
    counts = np.bincount(pairs[:, 0], minlength=n_vertices)
    width = max(1, int(counts.max(initial=0)))
    out = np.full((n_vertices, width), -1, dtype=np.int64)
    starts = np.concatenate([[0], np.cumsum(counts)[:-1]])
    col = np.arange(len(pairs)) - starts[pairs[:, 0]]
    out[pairs[:, 0], col] = pairs[:, 1]
    return out


def _unique_pairs(a, b) -> np.ndarray:
    """The distinct rows of (a, b) (non-negative integers), sorted: one sort of 64-bit keys."""
    if not len(a):
        return np.zeros((0, 2), dtype=np.int64)
    span = np.int64(b.max()) + 1
    keys = np.unique(a.astype(np.int64) * span + b)
    return np.stack([keys // span, keys % span], 1)


def _independent_three(matrices, sets, x):
    """Per row of ``sets`` (N, k > 3), the three quadrics whose unit normals at ``x`` span
    the largest volume."""
    xh = np.concatenate([x, np.ones((len(x), 1))], axis=1)
    ok = sets >= 0
    g = np.einsum("nkij,nj->nki", matrices[np.where(ok, sets, 0)], xh)[..., :3]
    g /= np.maximum(np.linalg.norm(g, axis=2, keepdims=True), 1e-300)
    best = np.full(len(x), -1.0)
    pick = np.repeat(np.arange(3)[None], len(x), 0)
    for c in combinations(range(sets.shape[1]), 3):
        valid = ok[:, list(c)].all(axis=1)
        vol = np.abs(np.linalg.det(g[:, list(c)]))
        better = valid & (vol > best)
        best[better] = vol[better]
        pick[better] = c
    return np.take_along_axis(sets, pick, axis=1)


def _solve(matrices, subsets, x0, limit):
    """Newton from ``x0`` (N, 3) onto each of the ``subsets`` (list of (N, j) index arrays, one
    j for all; solved in one batch); per point the converged solution within ``limit`` that
    moved least: (x, chosen subset index (-1: none))."""
    n = len(x0)
    got, ok = newton(matrices[np.concatenate(subsets)], np.tile(x0, (len(subsets), 1)), 2.0 * limit)
    move = np.where(ok & (np.linalg.norm(got - np.tile(x0, (len(subsets), 1)), axis=1) <= limit),
                    np.linalg.norm(got - np.tile(x0, (len(subsets), 1)), axis=1), np.inf).reshape(len(subsets), n)
    pick = np.argmin(move, axis=0)
    found = np.isfinite(move[pick, np.arange(n)])
    x = np.where(found[:, None], got.reshape(len(subsets), n, 3)[pick, np.arange(n)], x0)
    return x, np.where(found, pick, -1)


def snap(vertices, sets, matrices, tol: float):
    """(vertices moved, the quadrics each lies on (V, max(3, width of ``sets``)) -1 padded,
    fallbacks: the vertices solved for fewer of their (at most three) quadrics than they touch): see the module docstring.  ``matrices``: the
    quadric matrices the set indices name."""
    x = np.array(vertices, dtype=np.float64, copy=True)
    n = len(x)
    count = np.minimum((sets >= 0).sum(axis=1), 3)
    three = np.full((n, 3), -1, dtype=np.int64)
    w = min(3, sets.shape[1])
    three[:, :w] = sets[:, :w]
    wide = (sets >= 0).sum(axis=1) > 3
    if wide.any():
        three[wide] = _independent_three(matrices, sets[wide], x[wide])
    kept = np.full((n, 3), -1, dtype=np.int64)
    limit = MAX_MOVE * tol
    for k in (1, 2, 3):
        sel = np.flatnonzero(count == k)
        todo = sel
        for j in range(k, 0, -1):  # all k quadrics, then each subset of k - 1, ...
            if not len(todo):
                break
            subsets = [list(c) for c in combinations(range(k), j)]
            got, pick = _solve(matrices, [three[todo][:, c] for c in subsets], x[todo], limit)
            done = pick >= 0
            if j == 1:  # the last resort: where it is, on its first quadric to the facets' accuracy
                pick[~done], done = 0, np.ones(len(todo), dtype=bool)
            rows = todo[done]
            x[rows] = got[done]
            for s, c in enumerate(subsets):
                r = rows[pick[done] == s]
                kept[r, :j] = three[r][:, c]
            todo = todo[~done]
    fallbacks = int(((kept >= 0).sum(axis=1) < count).sum())
    return x, with_satisfied(matrices, sets, kept, x), fallbacks


def with_satisfied(matrices, sets, kept, x):
    """Per vertex every quadric of its ``sets`` that the solved point satisfies to rounding
    (V, max(3, width)) -1 padded, those solved for (``kept``) first: three quadrics through
    one curve (a cone standing on a cylinder on the cap's plane), or a fourth plane through a
    corner."""
    scale = np.maximum(1.0, np.abs(x).max(axis=1))
    width = max(3, sets.shape[1])
    out = np.full((len(x), width), -1, dtype=np.int64)
    out[:, :3] = kept
    fill = (kept >= 0).sum(axis=1)
    for c in range(sets.shape[1]):
        cand = sets[:, c]
        rows = np.flatnonzero((cand >= 0) & ~(kept == cand[:, None]).any(axis=1))
        if not len(rows):
            continue
        d = first_order_distance(matrices[cand[rows]][:, None], x[rows])
        rows = rows[d <= 1e3 * REL * scale[rows]]
        out[rows, fill[rows]] = cand[rows]
        fill[rows] += 1
    return out


def fibonacci_directions(n: int) -> np.ndarray:
    """``n`` unit vectors spread evenly over the sphere (a Fibonacci lattice)."""
    k = np.arange(n) + 0.5
    z = 1.0 - 2.0 * k / n
    phi = k * np.pi * (3.0 - np.sqrt(5.0)) + 0.3
    return np.stack([np.sqrt(1 - z * z) * np.cos(phi), np.sqrt(1 - z * z) * np.sin(phi), z], axis=1)


#: directions of the straddle test
_DIRS = fibonacci_directions(32)
#: the straddle test's radius, relative to max(1, largest |coordinate|)
STRADDLE = 1e-7


def straddles(x, contains, eps, directions=_DIRS) -> np.ndarray:
    """Per point of ``x`` whether points at distance ``eps`` around it are both inside and
    outside the solid (``contains(x, eps, directions)``: the membership of the points
    x_i + eps d_j as (N, k) bool): it is on the surface."""
    if not len(x):
        return np.zeros(0, dtype=bool)
    ins = contains(x, eps, directions)
    return ins.any(axis=1) & ~ins.all(axis=1)


def _neighbour_candidates(x, kept, triangles, matrices, tol):
    """(vertex, quadric) pairs: a quadric of a neighbouring vertex's set, not the vertex's own,
    within ``tol`` of it (first order), nearest first."""
    e = np.concatenate([triangles[:, [0, 1]], triangles[:, [1, 2]], triangles[:, [2, 0]]])
    e = np.concatenate([e, e[:, ::-1]])
    v = np.repeat(e[:, 0], kept.shape[1])  # a vertex's set has kept.shape[1] slots (-1 padded)
    q = kept[e[:, 1]].reshape(-1)
    keep = (q >= 0) & ~(kept[v] == q[:, None]).any(axis=1)
    pairs = _unique_pairs(v[keep], q[keep])
    if not len(pairs):
        return pairs, np.zeros(0)
    d = first_order_distance(matrices[pairs[:, 1]][:, None], x[pairs[:, 0]])
    near = d <= tol
    pairs, d = pairs[near], d[near]
    order = np.lexsort((d, pairs[:, 0]))
    return pairs[order], d[order]


def _nearby_candidates(x, kept, rows, matrices, tol, chunk=1 << 17):
    """(vertex, quadric) pairs for the vertices ``rows``: every quadric, not the vertex's own,
    within ``tol`` of it (first order), nearest first (for a vertex off the surface whose
    neighbours are all on its own quadrics)."""
    nq = len(matrices)
    out_v, out_q, out_d = [], [], []
    per = max(1, chunk // max(nq, 1))
    for s in range(0, len(rows), per):
        r = rows[s:s + per]
        v = np.repeat(r, nq)
        q = np.tile(np.arange(nq), len(r))
        d = first_order_distance(matrices[q][:, None], x[v])
        keep = (d <= tol) & ~(kept[v] == q[:, None]).any(axis=1)
        out_v.append(v[keep]), out_q.append(q[keep]), out_d.append(d[keep])
    v, q, d = np.concatenate(out_v), np.concatenate(out_q), np.concatenate(out_d)
    order = np.lexsort((d, v))
    return np.stack([v[order], q[order]], 1)


def repair_off_surface(x, kept, triangles, matrices, tol, contains):
    """Vertices solved onto a curve beyond the corner where a third quadric cuts it off (the
    faceted cutter is inscribed, so its facets meet the curve short of the exact corner): such
    a vertex, off the solid's surface by the straddle test, is solved again with a neighbour's
    quadric added (the corner; of a vertex on three, with each pair of them), in place of one
    of its own (a point of a curve that is not on the surface at all), or in place of all of
    them (a point of a surface hidden inside the solid: where a hull's sphere meets its
    cylinder tangentially, the faceted sphere pokes out of the inscribed cylinder), the nearest
    candidate first, and takes the first solution within :data:`MAX_MOVE` tolerances that
    straddles.  In place; returns (the vertices found off the surface, those moved onto it)."""
    pairs, _ = _neighbour_candidates(x, kept, triangles, matrices, tol)
    scale = max(1.0, float(np.abs(x).max()))
    eps = STRADDLE * scale
    # tested: the vertices with a neighbour on another quadric, and those on one plane alone (a
    # flat face needs no inner vertex: one there is a corner of a faceted surface hidden by the
    # exact one, as a hub's inscribed polygon on the face round it)
    flat = np.all(matrices[:, :3, :3] == 0, axis=(1, 2))
    alone = (kept[:, 0] >= 0) & flat[np.maximum(kept[:, 0], 0)]
    if kept.shape[1] > 1:
        alone &= kept[:, 1] < 0
    rows = np.union1d(pairs[:, 0], np.flatnonzero(alone))
    off = rows[~straddles(x[rows], contains, eps)]
    if not len(off):
        return 0, 0
    lacking = off[~np.isin(off, pairs[:, 0])]  # off, with no neighbour on another quadric
    if len(lacking):
        pairs = np.concatenate([pairs, _nearby_candidates(x, kept, lacking, matrices, tol)])
    cand = pairs[np.isin(pairs[:, 0], off)]
    if not len(cand):
        return len(off), 0
    v, c = cand[:, 0], cand[:, 1]
    own = kept[v]  # (P, W) -1 padded, the quadrics first
    n_own = (own >= 0).sum(axis=1)
    best_rank = np.full(len(x), np.iinfo(np.int64).max)
    best_x = np.zeros((len(x), 3))
    best_q = np.full((len(x), 3), -1, dtype=np.int64)
    # with the candidate: a vertex's two quadrics (its third), each pair of its three; then
    # the candidate in place of one of them (a curve point of the wrong curve: the chamfer
    # cone's circle on the top face, inside the bore, belongs on the bore's rim)
    tries = [((0, 1), n_own == 2), ((0, 1), n_own >= 3), ((0, 2), n_own >= 3), ((1, 2), n_own >= 3),
             ((0,), n_own == 1), ((0,), n_own >= 2), ((1,), n_own >= 2), ((2,), n_own >= 3), ((), n_own >= 1)]
    for k, (cols, which) in enumerate(tries):
        sel = np.flatnonzero(which)
        if len(sel):
            qs = np.stack([own[sel, j] for j in cols] + [c[sel]], 1)
            size = len(cols) + 1
            got, ok = newton(matrices[qs], x[v[sel]], 2.0 * MAX_MOVE * tol)
            ok &= np.linalg.norm(got - x[v[sel]], axis=1) <= MAX_MOVE * tol
            idx = np.flatnonzero(ok)
            idx = idx[straddles(got[idx], contains, eps)]
            rank = len(tries) * sel[idx] + k  # candidates nearest first (pairs are sorted so), then the try
            vi = v[sel[idx]]
            order = np.lexsort((rank, vi))
            vi, rank, idx = vi[order], rank[order], idx[order]
            first = np.concatenate([[True], vi[1:] != vi[:-1]]) if len(vi) else np.zeros(0, dtype=bool)
            vi, rank, idx = vi[first], rank[first], idx[first]
            better = rank < best_rank[vi]
            vi, rank, idx = vi[better], rank[better], idx[better]
            best_rank[vi], best_x[vi] = rank, got[idx]
            best_q[vi, :size] = qs[idx]
            best_q[vi, size:] = -1
    done = np.flatnonzero(best_rank < np.iinfo(np.int64).max)
    x[done] = best_x[done]
    kept[done] = -1
    kept[done, :3] = best_q[done]
    return len(off), len(done)
