"""The conservative signed distance of a CSG graph at the centers of many boxes at once,
evaluated only for the primitives near each box (a :class:`~clcsg.compile.bvh.BoxTree` over the
primitives' boxes).

The graph is in negation normal form: leaves are primitives (possibly negated), inner nodes AND
(max) and OR (min), children before parents.  A literal's value is its conservative signed
distance (eqs. 8-12: negative inside, its magnitude a radius of constant sign); a primitive's is
the max over its literals, negated for a negated primitive.

Over a box C (center c, half-diagonal r) a primitive whose exact box misses C is constant: its
solid has no point in C, so it is FALSE there (+inf), and its negation TRUE (-inf).
Substituting those constants keeps what the callers read from the value v at c: v > r proves C
empty of the solid, v <= 0 that c is in it, v <= -r that all of C is (by induction over the
graph: the maximizing operand of an AND that is > r is either a real distance, so the ball of
radius r around c, which holds C, is outside it, or a primitive FALSE over C; every operand of
an AND <= -r holds C; OR likewise).

So each node's values are stored sparsely: a default constant (+-inf, the value where none of
its primitives is near) and the (cell, value) entries that differ.  The nodes are processed by
height, all nodes of one height in one batch of numpy segment reductions, so the cost is the
number of (box, near primitive) pairs times the depth, not boxes times primitives.
"""

from __future__ import annotations

import numpy as np

from ...model.quadric import ray_distance
from ..bvh import BoxTree

LEAF, AND, OR = 0, 1, 2


def _segments(lengths: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(owner, rank) of the items of consecutive segments of the given lengths."""
    total = int(lengths.sum())
    owner = np.repeat(np.arange(len(lengths)), lengths)
    starts = np.cumsum(lengths) - lengths
    return owner, np.arange(total) - starts[owner]


def _flatten(kind, kids) -> list:
    """Per inner node its operands with same-kind inner operands of a single parent inlined
    (an AND of an AND is one AND: a chain of nested differences is one level, not a thousand);
    None for the inlined nodes."""
    n = len(kind)
    n_parents = np.zeros(n, dtype=np.int64)
    for ks in kids:
        for k in ks:
            n_parents[k] += 1
    inlined = np.zeros(n, dtype=bool)
    for i in range(n):
        for k in kids[i]:
            if kind[k] != LEAF and kind[k] == kind[i] and n_parents[k] == 1:
                inlined[k] = True
    out: list = [None] * n
    for i in range(n):
        if kind[i] == LEAF or inlined[i]:
            continue
        ops, stack = [], list(reversed(kids[i]))
        while stack:
            k = stack.pop()
            if inlined[k]:
                stack.extend(reversed(kids[k]))
            else:
                ops.append(k)
        out[i] = ops
    return out


class SparseDistance:
    """Evaluator of one graph; see the module docstring.

    ``kind``, ``kids``, ``neg``: per node (post-order: children before parents).  Per leaf
    node ``i`` (``leaf_nodes``, in that order): its literals ``mats[lit_first[l]:...+count]``
    (world matrices, solid Q <= 0), their eigenvalue ranges and the primitive's own box.
    """

    def __init__(self, kind, kids, neg, leaf_nodes, lit_first, lit_count, mats, lam_min, lam_max, box_lo, box_hi):
        self.kind = np.asarray(kind, dtype=np.int8)
        n = len(self.kind)
        self.root = n - 1
        self.leaf_nodes = np.asarray(leaf_nodes, dtype=np.int64)
        self.lit_first = np.asarray(lit_first, dtype=np.int64)
        self.lit_count = np.asarray(lit_count, dtype=np.int64)
        self.mats, self.lam_min, self.lam_max = mats, lam_min, lam_max
        self.leaf_neg = np.asarray([neg[i] for i in self.leaf_nodes], dtype=bool)
        self.tree = BoxTree(box_lo, box_hi)
        self.default = np.empty(n)
        self.n_absorbing = np.zeros(n, dtype=np.int64)
        height = np.zeros(n, dtype=np.int64)
        levels: dict = {}
        flat = _flatten(self.kind, kids)
        for i in range(n):
            if self.kind[i] == LEAF:
                self.default[i] = -np.inf if neg[i] else np.inf
                continue
            if flat[i] is None:
                continue
            ks = np.asarray(flat[i], dtype=np.int64)
            absorbing = np.inf if self.kind[i] == AND else -np.inf
            is_abs = self.default[ks] == absorbing
            self.n_absorbing[i] = int(is_abs.sum())
            self.default[i] = absorbing if self.n_absorbing[i] else -absorbing
            height[i] = 1 + (height[ks].max() if len(ks) else 0)
            levels.setdefault(int(height[i]), []).append((np.full(len(ks), i), ks, is_abs))
        self.heights = sorted(levels)
        self.levels = [tuple(np.concatenate(parts) for parts in zip(*levels[h])) for h in self.heights]
        # the height of a node's last parent: its entries are dropped once that is done
        self.last_use = np.full(n, np.iinfo(np.int64).max)
        for h, (parents, kids, _) in zip(self.heights, self.levels):
            self.last_use[kids] = h
        if n:
            self.last_use[self.root] = np.iinfo(np.int64).max

    def _leaf_entries(self, centers, half):
        """(node, box, value) of every box and leaf whose boxes meet."""
        pad = 1e-9 * (1.0 + np.abs(centers).max(axis=1) + half.max(axis=1))
        reach = half + pad[:, None]
        cell, leaf = self.tree.query(centers - reach, centers + reach)
        if not len(cell):
            return cell, cell, np.zeros(0)
        counts = self.lit_count[leaf]
        pair, rank = _segments(counts)
        lit = self.lit_first[leaf][pair] + rank
        x = centers[cell][pair]
        m = self.mats[lit]
        xh = np.concatenate([x, np.ones((len(x), 1))], axis=1)
        mx = np.einsum("nij,nj->ni", m, xh)
        f = np.einsum("ni,ni->n", mx, xh)
        g = 2.0 * np.sqrt((mx[:, :3] ** 2).sum(axis=1))
        d = ray_distance(f, g, self.lam_min[lit], self.lam_max[lit])
        v = np.maximum.reduceat(d, np.cumsum(counts) - counts)
        v = np.where(self.leaf_neg[leaf], -v, v)
        return self.leaf_nodes[leaf], cell, v

    def __call__(self, centers, half) -> np.ndarray:
        """Values (N,) at the centers of the boxes ``centers`` +- ``half`` (N, 3); see the
        module docstring."""
        centers = np.asarray(centers, dtype=np.float64).reshape(-1, 3)
        half = np.broadcast_to(np.asarray(half, dtype=np.float64), centers.shape)
        n_cells = len(centers)
        node, cell, val = self._leaf_entries(centers, half)
        keep = val != self.default[node]
        node, cell, val = node[keep], cell[keep], val[keep]
        for h, (parents, kids, is_abs) in zip(self.heights, self.levels):
            alive = self.last_use[node] >= h
            node, cell, val = node[alive], cell[alive], val[alive]
            order = np.argsort(node, kind="stable")
            node, cell, val = node[order], cell[order], val[order]
            first = np.searchsorted(node, kids, "left")
            lengths = np.searchsorted(node, kids, "right") - first
            if not lengths.any():
                continue
            edge, rank = _segments(lengths)
            src = first[edge] + rank
            par, b, v, ab = parents[edge], cell[src], val[src], is_abs[edge]
            key = par * n_cells + b
            order = np.argsort(key, kind="stable")
            key, par, b, v, ab = key[order], par[order], b[order], v[order], ab[order]
            starts = np.flatnonzero(np.concatenate([[True], key[1:] != key[:-1]]))
            gpar, gcell = par[starts], b[starts]
            is_and = self.kind[gpar] == AND
            red = np.where(is_and, np.maximum.reduceat(v, starts), np.minimum.reduceat(v, starts))
            present = np.add.reduceat(ab.astype(np.int64), starts)
            red = np.where(present < self.n_absorbing[gpar], np.where(is_and, np.inf, -np.inf), red)
            new = red != self.default[gpar]
            node = np.concatenate([node, gpar[new]])
            cell = np.concatenate([cell, gcell[new]])
            val = np.concatenate([val, red[new]])
        out = np.full(n_cells, self.default[self.root])
        at_root = node == self.root
        out[cell[at_root]] = val[at_root]
        return out
