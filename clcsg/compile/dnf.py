"""Normalization of a CSG graph to disjunctive normal form (paper section 5, eq. 18).

    S = union_i intersection_j L_ij,   L_ij = {x : s_ij K_ij(x) <= 0}

* transforms are pushed into the leaves (Q' = M^-T Q M^-1, eq. 17);
* complements are pushed to the leaves (De Morgan) and become negated quadrics;
* intersection is distributed over union;
* every quadric is stored once in canonical form K (unit norm, first non-zero coefficient
  positive) and the sign goes into the literal's polarity s, so coincident faces of different
  solids are one and the same quadric whichever way they face;
* terms holding K and not-K, terms whose literal boxes are disjoint and terms whose supporting
  polytope is empty are dropped; every remaining term gets an axis-aligned bound.

A term limit stops runaway distribution before it allocates: the product sizes are checked
before a cross product is formed.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from ..model.csg import Complement, Difference, Intersection, Primitive, Shape, Transformed, Union
from ..errors import DnfLimitError, SceneError, UnboundedError
from ..model.quadric import Quadric
from .bounds import term_boxes as _bounds

DEFAULT_TERM_LIMIT = 100_000

#: canonical coefficients closer than this are the same quadric
SAME_QUADRIC = 1e-9

_EMPTY = ("empty",)

Literal = tuple[int, int]  # (quadric index, sign +1 / -1)


@dataclass
class Dnf:
    """A union of intersection terms over a table of unique canonical quadrics."""

    quadrics: np.ndarray  # (U, 4, 4) float64 canonical matrices
    colors: np.ndarray  # (U, 4) float32 RGBA of the first solid that used each quadric
    terms: list[tuple[Literal, ...]]  # each a sorted tuple of (quadric index, sign)
    term_bounds: np.ndarray  # (T, 2, 3) float64 lo, hi
    bound: np.ndarray  # (2, 3) float64 scene bound (union of term bounds)
    stats: dict = field(default_factory=dict)

    @property
    def n_quadrics(self) -> int:
        return len(self.quadrics)

    @property
    def n_terms(self) -> int:
        return len(self.terms)

    def quadric(self, i: int) -> Quadric:
        return Quadric(self.quadrics[i])

    def values(self, points) -> np.ndarray:
        """Q_u(x) for every unique quadric: shape (..., U)."""
        x = np.asarray(points, dtype=np.float64)
        xh = np.concatenate([x, np.ones(x.shape[:-1] + (1,))], axis=-1)
        return np.einsum("...i,uij,...j->...u", xh, self.quadrics, xh)

    def term_contains(self, points) -> np.ndarray:
        """Membership in each term: shape (..., T)."""
        v = self.values(points)
        out = np.ones(v.shape[:-1] + (len(self.terms),), dtype=bool)
        for t, lits in enumerate(self.terms):
            for qi, s in lits:
                out[..., t] &= s * v[..., qi] <= 0.0
        return out

    def contains(self, points) -> np.ndarray:
        """Membership in the solid (any term)."""
        return self.term_contains(points).any(-1)


class _Table:
    """Unique canonical quadrics, found with a tolerance."""

    def __init__(self):
        self.coefs: list[np.ndarray] = []
        self.colors: list[tuple] = []
        self._arr = np.zeros((0, 10))

    def add(self, q: Quadric, color) -> Literal:
        k, s = q.canonical()
        c = k.coefficients()
        if len(self._arr):
            diff = np.abs(self._arr - c).max(axis=1)
            hit = np.flatnonzero(diff < SAME_QUADRIC)
            if len(hit):
                return int(hit[0]), s
        self.coefs.append(c)
        self.colors.append(color)
        self._arr = np.vstack([self._arr, c])
        return len(self.coefs) - 1, s


class _SharedTable:
    """A :class:`~clcsg.compile.tape.QuadricTable` seen through :class:`_Table`'s interface,
    so that the DNF and the tree tape of one scene number their quadrics alike."""

    def __init__(self, table):
        self.table = table
        self.colors = []

    @property
    def coefs(self):
        return self.table.coefs

    def add(self, q: Quadric, color) -> Literal:
        idx, s = self.table.add(q.matrix)
        while len(self.colors) < len(self.table.coefs):
            self.colors.append(color)
        return idx, s


def normalize(
    shape: Shape,
    term_limit: int = DEFAULT_TERM_LIMIT,
    user_bound=None,
    source: str = "scene",
    table=None,
) -> Dnf:
    """Normalize ``shape`` to a :class:`Dnf`.

    ``user_bound`` ((lo, hi) corners) bounds every term; a term without a finite bound and no
    user bound raises :class:`UnboundedError`.  ``source`` names the scene in messages.
    """
    if not isinstance(shape, Shape):
        raise SceneError(f"{source}: expected a CSG shape, got {type(shape).__name__}")
    if user_bound is not None:
        ub = np.asarray(user_bound, dtype=np.float64)
        if ub.shape != (2, 3) or not np.all(np.isfinite(ub)) or np.any(ub[1] <= ub[0]):
            raise SceneError(f"{source}: bound must be two finite corners lo < hi, got {ub.tolist()}")
        user_bound = ub
    n = _Normalizer(term_limit, source, table)
    raw_terms = n.visit(shape, np.eye(4), False)
    terms_before = len(raw_terms)
    quadrics = np.array([Quadric.from_coefficients(c).matrix for c in n.table.coefs]).reshape(-1, 4, 4)
    colors = np.array(n.table.colors, dtype=np.float32).reshape(-1, 4)

    qobjs = [Quadric(m) for m in quadrics]
    kept, boxes = [], []
    pruned_empty = 0
    for term in raw_terms:
        box = _bounds.term_box([(qobjs[qi], s) for qi, s in term], user_bound)
        if box is None:
            pruned_empty += 1
            continue
        lo, hi = box
        if not (np.all(np.isfinite(lo)) and np.all(np.isfinite(hi))):
            desc = " & ".join(f"{'' if s > 0 else '~'}q{qi}" for qi, s in term)
            raise UnboundedError(
                f"{source}: the solid is unbounded (DNF term {desc} has no finite bound); "
                "intersect it with a box or give a bound"
            )
        kept.append(tuple(sorted(term)))
        boxes.append((lo, hi))
    term_bounds = np.array(boxes, dtype=np.float64).reshape(-1, 2, 3)
    if len(term_bounds):
        bound = np.array([term_bounds[:, 0].min(0), term_bounds[:, 1].max(0)])
    else:
        bound = np.zeros((2, 3))
    sizes = [len(t) for t in kept]
    stats = {
        "primitives": n.primitives,
        "literal_instances": n.literal_instances,
        "unique_quadrics": len(quadrics),
        "terms_before_pruning": terms_before,
        "terms_pruned_contradiction": n.pruned_contradiction,
        "terms_pruned_disjoint": n.pruned_disjoint,
        "terms_pruned_empty": pruned_empty,
        "redundant_literals_dropped": n.dropped_literals,
        "terms": len(kept),
        "literals": int(sum(sizes)),
        "max_term_size": max(sizes, default=0),
    }
    return Dnf(quadrics, colors, kept, term_bounds, bound, stats)


class _Normalizer:
    def __init__(self, term_limit: int, source: str, table=None):
        self.limit = int(term_limit)
        self.source = source
        self.table = _Table() if table is None else _SharedTable(table)
        self.primitives = 0
        self.literal_instances = 0
        self.pruned_contradiction = 0
        self.pruned_disjoint = 0
        self._boxes: dict[Literal, tuple] = {}
        self._quadrics: dict[int, Quadric] = {}
        self._lin: dict = {}
        self.dropped_literals = 0

    # A term is a frozenset of literals; a DNF is a list of terms.
    def visit(self, node: Shape, m: np.ndarray, neg: bool) -> list[frozenset]:
        if isinstance(node, Transformed):
            return self.visit(node.operand, m @ node.matrix, neg)
        if isinstance(node, Complement):
            return self.visit(node.operand, m, not neg)
        if isinstance(node, Primitive):
            self.primitives += 1
            lits = []
            for q in node.quadrics():
                self.literal_instances += 1
                try:
                    lits.append(self.table.add(q.transform(m), node.color))
                except (ValueError, StopIteration, FloatingPointError):
                    raise SceneError(
                        f"{self.source}: {node!r}: its quadric overflows float64 after the transforms "
                        "(sizes or offsets far too large)"
                    ) from None
            if not neg:
                return self._clean([frozenset(lits)])
            return self._clean([frozenset([(qi, -s)]) for qi, s in lits])
        if isinstance(node, Union):
            # neg: ~(a | b) = ~a & ~b
            return self._combine(node, m, [(c, neg) for c in node.operands], conj=neg)
        if isinstance(node, Intersection):
            return self._combine(node, m, [(c, neg) for c in node.operands], conj=not neg)
        if isinstance(node, Difference):
            # a - b - c = a & ~b & ~c; negated: ~a | b | c
            parts = [(node.operands[0], neg)] + [(c, not neg) for c in node.operands[1:]]
            return self._combine(node, m, parts, conj=not neg)
        raise SceneError(f"{self.source}: not a CSG node: {type(node).__name__}")

    def _combine(self, node, m, parts, conj: bool) -> list[frozenset]:
        what = type(node).__name__.lower()
        if parts and parts[0][1] and not isinstance(node, Difference):
            what = f"complement of a {what}"
        elif isinstance(node, Difference) and parts[0][1]:
            what = "complement of a difference"
        if not conj:
            out: list[frozenset] = []
            for child, neg in parts:
                out.extend(self.visit(child, m, neg))
                if len(out) > self.limit:
                    raise DnfLimitError(
                        f"{self.source}: DNF of a {what} of {len(parts)} operands has more than "
                        f"{self.limit} terms (term limit; raise it with --term-limit)"
                    )
            return self._clean(out)
        acc: list[frozenset] | None = None
        for child, neg in parts:
            terms = self.visit(child, m, neg)
            if acc is None:
                acc = terms
                continue
            n = len(acc) * len(terms)
            if n > self.limit:
                raise DnfLimitError(
                    f"{self.source}: distributing a {what} would create {len(acc)} x {len(terms)} "
                    f"= {n} DNF terms, past the limit of {self.limit} (raise it with --term-limit)"
                )
            acc = self._clean([a | b for a in acc for b in terms])
        # an empty intersection (the complement of an empty union) is everything
        return [frozenset()] if acc is None else acc

    def _clean(self, terms: list[frozenset]) -> list[frozenset]:
        """Drop duplicate, contradictory (K and not-K) and provably empty terms, and the
        literals that are redundant in their term (see :meth:`_simplify`)."""
        out = []
        seen = set()
        for t in terms:
            if t in seen:
                continue
            seen.add(t)
            qs = {}
            bad = False
            for qi, s in t:
                if qs.setdefault(qi, s) != s:
                    bad = True
                    break
            if bad:
                self.pruned_contradiction += 1
                continue
            t2 = self._simplify(t)
            if t2 is None:
                self.pruned_disjoint += 1
                continue
            if t2 is not t:
                if t2 in seen:
                    continue
                seen.add(t2)
            out.append(t2)
        return out

    def _literal_box(self, lit):
        """(x0, y0, z0, x1, y1, z1) of the literal's solid (+-inf where unbounded) or _EMPTY."""
        box = self._boxes.get(lit)
        if box is None:
            bx = _bounds.literal_box(self._quadric(lit[0]), lit[1])
            box = _EMPTY if bx is None else tuple(float(v) for v in (*bx[0], *bx[1]))
            self._boxes[lit] = box
        return box

    def _quadric(self, qi) -> Quadric:
        q = self._quadrics.get(qi)
        if q is None:
            q = self._quadrics[qi] = Quadric.from_coefficients(self.table.coefs[qi])
        return q

    def _simplify(self, term: frozenset):
        """The term without its redundant literals, or None if it is provably empty.

        The box of a term is the intersection of its literals' boxes.  A literal whose solid
        misses the box of the others empties the term; one whose solid contains that box
        never cuts the term's solid and is dropped (a hole far from the part it is subtracted
        from, one literal of a subtracted box that is beside the part).  Planes are tested
        exactly at the box corners, other quadrics by the conservative distance at the box
        center against the half-diagonal.
        """
        # plain Python floats: terms are small and numpy's per-call overhead dominates here
        lits = list(term)
        boxes = []
        for lit in lits:
            bx = self._literal_box(lit)
            if bx is _EMPTY:
                return None
            boxes.append(bx)
        n = len(lits)
        inf = math.inf
        # prefix / suffix intersections give the box of all literals but k
        pre = [(-inf, -inf, -inf, inf, inf, inf)]
        for bx in boxes:
            p = pre[-1]
            pre.append((max(p[0], bx[0]), max(p[1], bx[1]), max(p[2], bx[2]),
                        min(p[3], bx[3]), min(p[4], bx[4]), min(p[5], bx[5])))
        full = pre[-1]
        for k in range(3):
            if full[k] > full[3 + k] + 1e-9 * max(1.0, abs(full[k])):
                return None
        if n < 2:
            return term
        suf = [(-inf, -inf, -inf, inf, inf, inf)]
        for bx in reversed(boxes):
            p = suf[-1]
            suf.append((max(p[0], bx[0]), max(p[1], bx[1]), max(p[2], bx[2]),
                        min(p[3], bx[3]), min(p[4], bx[4]), min(p[5], bx[5])))
        suf.reverse()
        keep = []
        for k, lit in enumerate(lits):
            a, b = pre[k], suf[k + 1]
            box = (max(a[0], b[0]), max(a[1], b[1]), max(a[2], b[2]),
                   min(a[3], b[3]), min(a[4], b[4]), min(a[5], b[5]))
            if not all(math.isfinite(v) for v in box):
                keep.append(lit)
                continue
            side = self._side(lit, box)
            if side > 0:
                return None
            if side == 0:
                keep.append(lit)
        if len(keep) == n:
            return term
        self.dropped_literals += n - len(keep)
        return frozenset(keep)

    def _side(self, lit, box) -> int:
        """-1: the literal holds on the whole box, +1: it fails on all of it, 0: unknown."""
        g = self._linear(lit)
        cx, cy, cz = 0.5 * (box[0] + box[3]), 0.5 * (box[1] + box[4]), 0.5 * (box[2] + box[5])
        hx, hy, hz = 0.5 * (box[3] - box[0]), 0.5 * (box[4] - box[1]), 0.5 * (box[5] - box[2])
        if g is not None:
            # a linear function's range over a box: g . center +- |g| . half-extent + c0
            mid = g[0] * cx + g[1] * cy + g[2] * cz + g[3]
            spread = abs(g[0]) * hx + abs(g[1]) * hy + abs(g[2]) * hz
            return -1 if mid + spread <= 0 else 1 if mid - spread > 0 else 0
        r = math.sqrt(hx * hx + hy * hy + hz * hz)
        d = lit[1] * float(self._quadric(lit[0]).distance(np.array([[cx, cy, cz]]))[0])
        return -1 if d <= -r else 1 if d >= r else 0

    def _linear(self, lit):
        """(gx, gy, gz, c0) with sign * Q(x) = g . x + c0 for a plane literal, else None."""
        if lit not in self._lin:
            m = lit[1] * self._quadric(lit[0]).matrix
            if np.abs(m[:3, :3]).max() == 0.0:
                self._lin[lit] = tuple(float(v) for v in (2 * m[0, 3], 2 * m[1, 3], 2 * m[2, 3], m[3, 3]))
            else:
                self._lin[lit] = None
        return self._lin[lit]
