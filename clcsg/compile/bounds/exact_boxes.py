"""Exact axis-aligned boxes of one quadric literal cut by half-spaces.

:func:`literals_box` gives the exact box of ``{x : s Q(x) <= 0, n_i . x <= d_i}`` (and of each
of its faces) from the candidate extreme points of the Fritz John conditions, so ellipsoids,
finite cylinders and cone frusta under any affine map, and primitives clipped to a box, get
their exact box; :func:`primitive_box` applies it to one primitive's literals.
"""

from __future__ import annotations

from itertools import combinations

import numpy as np

from ...model.csg import _vec3
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
    face = np.empty((n, 2, 3))
    face[:, 0], face[:, 1] = np.inf, -np.inf
    if not quads:
        return result(*_planes_box(N, D, owner, (lo, hi), finite, face))
    box, exact = _quadrics_box(N, D, owner, quads, (lo, hi), finite, face)
    if is_empty(box):
        # the exact boxes of the parts do not meet
        return result(None)
    return result(box, face) if exact else result(box)


def _planes_box(N, D, owner, polytope, finite, face):
    """(box, face boxes or None) of a polytope of half-spaces only: the vertices' box, each
    face's from the vertices on it (``face`` is filled in place)."""
    if not finite:
        return polytope, None
    X, _, _ = _candidates(None, N, D)
    inside, _, on_p = _feasible(None, N, D, X)
    if not inside.any():
        return polytope, None
    box = meet(_box_of(X, inside), polytope)
    for col in range(len(owner)):
        face[owner[col]] = meet(_box_of(X, inside & on_p[:, col]), box)
    return box, face


def _quadrics_box(N, D, owner, quads, polytope, finite, face):
    """(box, exact) of the set with quadratic literals ``quads``: each quadric cut by all the
    half-spaces bounded exactly and the boxes intersected; ``exact`` (one quadric, bounded
    exactly) when ``face`` has been filled with the face boxes."""
    box = polytope
    single = len(quads) == 1
    exact_any = False
    for j, M in quads:
        NN, DD = N, D
        if not finite:
            if not _slab_bounded(M, N, D):
                continue
        elif not single:
            # another quadric may be what bounds the set: add the polytope's box
            bp = _split_literals(_box_literals(polytope))
            NN, DD = np.vstack([N, bp[0]]), np.concatenate([D, bp[1]])
        X, con_q, con_p = _candidates(M, NN, DD)
        inside, on_q, on_p = _feasible(M, NN, DD, X)
        if not inside.any():
            continue
        exact_any = True
        box = meet(box, _box_of(X, inside))
        if single:
            on_q |= con_q
            on_p = on_p | con_p
            face[j] = meet(_box_of(X, inside & on_q), box)
            for col in range(len(owner)):
                face[owner[col]] = meet(_box_of(X, inside & on_p[:, col]), box)
    return box, single and exact_any


def primitive_box(quadrics, region=None):
    """Box (lo, hi) of ONE primitive instance: the intersection of the world-space quadric
    literals ``quadrics`` (solid Q(x) <= 0 each), within ``region`` if given.

    -inf / inf where unbounded, None if provably empty.  Exact (to 1e-9 of the size) for every
    primitive with at most one quadratic literal (box, sphere, ellipsoid, finite cylinder, cone
    frustum, half-space, slab, ...) under any affine map; see :func:`literals_box`.
    """
    return literals_box([(q, 1) for q in quadrics], region)




def kind_boxes(nodes, matrices):
    """Exact boxes (lo, hi) (n, 3) of primitives ``nodes`` under affine ``matrices`` (n, 4, 4)
    in closed form, padded as :func:`literals_box` pads, for boxes, spheres, ellipsoids,
    finite cylinders and cone frusta (in numpy batches per kind), and a mask of the rows
    computed (the other kinds: use :func:`primitive_box`).

    Under x -> L x + t a box's half-extents are |L| s / 2; an ellipsoid's along x_k the norm of
    row k of L diag(radii); a disc of radius r normal to the unit axis w (a cylinder's or a
    frustum's end) has half-extent r sqrt(|L_k|^2 - (L_k . w)^2) along x_k, and a cylinder or
    frustum is the convex hull of its two end discs."""
    n = len(nodes)
    m = np.asarray(matrices, dtype=np.float64).reshape(n, 4, 4)
    lin, t = m[:, :3, :3], m[:, :3, 3]
    lo, hi = np.full((n, 3), np.inf), np.full((n, 3), -np.inf)
    by_kind: dict = {}
    for k, node in enumerate(nodes):
        by_kind.setdefault(node.kind, []).append(k)
    for kind, rows in by_kind.items():
        rows = np.array(rows)
        params = [nodes[k].params for k in rows]
        if kind == "box":
            s = np.array([_vec3(p.get("size", 1.0), "box size") for p in params])
            c = np.array([_vec3(p.get("center", (0, 0, 0)), "box center") for p in params])
            half = 0.5 * np.einsum("nij,nj->ni", np.abs(lin[rows]), s)
            mid = np.einsum("nij,nj->ni", lin[rows], c) + t[rows]
            lo[rows], hi[rows] = mid - half, mid + half
        elif kind in ("sphere", "ellipsoid"):
            key = "radius" if kind == "sphere" else "radii"
            r = np.array([_vec3(p.get(key, 1.0), "radii") for p in params])
            c = np.array([_vec3(p.get("center", (0, 0, 0)), "center") for p in params])
            a = lin[rows] * r[:, None, :]
            half = np.sqrt((a * a).sum(axis=2))
            mid = np.einsum("nij,nj->ni", lin[rows], c) + t[rows]
            lo[rows], hi[rows] = mid - half, mid + half
        elif kind in ("cylinder", "cone"):
            lo[rows], hi[rows] = _frusta_boxes(kind, params, lin[rows], t[rows])
        elif kind == "halfspace":
            lo[rows], hi[rows] = _halfspace_own_boxes(params, m[rows])
            for r in rows.tolist():  # a k-d cell's face plane: its box is the cell
                support = getattr(nodes[r], "support", None)
                if support is not None:
                    lo[r], hi[r] = _hinted(np.array([lo[r], hi[r]]), support, m[r])
    done = np.isin(np.array([node.kind for node in nodes]), list(_CLOSED_FORM)) if n else np.zeros(0, bool)
    size = 1.0 + np.abs(np.where(done[:, None] & np.isfinite(np.concatenate([lo, hi], axis=1)),
                                 np.concatenate([lo, hi], axis=1), 0.0)).max(axis=1, initial=0.0)
    # a box's (a half-space's) sides are its planes: no padding, as literals_box meets a
    # polytope's box with its vertices' (a face shared with a subtracted box must cut exactly)
    pad = np.where(np.array([node.kind in ("box", "halfspace") for node in nodes], dtype=bool), 0.0,
                   _FEASIBLE * size)
    return lo - pad[:, None], hi + pad[:, None], done


_CLOSED_FORM = ("box", "sphere", "ellipsoid", "cylinder", "cone", "halfspace")


def _halfspace_own_boxes(params, m):
    """Boxes of half-spaces n . x <= d under affine maps m (k, 4, 4): all space, except for a
    world normal along one axis k (n_w = L^-T n, d_w = d + n_w . t), bounded on that side at
    d_w / n_w,k."""
    n = np.array([_vec3(p.get("normal", (0, 0, 1)), "normal") for p in params])
    d = np.array([float(p.get("offset", 0.0)) for p in params])
    with np.errstate(all="ignore"):
        nw = np.einsum("nji,nj->ni", np.linalg.inv(m[:, :3, :3]), n)
    dw = d + np.einsum("ni,ni->n", nw, m[:, :3, 3])
    lo, hi = np.full((len(d), 3), -np.inf), np.full((len(d), 3), np.inf)
    axis = np.sum(nw != 0.0, axis=1) == 1
    for r in np.flatnonzero(axis):
        k = int(np.flatnonzero(nw[r])[0])
        if nw[r, k] > 0:
            hi[r, k] = dw[r] / nw[r, k]
        else:
            lo[r, k] = dw[r] / nw[r, k]
    return lo, hi


def _frusta_boxes(kind, params, lin, t):
    """Boxes of finite cylinders or cone frusta (the hull of their two end discs)."""
    h = np.array([float(p.get("height", 1.0)) for p in params])
    if kind == "cylinder":
        r = np.array([float(p.get("radius", 1.0)) for p in params])
        r1 = r2 = r
    else:
        r1 = np.array([float(p.get("r1", 1.0)) for p in params])
        r2 = np.array([float(p.get("r2", 0.0)) for p in params])
    w = np.array([_vec3(p.get("axis", (0, 0, 1)), "axis") for p in params])
    w = w / np.linalg.norm(w, axis=1)[:, None]
    c = np.array([_vec3(p.get("center", (0, 0, 0)), "center") for p in params])
    lw = np.einsum("nij,nj->ni", lin, w)
    half = np.sqrt(np.maximum((lin * lin).sum(axis=2) - lw * lw, 0.0))
    mid = np.einsum("nij,nj->ni", lin, c) + t
    e1, e2 = mid - 0.5 * h[:, None] * lw, mid + 0.5 * h[:, None] * lw
    lo = np.minimum(e1 - r1[:, None] * half, e2 - r2[:, None] * half)
    hi = np.maximum(e1 + r1[:, None] * half, e2 + r2[:, None] * half)
    return lo, hi


def kind_face_boxes(nodes, matrices, lo, hi, done):
    """Per primitive of :func:`kind_boxes` (``lo``, ``hi``, ``done`` its results) the boxes of
    its faces, one per literal in the primitive's order ((k, 2, 3) arrays; None where
    ``done`` is False): a box's faces are its six rectangles; a sphere's or ellipsoid's
    surface, a cylinder's or frustum's side span the whole box; the caps are the end discs."""
    out = [None] * len(nodes)
    for k, node in enumerate(nodes):
        if not done[k]:
            continue
        box = np.array([lo[k], hi[k]])
        m = np.asarray(matrices[k], dtype=np.float64)
        lin, t = m[:3, :3], m[:3, 3]
        p = node.params
        n_lits = len(node.quadrics())
        if node.kind == "box":
            s = _vec3(p.get("size", 1.0), "box size")
            c = _vec3(p.get("center", (0, 0, 0)), "box center")
            faces = []
            for axis in range(3):
                for side in (1, -1):  # the order of the box's literals: +e_k, then -e_k
                    half = np.abs(lin) @ np.where(np.arange(3) == axis, 0.0, s / 2)
                    mid = lin @ (c + side * s[axis] / 2 * np.eye(3)[axis]) + t
                    faces.append((mid - half, mid + half))
            out[k] = np.array(faces)
        elif node.kind in ("cylinder", "cone") and n_lits == 3:
            h = float(p.get("height", 1.0))
            if node.kind == "cylinder" or float(p.get("r1", 1.0)) == float(p.get("r2", 0.0)):
                r1 = r2 = float(p.get("radius", p.get("r1", 1.0)))
            else:
                r1, r2 = float(p.get("r1", 1.0)), float(p.get("r2", 0.0))
            w = _vec3(p.get("axis", (0, 0, 1)), "axis")
            w = w / np.linalg.norm(w)
            lw = lin @ w
            half = np.sqrt(np.maximum((lin * lin).sum(axis=1) - lw * lw, 0.0))
            mid = lin @ _vec3(p.get("center", (0, 0, 0)), "center") + t
            top, bottom = mid + 0.5 * h * lw, mid - 0.5 * h * lw
            caps = _padded(np.array([(top - r2 * half, top + r2 * half), (bottom - r1 * half, bottom + r1 * half)]))
            # a cone's tip is a cap of radius 0: no face (a box around the tip would make the
            # sampler start a task there, on a point where the classification is degenerate)
            for row, r in ((0, r2), (1, r1)):
                if r == 0:
                    caps[row] = (np.full(3, np.inf), np.full(3, -np.inf))
            out[k] = np.concatenate([box[None], caps])
        elif n_lits == 1:
            out[k] = _hinted(box, getattr(node, "face_box", None), m)[None]
    return out


def _hinted(box, face_box, m):
    """``box`` met with the world box of a primitive's own ``face_box`` (lo, hi) under the affine
    map ``m`` (None: no hint): where a mesh's face plane bounds the mesh (a
    :class:`~clcsg.model.polyhedron.FacePlane`)."""
    if face_box is None:
        return box
    lo, hi = face_box
    if np.any(lo > hi):  # none (a k-d split plane bounds no surface)
        return np.array([np.full(3, np.inf), np.full(3, -np.inf)])
    corners = np.array([[(lo, hi)[(c >> i) & 1][i] for i in range(3)] for c in range(8)])
    w = corners @ m[:3, :3].T + m[:3, 3]
    return np.array([np.maximum(box[0], w.min(axis=0)), np.minimum(box[1], w.max(axis=0))])


def _padded(boxes):
    """Boxes (k, 2, 3) padded as :func:`_box_of` pads."""
    size = 1.0 + np.abs(boxes).reshape(len(boxes), -1).max(axis=1)
    pad = _FEASIBLE * size[:, None]
    return np.stack([boxes[:, 0] - pad, boxes[:, 1] + pad], axis=1)


def kind_box(node, matrix):
    """:func:`kind_boxes` of one primitive: (lo, hi), or None for a kind without a closed form."""
    lo, hi, done = kind_boxes([node], np.asarray(matrix, dtype=np.float64)[None])
    return (lo[0], hi[0]) if done[0] else None


def halfspace_boxes(w: np.ndarray, d: np.ndarray, lo: np.ndarray, hi: np.ndarray):
    """Exact boxes (lo, hi) (n, 3) of the half-spaces w . x <= d (w (n, 3), d (n,)) within the
    finite boxes [lo, hi] (n, 3), all at once; empty rows are (inf, -inf).

    The set is a box cut by one plane, so along axis k its extent is an interval: with the
    other coordinates at the corner minimizing their part of w . x (``rest``), x_k ranges over
    the box's [lo_k, hi_k] where w_k x_k <= d - rest, i.e. up to (d - rest) / w_k for w_k > 0
    and down to it for w_k < 0.  The set is empty when even the minimizing corner is outside
    (by more than rounding: a plane touching the box leaves the touched face)."""
    w, d = np.asarray(w, dtype=np.float64), np.asarray(d, dtype=np.float64)
    lo, hi = np.asarray(lo, dtype=np.float64), np.asarray(hi, dtype=np.float64)
    part = np.minimum(w * lo, w * hi)
    rest = part.sum(axis=1, keepdims=True) - part
    with np.errstate(divide="ignore", invalid="ignore"):
        t = (d[:, None] - rest) / w
    out_lo = np.where(w < 0, np.minimum(np.maximum(lo, t), hi), lo)
    out_hi = np.where(w > 0, np.maximum(np.minimum(hi, t), lo), hi)
    # a plane touching the box (to rounding) leaves the face it touches, not nothing
    slack = 1e-12 * (np.abs(d) + np.abs(w).sum(axis=1) * np.maximum(np.abs(lo), np.abs(hi)).max(axis=1))
    empty = (part.sum(axis=1) > d + slack) | np.any(lo > hi, axis=1)
    out_lo[empty], out_hi[empty] = np.inf, -np.inf
    return out_lo, out_hi
