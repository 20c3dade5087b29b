"""Boxes of many quadric surfaces at once, and the other per-quadric facts the guard needs.

:func:`surface_boxes` is, per quadric Q,
the intersection of the boxes of its two literals (s Q <= 0 for s = +-1), each the box that
:func:`clcsg.compile.bounds.term_boxes.literal_box` derives from the literal's supporting
half-spaces (:func:`~clcsg.compile.bounds.term_boxes.supporting_planes`), exactly as there:

* a half-space (A = 0): its plane n . x <= d bounds axis k when n is along e_k;
* a literal whose quadratic part has a negative eigenvalue (s Q of a cone, a hyperboloid, the
  outside of an ellipsoid): no half-space, the box is all of space;
* a paraboloid's solid (a null axis u_k with beta_k != 0): the plane sign(beta_k) u_k . x <=
  u_k . q - gamma / (2 |beta_k|);
* gamma > 0 with every lam_m >= 0: the solid is empty (and so is the surface);
* an ellipsoid or elliptic cylinder, sum_m lam_m z_m^2 <= -gamma over its non-null axes P:
  the support n . x <= n . q + sqrt(-gamma sum_m (n . u_m)^2 / lam_m) in the directions +-u_m
  and +-(the world axes projected onto span P); a direction along e_k bounds axis k.

:func:`quadric_kinds` is the plane / convex / saddle class of the area bounds
(:mod:`clcsg.compile.bounds.estimates`), and :func:`surface_meets` the test that a box may
hold part of the surface Q = 0 (exact for planes, the conservative distance at the box center
against its half-diagonal otherwise), both for many quadrics and boxes in one pass.
"""

from __future__ import annotations

import numpy as np

from ..quadric_frames import mat_vec, principal_frames
from ...model.quadric import ray_distance

#: components below this count as zero when a plane's normal is tested for being axis-aligned
ALIGNED = 1e-12

PLANE, CONVEX, SADDLE = 0, 1, 2


def _bound_by_planes(lo, hi, rows, n, d):
    """Tighten boxes ``rows`` (lo, hi (N, 3), in place) by the half-spaces n . x <= d that are
    along a world axis (n (k, 3), d (k,), rows (k,) the box each belongs to)."""
    for k in range(3):
        others = [j for j in range(3) if j != k]
        aligned = np.all(np.abs(n[:, others]) < ALIGNED, axis=1)
        up = aligned & (n[:, k] > 0)
        dn = aligned & (n[:, k] < 0)
        np.minimum.at(hi[:, k], rows[up], d[up] / n[up, k])
        np.maximum.at(lo[:, k], rows[dn], d[dn] / n[dn, k])


def literal_boxes(matrices, sign: int):
    """(lo, hi (n, 3), empty (n,)): the box of each literal ``sign`` Q <= 0 (+-inf where
    unbounded), as :func:`~clcsg.compile.bounds.term_boxes.literal_box`; ``empty``: the solid
    is provably empty."""
    M = float(sign) * np.asarray(matrices, dtype=np.float64).reshape(-1, 4, 4)
    n = len(M)
    U, lam, center, beta, gamma = principal_frames(M)
    lo, hi = np.full((n, 3), -np.inf), np.full((n, 3), np.inf)
    empty = np.zeros(n, dtype=bool)
    null = lam == 0.0
    plane = null.all(axis=1)
    negative = (lam < 0.0).any(axis=1) & ~plane
    lin = null & (beta != 0.0)
    para = lin.any(axis=1) & ~plane & ~negative
    rest = ~plane & ~negative & ~para
    # half-spaces: 2 beta . z + gamma <= 0, the world normal g = 2 U beta
    i = np.flatnonzero(plane)
    g = 2.0 * mat_vec(U[i], beta[i])
    gn = np.linalg.norm(g, axis=1)
    flat = gn == 0.0
    empty[i[flat & (gamma[i] > 0)]] = True
    i, g, gn = i[~flat], g[~flat], gn[~flat]
    nrm = g / gn[:, None]
    _bound_by_planes(lo, hi, i, nrm, np.einsum("ni,ni->n", nrm, center[i]) - gamma[i] / gn)
    # paraboloids: the first null axis with a linear term
    i = np.flatnonzero(para)
    k = np.argmax(lin[i], axis=1)
    bk = beta[i, k]
    nrm = np.sign(bk)[:, None] * U[i, :, k]
    _bound_by_planes(lo, hi, i, nrm, np.einsum("ni,ni->n", nrm, center[i]) - gamma[i] / (2.0 * np.abs(bk)))
    # ellipsoids and elliptic cylinders
    empty[rest & (gamma > 0.0)] = True
    i = np.flatnonzero(rest & (gamma <= 0.0))
    if len(i):
        Ui, keep, rhs = U[i], ~null[i], -gamma[i]
        inv_lam = np.where(keep, 1.0 / np.where(keep, lam[i], 1.0), 0.0)
        proj = np.einsum("nim,nm,njm->nij", Ui, keep.astype(np.float64), Ui)  # P P^T
        pn = np.linalg.norm(proj, axis=1)  # (n, 3): |P P^T e_j| per world axis j
        dirs = np.concatenate([Ui.transpose(0, 2, 1), (proj / np.where(pn > 0, pn, 1.0)[:, None, :]).transpose(0, 2, 1)],
                              axis=1)  # (n, 6, 3): u_m, then the projected e_j
        valid = np.concatenate([keep, pn > 1e-9], axis=1)
        s = np.einsum("nkj,njm->nkm", dirs, Ui)
        spread = np.sqrt(rhs[:, None] * np.sum(s * s * inv_lam[:, None, :], axis=2))
        nc = np.einsum("nkj,nj->nk", dirs, center[i])
        rows = np.repeat(i, 6).reshape(-1, 6)[valid]
        dv, nv, sv = dirs[valid], nc[valid], spread[valid]
        _bound_by_planes(lo, hi, np.concatenate([rows, rows]), np.concatenate([dv, -dv]),
                         np.concatenate([nv + sv, -nv + sv]))
    lo[empty], hi[empty] = np.inf, -np.inf
    return lo, hi, empty


def surface_boxes(matrices):
    """(lo, hi (n, 3), empty (n,)): per quadric, the box of its surface (the intersection of
    its two literals' boxes); ``empty``: one literal's solid is empty, so the surface is too."""
    lo1, hi1, e1 = literal_boxes(matrices, 1)
    lo2, hi2, e2 = literal_boxes(matrices, -1)
    return np.maximum(lo1, lo2), np.minimum(hi1, hi2), e1 | e2


def quadric_kinds(matrices):
    """(kind (n,) PLANE / CONVEX / SADDLE, |unit normal| (n, 3) of the planes, NaN where a
    plane has no normal): a plane when A vanishes against the largest coefficient, convex when
    A is semidefinite (one side of the surface is convex), else a saddle."""
    M = np.asarray(matrices, dtype=np.float64).reshape(-1, 4, 4)
    A = M[:, :3, :3]
    scale = np.abs(M).max(axis=(1, 2), initial=0.0)
    kind = np.full(len(M), SADDLE, dtype=np.int8)
    plane = np.abs(A).max(axis=(1, 2), initial=0.0) <= 1e-14 * scale
    kind[plane] = PLANE
    b = M[:, :3, 3]
    nb = np.linalg.norm(b, axis=1)
    normal = np.full((len(M), 3), np.nan)
    ok = plane & (nb > 0)
    normal[ok] = np.abs(b[ok]) / nb[ok, None]
    i = np.flatnonzero(~plane)
    if len(i):
        lam = np.linalg.eigvalsh(0.5 * (A[i] + A[i].transpose(0, 2, 1)))
        tol = 1e-12 * np.abs(lam).max(axis=1)
        convex = np.all(lam >= -tol[:, None], axis=1) | np.all(lam <= tol[:, None], axis=1)
        kind[i[convex]] = CONVEX
    return kind, normal


def surface_meets(matrices, q, lo, hi):
    """Mask of the boxes (lo, hi (N, 3)) that the surface of quadric ``q`` (N,) of
    ``matrices`` may meet: for planes the range of the linear function over the box holds 0,
    for other quadrics the conservative distance at the center is at most the half-diagonal."""
    M = np.asarray(matrices, dtype=np.float64).reshape(-1, 4, 4)
    M = 0.5 * (M + M.transpose(0, 2, 1))
    q = np.asarray(q, dtype=np.int64)
    c, half = 0.5 * (lo + hi), 0.5 * (hi - lo)
    scale = np.abs(M).max(axis=(1, 2), initial=0.0)
    flat = np.abs(M[:, :3, :3]).max(axis=(1, 2), initial=0.0) <= 1e-14 * scale
    out = np.zeros(len(q), dtype=bool)
    p = flat[q]
    if p.any():
        g = 2.0 * M[q[p], :3, 3]
        mid = np.einsum("ni,ni->n", c[p], g) + M[q[p], 3, 3]
        spread = np.einsum("ni,ni->n", half[p], np.abs(g))
        out[p] = np.abs(mid) <= spread + 1e-12 * (scale[q[p]] + np.abs(mid))
    s = ~p
    if s.any():
        u = np.flatnonzero(~flat)
        lam = np.zeros((len(M), 3))
        if len(u):
            lam[u] = np.linalg.eigvalsh(M[u, :3, :3])
        qs, x = q[s], c[s]
        A, b = M[qs, :3, :3], -M[qs, :3, 3]
        Ax = mat_vec(A, x)
        f = np.einsum("ni,ni->n", x, Ax) - 2.0 * np.einsum("ni,ni->n", x, b) + M[qs, 3, 3]
        g = 2.0 * np.linalg.norm(Ax - b, axis=1)
        d = ray_distance(f, g, lam[qs, 0], lam[qs, 2])
        r = np.linalg.norm(half[s], axis=1)
        out[s] = ~(np.abs(d) > r * (1 + 1e-9) + 1e-12)
    return out
