"""Conservative axis-aligned boxes of literals and of intersection terms (the DNF's terms).

A literal is the solid ``{x : s Q(x) <= 0}``.  Two kinds of literals bound space:

* half-spaces (A = 0): the plane itself;
* convex quadric solids: in the principal frame ``sum_m lam_m z_m^2 + 2 beta_m z_m + gamma <= 0``
  with every non-zero lam_m > 0.  Without linear terms (ellipsoids, elliptic cylinders,
  slabs) the support function in a direction n orthogonal to the null axes is
  ``n.q + sqrt(-gamma sum_m (n.u_m)^2 / lam_m)`` (empty if gamma > 0); with a linear term
  beta_k on a null axis (paraboloids) the solid lies in ``sign(beta_k) z_k <= -gamma / (2|beta_k|)``.

A term's bound is the bounding box of the polytope cut out by all these supporting
half-spaces (vertex enumeration: every triple of planes, kept where it satisfies all others).
That polytope contains the term's solid, so the box is conservative; an empty polytope proves
the term empty.  Unbounded polytopes are detected with a far box.
"""

from __future__ import annotations

from itertools import combinations

import numpy as np

from ...model.quadric import Quadric
from ..quadric_frames import principal_frame
#: far box used to detect unbounded polytopes
FAR = 1e9
_WORLD = np.eye(3)


def supporting_planes(q: Quadric, sign: int) -> tuple[np.ndarray, np.ndarray] | None:
    """Half-spaces n.x <= d (rows) that contain the literal's solid; None if it is empty.

    Non-convex solids give no planes (shape (0, 3) and (0,)).
    """
    sq = Quadric(sign * q.matrix)
    f = principal_frame(sq)
    lam = f.lam
    if np.all(lam == 0.0):
        # half-space: 2 beta . z + gamma <= 0 in the frame; beta is along u_3
        g = 2.0 * (f.U @ f.beta)  # world-space normal: Q = g.(x - q) + gamma
        gn = np.linalg.norm(g)
        if gn == 0.0:
            return None if f.gamma > 0 else (np.zeros((0, 3)), np.zeros(0))
        n = g / gn
        return n[None, :], np.array([n @ f.center - f.gamma / gn])
    if np.any(lam < 0.0):
        return np.zeros((0, 3)), np.zeros(0)
    normals, offsets = [], []
    null = lam == 0.0
    lin = np.flatnonzero(null & (f.beta != 0.0))
    if len(lin):
        k = lin[0]
        n = np.sign(f.beta[k]) * f.U[:, k]
        normals.append(n)
        offsets.append(n @ f.center - f.gamma / (2.0 * abs(f.beta[k])))
        return np.array(normals), np.array(offsets)
    if f.gamma > 0.0:
        return None  # sum lam z^2 <= -gamma < 0 is empty
    return ellipse_support(f.center, f.U[:, ~null], lam[~null], -f.gamma)


def ellipse_support(center, P, lam, rhs) -> tuple[np.ndarray, np.ndarray]:
    """Supporting half-spaces of {x : sum_m lam_m (u_m . (x - center))^2 <= rhs} (columns u_m of
    P, lam_m > 0; an ellipsoid, or an elliptic cylinder along the axes P leaves out), in the
    directions of P's axes and of the world axes projected onto their span:
    n . x <= n . center + sqrt(rhs sum_m (n . u_m)^2 / lam_m)."""
    dirs = [P[:, m] for m in range(P.shape[1])]
    for e in _WORLD:
        p = P @ (P.T @ e)
        if np.linalg.norm(p) > 1e-9:
            dirs.append(p / np.linalg.norm(p))
    N = np.array([s * n for n in dirs for s in (1.0, -1.0)])
    h = N @ center + np.sqrt(rhs * np.sum((N @ P) ** 2 / lam, axis=1))
    return N, h


def polytope_vertices(normals: np.ndarray, offsets: np.ndarray, far: float = FAR):
    """(vertices, (lo, hi)) of {x : normals x <= offsets} cut by the far box; None if empty.

    Coordinates of lo/hi are +-inf along axes where the polytope reaches the far box.
    """
    box_n = np.vstack([_WORLD, -_WORLD])
    N = np.vstack([normals.reshape(-1, 3), box_n])
    d = np.concatenate([offsets.reshape(-1), np.full(6, far)])
    # the tolerance follows the caller's planes, not the far box
    scale = max(np.abs(offsets[np.isfinite(offsets)]).max(initial=1.0), 1e-300)
    idx = np.array(list(combinations(range(len(N)), 3)))
    M = N[idx]  # (K, 3, 3)
    rhs = d[idx]
    det = np.linalg.det(M)
    ok = np.abs(det) > 1e-12
    if not ok.any():
        return None
    pts = np.linalg.solve(M[ok], rhs[ok][..., None])[..., 0]
    # relative to the caller's planes, and to each vertex's own size: vertices on the far box
    # carry rounding errors of ~1e-16 * far
    tol = 1e-9 * scale + 1e-12 * np.abs(pts).max(axis=1, keepdims=True)
    feasible = np.all(pts @ N.T <= d + tol, axis=1)
    if not feasible.any():
        return None
    v = pts[feasible]
    lo, hi = v.min(0), v.max(0)
    lo = np.where(lo <= -0.5 * far, -np.inf, lo)
    hi = np.where(hi >= 0.5 * far, np.inf, hi)
    return v, (lo, hi)


def literal_box(q: Quadric, sign: int):
    """Axis-aligned box of a literal's solid (+-inf where unbounded); None if empty."""
    planes = supporting_planes(q, sign)
    if planes is None:
        return None
    n, d = planes
    lo = np.full(3, -np.inf)
    hi = np.full(3, np.inf)
    if len(n) == 0:
        return lo, hi
    for k in range(3):
        # planes that are (exactly) axis-aligned bound that axis directly
        axis_aligned = np.all(np.abs(np.delete(n, k, axis=1)) < 1e-12, axis=1)
        up = axis_aligned & (n[:, k] > 0)
        dn = axis_aligned & (n[:, k] < 0)
        if up.any():
            hi[k] = np.min(d[up] / n[up, k])
        if dn.any():
            lo[k] = np.max(d[dn] / n[dn, k])
    return lo, hi


def _hyperbolic_cone(q: Quadric, sign: int):
    """(frame, k) for a literal sum_pos lam z^2 - |lam_k| z_k^2 + gamma <= 0 (double cones and
    hyperboloid insides): bounded across u_k wherever |z_k| is bounded.  None otherwise."""
    f = principal_frame(Quadric(sign * q.matrix))
    neg = np.flatnonzero(f.lam < 0.0)
    if len(neg) != 1 or np.any(f.lam == 0.0):
        return None
    return f, int(neg[0])


def _dedupe(N, d):
    key = np.round(N, 12)
    order = np.lexsort((d, *key.T[::-1]))
    N, d, key = N[order], d[order], key[order]
    keep = np.ones(len(N), dtype=bool)
    keep[1:] = np.any(key[1:] != key[:-1], axis=1)
    N, d = N[keep], d[keep]
    if len(N) > 120:
        # enumeration would be too slow; fall back to the axis-aligned planes only
        aligned = np.sum(np.abs(N) > 1e-12, axis=1) == 1
        N, d = N[aligned], d[aligned]
    return N, d


_MEMO: dict = {}
_MEMO_SIZE = 200_000


def _memo(fn, q: Quadric, sign: int):
    """``fn(q, sign)`` remembered by the literal's matrix: the tree bounds ask for the same
    literals' planes and frames many times (passes, faces, clipped leaves).  Callers must not
    modify the results."""
    key = (fn.__name__, q.matrix.tobytes(), int(sign))
    try:
        return _MEMO[key]
    except KeyError:
        pass
    if len(_MEMO) >= _MEMO_SIZE:
        _MEMO.clear()
    out = _MEMO[key] = fn(q, sign)
    return out


def term_box(literals: list[tuple[Quadric, int]], user_bound=None):
    """Bounding box (lo, hi) of a term's solid, None if provably empty.

    First the polytope of all supporting planes (and the user bound).  Then each double cone
    or hyperboloid literal whose axis extent |z_k| <= H is bounded by that polytope lies in
    the elliptic cylinder sum_pos lam z^2 <= |lam_k| H^2 - gamma; its supporting planes are
    added and the polytope is cut again.
    """
    normals, offsets = [], []
    for q, s in literals:
        p = _memo(supporting_planes, q, s)
        if p is None:
            return None
        if len(p[0]):
            normals.append(p[0])
            offsets.append(p[1])
    if user_bound is not None:
        lo, hi = np.asarray(user_bound, dtype=np.float64)
        normals.append(np.vstack([_WORLD, -_WORLD]))
        offsets.append(np.concatenate([hi, -lo]))
    cones = [c for c in (_memo(_hyperbolic_cone, q, s) for q, s in literals) if c is not None]
    for _ in range(2):
        if not normals:
            return np.full(3, -np.inf), np.full(3, np.inf)
        N, d = _dedupe(np.vstack(normals), np.concatenate(offsets))
        res = polytope_vertices(N, d)
        if res is None:
            return None
        verts, box = res
        if np.all(np.isfinite(box[0])) and np.all(np.isfinite(box[1])) or not cones:
            return box
        added = False
        for f, k in cones:
            zk = (verts - f.center) @ f.U[:, k]
            H = np.abs(zk).max()
            if H >= 0.5 * FAR:
                continue
            rhs = -f.lam[k] * H * H - f.gamma
            if rhs < 0:
                return None
            pos = [m for m in range(3) if m != k]
            n, h = ellipse_support(f.center, f.U[:, pos], f.lam[pos], rhs)
            normals.append(n)
            offsets.append(h)
            added = True
        if not added:
            return box
    N, d = _dedupe(np.vstack(normals), np.concatenate(offsets))
    res = polytope_vertices(N, d)
    return None if res is None else res[1]


