"""Marching tetrahedra on a conforming tetrahedral mesh: a closed, consistently oriented
2-manifold.

Each cube is split into the six tetrahedra of its Kuhn (Freudenthal) triangulation, all
sharing the diagonal from corner 000 to corner 111; neighbouring cubes then induce the same
diagonal on their common face, so the tetrahedra form a simplicial complex of the grid (and
stay one under :mod:`clcsg.meshing.bisect`'s refinement).  With
a binary label per mesh vertex (inside the closed solid or not) the surface is the zero set of
the piecewise-linear interpolant of the labels: one triangle per tetrahedron with one or three
inside corners, two (a quad) with two.  That set separates inside from outside labels, is a
closed 2-manifold without boundary (the outermost grid points are outside) and keeps its
topology when each vertex slides along its crossing edge: the vertices are placed later, on
the exact surface, each strictly inside its edge.  Triangles are oriented with the outward
normal (towards the outside corners), decided on the grid's own exact midpoints.
"""

from __future__ import annotations

import itertools

import numpy as np

#: cube corner offsets, corner c = (c >> 2 & 1, c >> 1 & 1, c & 1)
CORNERS = np.array([[(c >> 2) & 1, (c >> 1) & 1, c & 1] for c in range(8)], dtype=np.int64)
#: the six Kuhn tetrahedra: 0 -> e_a -> e_a + e_b -> 7 for every order (a, b, c) of the axes
KUHN = np.array(
    [[0, 4 >> a, (4 >> a) | (4 >> b), 7] for a, b, _ in itertools.permutations(range(3))],
    dtype=np.int64,
)


def _case_table():
    """Per inside-bitmask of a tetrahedron's 4 corners: triangles as triples of corner pairs."""
    table = {}
    for mask in range(16):
        ins = [i for i in range(4) if mask >> i & 1]
        out = [i for i in range(4) if not mask >> i & 1]
        if len(ins) in (0, 4):
            table[mask] = []
        elif len(ins) == 1 or len(out) == 1:
            if len(ins) == 1:
                table[mask] = [[(ins[0], r) for r in out]]
            else:
                table[mask] = [[(r, out[0]) for r in ins]]
        else:
            (a, b), (c, d) = ins, out
            quad = [(a, c), (a, d), (b, d), (b, c)]
            table[mask] = [[quad[0], quad[1], quad[2]], [quad[0], quad[2], quad[3]]]
    return table


_TABLE = _case_table()


def triangulate(keys, xyz, inside):
    """Marching tetrahedra: (edges (E, 2) vertex keys, inside (E,) bool of edge[:, 0],
    triangles (T, 3) indices into edges, the tetrahedron holding each edge (E,) and each
    triangle (T,)).  ``keys``
    (N, 4) int64 and ``xyz`` (N, 4, 3) are the tetrahedra's corners, ``inside`` (N, 4) their
    membership.  Each edge is listed once (its keys sorted)."""
    mask = (inside * (1 << np.arange(4))).sum(axis=1)
    tris_a, tris_b, owner, tet_of = [], [], [], []
    for m, tris in _TABLE.items():
        sel = np.flatnonzero(mask == m)
        if not tris or not len(sel):
            continue
        for tri in tris:
            pa = np.array([p for p, _ in tri])
            pb = np.array([q for _, q in tri])
            tris_a.append(keys[sel][:, pa])
            tris_b.append(keys[sel][:, pb])
            owner.append((sel, m, pa, pb))
            tet_of.append(sel)
    if not tris_a:
        none = np.zeros(0, np.int64)
        return np.zeros((0, 2), np.int64), np.zeros(0, bool), np.zeros((0, 3), np.int64), none, none
    ea, eb = np.concatenate(tris_a), np.concatenate(tris_b)  # (T, 3) keys, a inside
    flip = np.concatenate([_needs_flip(xyz[sel], m, pa, pb) for sel, m, pa, pb in owner])
    key_lo, key_hi = np.minimum(ea, eb), np.maximum(ea, eb)
    vk, vi = np.unique(np.concatenate([key_lo.ravel(), key_hi.ravel()]), return_inverse=True)
    n = np.int64(len(vk))
    lo_i, hi_i = vi[:key_lo.size], vi[key_lo.size:]
    uniq, tri = np.unique(lo_i * n + hi_i, return_inverse=True)
    edges = np.stack([vk[uniq // n], vk[uniq % n]], axis=1)
    tri = tri.reshape(-1, 3)
    lo_inside = np.zeros(len(edges), dtype=bool)
    lo_inside[tri.ravel()] = (key_lo == ea).ravel()
    tri[flip] = tri[flip][:, ::-1]
    tri_tet = np.concatenate(tet_of)
    edge_tet = np.zeros(len(edges), dtype=np.int64)
    edge_tet[tri.ravel()] = np.repeat(tri_tet, 3)
    return edges, lo_inside, tri, edge_tet, tri_tet


def _needs_flip(xyz, mask, pa, pb) -> np.ndarray:
    """Triangles (on the edges' exact midpoints) whose normal points to the inside corners."""
    mid = 0.5 * (xyz[:, pa] + xyz[:, pb]).astype(np.float64)  # (n, 3, 3)
    n = np.cross(mid[:, 1] - mid[:, 0], mid[:, 2] - mid[:, 0])
    w = np.array([1.0 if mask >> i & 1 else -1.0 for i in range(4)])
    w = np.where(w > 0, -1.0 / (w > 0).sum(), 1.0 / (w < 0).sum())
    outward = np.einsum("nkc,k->nc", xyz.astype(np.float64), w)
    return np.einsum("nc,nc->n", n, outward) < 0
