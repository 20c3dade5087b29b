"""Normalization of a CSG graph to disjunctive normal form (paper section 5, eq. 18).

    S = union_i intersection_j L_ij,   L_ij = {x : s_ij K_ij(x) <= 0}

* transforms are pushed into the leaves (Q' = M^-T Q M^-1, eq. 17);
* complements are pushed to the leaves (De Morgan) and become negated quadrics;
* intersection is distributed over union;
* every quadric is stored once in canonical form K (unit norm, first non-zero coefficient
  positive) and the sign goes into the literal's polarity s, so coincident faces of different
  solids are one and the same quadric whichever way they face (design note, rule 1);
* terms holding K and not-K, terms whose literal boxes are disjoint and terms whose supporting
  polytope is empty are dropped; every remaining term gets an axis-aligned bound.

A term limit stops runaway distribution before it allocates: the product sizes are checked
before a cross product is formed.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..csg import Complement, Difference, Intersection, Primitive, Shape, Transformed, Union
from ..errors import DnfLimitError, SceneError, UnboundedError
from ..quadric import Quadric
from . import bounds as _bounds

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


def normalize(
    shape: Shape,
    term_limit: int = DEFAULT_TERM_LIMIT,
    user_bound=None,
    source: str = "scene",
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
    n = _Normalizer(term_limit, source)
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
        "terms": len(kept),
        "literals": int(sum(sizes)),
        "max_term_size": max(sizes, default=0),
    }
    return Dnf(quadrics, colors, kept, term_bounds, bound, stats)


class _Normalizer:
    def __init__(self, term_limit: int, source: str):
        self.limit = int(term_limit)
        self.source = source
        self.table = _Table()
        self.primitives = 0
        self.literal_instances = 0
        self.pruned_contradiction = 0
        self.pruned_disjoint = 0
        self._boxes: dict[Literal, tuple] = {}

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
                lits.append(self.table.add(q.transform(m), node.color))
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
            if self._disjoint(t):
                self.pruned_disjoint += 1
                continue
            out.append(t)
        return out

    def _disjoint(self, term) -> bool:
        lo = np.full(3, -np.inf)
        hi = np.full(3, np.inf)
        for lit in term:
            box = self._boxes.get(lit)
            if box is None:
                q = Quadric.from_coefficients(self.table.coefs[lit[0]])
                box = _bounds.literal_box(q, lit[1]) or _EMPTY
                self._boxes[lit] = box
            if box is _EMPTY:
                return True
            lo = np.maximum(lo, box[0])
            hi = np.minimum(hi, box[1])
        return bool(np.any(lo > hi + 1e-9 * np.maximum(1.0, np.abs(lo))))
