"""Exact axis-aligned boxes of one quadric literal cut by half-spaces.

:func:`literals_box` gives the exact box of ``{x : s Q(x) <= 0, n_i . x <= d_i}`` (and of each
of its faces) from the candidate extreme points of the Fritz John conditions, so ellipsoids,
finite cylinders and cone frusta under any affine map, and primitives clipped to a box, get
their exact box; :func:`primitive_box` applies it to one primitive's literals.
"""

from __future__ import annotations

from itertools import combinations

import numpy as np

from ...model.quadric import Quadric, frame_z_to
from .term_boxes import FAR, term_box

# The box of a compact set S = {x : Q(x) <= 0, n_i . x <= d_i} is given by the extremes of the
# coordinates x_k over S.  A maximizer of the linear function e_k . x satisfies the Fritz John
# condition: e_k is a combination of the gradients of the constraints active there.  With one
# quadric Q (grad Q = 2 (A x - b)) and planes, the active sets give finitely many candidates,
# each a point of a line meeting Q or of three planes:
#
# * Q alone:           A x - b = t e_k, the line through the center in direction A^+ e_k, met
#                      with Q (and the center itself, where grad Q = 0: a cone's apex);
# * Q and plane i:     e_k, n_i, A x - b linearly dependent: (e_k x n_i) . (A x - b) = 0 is a
#                      plane; its line of intersection with plane i, met with Q;
# * Q, planes i and j: the line of the two planes met with Q;
# * planes i, j, l:    the vertex of the three planes.
#
# Where a set of maximizers is not isolated (a cylinder's side along its axis, a face normal
# to e_k) its end points have one more active constraint and are candidates of the next kind.
# The candidates inside S (to a relative 1e-9) are the extreme points of every coordinate, so
# the box of the feasible candidates is the exact box of S (padded by 1e-9 of its size
# against rounding).  The same candidates give the box of each *face* S ∩ {literal = 0}: the
# candidates constructed on that literal, or lying on it.
#
# Compactness comes from the supporting polytope (term_box is finite) or from a slab: Q cut by
# two opposite half-spaces n . x <= d1, -n . x <= d2 is bounded when A restricted to the plane
# n . x = 0 is positive definite (each section is an ellipse): that is how a cone frustum under
# a shear is known to be bounded although its supporting polytope is only the slab.

#: conjunctions with more half-spaces than this are bounded by their polytope only
MAX_EXACT_PLANES = 40

#: relative tolerance of the feasibility test of candidates and of the box padding
_FEASIBLE = 1e-9


def empty_box():
    return np.full(3, np.inf), np.full(3, -np.inf)


def _box_literals(box):
    """Half-space literals x_k <= hi_k, -x_k <= -lo_k for the finite sides of ``box``."""
    if box is None:
        return []
    lo, hi = np.asarray(box[0], dtype=np.float64), np.asarray(box[1], dtype=np.float64)
    out = []
    for k in range(3):
        e = np.zeros(3)
        e[k] = 1.0
        if np.isfinite(hi[k]):
            out.append((Quadric.half_space(e, hi[k]), 1))
        if np.isfinite(lo[k]):
            out.append((Quadric.half_space(-e, -lo[k]), 1))
    return out


def _split_literals(literals):
    """(planes N (p, 3) unit rows, offsets D (p,), plane literal index (p,), quadratic literals
    [(literal index, matrix with the sign applied, unit Frobenius norm)]); None if a literal is
    a positive constant (empty).  A plane literal is n . x <= d; constant literals <= 0 are
    dropped."""
    normals, offsets, owner, quads = [], [], [], []
    for j, (q, s) in enumerate(literals):
        m = s * q.matrix
        scale = np.abs(m).max()
        if scale == 0.0:
            continue
        if np.abs(m[:3, :3]).max() <= 1e-12 * scale:
            g = 2.0 * m[:3, 3]
            gn = np.linalg.norm(g)
            if gn <= 1e-12 * scale:
                if m[3, 3] > 0:
                    return None
                continue
            normals.append(g / gn)
            offsets.append(-m[3, 3] / gn)
            owner.append(j)
        else:
            quads.append((j, m / np.linalg.norm(m)))
    return (np.array(normals, dtype=np.float64).reshape(-1, 3), np.array(offsets, dtype=np.float64),
            np.array(owner, dtype=np.int64), quads)


def _plane_lines(n1, d1, n2, d2):
    """Lines p + t v (unit v) where planes n1 . x = d1 and n2 . x = d2 meet (rows; pairs that are
    nearly parallel are dropped) and the mask of the kept pairs."""
    v = np.cross(n1, n2)
    vv = np.einsum("ij,ij->i", v, v)
    ok = vv > 1e-18 * np.einsum("ij,ij->i", n1, n1) * np.einsum("ij,ij->i", n2, n2)
    v, vv = v[ok], vv[ok]
    p = (d1[ok, None] * np.cross(n2[ok], v) + d2[ok, None] * np.cross(v, n1[ok])) / vv[:, None]
    return p, v / np.sqrt(vv)[:, None], ok


def _line_quadric_points(M, p, v):
    """The points where lines p + t v meet the quadric M (up to two per line, tangencies
    included: a discriminant that is negative by rounding counts as zero), and for each point
    the index of its line."""
    if len(p) == 0:
        return np.zeros((0, 3)), np.zeros(0, dtype=np.int64)
    ph = np.concatenate([p, np.ones((len(p), 1))], axis=1)
    vh = np.concatenate([v, np.zeros((len(v), 1))], axis=1)
    a = np.einsum("ni,ij,nj->n", vh, M, vh)
    h = np.einsum("ni,ij,nj->n", vh, M, ph)
    c = np.einsum("ni,ij,nj->n", ph, M, ph)
    disc = h * h - a * c
    disc = np.where((disc < 0) & (disc > -1e-10 * (h * h + np.abs(a * c))), 0.0, disc)
    with np.errstate(invalid="ignore", divide="ignore", over="ignore"):
        sq = np.sqrt(np.where(disc >= 0.0, disc, np.nan))
        q = -(h + np.where(h >= 0.0, sq, -sq))
        t1 = np.where(np.abs(a) > 1e-14, q / a, np.nan)
        t2 = np.where(q != 0.0, c / q, np.where(np.abs(a) > 1e-14, 0.0, np.nan))
    t = np.concatenate([t1, t2])
    line = np.concatenate([np.arange(len(p)), np.arange(len(p))])
    ok = np.isfinite(t)
    t, line = t[ok], line[ok]
    return p[line] + t[:, None] * v[line], line


def _candidates(M, N, D):
    """Candidate extreme points of {M <= 0, N x <= D} (see the section comment): the points,
    whether each was constructed on the quadric, and on which planes (K, p)."""
    p = len(N)
    pts, on_q, on_p = [], [], []

    def add(x, q_flag, planes):
        pts.append(x)
        on_q.append(np.full(len(x), q_flag))
        on_p.append(planes)

    if M is not None:
        A = M[:3, :3]
        b = -M[:3, 3]
        Ap = np.linalg.pinv(A, rcond=1e-12)
        center = Ap @ b
        add(center[None, :], False, np.zeros((1, p), dtype=bool))
        # Q alone: lines through the center along A^+ e_k
        dirs = Ap.T.copy()
        dn = np.linalg.norm(dirs, axis=1)
        keep = dn > 1e-12 * max(dn.max(), 1e-300)
        if keep.any():
            x, _ = _line_quadric_points(M, np.repeat(center[None, :], keep.sum(), 0), dirs[keep] / dn[keep, None])
            add(x, True, np.zeros((len(x), p), dtype=bool))
        if p:
            # Q and plane i: the plane (A c) . x = c . b with c = e_k x n_i
            E = np.eye(3)
            ii = np.repeat(np.arange(p), 3)
            c = np.cross(np.tile(E, (p, 1)), N[ii])
            w = c @ A
            wn = np.linalg.norm(w, axis=1)
            good = (np.linalg.norm(c, axis=1) > 1e-9) & (wn > 1e-9 * np.abs(A).max())
            if good.any():
                ii, w, wn, c = ii[good], w[good], wn[good], c[good]
                lp, lv, ok = _plane_lines(N[ii], D[ii], w / wn[:, None], (c @ b) / wn)
                x, line = _line_quadric_points(M, lp, lv)
                planes = np.zeros((len(x), p), dtype=bool)
                planes[np.arange(len(x)), ii[ok][line]] = True
                add(x, True, planes)
            # Q, planes i and j
            if p >= 2:
                i, j = np.triu_indices(p, 1)
                lp, lv, ok = _plane_lines(N[i], D[i], N[j], D[j])
                x, line = _line_quadric_points(M, lp, lv)
                planes = np.zeros((len(x), p), dtype=bool)
                planes[np.arange(len(x)), i[ok][line]] = True
                planes[np.arange(len(x)), j[ok][line]] = True
                add(x, True, planes)
    if p >= 3:
        idx = np.array(list(combinations(range(p), 3)))
        T = N[idx]
        det = np.linalg.det(T)
        ok = np.abs(det) > 1e-12
        if ok.any():
            x = np.linalg.solve(T[ok], D[idx][ok][..., None])[..., 0]
            planes = np.zeros((len(x), p), dtype=bool)
            for col in range(3):
                planes[np.arange(len(x)), idx[ok][:, col]] = True
            add(x, False, planes)
    if not pts:
        return np.zeros((0, 3)), np.zeros(0, dtype=bool), np.zeros((0, p), dtype=bool)
    X = np.concatenate(pts)
    finite = np.all(np.isfinite(X), axis=1)
    return X[finite], np.concatenate(on_q)[finite], np.concatenate(on_p)[finite]


def _feasible(M, N, D, X):
    """(inside, on the quadric (K,), on each plane (K, p)) to a tolerance of 1e-9 relative to
    each candidate's own size (and the plane's offset): no scene-wide size is needed, which a
    polytope reaching far out would spoil."""
    scale = 1.0 + np.abs(X).max(axis=1, initial=0.0)
    vp = X @ N.T - D if len(N) else np.zeros((len(X), 0))
    tol_p = _FEASIBLE * (scale[:, None] + np.abs(D)[None, :])
    inside = np.all(vp <= tol_p, axis=1)
    on_p = np.abs(vp) <= tol_p
    if M is None:
        return inside, np.zeros(len(X), dtype=bool), on_p
    xh = np.concatenate([X, np.ones((len(X), 1))], axis=1)
    vq = np.einsum("ni,ij,nj->n", xh, M, xh)
    grad = 2.0 * np.linalg.norm(X @ M[:3, :3] + M[3, :3], axis=1)
    tol_q = _FEASIBLE * scale * grad + 1e-12 * (1.0 + np.einsum("ni,ni->n", X, X))
    return inside & (vq <= tol_q), np.abs(vq) <= tol_q, on_p


def _slab_bounded(M, N, D) -> bool:
    """Whether {M <= 0} between two opposite planes of (N, D) is bounded: A positive definite
    on the planes' directions (every section an ellipse)."""
    A = M[:3, :3]
    amax = np.abs(A).max()
    for i, j in combinations(range(len(N)), 2):
        if N[i] @ N[j] < -1.0 + 1e-9 and D[i] + D[j] >= -_FEASIBLE * (1.0 + abs(D[i])):
            E = frame_z_to(N[i])[:, :2]
            if np.linalg.eigvalsh(E.T @ A @ E).min() > 1e-9 * amax:
                return True
    return False


def _box_of(X, mask):
    """Box of the points X[mask], padded by 1e-9 of their size against rounding."""
    if not mask.any():
        return empty_box()
    lo, hi = X[mask].min(axis=0), X[mask].max(axis=0)
    pad = _FEASIBLE * (1.0 + float(np.abs(np.concatenate([lo, hi])).max()))
    return lo - pad, hi + pad


def meet(a, b):
    return np.maximum(a[0], b[0]), np.minimum(a[1], b[1])


def is_empty(box) -> bool:
    return box is None or bool(np.any(box[0] > box[1]))


def literals_box(literals, region=None, faces: bool = False):
    """Box of the intersection of ``literals`` [(Quadric, sign): solid sign Q(x) <= 0] with the
    box ``region`` ((lo, hi), +-inf allowed; None: everywhere).

    Returns (lo, hi) (+-inf where unbounded), or None if provably empty; with ``faces=True``
    ((lo, hi), face_boxes) where face_boxes (n, 2, 3) bounds the part of the set's boundary on
    each literal (lo > hi: that literal carries none of it).

    The supporting polytope (:func:`term_box`) gives a conservative box and proves emptiness;
    where the set is compact and at most :data:`MAX_EXACT_PLANES` half-spaces cut it, each
    quadratic literal cut by all half-spaces is bounded exactly (section comment above) and the
    boxes are intersected: exact for one quadratic literal (ellipsoids, finite cylinders and
    cone frusta under any affine map, a sphere cut by a rotated box), a superset otherwise.
    """
    literals = list(literals)
    n = len(literals)

    def result(box, face=None):
        if not faces:
            return box
        if box is None:
            return None
        if face is None:
            face = np.repeat(np.array(box)[None], n, axis=0)
        return box, face

    parts = _split_literals(literals)
    if parts is None:
        return result(None)
    N, D, owner, quads = parts
    reg = None
    if region is not None:
        reg = np.clip(np.array(region, dtype=np.float64).reshape(2, 3), -FAR, FAR)
        if np.any(reg[0] > reg[1]):
            return result(None)
    tb = term_box(literals, reg)
    if tb is None:
        return result(None)
    lo, hi = np.asarray(tb[0], dtype=np.float64), np.asarray(tb[1], dtype=np.float64)
    if region is not None:
        # the region's finite sides are constraints (not faces)
        rp = _split_literals(_box_literals(region))
        N = np.vstack([N, rp[0]])
        D = np.concatenate([D, rp[1]])
    if len(N) > MAX_EXACT_PLANES:
        return result((lo, hi))
    # a polytope that reaches far out (a slab cut by the far box, the elliptic cylinder of a
    # cone around such a slab) proves nothing about compactness, and its size is not the
    # scene's
    finite = bool(np.all(np.abs(np.concatenate([lo, hi])) < 1e-3 * FAR))
    n_planes = len(owner)
    face = np.empty((n, 2, 3))
    face[:, 0], face[:, 1] = np.inf, -np.inf
    if not quads:
        if not finite:
            return result((lo, hi))
        X, _, _ = _candidates(None, N, D)
        inside, _, on_p = _feasible(None, N, D, X)
        if not inside.any():
            return result((lo, hi))
        box = meet(_box_of(X, inside), (lo, hi))
        for col in range(n_planes):
            face[owner[col]] = meet(_box_of(X, inside & on_p[:, col]), box)
        return result(box, face)
    box = (lo, hi)
    single = len(quads) == 1
    exact_any = False
    for j, M in quads:
        NN, DD = N, D
        if not finite:
            if not _slab_bounded(M, N, D):
                continue
        elif not single:
            # another quadric may be what bounds the set: add the polytope's box
            bp = _split_literals(_box_literals((lo, hi)))
            NN, DD = np.vstack([N, bp[0]]), np.concatenate([D, bp[1]])
        X, con_q, con_p = _candidates(M, NN, DD)
        inside, on_q, on_p = _feasible(M, NN, DD, X)
        if not inside.any():
            continue
        exact_any = True
        qbox = _box_of(X, inside)
        box = meet(box, qbox)
        if single:
            on_q |= con_q
            on_p = on_p | con_p
            face[j] = meet(_box_of(X, inside & on_q), box)
            for col in range(n_planes):
                face[owner[col]] = meet(_box_of(X, inside & on_p[:, col]), box)
    if is_empty(box):
        # the exact boxes of the parts do not meet
        return result(None)
    if not (single and exact_any):
        return result(box)
    return result(box, face)


def primitive_box(quadrics, region=None):
    """Box (lo, hi) of ONE primitive instance: the intersection of the world-space quadric
    literals ``quadrics`` (solid Q(x) <= 0 each), within ``region`` if given.

    -inf / inf where unbounded, None if provably empty.  Exact (to 1e-9 of the size) for every
    primitive with at most one quadratic literal (box, sphere, ellipsoid, finite cylinder, cone
    frustum, half-space, slab, ...) under any affine map; see :func:`literals_box`.
    """
    return literals_box([(q, 1) for q in quadrics], region)


