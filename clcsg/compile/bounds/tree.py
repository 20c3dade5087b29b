"""Bounds of a CSG graph computed on the graph: the scene's box and each primitive instance's box.

:func:`tree_bounds` walks the graph iteratively (bottom-up and top-down passes over
(node, transform, polarity) instances), then refines the root box by the graph's conservative
distance; :func:`shape_bound` is the scene bound alone.  The boxes of the primitive instances
feed :func:`clcsg.compile.bounds.regions.quadric_regions` (the resource guard's regions).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ...errors import SceneError, UnboundedError
from ...model.csg import Complement, Difference, Intersection, Primitive, Shape, Transformed, Union
from ...model.quadric import Quadric
from .sparse_distance import MIN_GROUP, SparseDistance, plane_rows
from .exact_boxes import empty_box, halfspace_boxes, is_empty, kind_boxes, literals_box, meet, primitive_box

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
    """Skip Transformed and Complement edges: (node, world matrix, negated); a node with a
    ``bounds_proxy`` (a large mesh: its grown box) stands for it."""
    while True:
        proxy = getattr(node, "bounds_proxy", None)
        if proxy is not None:
            node = proxy
        elif isinstance(node, Transformed):
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
        self.leaf_ids = np.array([i for i, k in enumerate(self.kind) if k == _LEAF], dtype=np.int64)
        self.inner = [i for i, k in enumerate(self.kind) if k != _LEAF]
        self.kid_array = [np.asarray(k, dtype=np.int64) for k in self.kids]
        # an AND's negated convex primitives: what may cut its box
        self.cutters = {i: np.array([k for k in self.kids[i] if self.kind[k] == _LEAF and self.neg[k]
                                     and self.node[k].kind in CONVEX_KINDS], dtype=np.int64)
                        for i in self.inner if self.kind[i] == _AND}
        self.edge_parent = np.array([i for i, ks in enumerate(self.kids) for _ in ks], dtype=np.int64)
        self.edge_child = np.array([k for ks in self.kids for k in ks], dtype=np.int64)

    def _add(self, kind, kids, node, m, neg) -> int:
        self.kind.append(kind)
        self.kids.append(kids)
        self.node.append(node)
        self.matrix.append(m)
        self.neg.append(neg)
        return len(self.kind) - 1


def _union_boxes(boxes):
    boxes = [b for b in boxes if not is_empty(b)]
    if not boxes:
        return empty_box()
    return np.min([b[0] for b in boxes], axis=0), np.max([b[1] for b in boxes], axis=0)


def _norm_box(b):
    """(lo, hi) with every empty box as (inf, -inf)."""
    if is_empty(b):
        return empty_box()
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


def _user_bound(user_bound, source):
    if user_bound is None:
        return None
    ub = np.asarray(user_bound, dtype=np.float64)
    if ub.shape != (2, 3) or not np.all(np.isfinite(ub)) or np.any(ub[1] <= ub[0]):
        raise SceneError(f"{source}: bound must be two finite corners lo < hi, got {ub.tolist()}")
    return ub[0], ub[1]


def tree_bounds(shape, user_bound=None, source: str = "scene") -> TreeBounds:
    """Bound of the solid of ``shape`` computed on the CSG graph, and the boxes of its
    primitive instances (see the section comment: bottom-up / top-down passes over the
    instances, no recursion, linear in the number of distinct (node, transform, polarity):
    the leaves of a pass are handled in one numpy batch, and the distance refinement evaluates
    only the primitives near each cell, found in a bounding volume hierarchy).

    ``user_bound`` ((lo, hi) corners) is intersected with everything.  An unbounded solid
    without a user bound raises :class:`UnboundedError`; an empty one gives ``empty=True``
    and a zero bound.  ``instances`` (with the face boxes the guard needs) are computed on
    first access.
    """
    if not isinstance(shape, Shape):
        raise SceneError(f"{source}: expected a CSG shape, got {type(shape).__name__}")
    ub = _user_bound(user_bound, source)
    g = _Graph(shape, source)
    leaves = _Leaves(g, source)
    box, passes = _box_passes(g, leaves, ub)
    root_box = (box[0][g.root], box[1][g.root])
    if ub is not None:
        root_box = _norm_box(meet(root_box, ub))
    refine_rounds = 0
    if (_refinable(g, ub) and not is_empty(root_box) and np.all(np.isfinite(root_box[0]))
            and np.all(np.isfinite(root_box[1]))):
        root_box, refine_rounds = _refine_by_distance(leaves.sparse_distance(), root_box)
        box[0][g.root], box[1][g.root] = _norm_box(root_box)
    empty = is_empty(root_box)
    if not empty and not (np.all(np.isfinite(root_box[0])) and np.all(np.isfinite(root_box[1]))):
        axes = "".join(a for a, lo, hi in zip("xyz", root_box[0], root_box[1])
                       if not (np.isfinite(lo) and np.isfinite(hi)))
        raise UnboundedError(f"{source}: the solid is unbounded (no finite bound along {axes}); "
                             "intersect it with a box or give a bound")
    bound = np.zeros((2, 3)) if empty else np.array(root_box)
    stats = {"instances": len(g.kind), "primitive_instances": len(leaves.ids), "passes": passes,
             "distance_rounds": refine_rounds}
    out = TreeBounds(bound, empty, None, stats)
    out._make_instances = lambda: _instances(g, leaves, box, ub, empty)
    return out


def _normalize(lo, hi):
    """Rows of (lo, hi) (n, 3) with every empty box as (inf, -inf)."""
    bad = np.any(lo > hi, axis=1)
    lo, hi = lo.copy(), hi.copy()
    lo[bad], hi[bad] = np.inf, -np.inf
    return lo, hi


def _same_rows(a, b) -> np.ndarray:
    """Per row, whether the (normalized) boxes a and b ((lo, hi) of (n, 3)) are equal to 1e-9."""
    x = np.concatenate([a[0], a[1]], axis=1)
    y = np.concatenate([b[0], b[1]], axis=1)
    with np.errstate(invalid="ignore"):
        d = np.abs(x - y)
    d = np.where(np.isnan(d), 0.0, d)  # inf - inf: the same infinity
    scale = 1.0 + np.abs(x)
    scale = np.where(np.isfinite(scale), scale, 1.0)
    return np.all(d <= 1e-9 * scale, axis=1)


def _box_passes(g: _Graph, leaves: "_Leaves", ub):
    """The bottom-up / top-down passes of the section comment: ((lo, hi) arrays of every
    instance's box, number of bottom-up passes)."""
    n = len(g.kind)
    region = (np.full((n, 3), -np.inf), np.full((n, 3), np.inf))
    if ub is not None:
        region[0][g.root], region[1][g.root] = ub
    box = (np.full((n, 3), -np.inf), np.full((n, 3), np.inf))
    passes = 0
    for passes in range(1, MAX_PASSES + 1):
        new = _bottom_up(g, leaves, region, box)
        tightened = not np.all(_same_rows(new, box))
        box = new
        if passes == MAX_PASSES or (passes > 1 and not tightened):
            break
        new_region = _top_down(g, box, ub)
        if passes > 1 and np.all(_same_rows(new_region, region)):
            break
        region = new_region
    return box, passes


def _bottom_up(g: _Graph, leaves: "_Leaves", region, old):
    """One bottom-up pass: every instance's box within its region, never looser than ``old``."""
    lo, hi = old[0].copy(), old[1].copy()
    ids = leaves.ids
    b = leaves.boxes(region[0][ids], region[1][ids])
    b = _normalize(np.maximum(b[0], region[0][ids]), np.minimum(b[1], region[1][ids]))
    lo[ids], hi[ids] = _normalize(np.maximum(b[0], old[0][ids]), np.minimum(b[1], old[1][ids]))
    for i in g.inner:
        kids = g.kid_array[i]
        if g.kind[i] == _OR:
            blo = lo[kids].min(axis=0) if len(kids) else np.full(3, np.inf)
            bhi = hi[kids].max(axis=0) if len(kids) else np.full(3, -np.inf)
        else:
            blo = np.max(np.vstack([region[0][i][None], lo[kids]]), axis=0)
            bhi = np.min(np.vstack([region[1][i][None], hi[kids]]), axis=0)
            if np.all(blo <= bhi):
                blo, bhi = leaves.cut_by(g.cutters[i], (blo, bhi))
        blo, bhi = np.maximum(blo, region[0][i]), np.minimum(bhi, region[1][i])
        blo, bhi = _norm_box((np.maximum(blo, old[0][i]), np.minimum(bhi, old[1][i])))
        lo[i], hi[i] = blo, bhi
    return lo, hi


def _top_down(g: _Graph, box, ub):
    """The regions: an instance's box within the union of its parents' regions."""
    n = len(g.kind)
    lo, hi = np.full((n, 3), np.inf), np.full((n, 3), -np.inf)
    for i in g.inner[::-1]:
        if i == g.root:
            r = (box[0][i], box[1][i]) if ub is None else meet((box[0][i], box[1][i]), ub)
        else:
            ps = g.parents[i]
            r = meet((box[0][i], box[1][i]), (lo[ps].min(axis=0), hi[ps].max(axis=0)))
        lo[i], hi[i] = _norm_box(r)
    ulo, uhi = np.full((n, 3), np.inf), np.full((n, 3), -np.inf)
    np.minimum.at(ulo, g.edge_child, lo[g.edge_parent])
    np.maximum.at(uhi, g.edge_child, hi[g.edge_parent])
    ids = g.leaf_ids
    if len(g.kind) == 1:  # the root is a primitive
        ulo[ids], uhi[ids] = (box[0][ids], box[1][ids]) if ub is None else (
            np.maximum(box[0][ids], ub[0]), np.minimum(box[1][ids], ub[1]))
    lo[ids], hi[ids] = _normalize(np.maximum(box[0][ids], ulo[ids]), np.minimum(box[1][ids], uhi[ids]))
    return lo, hi


class _Leaves:
    """World quadrics of the leaf instances (one numpy batch), their own exact boxes and the
    box operations on them."""

    def __init__(self, g: _Graph, source: str):
        self.g = g
        self.ids = g.leaf_ids
        mats, first, count, inv = [], [], [], {}
        for i in self.ids:
            node, m = g.node[i], g.matrix[i]
            k = m.tobytes()
            if k not in inv:
                inv[k] = np.linalg.inv(m)
            first.append(len(mats))
            count.append(len(node.quadrics()))
            mats.extend((q.matrix, inv[k]) for q in node.quadrics())
        q = np.array([a for a, _ in mats]).reshape(-1, 4, 4)
        im = np.array([b for _, b in mats]).reshape(-1, 4, 4)
        with np.errstate(all="ignore"):
            w = np.einsum("nji,njk,nkl->nil", im, q, im)
            w = 0.5 * (w + w.transpose(0, 2, 1))
            bad = ~np.all(np.isfinite(w), axis=(1, 2))
        if bad.any():
            node = g.node[self.ids[np.searchsorted(np.cumsum(count), np.flatnonzero(bad)[0], "right")]]
            raise SceneError(f"{source}: {node!r}: its quadric overflows float64 after the transforms "
                             "(sizes or offsets far too large)")
        self.world = w
        self.first = dict(zip(self.ids.tolist(), first))
        self.count = dict(zip(self.ids.tolist(), count))
        self.first_array, self.count_array = np.array(first, dtype=np.int64), np.array(count, dtype=np.int64)
        norms = np.linalg.norm(w, axis=(1, 2))
        self.unit = w / np.where(norms > 0, norms, 1.0)[:, None, None]
        n = len(g.kind)
        self.own_lo, self.own_hi = np.full((n, 3), np.inf), np.full((n, 3), -np.inf)
        self._quads: dict[int, tuple] = {}
        self._cache: dict = {}
        if len(self.ids):
            lo, hi, done = kind_boxes([g.node[i] for i in self.ids], np.array([g.matrix[i] for i in self.ids]))
            self.own_lo[self.ids], self.own_hi[self.ids] = _normalize(lo, hi)
            for i in self.ids[~done]:
                self.own_lo[i], self.own_hi[i] = _norm_box(primitive_box(self.quads(i)))
        self.convex = np.array([g.kind[i] == _LEAF and g.node[i].kind in CONVEX_KINDS for i in range(n)], dtype=bool)
        self.single = np.array([self.count.get(i, 0) == 1 for i in range(n)], dtype=bool)
        self.leaf_index = np.zeros(n, dtype=np.int64)
        self.leaf_index[self.ids] = np.arange(len(self.ids))
        self.halfspace = np.zeros(n, dtype=bool)
        if len(self.ids) and len(self.world):
            first = np.minimum(self.first_array, len(self.world) - 1)
            self.halfspace[self.ids] = self.single[self.ids] & plane_rows(self.world[first])

    def quads(self, i):
        qs = self._quads.get(i)
        if qs is None:
            f = self.first[i]
            qs = self._quads[i] = tuple(Quadric(m) for m in self.world[f:f + self.count[i]])
        return qs

    def mats(self, i):
        f = self.first[i]
        return self.unit[f:f + self.count[i]]

    def sparse_distance(self, min_group: int = MIN_GROUP) -> SparseDistance:
        """The conservative distance of the graph over balls (:mod:`.sparse_distance`; an
        AND/OR's plane operands as one dense group when there are ``min_group`` of them, 0:
        never)."""
        lam = np.linalg.eigvalsh(self.world[:, :3, :3]) if len(self.world) else np.zeros((0, 3))
        g = self.g
        return SparseDistance(g.kind, g.kids, g.neg, self.ids, self.first_array, self.count_array, self.world,
                              lam[:, 0], lam[:, -1], self.own_lo[self.ids], self.own_hi[self.ids], min_group)

    def own(self, i):
        """The exact box of the primitive itself (not negated)."""
        return self.own_lo[i], self.own_hi[i]

    def boxes(self, rlo, rhi):
        """Boxes of the leaves' solids (negated where they are) within regions (rlo, rhi), one
        row per leaf of ``ids``: the primitive's own box where the region holds it, the region
        without the slabs inside a negated convex primitive, else the exact box within the
        region (computed one by one: rare)."""
        ids = self.ids
        lo, hi = rlo.copy(), rhi.copy()
        neg = np.array([self.g.neg[i] for i in ids], dtype=bool)
        olo, ohi = self.own_lo[ids], self.own_hi[ids]
        holds = np.all(rlo <= olo, axis=1) & np.all(ohi <= rhi, axis=1)
        pos = ~neg & holds
        lo[pos], hi[pos] = olo[pos], ohi[pos]
        live = np.all(rlo <= rhi, axis=1)
        finite = np.all(np.isfinite(rlo) & np.isfinite(rhi), axis=1) & live
        single = ~self.convex[ids] & self.single[ids]
        slow = (~neg & ~holds & live) | (neg & finite & (self._may_cut(ids, rlo, rhi) | single))
        half = slow & ~neg & finite & self.halfspace[ids]
        if half.any():  # one batch: the many face planes of a mesh operand
            k = np.flatnonzero(half)
            m = self.world[self.first_array[self.leaf_index[ids[k]]]]
            b = m[:, :3, 3]
            lo[k], hi[k] = halfspace_boxes(2.0 * b, -m[:, 3, 3], rlo[k], rhi[k])
            lo[k], hi[k] = np.maximum(lo[k], olo[k]), np.minimum(hi[k], ohi[k])  # a k-d cell's plane: in its cell
            slow &= ~half
        for k in np.flatnonzero(slow):
            lo[k], hi[k] = self.box(int(ids[k]), (rlo[k], rhi[k]))
        return lo, hi

    def _may_cut(self, ids, rlo, rhi):
        """Whether a negated convex primitive may hold a face of the region: at least four of
        the region's corners in its box (a necessary condition for :meth:`cut`)."""
        olo, ohi = self.own_lo[ids], self.own_hi[ids]
        inside = np.zeros(len(ids), dtype=np.int64)
        for c in range(8):
            corner = np.where(np.array([(c >> k) & 1 for k in range(3)], dtype=bool), rhi, rlo)
            inside += np.all((olo <= corner) & (corner <= ohi), axis=1)
        return self.convex[ids] & (inside >= 4)

    def cut_by(self, cutters, b):
        """``b`` cut by each negated convex primitive of ``cutters`` (an AND's operands) that
        may hold a face of it, until none does."""
        done = set()
        while len(cutters):
            cand = cutters[self._may_cut(cutters, np.asarray(b[0])[None], np.asarray(b[1])[None])]
            cand = [int(k) for k in cand if int(k) not in done]
            changed = False
            for k in cand:
                done.add(k)
                nb = self.cut(k, b)
                if is_empty(nb):
                    return empty_box()
                if not _same(nb, b):
                    b, changed = nb, True
                    break
            if not changed:
                break
        return b

    def box(self, i, r):
        """Box of leaf i's solid (negated if it is) within region r."""
        key = (i, r[0].tobytes(), r[1].tobytes())
        b = self._cache.get(key)
        if b is not None:
            return b
        qs = self.quads(i)
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
        if self.g.node[i].kind not in CONVEX_KINDS or is_empty(b):
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


def _refinable(g: _Graph, ub) -> bool:
    """Whether the distance refinement can shrink the root box.  Not for a union of positive
    primitives without a user bound: its box is the union of the primitives' own exact boxes,
    and each face of it touches the primitive whose box reaches it, so no cell beyond the solid
    is left to drop."""
    return ub is not None or any(k == _AND for k in g.kind) or any(
        g.neg[i] for i, k in enumerate(g.kind) if k == _LEAF)


def _refine_by_distance(distance: SparseDistance, box):
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

    def evaluate(c, h):
        """(undecided mask, distance) of cells (centers c, half-sizes h)."""
        r = np.linalg.norm(h, axis=1)
        d = distance(c, h)
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
            return empty_box(), rounds
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
        return empty_box(), rounds
    return (np.maximum(lo, (cen - half).min(axis=0)), np.minimum(hi, (cen + half).max(axis=0))), rounds


def _instances(g: _Graph, leaves: _Leaves, box, ub, empty) -> list:
    out = []
    for i in range(len(g.kind)):
        if g.kind[i] != _LEAF:
            continue
        qs = leaves.quads(i)
        b = (box[0][i], box[1][i])
        if ub is not None:
            b = _norm_box(meet(b, ub))
        if empty or is_empty(b):
            surf = None
        else:
            # a region holding the whole primitive adds no constraint (and no planes to cost)
            clip = None if _contains_box(b, leaves.own(i)) else b
            surf = literals_box([(q, 1) for q in qs], clip, faces=True)
        if surf is None or is_empty(surf[0]):
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


