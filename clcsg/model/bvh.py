"""A bounding volume hierarchy over axis-aligned boxes, queried by many boxes at once.

The boxes are sorted along a Morton (Z-order) curve of their centers and become the leaves of
an implicit complete binary tree: level L holds 2^L nodes, node k of level L covers the
sorted leaves [k 2^(H-L), (k+1) 2^(H-L)), and its box is the union of its two children's.
Building is a sort and H pairwise reductions, all in numpy: O(n log n) with a small constant.

A query takes a batch of boxes and walks the levels breadth first with a frontier of
(query, node) pairs, all in numpy: the pairs whose boxes meet are expanded to both children,
the others dropped.  The answer is every (query, box) pair of closed boxes that meet: the test
is exact (no pair is missed, none is added), so callers may rely on "not listed" meaning
"disjoint".  Boxes with an infinite side (unbounded primitives) are not put in the tree; they
are tested against every query directly.  Empty boxes (lo > hi on some axis) never meet
anything.
"""

from __future__ import annotations

import numpy as np

#: bits per axis of the Morton code
_BITS = 10


def _spread(v: np.ndarray) -> np.ndarray:
    """The 10 low bits of ``v`` spread to every third bit (uint64)."""
    v = v.astype(np.uint64) & np.uint64(0x3FF)
    for shift, mask in ((16, 0x030000FF), (8, 0x0300F00F), (4, 0x030C30C3), (2, 0x09249249)):
        v = (v | (v << np.uint64(shift))) & np.uint64(mask)
    return v


def morton_order(points: np.ndarray) -> np.ndarray:
    """Indices sorting ``points`` (n, 3) along the Z-order curve of their bounding box."""
    if len(points) == 0:
        return np.zeros(0, dtype=np.int64)
    lo, hi = points.min(axis=0), points.max(axis=0)
    span = np.where(hi > lo, hi - lo, 1.0)
    q = np.clip(((points - lo) / span * ((1 << _BITS) - 1)).astype(np.int64), 0, (1 << _BITS) - 1)
    code = _spread(q[:, 0]) | (_spread(q[:, 1]) << np.uint64(1)) | (_spread(q[:, 2]) << np.uint64(2))
    return np.argsort(code, kind="stable")


def _meets(alo, ahi, blo, bhi) -> np.ndarray:
    """Rows where the closed boxes [alo, ahi] and [blo, bhi] meet (arrays (k, 3))."""
    return np.all((alo <= bhi) & (blo <= ahi), axis=1)


class BoxTree:
    """The hierarchy over boxes ``lo``, ``hi`` (n, 3); see the module docstring."""

    def __init__(self, lo, hi):
        lo = np.asarray(lo, dtype=np.float64).reshape(-1, 3)
        hi = np.asarray(hi, dtype=np.float64).reshape(-1, 3)
        self.n = len(lo)
        live = np.all(lo <= hi, axis=1)
        finite = live & np.all(np.isfinite(lo) & np.isfinite(hi), axis=1)
        self.unbounded = np.flatnonzero(live & ~finite)
        self.unb_lo, self.unb_hi = lo[self.unbounded], hi[self.unbounded]
        ids = np.flatnonzero(finite)
        ids = ids[morton_order(0.5 * (lo[ids] + hi[ids]))]
        height = max(0, int(np.ceil(np.log2(max(len(ids), 1)))))
        size = 1 << height
        self.leaf_id = np.full(size, -1, dtype=np.int64)
        self.leaf_id[:len(ids)] = ids
        llo = np.full((size, 3), np.inf)
        lhi = np.full((size, 3), -np.inf)
        llo[:len(ids)], lhi[:len(ids)] = lo[ids], hi[ids]
        levels = [(llo, lhi)]
        while len(levels[-1][0]) > 1:
            a, b = levels[-1]
            levels.append((np.minimum(a[0::2], a[1::2]), np.maximum(b[0::2], b[1::2])))
        self.levels = levels[::-1]  # root first
        self.empty = len(ids) == 0

    def query(self, qlo, qhi) -> tuple[np.ndarray, np.ndarray]:
        """(query index, box index) of every pair of meeting boxes, for query boxes ``qlo``,
        ``qhi`` (m, 3); pairs in no particular order, each once."""
        qlo = np.asarray(qlo, dtype=np.float64).reshape(-1, 3)
        qhi = np.asarray(qhi, dtype=np.float64).reshape(-1, 3)
        out_q, out_b = [], []
        if len(self.unbounded) and len(qlo):
            hit = np.all((qlo[:, None, :] <= self.unb_hi[None]) & (self.unb_lo[None] <= qhi[:, None, :]), axis=2)
            qi, bi = np.nonzero(hit)
            out_q.append(qi)
            out_b.append(self.unbounded[bi])
        if not self.empty and len(qlo):
            qi = np.arange(len(qlo))
            node = np.zeros(len(qlo), dtype=np.int64)
            for depth, (nlo, nhi) in enumerate(self.levels):
                keep = _meets(qlo[qi], qhi[qi], nlo[node], nhi[node])
                qi, node = qi[keep], node[keep]
                if depth + 1 < len(self.levels):
                    qi = np.repeat(qi, 2)
                    node = (np.repeat(2 * node, 2) + np.tile([0, 1], len(node)))
            bid = self.leaf_id[node]
            ok = bid >= 0
            out_q.append(qi[ok])
            out_b.append(bid[ok])
        if not out_q:
            return np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64)
        return np.concatenate(out_q).astype(np.int64), np.concatenate(out_b).astype(np.int64)
