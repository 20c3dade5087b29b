"""Float64 numpy oracles for the sampler's guarantees (independent of the kernels).

* :func:`surface_residuals` — how far each sample is from its quadric and from the CSG surface;
* :func:`uncovered` — reference surface points with no sample on the same quadric within r,
  found with a uniform grid hash (cell size r), so millions of pairs cost little.
"""

from __future__ import annotations

import numpy as np


def _values(matrices, points):
    xh = np.concatenate([points, np.ones((len(points), 1))], axis=1)
    return np.einsum("ni,nij,nj->n", xh, matrices, xh)


def _grad_norm(matrices, points):
    xh = np.concatenate([points, np.ones((len(points), 1))], axis=1)
    g = 2.0 * np.einsum("nij,nj->ni", matrices[:, :3, :], xh)
    return np.linalg.norm(g, axis=1)


def surface_residuals(samples):
    """(on_quadric, csg) residuals in world units, per sample.

    on_quadric: |Q(s)| / |grad Q(s)| (first-order distance to the sample's quadric).
    csg: how far the sample is from satisfying "inside every other literal of its term and
    outside every other term": max over the violated conditions of the first-order distances;
    0 when all hold.  Another term that contains the sample's quadric with the same polarity
    is a shared surface; the sample must then lie on its boundary, which the same test
    accepts (that literal is 0 there).
    """
    dnf = samples.dnf
    P = samples.positions
    Qs = dnf.quadrics
    own = Qs[samples.quadrics]
    val = np.abs(_values(own, P))
    gn = _grad_norm(own, P)
    # a singular point (a cone's apex) has no gradient; it is on the surface iff Q = 0
    on_quadric = np.divide(val, gn, out=np.where(val == 0.0, 0.0, np.inf), where=gn > 0)
    # signed first-order distance of every point to every quadric
    U = len(Qs)
    dist = np.empty((len(P), U))
    for u in range(U):
        m = np.broadcast_to(Qs[u], (len(P), 4, 4))
        dist[:, u] = _values(m, P) / np.maximum(_grad_norm(m, P), 1e-300)
    csg = np.zeros(len(P))
    for t, lits in enumerate(dnf.terms):
        mine = samples.terms == t
        lit_q = np.array([q for q, _ in lits])
        lit_s = np.array([s for _, s in lits])
        sd = dist[:, lit_q] * lit_s  # > 0: outside that literal
        # own term: every other literal holds (ignore the sample's own quadric)
        own_lit = lit_q[None, :] == samples.quadrics[:, None]
        viol_in = np.where(own_lit, 0.0, np.maximum(sd, 0.0)).max(axis=1)
        csg = np.where(mine, np.maximum(csg, viol_in), csg)
        # other terms: some literal fails (the point is outside the term, up to tolerance)
        out_depth = np.maximum(-sd.max(axis=1), 0.0)  # > 0: strictly inside term t
        csg = np.where(~mine, np.maximum(csg, out_depth), csg)
    return on_quadric, csg


def uncovered(points, point_quadrics, samples, radius, slack=1e-5):
    """Indices of reference points with no sample on the same quadric within radius*(1+slack)."""
    P = np.asarray(samples.positions, dtype=np.float64)
    q = np.asarray(samples.quadrics, dtype=np.int64)
    X = np.asarray(points, dtype=np.float64)
    xq = np.asarray(point_quadrics, dtype=np.int64)
    r = radius * (1.0 + slack)
    if len(P) == 0:
        return np.arange(len(X))
    origin = np.minimum(P.min(0), X.min(0)) - 2 * r
    cell = lambda a: np.floor((a - origin) / r).astype(np.int64)  # noqa: E731
    ps = cell(P)
    dims = ps.max(0) + 3
    dims = np.maximum(dims, cell(X).max(0) + 3)

    def key(qi, c):
        return ((qi * dims[0] + c[:, 0]) * dims[1] + c[:, 1]) * dims[2] + c[:, 2]

    skeys = key(q, ps)
    order = np.argsort(skeys, kind="stable")
    skeys = skeys[order]
    Ps = P[order]
    found = np.zeros(len(X), dtype=bool)
    xc = cell(X)
    for dx in (-1, 0, 1):
        for dy in (-1, 0, 1):
            for dz in (-1, 0, 1):
                todo = np.flatnonzero(~found)
                if not len(todo):
                    break
                k = key(xq[todo], xc[todo] + np.array([dx, dy, dz]))
                lo = np.searchsorted(skeys, k, "left")
                hi = np.searchsorted(skeys, k, "right")
                span = hi - lo
                for j in range(int(span.max(initial=0))):
                    live = span > j
                    idx = lo[live] + j
                    d = np.linalg.norm(Ps[idx] - X[todo[live]], axis=1)
                    hit = todo[live][d <= r]
                    found[hit] = True
    return np.flatnonzero(~found)


def _canonical_order(s):
    key = np.column_stack([s.positions, s.quadrics, s.terms, s.radii])
    return np.lexsort(key.T[::-1])


def assert_same_samples(a, b, stats=("distance_queries", "unresolved", "filled", "single")):
    """Two runs gave the same samples (in any order), clip sets and the named counters."""
    assert len(a) == len(b)
    ia, ib = _canonical_order(a), _canonical_order(b)
    for name in ("positions", "normals", "radii", "quadrics", "signs", "terms"):
        np.testing.assert_array_equal(getattr(a, name)[ia], getattr(b, name)[ib], err_msg=name)
    ca = [tuple(map(tuple, a.clip_literals[f:f + c])) for f, c in zip(a.clip_first[ia], a.clip_count[ia])]
    cb = [tuple(map(tuple, b.clip_literals[f:f + c])) for f, c in zip(b.clip_first[ib], b.clip_count[ib])]
    assert ca == cb
    for k in stats:
        assert a.stats[k] == b.stats[k], k
