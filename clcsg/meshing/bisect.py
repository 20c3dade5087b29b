"""A conforming tetrahedral mesh of the grid cells, refined locally by newest-vertex bisection.

The cells' Kuhn tetrahedra (:data:`~clcsg.model.marching_tetrahedra.KUHN`: 0 -> e_a -> e_a + e_b -> 7, tag 3) are
refined by Maubach's rule: a tetrahedron (x0, x1, x2, x3) with tag k is cut at the midpoint
z of its edge x0 x_k into

    (x0, ..., x_{k-1}, z, x_{k+1}, ..., x3)   and   (x1, ..., x_k, z, x_{k+1}, ..., x3),

both with tag k - 1 (3 after 1).  Three bisections of a Kuhn tetrahedron give eight Kuhn
tetrahedra of half the size, so the refinement is the Kuhn triangulation of a finer grid
wherever it is uniform.  A bisection leaves the mesh non-conforming where a neighbour shares
the cut edge; :func:`conform` bisects every tetrahedron that has a new vertex at the
midpoint of one of its edges until none has (this closure terminates for Kuhn meshes, and the
result is conforming: marching tetrahedra on it is still a closed 2-manifold).

Vertices live on an integer lattice :data:`SCALE` times finer than the grid, so every
midpoint is exact and a vertex is its integer key.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..model.marching_tetrahedra import CORNERS, KUHN

#: bisections of a grid cell's tetrahedra at most (three halve the size)
MAX_BISECTIONS = 9
#: lattice points per grid cell side: midpoints stay integral down to MAX_BISECTIONS and the
#: closure's few bisections beyond it (MAX_BISECTIONS + 6)
SCALE = 1 << (MAX_BISECTIONS // 3 + 3)
#: the six edges of a tetrahedron, as corner pairs
TET_EDGES = np.array([[0, 1], [0, 2], [0, 3], [1, 2], [1, 3], [2, 3]], dtype=np.int64)


@dataclass
class Tets:
    """Tetrahedra by lattice corners ``xyz`` (T, 4, 3) int64 in Maubach order, their ``tag``
    (T,) and ``depth`` (T,) (bisections from the cell), the quadrics of each one's pruned tape
    (T, U) bool, whether those were pruned over its own box (``pruned`` (T,), else inherited);
    lattice point (x, y, z) is grid point (x, y, z) / SCALE."""

    xyz: np.ndarray
    tag: np.ndarray
    depth: np.ndarray
    quadrics: np.ndarray
    pruned: np.ndarray
    side: int  # lattice points per axis

    def keys(self, xyz=None) -> np.ndarray:
        """Integer keys of lattice points (..., 3) (of the corners (T, 4) by default)."""
        p = self.xyz if xyz is None else np.asarray(xyz, dtype=np.int64)
        return (p[..., 0] * self.side + p[..., 1]) * self.side + p[..., 2]

    def lattice(self, keys) -> np.ndarray:
        """Lattice points (N, 3) of keys (the inverse of :meth:`keys`)."""
        k = np.asarray(keys, dtype=np.int64)
        return np.stack([k // (self.side * self.side), (k // self.side) % self.side, k % self.side], axis=-1)

    def __len__(self) -> int:
        return len(self.xyz)


def kuhn_tets(cells) -> Tets:
    """The six Kuhn tetrahedra of every cell, on the lattice, with the cell's quadrics."""
    corner = (cells.ijk[:, None, :] + CORNERS[None]) * SCALE  # (C, 8, 3)
    xyz = corner[:, KUHN].reshape(-1, 4, 3)
    n = len(xyz)
    return Tets(xyz, np.full(n, 3, dtype=np.int8), np.zeros(n, dtype=np.int16),
                np.repeat(cells.quadrics, 6, axis=0), np.ones(n, dtype=bool), (cells.size - 1) * SCALE + 1)


def bisect(tets: Tets, sel) -> tuple:
    """``tets`` with the tetrahedra ``sel`` (indices) each replaced by its two children, the
    children last.  Returns (new Tets, parent of each child (2 S,) into the old tets, the cuts:
    keys of the midpoints (S,) and of the cut edges' ends (S, 2)).  The children inherit their
    parent's quadrics (a superset: callers may prune them)."""
    sel = np.asarray(sel, dtype=np.int64)
    x, k = tets.xyz[sel], tets.tag[sel].astype(np.int64)
    twice = x[:, 0] + x[np.arange(len(sel)), k]
    if np.any(twice % 2):
        raise RuntimeError("bisection below the lattice: raise SCALE")
    z = twice // 2
    a = x.copy()
    a[np.arange(len(sel)), k] = z
    # child 2: (x1, ..., x_k, z, x_{k+1}, ..., x3): position i < k holds x_{i+1}, position k holds z
    i = np.arange(4)[None, :]
    src = np.where(i < k[:, None], i + 1, i)
    b = np.take_along_axis(x, src[:, :, None], axis=1)
    b[np.arange(len(sel)), k] = z
    tag = np.where(k > 1, k - 1, 3).astype(np.int8)
    keep = np.ones(len(tets), dtype=bool)
    keep[sel] = False
    parent = np.concatenate([sel, sel])
    return Tets(np.concatenate([tets.xyz[keep], a, b]),
                np.concatenate([tets.tag[keep], tag, tag]),
                np.concatenate([tets.depth[keep], tets.depth[sel] + 1, tets.depth[sel] + 1]),
                np.concatenate([tets.quadrics[keep], tets.quadrics[parent]]),
                np.concatenate([tets.pruned[keep], np.zeros(len(parent), dtype=bool)]), tets.side), parent, \
        (tets.keys(z), tets.keys(np.stack([x[:, 0], x[np.arange(len(sel)), k]], axis=1)))


def isin_sorted(x, sorted_keys) -> np.ndarray:
    """Which of ``x`` are among ``sorted_keys`` (sorted, int64)."""
    if not len(sorted_keys):
        return np.zeros(np.shape(x), dtype=bool)
    pos = np.minimum(np.searchsorted(sorted_keys, x), len(sorted_keys) - 1)
    return sorted_keys[pos] == x


def hanging(tets: Tets, midpoints, ends) -> np.ndarray:
    """Tetrahedra (indices) with one of the vertex keys ``midpoints`` (sorted) at the middle of
    an edge.  In a mesh that conformed before some bisections only their midpoints can be such
    vertices, and only on edges between two of their edges' ends (``ends``, sorted)."""
    near = np.flatnonzero(isin_sorted(tets.keys(), ends).sum(axis=1) >= 2)
    x = tets.xyz[near]
    s = x[:, TET_EDGES[:, 0]] + x[:, TET_EDGES[:, 1]]  # (N, 6, 3): twice the midpoints
    even = np.all(s % 2 == 0, axis=2)
    hit = even & isin_sorted(tets.keys(s // 2), midpoints)
    return near[hit.any(axis=1)]


def conform(tets: Tets, cuts) -> Tets:
    """Bisect until no tetrahedron has a hanging vertex, given the last bisection's ``cuts``
    (midpoint keys, edge end keys (S, 2)); the mesh conformed before it, so only vertices made
    since can hang."""
    midpoints, ends = np.unique(cuts[0]), np.unique(cuts[1])
    while True:
        h = hanging(tets, midpoints, ends)
        if not len(h):
            return tets
        tets, _parent, (made, made_ends) = bisect(tets, h)
        midpoints, ends = np.union1d(midpoints, made), np.union1d(ends, made_ends)


def refine_tets(tets: Tets, sel) -> Tets:
    """Bisect the tetrahedra ``sel`` and close the mesh again (:func:`conform`)."""
    tets, _parent, cuts = bisect(tets, sel)
    return conform(tets, cuts)
