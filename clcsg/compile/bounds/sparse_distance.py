"""The conservative signed distance of a CSG graph at the centers of many boxes at once,
evaluated only for the primitives near each box (a :class:`~clcsg.model.bvh.BoxTree` over the
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

Half-spaces are near every box (their boxes are unbounded), so an AND or OR with many plane
operands (a mesh operand is an expression of its face planes; a convex one is one AND of them)
would make boxes x planes pairs, each carried through the reductions.  Such operands are a
*plane group* of their parent instead: a plane's conservative distance is its exact signed
distance, ``s (w . c + e)`` with w its unit normal and s = -1 for a negated plane (eq. 10 with
lam = 0: f / |grad f|), so the group's reduction (max for an AND, min for an OR) is one dense
matrix product per batch of boxes, and enters the parent as a single operand present at every
box: the same value the parent would reduce from the planes one by one (to rounding; a plane
with a bounded side, normal to an axis, is FALSE over the boxes that miss its box, as above).
"""

from __future__ import annotations

import numpy as np

from ...model.quadric import ray_distance
from ...model.bvh import BoxTree

LEAF, AND, OR = 0, 1, 2
#: the fewest plane operands of one AND/OR evaluated as a dense group
MIN_GROUP = 4
#: the most (box, plane) values computed at once (memory of the dense products)
GROUP_CHUNK = 1 << 22


def plane_rows(mats: np.ndarray) -> np.ndarray:
    """Per literal (world matrices (n, 4, 4), solid x^T M x <= 0), whether it is a plane (no
    quadratic part, a nonzero linear one)."""
    return np.all(mats[:, :3, :3] == 0.0, axis=(1, 2)) & np.any(mats[:, :3, 3] != 0.0, axis=1)


def plane_distance(mats: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(w (n, 3), e (n,)) of plane literals: their signed distance at x is ``w . x + e``
    (x^T M x = 2 b . x + c with b = M[:3, 3], c = M[3, 3]; divided by |grad| = 2 |b|)."""
    b = mats[:, :3, 3]
    norm = np.linalg.norm(b, axis=1)
    return b / norm[:, None], mats[:, 3, 3] / (2.0 * norm)


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

    def __init__(self, kind, kids, neg, leaf_nodes, lit_first, lit_count, mats, lam_min, lam_max, box_lo, box_hi,
                 min_group: int = MIN_GROUP):
        self.kind = np.asarray(kind, dtype=np.int8)
        n = len(self.kind)
        self.root = n - 1
        self.leaf_nodes = np.asarray(leaf_nodes, dtype=np.int64)
        self.lit_first = np.asarray(lit_first, dtype=np.int64)
        self.lit_count = np.asarray(lit_count, dtype=np.int64)
        self.mats, self.lam_min, self.lam_max = mats, lam_min, lam_max
        self.leaf_neg = np.asarray([neg[i] for i in self.leaf_nodes], dtype=bool)
        flat = _flatten(self.kind, kids)
        groups = self._groups(flat, neg, min_group)
        # the groups are extra nodes n, n+1, ... (height 0, present at every box)
        n_all = n + len(groups)
        self.default = np.empty(n_all)
        self.default[n:] = np.nan  # never equal: a group's values are always kept
        self.n_absorbing = np.zeros(n_all, dtype=np.int64)
        height = np.zeros(n_all, dtype=np.int64)
        levels: dict = {}
        grouped_of = {parent: (n + g, members) for g, (parent, members) in enumerate(groups)}
        used = np.zeros(n, dtype=bool)  # leaves some parent reads one by one
        for i in range(n):
            if self.kind[i] == LEAF:
                self.default[i] = -np.inf if neg[i] else np.inf
                continue
            if flat[i] is None:
                continue
            ops = flat[i]
            if i in grouped_of:
                gid, members = grouped_of[i]
                member = set(members)
                ops = [k for k in ops if k not in member] + [gid]
            used[[k for k in ops if k < n]] = True
            ks = np.asarray(ops, dtype=np.int64)
            absorbing = np.inf if self.kind[i] == AND else -np.inf
            is_abs = self.default[ks] == absorbing
            if i in grouped_of:  # the group holds an absorbing plane: the parent's default is kept
                gid, members = grouped_of[i]
                is_abs[-1] = bool(np.any(self.default[members] == absorbing))
            self.n_absorbing[i] = int(is_abs.sum())
            self.default[i] = absorbing if self.n_absorbing[i] else -absorbing
            height[i] = 1 + (height[ks].max() if len(ks) else 0)
            levels.setdefault(int(height[i]), []).append((np.full(len(ks), i), ks, is_abs))
        self.heights = sorted(levels)
        self.levels = [tuple(np.concatenate(parts) for parts in zip(*levels[h])) for h in self.heights]
        self.group_nodes = np.arange(n, n_all)
        self.group_kind = np.array([self.kind[p] for p, _ in groups], dtype=np.int8)
        self.group_planes = []  # per group: (w (k, 3), e (k,)), signs folded in
        self.group_bounded = []  # per group: (columns, their boxes' lo, hi, FALSE values)
        leaf_index = {int(node): j for j, node in enumerate(self.leaf_nodes)}
        box_lo, box_hi = np.asarray(box_lo, dtype=np.float64), np.asarray(box_hi, dtype=np.float64)
        for _, members in groups:
            rows = np.array([leaf_index[k] for k in members], dtype=np.int64)
            w, e = plane_distance(self.mats[self.lit_first[rows]])
            s = np.where([neg[k] for k in members], -1.0, 1.0)
            self.group_planes.append((w * s[:, None], e * s))
            cols = np.flatnonzero(np.any(np.isfinite(box_lo[rows]) | np.isfinite(box_hi[rows]), axis=1))
            self.group_bounded.append((cols, box_lo[rows[cols]], box_hi[rows[cols]], np.where(s[cols] < 0, -np.inf, np.inf)))
        used[self.root] = True
        self.tree_leaves = np.flatnonzero(used[self.leaf_nodes]) if n else np.zeros(0, dtype=np.int64)
        self.tree = BoxTree(np.asarray(box_lo)[self.tree_leaves], np.asarray(box_hi)[self.tree_leaves])
        # the height of a node's last parent: its entries are dropped once that is done
        self.last_use = np.full(n_all, np.iinfo(np.int64).max)
        for h, (parents, kids, _) in zip(self.heights, self.levels):
            self.last_use[kids] = h
        if n:
            self.last_use[self.root] = np.iinfo(np.int64).max

    def _groups(self, flat, neg, min_group) -> list:
        """(parent, plane leaf nodes) of every AND/OR with at least ``min_group`` plane
        operands (single-literal leaves whose literal is a plane)."""
        if not min_group or not len(self.leaf_nodes):
            return []
        is_plane = np.zeros(len(self.kind), dtype=bool)
        single = self.lit_count == 1
        rows = plane_rows(self.mats[self.lit_first[single]]) if single.any() else np.zeros(0, dtype=bool)
        is_plane[self.leaf_nodes[single][rows]] = True
        out = []
        for i, ops in enumerate(flat):
            if ops is None:
                continue
            members = np.array([k for k in ops if is_plane[k]], dtype=np.int64)
            if len(members) >= min_group:
                out.append((i, members))
        return out

    def _group_entries(self, centers, reach):
        """(node, box, value) of every plane group at every box: the dense reductions."""
        nodes, cells, vals = [], [], []
        n_cells = len(centers)
        for gid, kind, (w, e), (cols, blo, bhi, false) in zip(self.group_nodes, self.group_kind, self.group_planes,
                                                             self.group_bounded):
            step = max(1, GROUP_CHUNK // max(1, len(e)))
            out = np.empty(n_cells)
            reduce = np.max if kind == AND else np.min
            for s in range(0, n_cells, step):
                v = centers[s:s + step] @ w.T + e
                if len(cols):
                    c, r = centers[s:s + step, None, :], reach[s:s + step, None, :]
                    miss = np.any((c - r > bhi[None]) | (c + r < blo[None]), axis=2)
                    v[:, cols] = np.where(miss, false[None], v[:, cols])
                out[s:s + step] = reduce(v, axis=1)
            nodes.append(np.full(n_cells, gid))
            cells.append(np.arange(n_cells))
            vals.append(out)
        return nodes, cells, vals

    @staticmethod
    def _reach(centers, half):
        """Half-sizes of the boxes padded as the box tree is queried."""
        pad = 1e-9 * (1.0 + np.abs(centers).max(axis=1) + half.max(axis=1))
        return half + pad[:, None]

    def _leaf_entries(self, centers, half):
        """(node, box, value) of every box and leaf read one by one whose boxes meet."""
        reach = self._reach(centers, half)
        cell, leaf = self.tree.query(centers - reach, centers + reach)
        leaf = self.tree_leaves[leaf]
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
        gn, gc, gv = self._group_entries(centers, self._reach(centers, half))
        node = np.concatenate([node[keep]] + gn).astype(np.int64)
        cell = np.concatenate([cell[keep]] + gc).astype(np.int64)
        val = np.concatenate([val[keep]] + gv)
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
