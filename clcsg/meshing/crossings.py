"""Where the CSG surface crosses a grid edge, exactly: the roots of the cell's quadrics along the
edge and the membership between them.

Along the segment p(t) = p0 + t (p1 - p0), t in [0, 1], quadric K has value
a t^2 + 2 h t + c with (homogeneous x = (p0, 1), v = (p1 - p0, 0)) a = v^T K v, h = v^T K x,
c = x^T K x; its roots are q / a and c / q with q = -(h + sign(h) sqrt(h^2 - a c)) (no
cancellation).  Membership is constant between consecutive roots of the quadrics of the
cell's pruned tape (nothing else can change it there), so evaluating the tape at the midpoint
of every interval finds the first root where it flips: that root is the crossing, on its
quadric to rounding, and on the CSG surface.  When rounding hides the flip (a root at an
end point, a tangent double root) the crossing is found by bisection on the membership and
snapped to the nearest root.
"""

from __future__ import annotations

import numpy as np

from ..compile.interpret import contains
from .project import first_order_distance

#: bisection steps of the fallback (2^-50 of an edge)
BISECTION_STEPS = 50


def line_roots(matrices, p0, p1):
    """(t1, t2) with K(p0 + t (p1 - p0)) = 0 per row (NaN where missing); ``matrices`` (N, 4, 4)."""
    x = np.concatenate([p0, np.ones((len(p0), 1))], axis=1)
    v = np.concatenate([p1 - p0, np.zeros((len(p0), 1))], axis=1)
    kx = np.einsum("nij,nj->ni", matrices, x)
    a = np.einsum("ni,nij,nj->n", v, matrices, v)
    h = np.einsum("ni,ni->n", v, kx)
    c = np.einsum("ni,ni->n", x, kx)
    disc = h * h - a * c
    with np.errstate(invalid="ignore", divide="ignore", over="ignore"):
        sq = np.sqrt(np.where(disc >= 0.0, disc, np.nan))
        q = -(h + np.where(h >= 0.0, sq, -sq))
        r1 = np.where(a != 0.0, q / a, np.nan)
        r2 = np.where(q != 0.0, c / q, np.nan)
    r1[~np.isfinite(r1)] = np.nan
    r2[~np.isfinite(r2)] = np.nan
    return r1, r2


def _intervals(tape, p0, p1, candidates):
    """The candidates' roots along each edge and the membership between them: (ts (E, W + 1)
    roots padded with 0 before and 1 after, tq (E, W + 1) their quadrics (-1 padding), count (E,)
    of roots, state (E, W) membership per interval, constant past the last one)."""
    e_idx, q_idx = np.nonzero(candidates)
    r1, r2 = line_roots(tape.quadrics[q_idx], p0[e_idx], p1[e_idx])
    t = np.concatenate([r1, r2])
    e = np.concatenate([e_idx, e_idx])
    q = np.concatenate([q_idx, q_idx])
    ok = np.isfinite(t) & (t > 0.0) & (t < 1.0)
    t, e, q = t[ok], e[ok], q[ok]
    order = np.lexsort((t, e))
    t, e, q = t[order], e[order], q[order]
    n = len(p0)
    count = np.bincount(e, minlength=n)
    start = np.concatenate([[0], np.cumsum(count)[:-1]])
    rank = np.arange(len(t)) - start[e]
    width = int(count.max(initial=0)) + 1
    ts = np.ones((n, width + 1))
    ts[:, 0] = 0.0
    ts[e, rank + 1] = t
    valid = np.arange(width)[None, :] <= count[:, None]  # intervals [ts[k], ts[k+1]]
    mid_t = 0.5 * (ts[:, :-1] + ts[:, 1:])
    ee, kk = np.nonzero(valid)
    pts = p0[ee] + mid_t[ee, kk, None] * (p1[ee] - p0[ee])
    state = np.zeros((n, width), dtype=bool)
    state[ee, kk] = contains(tape.ops, tape.quadrics, pts)
    last = state[np.arange(n), count]
    state = np.where(valid, state, last[:, None])  # past the last interval: no more flips
    tq = np.full((n, width + 1), -1, dtype=np.int64)
    tq[e, rank + 1] = q
    return ts, tq, count, state


def thin_stretches(tape, p0, p1, candidates) -> tuple:
    """The stretches of the edges p0 -> p1 between two membership changes: a wall, rod or slot
    the edge crosses, which marching over the edge's two labels cannot see.  Returns (edge,
    quadric it starts on, quadric it ends on, depth), the depth being the first-order
    distance of the stretch's middle from the nearer of the two (a stretch an edge merely
    clips off a curved surface is as deep as its sagitta)."""
    ts, tq, _count, state = _intervals(tape, p0, p1, candidates)
    flips = state[:, 1:] != state[:, :-1]  # flip j: at root j + 1
    e, k = np.nonzero(flips[:, :-1] & flips[:, 1:])  # interval k + 1 between roots k + 1, k + 2
    qa, qb = tq[e, k + 1], tq[e, k + 2]
    if not len(e):
        return e, qa, qb, np.zeros(0)
    mid_t = 0.5 * (ts[e, k + 1] + ts[e, k + 2])
    x = p0[e] + mid_t[:, None] * (p1[e] - p0[e])
    d = np.minimum(first_order_distance(tape.quadrics[qa][:, None], x),
                   first_order_distance(tape.quadrics[qb][:, None], x))
    return e, qa, qb, d


def crossings(tape, p0, p1, in0, candidates):
    """Crossing points of the edges p0 -> p1 (E, 3) whose ends differ in membership (``in0``
    at p0).  ``candidates`` (E, U) bool: the quadrics that may carry the surface on each edge.
    Returns (points (E, 3), quadric (E,), fallbacks: how many needed bisection)."""
    n = len(p0)
    ts, tq, count, state = _intervals(tape, p0, p1, candidates)
    flips = state[:, 1:] != state[:, :-1]
    has = flips.any(axis=1) & (state[:, 0] == in0)
    first = np.argmax(flips, axis=1)  # root number first + 1 in ts
    rows = np.arange(n)
    t_hit = ts[rows, first + 1]
    q_hit = tq[rows, first + 1]
    bad = ~has | (q_hit < 0)
    if bad.any():
        t_hit[bad], q_hit[bad] = _bisect(tape, p0[bad], p1[bad], in0[bad], ts[bad], tq[bad], count[bad], candidates[bad])
    points = p0 + t_hit[:, None] * (p1 - p0)
    return points, q_hit, int(bad.sum())


def _bisect(tape, p0, p1, in0, ts, tq, count, candidates):
    """Crossings by bisection on the membership, snapped to the nearest candidate root."""
    a, b = np.zeros(len(p0)), np.ones(len(p0))
    for _ in range(BISECTION_STEPS):
        m = 0.5 * (a + b)
        same = contains(tape.ops, tape.quadrics, p0 + m[:, None] * (p1 - p0)) == in0
        a, b = np.where(same, m, a), np.where(same, b, m)
    t = 0.5 * (a + b)
    q = np.full(len(p0), -1, dtype=np.int64)
    k = np.arange(ts.shape[1])[None, :]
    real = (k >= 1) & (k <= count[:, None])
    gap = np.where(real, np.abs(ts - t[:, None]), np.inf)
    near = np.argmin(gap, axis=1)
    rows = np.arange(len(p0))
    snap = np.isfinite(gap[rows, near])
    t[snap] = ts[rows, near][snap]
    q[snap] = tq[rows, near][snap]
    if (~snap).any():  # no root inside the edge: the nearest quadric by its first-order distance
        x = p0[~snap] + t[~snap, None] * (p1[~snap] - p0[~snap])
        q[~snap] = _nearest_quadric(tape.quadrics, x, candidates[~snap])
    return t, q


def _nearest_quadric(quadrics, x, candidates):
    xh = np.concatenate([x, np.ones((len(x), 1))], axis=1)
    kx = np.einsum("uij,nj->nui", quadrics, xh)
    val = np.abs(np.einsum("nui,ni->nu", kx, xh))
    grad = 2.0 * np.linalg.norm(kx[..., :3], axis=2)
    with np.errstate(divide="ignore", invalid="ignore"):
        d = np.where(candidates, val / grad, np.inf)
    d = np.where(np.isnan(d), np.inf, d)
    return np.argmin(d, axis=1)
