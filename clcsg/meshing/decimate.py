"""Fewer triangles at the same tolerance: half-edge collapses that keep every vertex on its
quadrics, every triangle on one, the chord error bound and the mesh closed and 2-manifold.

A vertex v may collapse into a neighbour u (v's triangles take u, the two triangles of the
edge (v, u) disappear) when

* u lies on every quadric v lies on (a patch vertex into a patch, curve or corner vertex of
  its quadric; a curve vertex into one on the same curve or a corner of it; a corner never
  moves): each triangle around v keeps a quadric its three vertices share, and sharp edges
  stay on the intersection curves;
* the link condition holds (v and u have exactly the two common neighbours opposite the
  edge) and the two are not both of degree three (the edge of a lone tetrahedron): the mesh
  stays a closed 2-manifold of the same topology;
* every new triangle lies within :data:`CHORD_FRACTION` of the tolerance of a quadric its
  vertices share, measured (first order, |K| / |grad K|) at its centroid, its edges'
  midpoints and three interior points; it turns its normal by less than :data:`MAX_TURN` and is
  not degenerate.  On a plane the chord error is zero: a flat face keeps only what its boundary
  needs;
* the first quadric its vertices share bounds the solid at its centroid (moved onto that
  quadric), or the solid's surface is within the rest of the tolerance of that point: three
  vertices on a face do not make the triangle between them part of it.

Each pass takes the vertices with a collapse that passes the quadric and topology rules,
keeps an independent set of them (no two within two edges of each other, so their
neighbourhoods are disjoint and every check still holds when all are applied at once), checks
the geometry of all their collapses and applies each one's shortest that passes, all in
numpy; a collapse that fails is not tried again until another changes its neighbourhood.
"""

from __future__ import annotations

import numpy as np
from scipy.sparse import csr_matrix

from ..compile.interpret import member_per_point
from .planar import closed, flat_quadrics
from .refine import PROBES, common, edges_of, straddles

#: the largest chord error, as a fraction of the tolerance, at a new triangle's sample points
CHORD_FRACTION = 0.7
#: the cosine of the largest turn of a triangle's normal in one collapse
MAX_TURN = 0.5
#: rounds of Luby's independent-set selection per pass
LUBY_ROUNDS = 4
#: passes of collapses
MAX_PASSES = 200
#: barycentric sample points of the chord error: centroid, edge midpoints, interior points
SAMPLES = np.array([[1 / 3, 1 / 3, 1 / 3], [0.5, 0.5, 0], [0, 0.5, 0.5], [0.5, 0, 0.5],
                    [2 / 3, 1 / 6, 1 / 6], [1 / 6, 2 / 3, 1 / 6], [1 / 6, 1 / 6, 2 / 3]])


def _contained_both(m, edges):
    """Per edge (a, b): (every quadric of a is one of b's, every quadric of b is one of a's),
    from the nine comparisons of the two sets, made once for both directions."""
    sa, sb = m.sets[edges[:, 0]], m.sets[edges[:, 1]]
    eq = [[sa[:, i] == sb[:, j] for j in range(3)] for i in range(3)]
    a_in_b = np.ones(len(edges), dtype=bool)
    b_in_a = np.ones(len(edges), dtype=bool)
    for i in range(3):
        a_in_b &= (sa[:, i] < 0) | eq[i][0] | eq[i][1] | eq[i][2]
        b_in_a &= (sb[:, i] < 0) | eq[0][i] | eq[1][i] | eq[2][i]
    return a_in_b, b_in_a


def _not_failed(edges, n, failed):
    """Per directed edge (rows: edges (a, b), then (b, a)) False where its key v * n + u is in
    ``failed``: the failed keys looked up among the sorted edge keys."""
    out = np.ones(2 * len(edges), dtype=bool)
    if not len(failed) or not len(edges):
        return out
    fv, fu = failed // n, failed % n
    key = np.minimum(fv, fu) * n + np.maximum(fv, fu)
    ekey = edges[:, 0] * n + edges[:, 1]  # sorted: edges_of's order
    at = np.minimum(np.searchsorted(ekey, key), len(ekey) - 1)
    hit = ekey[at] == key
    out[(at + len(edges) * (fv > fu))[hit]] = False
    return out


def _topology_ok(m, edges, v, u):
    """The link condition, and not both of degree three (a tetrahedron), per candidate (v, u)."""
    if not len(v):  # scipy indexes a sparse matrix by empty arrays into a sparse matrix
        return np.zeros(0, dtype=bool)
    n = len(m.vertices)
    a = np.concatenate([edges[:, 0], edges[:, 1]])
    b = np.concatenate([edges[:, 1], edges[:, 0]])
    adj = csr_matrix((np.ones(len(a), dtype=np.int32), (a, b)), shape=(n, n))
    shared = np.asarray((adj @ adj)[v, u]).ravel()
    deg = np.bincount(a, minlength=n)
    return (shared == 2) & ((deg[v] > 3) | (deg[u] > 3))


def _incidences(tri, n):
    """(order, start, count): the (triangle, corner) incidences of each vertex, grouped."""
    flat = tri.ravel()
    order = np.argsort(flat, kind="stable")
    count = np.bincount(flat, minlength=n)
    start = np.concatenate([[0], np.cumsum(count)[:-1]])
    return order, start, count


def _sample_points(corners):
    """Homogeneous sample points (R, S, 4) of triangles (R, 3, 3): sum_k SAMPLES[s, k] c_k,
    the terms added in k order from the first (einsum's sum, to the bit), one sample at a
    time over contiguous (R, 3) corner arrays."""
    ct = np.ascontiguousarray(corners.transpose(1, 0, 2))  # (3, R, 3): corner k of every row
    ph = np.empty((len(corners), len(SAMPLES), 4))
    ph[:, :, 3] = 1.0
    acc, tmp = np.empty_like(ct[0]), np.empty_like(ct[0])
    for s, w in enumerate(SAMPLES):
        np.multiply(w[0], ct[0], out=acc)
        for k in (1, 2):
            np.multiply(w[k], ct[k], out=tmp)
            acc += tmp
        ph[:, s, :3] = acc
    return ph


def _chord_error(m, corners, sets, flat):
    """Per new triangle (corners (R, 3, 3)) the smallest over its shared quadrics (R, 3) of the
    largest first-order distance at :data:`SAMPLES`; inf where it shares none.  On a flat
    quadric (``flat`` (U,) bool: a plane or a slab's two planes) the centroid alone decides:
    zero if the corners lie on one plane, far off if on both."""
    ph = _sample_points(corners)
    err = np.full(len(corners), np.inf)
    for k in range(sets.shape[1]):
        on = sets[:, k] >= 0
        sel = np.flatnonzero(on & flat[np.maximum(sets[:, k], 0)])
        if len(sel):
            kx = np.matmul(m.tape.quadrics[sets[sel, k]], ph[sel, 0, :, None])[..., 0]
            f = np.abs((kx * ph[sel, 0]).sum(axis=1))
            g = 2.0 * np.linalg.norm(kx[:, :3], axis=1)
            with np.errstate(divide="ignore", invalid="ignore"):
                d = np.where(g > 0, f / g, np.where(f == 0, 0.0, np.inf))
            err[sel] = np.minimum(err[sel], d)
        sel = np.flatnonzero(on & ~flat[np.maximum(sets[:, k], 0)])
        if not len(sel):
            continue
        kx = np.matmul(ph[sel], m.tape.quadrics[sets[sel, k]])  # K symmetric: x^T K = (K x)^T
        f = np.abs((kx * ph[sel]).sum(axis=2))
        g = 2.0 * np.linalg.norm(kx[..., :3], axis=2)
        with np.errstate(divide="ignore", invalid="ignore"):
            d = np.where(g > 0, f / g, np.where(f == 0, 0.0, np.inf)).max(axis=1)
        err[sel] = np.minimum(err[sel], d)
    return err


def _geometry_ok(m, v, u, tol, flat):
    """Per candidate (v, u): every triangle of v that does not hold u, with v replaced by u,
    passes the chord error, turn and degeneracy checks."""
    tri, x = m.triangles, m.vertices
    order, start, count = _incidences(tri, len(x))
    cnt = count[v]
    row = np.repeat(np.arange(len(v)), cnt)
    off = np.arange(cnt.sum()) - np.repeat(np.cumsum(cnt) - cnt, cnt)
    inc = order[start[v][row] + off]
    t, k = inc // 3, inc % 3
    old = tri[t]
    keep = ~(old == u[row, None]).any(axis=1)  # the edge's own triangles disappear
    row, t, k, old = row[keep], t[keep], k[keep], old[keep]
    new = old.copy()
    new[np.arange(len(new)), k] = u[row]
    c_old, c_new = x[old], x[new]
    n_old = np.cross(c_old[:, 1] - c_old[:, 0], c_old[:, 2] - c_old[:, 0])
    n_new = np.cross(c_new[:, 1] - c_new[:, 0], c_new[:, 2] - c_new[:, 0])
    l_old, l_new = np.linalg.norm(n_old, axis=1), np.linalg.norm(n_new, axis=1)
    longest = np.max(np.linalg.norm(c_new - np.roll(c_new, 1, axis=1), axis=2), axis=1)
    good = (l_new > 1e-6 * longest * longest) & (np.einsum("ri,ri->r", n_old, n_new) > MAX_TURN * l_old * l_new)
    s = m.sets[new]
    shared = common(common(s[:, 0], s[:, 1]), s[:, 2])
    ok = np.bincount(row[~good], minlength=len(v)) == 0
    test = good & ok[row]  # a candidate already out needs no chord errors
    ok[row[test][~(_chord_error(m, c_new[test], shared[test], flat) <= CHORD_FRACTION * tol)]] = False  # NaN fails
    test &= ok[row]
    ok[row[test][~_bounds_at_centroid(m, c_new[test], shared[test], tol)]] = False
    return ok


def _bounds_at_centroid(m, corners, shared, tol):
    """Per new triangle (corners (R, 3, 3)) whether its centroid, moved onto the first quadric
    its vertices share (``shared`` (R, 3), one step along the gradient), lies where that
    quadric bounds the solid (its substituted sides differ).  Vertices on a quadric's face do
    not make the triangle between them part of that face: three corners of a crenel's gap lie
    on the turret's cylinder, the triangle across the gap does not."""
    q = _first_shared(shared)
    has = q >= 0
    out = np.ones(len(corners), dtype=bool)
    if not has.any():
        return out
    c = corners[has].mean(axis=1)
    k = m.tape.quadrics[q[has]]
    kx = np.einsum("rij,rj->ri", k, np.concatenate([c, np.ones((len(c), 1))], axis=1))
    f = np.einsum("ri,ri->r", kx[:, :3], c) + kx[:, 3]
    g = 2.0 * kx[:, :3]
    gg = np.einsum("ri,ri->r", g, g)
    with np.errstate(divide="ignore", invalid="ignore"):
        p = c - np.where(gg > 0, f / gg, 0.0)[:, None] * g
    neg, pos = member_per_point(m.tape.ops, m.tape.quadrics, p, q[has])
    bounds = neg != pos
    off = np.flatnonzero(~bounds)
    # a face of the solid within the rest of the tolerance of the point still bounds the
    # triangle's error: a step below the tolerance (a 0.01 rim between two primitives) need
    # not be kept
    bounds[off] = straddles(m.tape, p[off], (1.0 - CHORD_FRACTION) * tol, PROBES[::4])
    out[has] = bounds
    return out


def _first_shared(shared):
    """The first quadric of each row of ``shared`` (R, 3), -1 if none."""
    first = np.argmax(shared >= 0, axis=1)
    return np.where((shared >= 0).any(axis=1), shared[np.arange(len(shared)), first], -1)


def _independent(n, edges, tri, v, rounds=LUBY_ROUNDS):
    """A maximal-ish set of the candidate vertices ``v`` (unique) no two within two edges of
    each other: Luby's rounds, each keeping the candidates whose random rank is the lowest
    within two edges and dropping the candidates near those."""
    rng = np.random.default_rng(len(v))
    alive = np.zeros(n, dtype=bool)
    alive[v] = True
    won = np.zeros(n, dtype=bool)
    rank_v = rng.permutation(len(v)).astype(np.float64)
    for _ in range(rounds):
        rank = np.full(n, np.inf)
        rank[v] = np.where(alive[v], rank_v, np.inf)
        best = rank.copy()
        for _ in range(2):
            nxt = best.copy()
            np.minimum.at(nxt, edges[:, 0], best[edges[:, 1]])
            np.minimum.at(nxt, edges[:, 1], best[edges[:, 0]])
            best = nxt
        win = alive & (best == rank) & np.isfinite(rank)
        if not win.any():
            break
        won |= win
        alive &= ~_near(n, tri, np.flatnonzero(win))
    return won[v]


def _near(n, tri, seeds, rings=2):
    """Vertices within ``rings`` edges of ``seeds`` (bool (n,))."""
    mark = np.zeros(n, dtype=bool)
    mark[seeds] = True
    for _ in range(rings):
        m3 = mark[tri]
        mark[tri[m3[:, 0] | m3[:, 1] | m3[:, 2]]] = True
    return mark


def _one_pass(m, tol, failed, flat):
    """Apply one independent set of valid collapses; returns the vertex map (collapsed vertex
    -> its target; None when no candidate is left) and adds the candidates that failed the
    geometric checks to ``failed[0]`` (sorted keys v * V + u)."""
    n = len(m.vertices)
    edges, _ = edges_of(m.triangles)
    v = np.concatenate([edges[:, 0], edges[:, 1]])
    u = np.concatenate([edges[:, 1], edges[:, 0]])
    sel = np.concatenate(_contained_both(m, edges)) & _not_failed(edges, n, failed[0])
    v, u = v[sel], u[sel]
    sel = _topology_ok(m, edges, v, u)
    v, u = v[sel], u[sel]
    if not len(v):
        return None
    cand = np.flatnonzero(np.bincount(v, minlength=n))
    win = np.zeros(n, dtype=bool)
    win[cand[_independent(n, edges, m.triangles, cand)]] = True
    v, u = v[win[v]], u[win[v]]
    ok = _geometry_ok(m, v, u, tol, flat)
    failed[0] = np.sort(np.concatenate([failed[0], v[~ok] * n + u[~ok]]))
    v, u = v[ok], u[ok]
    length = np.linalg.norm(m.vertices[v] - m.vertices[u], axis=1)
    order = np.lexsort((length, v))
    first = np.ones(len(order), dtype=bool)
    first[1:] = v[order][1:] != v[order][:-1]
    v, u = v[order[first]], u[order[first]]
    target = np.arange(n)
    target[v] = u
    return target


def decimate(m, tol: float, stats: dict) -> None:
    """Collapse edges of ``m`` in place while every check holds (see the module); drops the
    removed vertices."""
    failed = [np.zeros(0, dtype=np.int64)]
    before = len(m.triangles)
    passes = 0
    flat = np.zeros(max(len(m.tape.quadrics), 1), dtype=bool)
    flat[flat_quadrics(m.tape.quadrics)] = True
    for _ in range(MAX_PASSES):
        target = _one_pass(m, tol, failed, flat)
        if target is None:
            break
        moved = np.flatnonzero(target != np.arange(len(target)))
        passes += 1
        if not len(moved):
            continue
        tri = target[m.triangles]
        tri = tri[(tri[:, 0] != tri[:, 1]) & (tri[:, 1] != tri[:, 2]) & (tri[:, 2] != tri[:, 0])]
        if not closed(tri):  # a safety net: the checks above should make this impossible
            break
        m.triangles = tri
        if len(failed[0]):  # a failed candidate near a collapse may pass now
            near = _near(len(m.vertices), tri, target[moved])
            failed[0] = failed[0][~near[failed[0] // len(m.vertices)]]
    used = np.zeros(len(m.vertices), dtype=bool)
    used[m.triangles.ravel()] = True
    remap = np.cumsum(used) - 1
    m.vertices, m.sets = m.vertices[used], m.sets[used]
    m.triangles = remap[m.triangles]
    stats.update(decimated_triangles=int(before - len(m.triangles)), decimation_passes=passes)
