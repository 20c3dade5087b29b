"""Float64 numpy oracles for the sampler's guarantees (independent of the kernels).

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
    key = np.column_stack([s.positions, s.quadrics, s.primitives, s.radii])
    return np.lexsort(key.T[::-1])


def assert_same_samples(a, b, stats=("distance_queries", "leaf_distances", "unresolved", "filled", "single")):
    """Two runs gave the same samples (in any order), clip programs and the named counters."""
    assert len(a) == len(b)
    ia, ib = _canonical_order(a), _canonical_order(b)
    for name in ("positions", "normals", "radii", "quadrics", "signs", "primitives", "clip_count"):
        np.testing.assert_array_equal(getattr(a, name)[ia], getattr(b, name)[ib], err_msg=name)
    ca = [a.clip_ops[f:f + c].tolist() for f, c in zip(a.clip_first[ia], a.clip_count[ia])]
    cb = [b.clip_ops[f:f + c].tolist() for f, c in zip(b.clip_first[ib], b.clip_count[ib])]
    assert ca == cb
    for k in stats:
        assert a.stats[k] == b.stats[k], k
