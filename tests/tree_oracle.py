"""A float64 numpy oracle that evaluates the CSG *tree* itself (no DNF, no package compiler).

Semantics (closed solids).  A :class:`~clcsg.model.csg.Primitive` is ``{x : Q_i(x) <= 0 for
all its quadrics}``; Union = any operand, Intersection = all, Difference = the first minus all
others, Complement = not, ``Transformed(c, M)`` holds x iff ``M^-1 x`` is in c.  A leaf's world
matrix is ``M_root ... M_parent`` and its world quadrics are ``M^-T Q M^-1``.  Graphs may be
deep DAGs: every traversal uses an explicit stack and shared sub-graphs are evaluated once per
(node, world matrix).  Membership is the Boolean formula of the closed leaves' sign tests (as in
``clcsg.contains``), so a point on the surface of a subtracted solid is outside.

Literals.  Every world quadric Q is written ``Q = s |Q| K`` with K canonical (unit Frobenius
norm, first coefficient with ``|c| > 1e-13`` positive, order xx xy xz xw yy yz yw zz zw ww) and
K looked up in a :class:`QuadricTable` (tolerance 1e-9): the literal ``Q <= 0`` is ``s K <= 0``,
one sign test per table quadric and point, so coincident faces of different solids (facing
either way) are one quadric.  Values come from one matrix product: ``K(p) = mono(p) . coef``.

Surface.  For a point p on K, the solid just on K's negative / positive side is found exactly
by substitution (:func:`membership_sides`): every literal on K is the constant it has on that
side (``s K <= 0`` holds on the negative side iff s = +1), every other literal is its sign test
at p.  p is on the CSG surface, carried by K, iff the two sides differ.  A point on the surface
is on the boundary of some instance carrying K whose other literals hold at p (otherwise no
instance value could change across K); that necessary condition prunes candidates cheaply.

Public API::

    instances(shape) -> list[Instance]              quadric_table(shape) -> QuadricTable
    contains(shape, points) -> bool                 membership_sides(shape, points, K) -> (neg, pos)
    on_surface(shape, points, K, tol=0.0) -> bool   primitive_at(shape, points, K, tol=0.0) -> int
    surface_points(shape, bound, ...) -> SurfacePoints   lines(bound, ...) -> (origins, dirs)
    cast(shape, origins, directions, bound=None) -> Hits
    fragile(shape, origins, directions, rel=1e-9, scale=None, bound=None) -> bool
    sample_residuals(shape, positions, K, tol=None) -> (on_quadric, on_csg)

``K`` arguments are one 4x4 matrix or one per point (N, 4, 4), in any scale or orientation.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from clcsg.model.csg import Complement, Difference, Intersection, Primitive, Transformed, Union
from clcsg.model.quadric import Quadric

ZERO = 1e-13  # coefficients below this (unit-norm matrix) do not decide the canonical sign
MATCH_TOL = 1e-9  # max abs difference of canonical coefficients for "the same quadric"
_IU = np.triu_indices(4)  # xx xy xz xw yy yz yw zz zw ww
_CELLS = 1 << 22  # points x quadrics per evaluation chunk


def canonical(matrix):
    """(key (10,), sign s) with ``matrix = s |matrix|_F K`` and key the coefficients of K."""
    m = np.asarray(matrix, dtype=np.float64)
    m = 0.5 * (m + m.T)
    k = m[_IU] / np.linalg.norm(m)
    s = 1 if k[np.flatnonzero(np.abs(k) > ZERO)[0]] > 0 else -1
    return s * k, s


def _matrix(key):
    m = np.zeros((4, 4))
    m[_IU] = key
    return m + m.T - np.diag(np.diag(m))


def _mono(P):
    """Monomials with ``K(p) = mono(p) @ key``: x^2 2xy 2xz 2x y^2 2yz 2y z^2 2z 1."""
    x, y, z = P[:, 0], P[:, 1], P[:, 2]
    one = np.ones(len(P))
    return np.column_stack([x * x, 2 * x * y, 2 * x * z, 2 * x, y * y, 2 * y * z, 2 * y, z * z, 2 * z, one])


class QuadricTable:
    """Canonical quadrics K_0, K_1, ...; ``representatives[u]`` is the first matrix added for
    K_u times its sign (so it is a positive multiple of K_u): the oracle evaluates that, so
    that a point exactly on a leaf's world surface tests exactly 0 where float64 allows."""

    def __init__(self, matrices=()):
        self._keys = np.zeros((16, 10))
        self._reps = []
        self.n = 0
        for m in matrices:
            self.add(m)

    def __len__(self):
        return self.n

    @property
    def keys(self):
        return self._keys[: self.n]

    @property
    def matrices(self):
        """The canonical (unit Frobenius norm) matrices K_u, (U, 4, 4)."""
        return np.array([_matrix(k) for k in self.keys]).reshape(-1, 4, 4)

    @property
    def representatives(self):
        return np.array(self._reps).reshape(-1, 4, 4)

    def _find(self, key, s):
        if self.n:
            for sign in (1, -1):  # -key: only if a near-1e-13 first coefficient flipped the sign
                d = np.abs(self.keys - sign * key).max(axis=1)
                j = int(np.argmin(d))
                if d[j] <= MATCH_TOL:
                    return j, s * sign
        return -1, s

    def add(self, matrix):
        """(id, sign) of ``matrix``, appending its canonical form if it is new."""
        key, s = canonical(matrix)
        i, s2 = self._find(key, s)
        if i >= 0:
            return i, s2
        if self.n == len(self._keys):
            self._keys = np.concatenate([self._keys, np.zeros_like(self._keys)])
        self._keys[self.n] = key
        m = np.asarray(matrix, dtype=np.float64)
        self._reps.append(s * 0.5 * (m + m.T))
        self.n += 1
        return self.n - 1, s

    def id_of(self, matrix):
        """(id, sign) with ``matrix ~ sign * |matrix| * K_id``; id -1 if not in the table."""
        return self._find(*canonical(matrix))

    def match(self, matrices):
        """Table ids of other quadric matrices (U, 4, 4), -1 where none matches."""
        mats = np.asarray(matrices, dtype=np.float64).reshape(-1, 4, 4)
        return np.array([self.id_of(m)[0] for m in mats], dtype=np.int64)


@dataclass
class Instance:
    """A primitive placed in the world: ``quadrics`` are world matrices (inside Q <= 0),
    ``canonical`` their (key, sign) pairs."""

    index: int
    node: Primitive
    matrix: np.ndarray
    quadrics: list
    canonical: list
    color: tuple


# -- the flattened tree --------------------------------------------------------------------------

_OPS = {Union: "or", Intersection: "and", Difference: "diff", Complement: "not"}


class _Tree:
    """Instances, table and a post-order program over the distinct (node, world matrix) pairs.

    Program entries are (op, out slot, args, slots to free); ``prim`` args is an instance.
    """

    def __init__(self, shape):
        self.instances, self.program, self.root, self.nslots = [], [], None, 0
        memo = {}
        stack = [(shape, np.eye(4), None)]
        while stack:
            node, M, child_keys = stack.pop()
            key = (id(node), M.tobytes())
            if child_keys is not None:  # all children done
                if isinstance(node, Transformed):
                    memo[key] = memo[child_keys[0]]
                else:
                    # subclasses (a construction is a union) take their base's operation
                    op = next(_OPS[c] for c in type(node).__mro__ if c in _OPS) if node.children() else "none"
                    memo[key] = self._emit(op, [memo[k] for k in child_keys])
                continue
            if key in memo:
                continue
            if isinstance(node, Primitive):
                eye = np.array_equal(M, np.eye(4))
                qs = [q.matrix.copy() if eye else q.transform(M).matrix for q in node.quadrics()]
                inst = Instance(len(self.instances), node, M, qs, [canonical(q) for q in qs], node.color)
                self.instances.append(inst)
                memo[key] = self._emit("prim", inst.index)
                continue
            if not isinstance(node, (Transformed, Complement, Union, Intersection, Difference)):
                raise TypeError(f"not a CSG node: {type(node).__name__}")
            cm = M @ node.matrix if isinstance(node, Transformed) else M
            kids = node.children()
            stack.append((node, M, [(id(c), cm.tobytes()) for c in kids]))
            stack.extend((c, cm, None) for c in reversed(kids))
        self.root = memo[(id(shape), np.eye(4).tobytes())]
        last = {}
        for i, (op, _, args, _) in enumerate(self.program):
            for a in args if op != "prim" else ():
                last[a] = i
        for a, i in last.items():
            if a != self.root:
                self.program[i][3].append(a)
        self.table = QuadricTable()
        self.lits = [np.array([self.table.add(q) for q in i.quadrics]).reshape(-1, 2) for i in self.instances]
        U = self.U = len(self.table)
        Ks = self.K = self.table.representatives
        self.keys = Ks[:, _IU[0], _IU[1]]
        self.gkeys = np.array([(K[:3].T @ K[:3])[_IU] for K in Ks]).reshape(-1, 10)  # |grad|^2 / 4
        self.cols = [np.where(l[:, 1] > 0, l[:, 0], U + l[:, 0]) for l in self.lits]
        self.carriers = {}
        for inst, l in zip(self.instances, self.lits):
            for u in dict.fromkeys(l[:, 0].tolist()):
                self.carriers.setdefault(u, []).append(inst.index)

    def _emit(self, op, args):
        self.program.append((op, self.nslots, args, []))
        self.nslots += 1
        return self.nslots - 1

    def values(self, P, cols=slice(None), grad=False):
        """K_u(p) for the table quadrics ``cols`` (and |grad K_u(p)| if ``grad``)."""
        X = _mono(P)
        V = X @ self.keys[cols].T
        if not grad:
            return V
        return V, 2.0 * np.sqrt(np.maximum(X @ self.gkeys[cols].T, 0.0))

    def evaluate(self, L, switched=None):
        """Membership from the literal table L (n, 2U): column u is ``K_u <= 0``, U + u is
        ``K_u >= 0``; one pass over the program, slots freed after their last use.
        ``switched``: (instance, row mask): that instance's membership complemented there."""
        vals = [None] * self.nslots
        for op, out, args, free in self.program:
            if op == "prim":
                v = L[:, self.cols[args]].all(axis=1)
                if switched is not None and switched[0] == args:
                    v ^= switched[1]
            elif op == "none":
                v = np.zeros(len(L), dtype=bool)
            elif op == "not":
                v = ~vals[args[0]]
            else:
                v = vals[args[0]].copy()
                for a in args[1:]:
                    if op == "or":
                        v |= vals[a]
                    elif op == "and":
                        v &= vals[a]
                    else:
                        v &= ~vals[a]
            vals[out] = v
            for a in free:
                vals[a] = None
        return vals[self.root]

    def sides(self, V, k, amb=None, force=False):
        """(neg, pos) membership with literals on K_k (k per row, -1: none) substituted;
        ambiguous literals (mask amb) forced to ``force``."""
        le, ge = V <= 0.0, V >= 0.0
        if amb is not None:
            le[amb] = ge[amb] = force
        L = np.concatenate([le, ge], axis=1)
        r = np.flatnonzero(k >= 0)
        L[r, k[r]], L[r, self.U + k[r]] = True, False
        neg = self.evaluate(L)
        if not len(r):
            return neg, neg
        L[r, k[r]], L[r, self.U + k[r]] = False, True
        return neg, self.evaluate(L)

    def flags(self, P, k, tol=0.0):
        """(neg, exact, loose, strict) per point on K_k: membership on K's negative side;
        sides differ exactly / for the exact or either forced evaluation / for all three."""
        out = np.zeros((4, len(P)), dtype=bool)
        step = max(256, _CELLS // max(self.U, 1))
        for a in range(0, len(P), step):
            p, kk = P[a : a + step], k[a : a + step]
            if tol > 0.0:
                V, g = self.values(p, grad=True)
                aV = np.abs(V)
                with np.errstate(divide="ignore", invalid="ignore"):
                    amb = np.where(g > 0, aV / g, np.where(aV == 0, 0.0, np.inf)) < tol
                r = np.flatnonzero(kk >= 0)
                amb[r, kk[r]] = False
            else:
                V, amb = self.values(p), None
            neg, pos = self.sides(V, kk)
            exact = neg != pos
            loose, strict = exact.copy(), exact.copy()
            rows = np.flatnonzero(amb.any(axis=1)) if amb is not None else []
            for force in (True, False):
                if len(rows):
                    n2, p2 = self.sides(V[rows], kk[rows], amb[rows], force)
                    loose[rows] |= n2 != p2
                    strict[rows] &= n2 != p2
            out[:, a : a + step] = neg, exact, loose, strict
        return out

    def first_carrier(self, P, k, tol=0.0):
        """First instance (tree order) carrying table quadric k (one k for all points) whose
        other literals hold: ``s K_u(p) <= tol |grad K_u(p)|``; -1 if none."""
        out = np.full(len(P), -1, dtype=np.int64)
        carriers = self.carriers.get(int(k), []) if k >= 0 else []
        if not carriers or not len(P):
            return out
        cols = sorted({u for i in carriers for u in self.lits[i][:, 0].tolist() if u != k})
        pos = {u: j for j, u in enumerate(cols)}
        V, g = self.values(P, cols, grad=True) if tol > 0 else (self.values(P, cols), 0.0)
        lim = tol * g if tol > 0 else np.zeros_like(V)
        for i in carriers:
            other = self.lits[i][self.lits[i][:, 0] != k]
            j = [pos[u] for u in other[:, 0]]
            ok = (other[:, 1] * V[:, j] <= lim[:, j]).all(axis=1)
            out[(out < 0) & ok] = i
        return out

    def bounding_carrier(self, P, k, tol=0.0):
        """The colour rule: the first instance (tree order) carrying table quadric k whose other
        literals hold (as :meth:`first_carrier`) and whose membership, complemented on one
        side of K_k with the other literals substituted as in :meth:`sides`, changes the
        solid's membership on that side; where none does, :meth:`first_carrier`."""
        first = self.first_carrier(P, k, tol)
        out = np.full(len(P), -1, dtype=np.int64)
        carriers = self.carriers.get(int(k), []) if k >= 0 else []
        if len(carriers) < 2 or not len(P):
            return first
        step = max(256, _CELLS // max(self.U, 1))
        for a in range(0, len(P), step):
            p = P[a : a + step]
            V = self.values(p)
            lim = tol * self.values(p, grad=True)[1] if tol > 0 else np.zeros_like(V)
            le, ge = V <= 0.0, V >= 0.0
            tables = []
            for side in (True, False):  # K_k's negative side, then its positive side
                L = np.concatenate([le, ge], axis=1)
                L[:, k], L[:, self.U + k] = side, not side
                tables.append((L, self.evaluate(L)))
            o = out[a : a + step]
            for i in carriers:
                other = self.lits[i][self.lits[i][:, 0] != k]
                holds = (other[:, 1] * V[:, other[:, 0]] <= lim[:, other[:, 0]]).all(axis=1) & (o < 0)
                if not holds.any():
                    continue
                changed = np.zeros(len(p), dtype=bool)
                for L, plain in tables:
                    changed |= self.evaluate(L, (i, holds)) != plain
                o[holds & changed] = i
        return np.where(out >= 0, out, first)

    def line_roots(self, o, d, positive, bound=None, tol=0.0):
        """Roots of every table quadric along lines o + t d that lie on the boundary of an
        instance carrying it: (line, t, k, point, first carrier)."""
        if bound is not None:
            lo, hi = np.asarray(bound, dtype=np.float64)
            pad = 1e-6 * float(np.linalg.norm(hi - lo)) + 1e-12
        parts = []
        for k, K in enumerate(self.K):
            t1, t2 = Quadric(K).intersect_line(o, d)
            for t in (t1, t2):
                ok = np.isfinite(t) & (t > 0.0) if positive else np.isfinite(t)
                idx = np.flatnonzero(ok)
                P = o[idx] + t[idx, None] * d[idx]
                if bound is not None:
                    inb = np.all((P >= lo - pad) & (P <= hi + pad), axis=1)
                    idx, P = idx[inb], P[inb]
                prim = self.first_carrier(P, k, tol)
                keep = prim >= 0
                prim[keep] = self.bounding_carrier(P[keep], k, tol)
                parts.append((idx[keep], t[idx[keep]], np.full(keep.sum(), k), P[keep], prim[keep]))
        if not parts:
            z = np.zeros(0, dtype=np.int64)
            return z, np.zeros(0), z, np.zeros((0, 3)), z
        return tuple(np.concatenate(x) for x in zip(*parts))

    def normals(self, P, k, sign):
        """``sign * grad K / |grad K|``: the solid's outward normal for sign = +1 when the solid
        is on K's negative side."""
        K = self.K[k]
        g = 2.0 * np.einsum("nij,nj->ni", K[:, :3, :], np.column_stack([P, np.ones(len(P))]))
        with np.errstate(invalid="ignore", divide="ignore"):
            return sign[:, None] * g / np.linalg.norm(g, axis=1, keepdims=True)


_CACHE: dict = {}


def _tree(shape) -> _Tree:
    """The flattened tree of ``shape`` (cached; the cache keeps the shape alive, so ids are
    not reused)."""
    hit = _CACHE.get(id(shape))
    if hit is None or hit[0] is not shape:
        if len(_CACHE) >= 16:
            _CACHE.pop(next(iter(_CACHE)))
        hit = _CACHE[id(shape)] = (shape, _Tree(shape))
    return hit[1]


def _points(points):
    P = np.asarray(points, dtype=np.float64)
    return P.reshape(-1, 3), P.shape[:-1]


def _ids(tree, matrices, n):
    """Table id per point of one (4, 4) or per-point (n, 4, 4) quadric matrices."""
    m = np.asarray(matrices, dtype=np.float64)
    if m.shape == (4, 4):
        return np.full(n, tree.table.id_of(m)[0], dtype=np.int64)
    uniq, inv = np.unique(m.reshape(n, 16), axis=0, return_inverse=True)
    return tree.table.match(uniq.reshape(-1, 4, 4))[inv.reshape(-1)]


# -- public API ----------------------------------------------------------------------------------


def instances(shape) -> list:
    """Primitive instances in tree order (DAG expanded, first of each (node, matrix))."""
    return list(_tree(shape).instances)


def quadric_table(shape) -> QuadricTable:
    """The table of all instances' quadrics in tree order (the ids used below)."""
    return _tree(shape).table


def contains(shape, points) -> np.ndarray:
    """Membership of points (..., 3): the Boolean formula of the closed leaves' sign tests
    (like ``clcsg.contains``; so a point on a subtracted solid's surface is outside)."""
    t = _tree(shape)
    P, sh = _points(points)
    return t.flags(P, np.full(len(P), -1))[0].reshape(sh)


def membership_sides(shape, points, quadric_matrix):
    """(inside just on K's negative side, inside just on its positive side) for points on K,
    exact by substitution (see the module docstring); both are ``contains`` if K is no leaf
    quadric."""
    t = _tree(shape)
    P, sh = _points(points)
    neg, exact = t.flags(P, _ids(t, quadric_matrix, len(P)))[:2]
    return neg.reshape(sh), (neg ^ exact).reshape(sh)


def on_surface(shape, points, quadric_matrices, tol=0.0) -> np.ndarray:
    """Points on the CSG surface carried by their quadric: the two sides differ.

    With ``tol > 0`` a literal whose first-order distance ``|K(p)| / |grad K(p)|`` is below tol
    is ambiguous, and the point is accepted if the sides differ for the exact evaluation, or
    with all ambiguous literals forced true, or all forced false.  This absorbs rounding of
    points computed near edges; it is not a search over all combinations.
    """
    t = _tree(shape)
    P, sh = _points(points)
    return t.flags(P, _ids(t, quadric_matrices, len(P)), float(tol))[2].reshape(sh)


def primitive_at(shape, points, quadric_matrix, tol=0.0) -> np.ndarray:
    """For points on K: the first instance (tree order) that has a quadric canonically equal
    to K, whose other quadrics hold (``Q <= tol |grad Q|``) and which bounds the solid there
    (complementing its membership on one side of K changes the solid's on that side); where
    none bounds it, the first that holds the point; -1 if none holds it."""
    t = _tree(shape)
    P, sh = _points(points)
    k = _ids(t, quadric_matrix, len(P))
    out = np.full(len(P), -1, dtype=np.int64)
    for u in np.unique(k[k >= 0]):
        sel = np.flatnonzero(k == u)
        out[sel] = t.bounding_carrier(P[sel], u, float(tol))
    return out.reshape(sh)


@dataclass
class SurfacePoints:
    """Exact CSG surface points: ``points`` (M, 3), ``quadrics`` (oracle table ids), ``signs``
    (+1: the solid is on K's negative side), outward unit ``normals``, ``primitives``
    (:func:`primitive_at` instance index)."""

    points: np.ndarray
    quadrics: np.ndarray
    signs: np.ndarray
    normals: np.ndarray
    primitives: np.ndarray

    def __len__(self):
        return len(self.points)


def lines(bound, n_lines=20000, seed=0, directions="random"):
    """Line origins and unit directions covering the box ``bound`` ((2, 3) lo, hi):
    ``"random"`` (uniform origin in the box, uniform direction), ``"axes"`` (three grids of
    axis-parallel lines through the box) or ``"both"`` (half each)."""
    lo, hi = np.asarray(bound, dtype=np.float64)
    n_axes = {"random": 0, "axes": n_lines, "both": n_lines // 2}[directions]
    rng = np.random.default_rng(seed)
    o = lo + rng.random((n_lines - n_axes, 3)) * (hi - lo)
    d = rng.normal(size=o.shape)
    os_, ds = [o], [d / np.linalg.norm(d, axis=1, keepdims=True)]
    side = int(np.ceil(np.sqrt(n_axes / 3))) if n_axes else 0
    g = (np.arange(side) + 0.5) / max(side, 1)
    for ax in range(3 if side else 0):
        a, b = [i for i in range(3) if i != ax]
        ga, gb = np.meshgrid(g, g, indexing="ij")
        p = np.tile(0.5 * (lo + hi), (side * side, 1))
        p[:, a] = lo[a] + ga.ravel() * (hi[a] - lo[a])
        p[:, b] = lo[b] + gb.ravel() * (hi[b] - lo[b])
        os_.append(p)
        ds.append(np.tile(np.eye(3)[ax], (side * side, 1)))
    return np.concatenate(os_), np.concatenate(ds)


def surface_points(shape, bound, n_lines=20000, seed=0, directions="random") -> SurfacePoints:
    """Every root of every leaf quadric along :func:`lines` in ``bound`` that is on the CSG
    surface (exact :func:`on_surface`): outer, hidden and inner (cavity) surfaces alike.
    Points outside the bound padded by 1e-6 of its diagonal are dropped."""
    t = _tree(shape)
    o, d = lines(bound, n_lines, seed, directions)
    _, _, k, P, prim = t.line_roots(o, d, positive=False, bound=bound)
    neg, keep = t.flags(P, k)[:2]
    P, k, prim = P[keep], k[keep], prim[keep]
    sign = np.where(neg[keep], 1, -1)
    return SurfacePoints(P, k, sign, t.normals(P, k, sign), prim)


@dataclass
class Hits:
    """Nearest surface hit per ray (rays' leading shape): ``depth`` along the unit ray (+inf:
    miss), ``quadric`` (oracle id, -1), ``sign`` (0), ``primitive`` (-1), ``point``,
    ``normal`` (outward unit, NaN), ``second``: depth of the root on a different quadric
    closest to the hit (any root on some instance's boundary; +inf if none)."""

    depth: np.ndarray
    quadric: np.ndarray
    sign: np.ndarray
    primitive: np.ndarray
    point: np.ndarray
    normal: np.ndarray
    second: np.ndarray

    @property
    def mask(self):
        return np.isfinite(self.depth)

    def ties(self, rel=1e-9):
        with np.errstate(invalid="ignore"):
            return self.mask & (np.abs(self.second - self.depth) <= rel * self.depth)


def _first_per(ray, order_key, sel):
    """Indices (into the candidates) of the smallest ``order_key`` per ray among ``sel``."""
    idx = np.flatnonzero(sel)
    idx = idx[np.lexsort((order_key[idx], ray[idx]))]
    first = np.ones(len(idx), dtype=bool)
    first[1:] = ray[idx][1:] != ray[idx][:-1]
    return idx[first]


def _cast(t, o, d, bound, tol):
    ray, tt, k, P, prim = t.line_roots(o, d, positive=True, bound=bound, tol=tol)
    neg, exact, loose, strict = t.flags(P, k, tol)
    n = len(o)
    best = _first_per(ray, tt, exact)
    depth = np.full(n, np.inf)
    depth[ray[best]] = tt[best]
    hk = np.full(n, -1, dtype=np.int64)
    hk[ray[best]] = k[best]
    gap = np.where(k != hk[ray], np.abs(tt - depth[ray]), np.inf)
    near = _first_per(ray, gap, (hk[ray] >= 0) & np.isfinite(gap))
    second = np.full(n, np.inf)
    second[ray[near]] = tt[near]
    return ray, tt, k, P, prim, neg, exact, loose, strict, best, depth, hk, second


def _rays(origins, directions):
    o, d = np.broadcast_arrays(*(np.asarray(a, dtype=np.float64) for a in (origins, directions)))
    sh = o.shape[:-1]
    o, d = o.reshape(-1, 3), d.reshape(-1, 3)
    return o, d / np.linalg.norm(d, axis=1, keepdims=True), sh


def cast(shape, origins, directions, bound=None) -> Hits:
    """Nearest root t > 0 of any leaf quadric on the CSG surface (exact) along each unit ray;
    eyes may be anywhere, inside the solid too.  With ``bound`` roots outside it are ignored."""
    t = _tree(shape)
    o, d, sh = _rays(origins, directions)
    ray, tt, k, P, prim, neg, *_, best, depth, hk, second = _cast(t, o, d, bound, 0.0)
    n = len(o)
    sign, pr = np.zeros(n, dtype=np.int64), np.full(n, -1, dtype=np.int64)
    point, normal = np.full((n, 3), np.nan), np.full((n, 3), np.nan)
    r = ray[best]
    sign[r] = np.where(neg[best], 1, -1)
    pr[r], point[r] = prim[best], P[best]
    normal[r] = t.normals(P[best], k[best], sign[r])
    arrays = [a.reshape(sh + a.shape[1:]) for a in (depth, hk, sign, pr, point, normal, second)]
    return Hits(*arrays)


def fragile(shape, origins, directions, rel=1e-9, scale=None, bound=None) -> np.ndarray:
    """Rays whose result a rounding-level change could flip, with tol = rel * scale (scale:
    the largest |coordinate| of ``bound``, else of the origins, at least 1):

    * the hit is not robust: forcing its ambiguous literals (first-order distance < tol) all
      true or all false makes the sides equal;
    * a root in front (t <= depth (1 + rel)) is accepted by ``on_surface(tol)`` but not exactly
      (a near miss, also for missed rays);
    * a root on a different quadric is within ``rel`` relative depth of the hit (a tie).
    """
    t = _tree(shape)
    o, d, sh = _rays(origins, directions)
    if scale is None:
        ref = np.asarray(bound if bound is not None else o, dtype=np.float64)
        scale = max(1.0, float(np.abs(ref).max(initial=0.0)))
    ray, tt, k, P, prim, _, exact, loose, strict, best, depth, hk, second = _cast(t, o, d, bound, rel * scale)
    out = np.zeros(len(o), dtype=bool)
    out[ray[best[~strict[best]]]] = True
    front = loose & ~exact & (tt <= depth[ray] * (1.0 + rel))
    out[ray[front]] = True
    with np.errstate(invalid="ignore"):
        out |= np.isfinite(depth) & (np.abs(second - depth) <= rel * depth)
    return out.reshape(sh)


def sample_residuals(shape, positions, quadric_matrices, tol=None):
    """(first-order distance |Q(p)| / |grad Q(p)| of each sample to its own quadric,
    ``on_surface(..., tol)``); tol defaults to 1e-9 times max(1, largest |coordinate|).
    ``on_csg`` only asks whether the sides differ; how far the sample is from its quadric is
    ``on_quadric``: a sample is good if both hold."""
    P, _ = _points(positions)
    Q = np.broadcast_to(np.asarray(quadric_matrices, dtype=np.float64), (len(P), 4, 4))
    xh = np.column_stack([P, np.ones(len(P))])
    val = np.abs(np.einsum("ni,nij,nj->n", xh, Q, xh))
    gn = np.linalg.norm(2.0 * np.einsum("nij,nj->ni", Q[:, :3, :], xh), axis=1)
    on_q = np.divide(val, gn, out=np.where(val == 0.0, 0.0, np.inf), where=gn > 0)
    if tol is None:
        tol = 1e-9 * max(1.0, float(np.abs(P).max(initial=0.0)))
    return on_q, on_surface(shape, P, Q, tol)
