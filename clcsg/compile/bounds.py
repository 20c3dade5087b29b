"""Conservative axis-aligned bounds of literals and of intersection terms.

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

On top of that (for the pipeline that works on the CSG tree instead of the DNF):

* :func:`literals_box` / :func:`primitive_box`: exact boxes of one quadric literal cut by
  half-spaces (candidate extreme points from the Fritz John conditions), so ellipsoids, finite
  cylinders and cone frusta under any affine map, and primitives clipped to a box, get their
  exact box, plus the box of every face;
* :func:`tree_bounds` / :func:`shape_bound`: the bound of a CSG graph computed on the graph
  (iterative bottom-up / top-down passes over (node, transform, polarity) instances, then a
  conservative-distance refinement of the root box), and each primitive instance's box;
* :func:`quadric_regions`: per quadric, the boxes where its surface can carry CSG surface, for
  the resource guard (:func:`clcsg.sampling.guard.estimate_regions`).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from itertools import combinations

import numpy as np

from ..errors import SceneError, UnboundedError
from ..model.csg import Complement, Difference, Intersection, Primitive, Shape, Transformed, Union
from ..model.quadric import Quadric, frame_z_to
from .frames import principal_frame

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


# =============================================================================================
# Exact boxes of one quadric literal cut by half-spaces
# =============================================================================================
#
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


def _empty_box():
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
        return _empty_box()
    lo, hi = X[mask].min(axis=0), X[mask].max(axis=0)
    pad = _FEASIBLE * (1.0 + float(np.abs(np.concatenate([lo, hi])).max()))
    return lo - pad, hi + pad


def _meet(a, b):
    return np.maximum(a[0], b[0]), np.minimum(a[1], b[1])


def _is_empty(box) -> bool:
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
        box = _meet(_box_of(X, inside), (lo, hi))
        for col in range(n_planes):
            face[owner[col]] = _meet(_box_of(X, inside & on_p[:, col]), box)
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
        box = _meet(box, qbox)
        if single:
            on_q |= con_q
            on_p = on_p | con_p
            face[j] = _meet(_box_of(X, inside & on_q), box)
            for col in range(n_planes):
                face[owner[col]] = _meet(_box_of(X, inside & on_p[:, col]), box)
    if _is_empty(box):
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


# =============================================================================================
# Bounds on the CSG graph
# =============================================================================================
#
# The graph is walked once (iteratively) into *instances*: a node under one accumulated world
# transform M and one polarity (complements pushed to the leaves, De Morgan), memoized on
# (id(node), M, negated), so a sub-graph shared under the same transform is one instance.
# Every instance is a leaf (a primitive, possibly negated), an AND or an OR:
#
#     union        -> OR of the operands         (negated: AND of the negated operands)
#     intersection -> AND of the operands        (negated: OR of the negated operands)
#     A - B - C    -> AND of A, ~B, ~C           (negated: OR of ~A, B, C)
#
# Each instance i gets a box B_i and a region R_i, with the invariant
#
#     S_i ∩ R_i ⊂ B_i ⊂ R_i          (S_i: the instance's solid, R_root: the user bound)
#
# bottom-up: a leaf's box is the exact box of the primitive within R_i (:func:`primitive_box`
# with the region's planes: a sphere under an intersection with a rotated box is cut exactly);
# a negated leaf's box is R_i without the slabs of it that lie inside the (convex) primitive
# (a box lies inside a convex solid iff its 8 corners do); an OR's box is the union of its
# operands' boxes, an AND's their intersection, cut the same way by its negated (subtracted)
# convex primitives; all intersected with R_i.
#
# top-down: R_i = B_i ∩ (union of the boxes of i's parents): the part of an operand outside
# its parent's box does not matter to the parent.  Then bottom-up again with the new regions
# (a union under an intersection shrinks to the union of its operands' cut boxes), repeated
# while anything tightens (at most MAX_PASSES bottom-up passes).
#
# Both passes keep the invariant (S_P ∩ R_P lies in the old B_P, which lies in every child's
# R), so the root box contains the solid (within the user bound), and every point of the CSG
# surface lies on the boundary of a primitive instance *inside that instance's box*: the
# regions the resource guard needs (:func:`quadric_regions`).
#
# Last, boxes cannot see what a difference removes from inside its first operand, nor how
# little of several curved solids overlaps.  The root box is shrunk by the conservative
# signed distance of the whole graph (max over AND, min over OR of the literals' conservative
# distances, eqs. 8-12): cells of an adaptive grid where that distance exceeds the cell's
# half-diagonal hold no point of the solid (:func:`_refine_by_distance`).

#: bottom-up passes (the first one plus refinements while they tighten something)
MAX_PASSES = 3

#: primitive kinds whose solid is convex (a box inside one is inside if its corners are)
CONVEX_KINDS = frozenset({"box", "sphere", "ellipsoid", "cylinder", "cone", "halfspace", "slab"})

_LEAF, _AND, _OR = 0, 1, 2


@dataclass
class PrimitiveInstance:
    """One primitive under one world transform and polarity, with where it matters.

    ``quadrics`` are the world-space literals of the primitive's own solid (inside Q <= 0,
    not complemented even when ``negated``).  ``box`` bounds the part of the primitive's
    boundary that can carry CSG surface (the exact box of the primitive within the instance's
    region; None: none of it can); ``face_boxes`` (n, 2, 3) does the same per quadric (lo > hi:
    that face carries none).
    """

    node: object  # the Primitive
    matrix: np.ndarray  # (4, 4) world transform x -> M x
    negated: bool
    quadrics: tuple
    box: np.ndarray | None  # (2, 3)
    face_boxes: np.ndarray | None  # (n, 2, 3)

    def literals(self, add) -> list[tuple[int, int]]:
        """(index, sign) of each quadric in a caller's table: ``add(matrix) -> (index, sign)``
        (e.g. ``QuadricTable.add`` of the tape compiler)."""
        return [tuple(add(q.matrix))[:2] for q in self.quadrics]


@dataclass
class TreeBounds:
    """What :func:`tree_bounds` finds: the scene bound and the primitive instances' boxes."""

    bound: np.ndarray  # (2, 3); zeros when empty
    empty: bool
    _instances: list | None = field(default=None, repr=False)
    stats: dict = field(default_factory=dict)

    @property
    def instances(self) -> list:
        """The :class:`PrimitiveInstance` of every leaf instance, in post-order (computed on
        first access: the face boxes cost one exact box per instance)."""
        if self._instances is None:
            self._instances = self._make_instances()
        return self._instances


def _resolve(node, m, neg):
    """Skip Transformed and Complement edges: (node, world matrix, negated)."""
    while True:
        if isinstance(node, Transformed):
            m = m @ node.matrix
            node = node.operand
        elif isinstance(node, Complement):
            neg = not neg
            node = node.operand
        else:
            return node, m, neg


def _operands(node, neg):
    """(kind, [(child, negated)]) of an inner node after pushing the complement."""
    if isinstance(node, Union):
        return (_AND if neg else _OR), [(c, neg) for c in node.operands]
    if isinstance(node, Intersection):
        return (_OR if neg else _AND), [(c, neg) for c in node.operands]
    if isinstance(node, Difference):
        kids = [(node.operands[0], neg)] + [(c, not neg) for c in node.operands[1:]]
        return (_OR if neg else _AND), kids
    return None, None


class _Graph:
    """Instances in post-order (children before parents)."""

    def __init__(self, shape, source):
        self.kind: list[int] = []
        self.kids: list[list[int]] = []
        self.node: list = []
        self.matrix: list = []
        self.neg: list[bool] = []
        index: dict = {}
        root = _resolve(shape, np.eye(4), False)
        stack = [(root, None)]
        while stack:
            (node, m, neg), pending = stack.pop()
            key = (id(node), m.tobytes(), neg)
            if key in index:
                continue
            if isinstance(node, Primitive):
                index[key] = self._add(_LEAF, [], node, m, neg)
                continue
            kind, ops = _operands(node, neg)
            if kind is None:
                raise SceneError(f"{source}: not a CSG node: {type(node).__name__}")
            if pending is None:
                kids = [_resolve(c, m, n) for c, n in ops]
                stack.append(((node, m, neg), kids))
                for k in reversed(kids):
                    if (id(k[0]), k[1].tobytes(), k[2]) not in index:
                        stack.append((k, None))
            else:
                ids = [index[(id(k[0]), k[1].tobytes(), k[2])] for k in pending]
                index[key] = self._add(kind, ids, node, m, neg)
        self.root = len(self.kind) - 1
        self.parents: list[list[int]] = [[] for _ in self.kind]
        for i, ks in enumerate(self.kids):
            for k in ks:
                self.parents[k].append(i)

    def _add(self, kind, kids, node, m, neg) -> int:
        self.kind.append(kind)
        self.kids.append(kids)
        self.node.append(node)
        self.matrix.append(m)
        self.neg.append(neg)
        return len(self.kind) - 1


_EVERYTHING = (np.full(3, -np.inf), np.full(3, np.inf))


def _union_boxes(boxes):
    boxes = [b for b in boxes if not _is_empty(b)]
    if not boxes:
        return _empty_box()
    return np.min([b[0] for b in boxes], axis=0), np.max([b[1] for b in boxes], axis=0)


def _norm_box(b):
    """(lo, hi) with every empty box as (inf, -inf)."""
    if _is_empty(b):
        return _empty_box()
    return np.asarray(b[0], dtype=np.float64), np.asarray(b[1], dtype=np.float64)


def _same(a, b) -> bool:
    a, b = _norm_box(a), _norm_box(b)
    with np.errstate(invalid="ignore"):
        d = np.abs(np.concatenate([a[0] - b[0], a[1] - b[1]]))
    d = np.where(np.isnan(d), 0.0, d)  # inf - inf: the same infinity
    scale = 1.0 + np.abs(np.concatenate([a[0], a[1]]))
    scale = np.where(np.isfinite(scale), scale, 1.0)
    return bool(np.all(d <= 1e-9 * scale))


def _contains_box(outer, inner) -> bool:
    return bool(np.all(outer[0] <= inner[0]) and np.all(inner[1] <= outer[1]))


def _cut_by_convex(box, mats, cutter_box):
    """``box`` without the slabs of it that lie inside the convex solid {Q_m <= 0 for all m}
    (``mats`` (n, 4, 4), unit norm), for the difference box ∩ ~solid.  A slab [t, hi_k] of the
    box lies in the convex solid iff its 8 corners do.  Corners on the solid's surface count
    as inside to 1e-12 (coincident faces, as in a box minus a box sharing its side faces): what
    is lost is a sliver of that relative width, made by rounding only.  The cut end is found
    by bisection.  None if the whole box is inside (the difference is empty there)."""
    lo, hi = box[0].copy(), box[1].copy()
    if not (np.all(np.isfinite(lo)) and np.all(np.isfinite(hi))):
        return lo, hi

    def inside(l, h):
        c = np.array([[(l, h)[(i >> k) & 1][k] for k in range(3)] for i in range(8)])
        ch = np.concatenate([c, np.ones((8, 1))], axis=1)
        v = np.einsum("ni,mij,nj->nm", ch, mats, ch)
        return bool(np.all(v <= 1e-12 * (1.0 + np.einsum("ni,ni->n", c, c))[:, None]))

    for _ in range(2):
        changed = False
        for k in range(3):
            for side in (1, 0):
                # the face on this side must lie in the cutter's box first (cheap)
                fl, fh = lo.copy(), hi.copy()
                if side:
                    fl[k] = hi[k]
                else:
                    fh[k] = lo[k]
                if not (_contains_box(cutter_box, (fl, fh)) and inside(fl, fh)):
                    continue
                if inside(lo, hi):
                    return None
                a, b = (lo[k], hi[k]) if side else (hi[k], lo[k])  # a: not inside, b: inside
                for _ in range(48):
                    t = 0.5 * (a + b)
                    sl, sh = lo.copy(), hi.copy()
                    if side:
                        sl[k] = t
                    else:
                        sh[k] = t
                    if inside(sl, sh):
                        b = t
                    else:
                        a = t
                if side:
                    hi[k] = b
                else:
                    lo[k] = b
                changed = True
        if not changed:
            break
    return lo, hi


def tree_bounds(shape, user_bound=None, source: str = "scene") -> TreeBounds:
    """Bound of the solid of ``shape`` computed on the CSG graph, and the boxes of its
    primitive instances (see the section comment: bottom-up / top-down passes over the
    instances, no recursion, linear in the number of distinct (node, transform, polarity)).

    ``user_bound`` ((lo, hi) corners) is intersected with everything.  An unbounded solid
    without a user bound raises :class:`UnboundedError`; an empty one gives ``empty=True``
    and a zero bound.  ``instances`` (with the face boxes the guard needs) are computed on
    first access.
    """
    if not isinstance(shape, Shape):
        raise SceneError(f"{source}: expected a CSG shape, got {type(shape).__name__}")
    ub = None
    if user_bound is not None:
        ub = np.asarray(user_bound, dtype=np.float64)
        if ub.shape != (2, 3) or not np.all(np.isfinite(ub)) or np.any(ub[1] <= ub[0]):
            raise SceneError(f"{source}: bound must be two finite corners lo < hi, got {ub.tolist()}")
        ub = (ub[0], ub[1])
    g = _Graph(shape, source)
    n = len(g.kind)
    leaves = _Leaves(g, source)

    region = [_EVERYTHING] * n
    if ub is not None:
        region[g.root] = ub
    box = [_EVERYTHING] * n
    passes = 0
    for passes in range(1, MAX_PASSES + 1):
        tightened = False
        for i in range(n):
            r = region[i]
            if _is_empty(r):
                b = _empty_box()
            elif g.kind[i] == _LEAF:
                b = leaves.box(i, r)
            elif g.kind[i] == _OR:
                b = _union_boxes([box[k] for k in g.kids[i]])
            else:
                b = r
                for k in g.kids[i]:
                    b = _meet(b, box[k])
                for k in g.kids[i]:
                    if _is_empty(b):
                        break
                    if g.kind[k] == _LEAF and g.neg[k]:
                        b = leaves.cut(k, b)
            b = _norm_box(_meet(b, r))
            b = _norm_box(_meet(b, box[i]))  # never looser than before
            if not _same(b, box[i]):
                tightened = True
            box[i] = b
        if passes == MAX_PASSES or (passes > 1 and not tightened):
            break
        # top-down: the region of an instance is its box within the union of its parents'
        new_region = [None] * n
        for i in range(n - 1, -1, -1):
            if i == g.root:
                r = box[i] if ub is None else _norm_box(_meet(box[i], ub))
            else:
                r = _norm_box(_meet(box[i], _union_boxes([new_region[p] for p in g.parents[i]])))
            new_region[i] = r
        if passes > 1 and all(_same(a, b) for a, b in zip(new_region, region)):
            break
        region = new_region

    root_box = box[g.root]
    if ub is not None:
        root_box = _norm_box(_meet(root_box, ub))
    refine_rounds = 0
    if not _is_empty(root_box) and np.all(np.isfinite(root_box[0])) and np.all(np.isfinite(root_box[1])):
        root_box, refine_rounds = _refine_by_distance(g, leaves, root_box)
        box[g.root] = root_box
    empty = _is_empty(root_box)
    if not empty and not (np.all(np.isfinite(root_box[0])) and np.all(np.isfinite(root_box[1]))):
        axes = "".join(a for a, lo, hi in zip("xyz", root_box[0], root_box[1])
                       if not (np.isfinite(lo) and np.isfinite(hi)))
        raise UnboundedError(f"{source}: the solid is unbounded (no finite bound along {axes}); "
                             "intersect it with a box or give a bound")
    bound = np.zeros((2, 3)) if empty else np.array(root_box)
    stats = {"instances": n, "primitive_instances": sum(k == _LEAF for k in g.kind), "passes": passes,
             "distance_rounds": refine_rounds}
    out = TreeBounds(bound, empty, None, stats)
    out._make_instances = lambda: _instances(g, leaves, box, ub, empty)
    return out


class _Leaves:
    """World quadrics of the leaf instances, their own boxes (computed when first needed) and
    the box operations on them."""

    def __init__(self, g: _Graph, source: str):
        self.g = g
        self._quads: dict[int, tuple] = {}
        self._mats: dict[int, np.ndarray] = {}
        self._own: dict[int, tuple] = {}
        self._cache: dict = {}
        for i in range(len(g.kind)):
            if g.kind[i] != _LEAF:
                continue
            node, m = g.node[i], g.matrix[i]
            try:
                with np.errstate(over="raise", invalid="raise"):
                    qs = tuple(q.transform(m) for q in node.quadrics())
            except (ValueError, FloatingPointError, ArithmeticError):
                raise SceneError(f"{source}: {node!r}: its quadric overflows float64 after the transforms "
                                 "(sizes or offsets far too large)") from None
            self._quads[i] = qs

    def quads(self, i):
        return self._quads[i]

    def mats(self, i):
        m = self._mats.get(i)
        if m is None:
            m = self._mats[i] = np.array([q.matrix / np.linalg.norm(q.matrix) for q in self._quads[i]]).reshape(-1, 4, 4)
        return m

    def distance(self, i, x):
        """(n, N) conservative signed distances of leaf i's literals at ``x``: the batched
        :meth:`Quadric.distance` (eqs. 8-12), with the eigenvalue ranges computed once."""
        ev = self._eig.get(i) if hasattr(self, "_eig") else None
        if ev is None:
            if not hasattr(self, "_eig"):
                self._eig = {}
            lam = np.array([q.eigenvalue_range() for q in self._quads[i]]).reshape(-1, 2)
            mats = np.array([q.matrix for q in self._quads[i]]).reshape(-1, 4, 4)
            ev = self._eig[i] = (mats, lam[:, 0], lam[:, 1])
        mats, lam_min, lam_max = ev
        xh = np.concatenate([x, np.ones((len(x), 1))], axis=1)
        mx = np.matmul(xh[None], mats.transpose(0, 2, 1))  # (n, N, 4): M x^ (M symmetric)
        f = (mx * xh[None]).sum(axis=2)
        g = 2.0 * np.sqrt((mx[:, :, :3] ** 2).sum(axis=2))
        inside = f < 0.0
        lam = np.where(inside, lam_max[:, None], -lam_min[:, None])
        af = np.abs(f)
        disc = g * g + 4.0 * lam * af
        with np.errstate(invalid="ignore", divide="ignore"):
            t = np.where(disc >= 0.0, 2.0 * af / (g + np.sqrt(np.maximum(disc, 0.0))), np.inf)
        t = np.where(af == 0.0, 0.0, t)
        return np.where(inside, -t, t)

    def own(self, i):
        """The exact box of the primitive itself (not negated)."""
        b = self._own.get(i)
        if b is None:
            b = self._own[i] = _norm_box(primitive_box(self._quads[i]))
        return b

    def box(self, i, r):
        """Box of leaf i's solid (negated if it is) within region r."""
        key = (i, r[0].tobytes(), r[1].tobytes())
        b = self._cache.get(key)
        if b is not None:
            return b
        qs = self._quads[i]
        if not self.g.neg[i]:
            own = self.own(i)
            b = own if _contains_box(r, own) else _norm_box(primitive_box(qs, r))
        elif self.g.node[i].kind in CONVEX_KINDS:
            b = self.cut(i, r)  # r without the slabs inside the primitive
        elif len(qs) == 1 and np.all(np.isfinite(r[0])) and np.all(np.isfinite(r[1])):
            b = _norm_box(literals_box([(qs[0], -1)], r))
        else:
            b = r
        self._cache[key] = b
        return b

    def cut(self, i, b):
        """``b`` without the slabs that lie inside leaf i's convex primitive (b ∩ ~primitive)."""
        if self.g.node[i].kind not in CONVEX_KINDS or _is_empty(b):
            return b
        if not (np.all(np.isfinite(b[0])) and np.all(np.isfinite(b[1]))):
            return b
        # cheap rejection: a face of b inside the primitive needs corners of b inside it
        corners = np.array([[(b[0], b[1])[(c >> k) & 1][k] for k in range(3)] for c in range(8)])
        ch = np.concatenate([corners, np.ones((8, 1))], axis=1)
        v = np.einsum("ni,mij,nj->nm", ch, self.mats(i), ch)
        if np.sum(np.all(v <= 1e-12 * (1.0 + np.einsum("ni,ni->n", corners, corners))[:, None], axis=1)) < 4:
            return b
        return _norm_box(_cut_by_convex(b, self.mats(i), self.own(i)))


#: the conservative-distance refinement of the root box: initial grid (cells per axis),
#: subdivision rounds, cells split per side and round, and the smallest cell (fraction of the box)
REFINE_CELLS = 8
REFINE_ROUNDS = 40
REFINE_SPLIT = 32
REFINE_MIN = 0.002


def _tree_distance(g: _Graph, leaves: _Leaves, x: np.ndarray) -> np.ndarray:
    """Conservative signed distance of the solid at points ``x`` (N, 3), evaluated on the
    instances: a literal's conservative distance (:meth:`Quadric.distance`: its magnitude
    never exceeds the distance to the surface, negative inside), max over an AND, min over
    an OR, negated for a negated primitive.  Where the value is d > 0 no point of the solid is
    within d (the operand of an AND that is > d is empty in that ball; all operands of an OR
    are).  Arrays are dropped after their last parent has used them."""
    n = len(g.kind)
    last = [max(p) if p else n for p in g.parents]
    vals: dict[int, np.ndarray] = {}
    for i in range(n):
        if g.kind[i] == _LEAF:
            d = leaves.distance(i, x).max(axis=0)
            v = -d if g.neg[i] else d
        else:
            kids = [vals[k] for k in g.kids[i]]
            if g.kind[i] == _AND:
                v = np.max(kids, axis=0) if kids else np.full(len(x), -np.inf)
            else:
                v = np.min(kids, axis=0) if kids else np.full(len(x), np.inf)
            for k in g.kids[i]:
                if last[k] == i:
                    vals.pop(k, None)
        vals[i] = v
    return vals[g.root]


def _refine_by_distance(g: _Graph, leaves: _Leaves, box):
    """The root box shrunk to the cells that the conservative distance does not prove empty.

    A cell is empty if the distance at its center exceeds its half-diagonal.  The box starts
    as a REFINE_CELLS^3 grid; then, for each of the six sides, the undecided cells reaching
    farthest out on that side are split in 8 (at most REFINE_SPLIT per side and round, down to
    REFINE_MIN of the box), until the farthest cell on every side is of the smallest size or
    REFINE_ROUNDS have passed.  The result is the box of the undecided cells: conservative
    (only cells proven empty are dropped), and close to the solid where the conservative
    distance is (within a few smallest cells).  This cuts what the boxes of the operands
    cannot: the parts of a difference's first operand that the subtracted solids remove,
    intersections of curved solids, (nearly) empty parts.  Returns (box, rounds).
    """
    lo, hi = np.array(box[0], dtype=np.float64), np.array(box[1], dtype=np.float64)
    size = hi - lo
    if np.any(size <= 0.0):
        return (lo, hi), 0
    slack = 1e-12 * (1.0 + float(np.abs(np.concatenate([lo, hi])).max()))

    def undecided(c, h):
        d = _tree_distance(g, leaves, c)
        r = np.linalg.norm(h, axis=1)
        return ~(d > r * (1.0 + 1e-9) + slack)

    def evaluate(c, h):
        """(undecided mask, distance) of cells (centers c, half-sizes h)."""
        d = _tree_distance(g, leaves, c)
        r = np.linalg.norm(h, axis=1)
        return ~(d > r * (1.0 + 1e-9) + slack), d

    k = REFINE_CELLS
    idx = np.stack(np.meshgrid(*[np.arange(k)] * 3, indexing="ij"), axis=-1).reshape(-1, 3)
    half = np.tile(size / (2 * k), (len(idx), 1))
    cen = lo + (2 * idx + 1) * half
    keep, dist = evaluate(cen, half)
    cen, half, dist = cen[keep], half[keep], dist[keep]
    smallest = REFINE_MIN * size / 2
    offsets = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)], dtype=np.float64)
    rounds = 0
    for rounds in range(1, REFINE_ROUNDS + 1):
        if not len(cen):
            return _empty_box(), rounds
        big = np.any(half > smallest * (1 + 1e-9), axis=1)
        r = np.linalg.norm(half, axis=1)
        chosen = np.zeros(len(cen), dtype=bool)
        for axis in range(3):
            for sign in (1.0, -1.0):
                reach = sign * cen[:, axis] + half[:, axis]
                # the solid certainly reaches a center where the distance is <= 0 (inside), and a
                # cell's far face where the whole cell is inside: cells reaching no farther than
                # that (plus the smallest size) cannot move this side
                sure = np.concatenate([sign * cen[dist <= 0.0, axis], reach[dist <= -r]])
                floor = sure.max() if len(sure) else -np.inf
                want = big & (reach > floor + 2.0 * smallest[axis])
                if not want.any():
                    continue
                # farthest first; among equals the smallest cells, so one column goes deep
                cand = np.flatnonzero(want)
                order = cand[np.lexsort((half[cand].max(axis=1), -reach[cand]))]
                chosen[order[:REFINE_SPLIT]] = True
        if not chosen.any():
            break
        h = half[chosen] / 2
        c = (cen[chosen][:, None, :] + offsets[None] * h[:, None, :]).reshape(-1, 3)
        h = np.repeat(h, 8, axis=0)
        ok, d = evaluate(c, h)
        cen = np.vstack([cen[~chosen], c[ok]])
        half = np.vstack([half[~chosen], h[ok]])
        dist = np.concatenate([dist[~chosen], d[ok]])
    if not len(cen):
        return _empty_box(), rounds
    return (np.maximum(lo, (cen - half).min(axis=0)), np.minimum(hi, (cen + half).max(axis=0))), rounds


def _instances(g: _Graph, leaves: _Leaves, box, ub, empty) -> list:
    out = []
    for i in range(len(g.kind)):
        if g.kind[i] != _LEAF:
            continue
        qs = leaves.quads(i)
        b = box[i]
        if ub is not None:
            b = _norm_box(_meet(b, ub))
        if empty or _is_empty(b):
            surf = None
        else:
            # a region holding the whole primitive adds no constraint (and no planes to cost)
            clip = None if _contains_box(b, leaves.own(i)) else b
            surf = literals_box([(q, 1) for q in qs], clip, faces=True)
        if surf is None or _is_empty(surf[0]):
            out.append(PrimitiveInstance(g.node[i], g.matrix[i], g.neg[i], qs, None, None))
        else:
            out.append(PrimitiveInstance(g.node[i], g.matrix[i], g.neg[i], qs, np.array(surf[0]),
                                         np.asarray(surf[1])))
    return out


def shape_bound(shape, user_bound=None, source: str = "scene") -> tuple[np.ndarray, bool]:
    """(bound (2, 3), empty) of the solid of ``shape``, computed on the CSG graph.

    The bound contains the solid (intersected with ``user_bound`` if given); ``empty`` is True
    when the solid is provably empty, and the bound is then zeros.  Raises
    :class:`~clcsg.errors.UnboundedError` for an unbounded solid without a user bound.  See
    :func:`tree_bounds` (which also returns the primitive instances' boxes).
    """
    tb = tree_bounds(shape, user_bound, source)
    return tb.bound, tb.empty


# =============================================================================================
# Regions of the quadrics, for the resource guard
# =============================================================================================


def quadric_regions(table, instances, bound=None) -> list[np.ndarray]:
    """For every quadric of ``table`` the boxes where its surface can carry CSG surface.

    The CSG surface lies on the union of the primitives' boundaries, and the part of it on
    quadric q lies on the faces (boundary parts on q) of the primitive instances holding q,
    inside those instances' boxes.  So the boxes of those faces, intersected with the instance
    boxes and the scene bound, cover it; their areas bound the work of sampling q.

    ``table``: (U, 4, 4) the caller's unique (canonical) quadric matrices.
    ``instances``: one item per primitive instance, either an object with ``literals`` and
    ``box`` attributes (and optionally ``face_boxes``) or a tuple ``(literals, box)`` /
    ``(literals, box, face_boxes)``:

    * ``literals``: (index into table, sign) of the primitive's own literals (solid
      sign K(x) <= 0), in the primitive's order;
    * ``box``: (2, 3) where the instance's boundary can carry CSG surface (the
      :attr:`PrimitiveInstance.box` of :func:`tree_bounds`, or just the primitive's box), None
      for nowhere;
    * ``face_boxes``: (n, 2, 3) per literal (lo > hi: none); computed here when missing.

    ``bound``: (2, 3) scene bound or None.  Returns a list of U arrays of shape (k_u, 2, 3)
    (k_u = 0: the quadric carries no surface).
    """
    table = np.asarray(table, dtype=np.float64).reshape(-1, 4, 4)
    out: list[list] = [[] for _ in range(len(table))]
    bnd = None if bound is None else (np.asarray(bound[0], dtype=np.float64), np.asarray(bound[1], dtype=np.float64))
    for item in instances:
        if isinstance(item, tuple):
            lits, box = item[0], item[1]
            faces = item[2] if len(item) > 2 else None
        else:
            lits, box = item.literals, item.box
            faces = getattr(item, "face_boxes", None)
        if box is None or _is_empty(box):
            continue
        box = (np.asarray(box[0], dtype=np.float64), np.asarray(box[1], dtype=np.float64))
        if bnd is not None:
            box = _meet(box, bnd)
            if _is_empty(box):
                continue
        lits = [(int(q), int(s)) for q, s in lits]
        if faces is None:
            res = literals_box([(Quadric(table[q]), s) for q, s in lits], box, faces=True)
            if res is None:
                continue
            faces = res[1]
        faces = np.asarray(faces, dtype=np.float64)
        for (q, _), f in zip(lits, faces):
            r = _meet((f[0], f[1]), box)
            if not _is_empty(r):
                out[q].append(np.array(r))
    return [np.array(r, dtype=np.float64).reshape(-1, 2, 3) for r in out]


def unique_quadrics(instances, same: float = 1e-9):
    """(table (U, 4, 4), [(literals, box, face_boxes)]) for :class:`PrimitiveInstance` objects:
    their world quadrics stored once in canonical form (:meth:`Quadric.canonical`: unit norm,
    first non-zero coefficient positive; coefficients within ``same`` are one quadric), for
    callers without a quadric table of their own (tests, benchmarks)."""
    coefs: list[np.ndarray] = []
    grid: dict = {}

    def add(m):
        k, s = Quadric(m).canonical()
        c = k.coefficients()
        key = tuple(np.round(c / (4 * same)).astype(np.int64))
        for d in _neighbours(key):
            for idx in grid.get(d, ()):
                if np.abs(coefs[idx] - c).max() < same:
                    return idx, s
        coefs.append(c)
        grid.setdefault(key, []).append(len(coefs) - 1)
        return len(coefs) - 1, s

    items = [(inst.literals(add), inst.box, inst.face_boxes) for inst in instances]
    table = np.array([Quadric.from_coefficients(c).matrix for c in coefs]).reshape(-1, 4, 4)
    return table, items


def _neighbours(key):
    yield key
    for i in range(len(key)):
        for d in (-1, 1):
            yield key[:i] + (key[i] + d,) + key[i + 1:]
