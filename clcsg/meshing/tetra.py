"""Marching tetrahedra on the leaf cells: a closed, consistently oriented 2-manifold.

Each cube is split into the six tetrahedra of its Kuhn (Freudenthal) triangulation, all
sharing the diagonal from corner 000 to corner 111; neighbouring cubes then induce the same
diagonal on their common face, so the tetrahedra form a simplicial complex of the grid.  With
a binary label per grid point (inside the closed solid or not) the surface is the zero set of
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


def triangulate(cells, inside_of):
    """Triangles of the cells: (edges (E, 2) grid point ids, inside (E,) bool of edge[:, 0],
    triangles (T, 3) indices into edges, a cell (E,) holding each edge).  ``inside_of(ids)`` gives the membership of grid
    points.  Each edge is listed once (its ids sorted)."""
    ijk = cells.ijk
    corner_ijk = ijk[:, None, :] + CORNERS[None]  # (C, 8, 3)
    corner_id = cells.point_ids(corner_ijk)
    uniq, inv = np.unique(corner_id.ravel(), return_inverse=True)
    inside_u = inside_of(uniq)
    ins = inside_u[inv].reshape(-1, 8)
    tet_id = corner_id[:, KUHN]  # (C, 6, 4)
    tet_in = ins[:, KUHN]
    tet_xyz = corner_ijk[:, KUHN]  # (C, 6, 4, 3)
    mask = (tet_in * (1 << np.arange(4))).sum(axis=2)
    tris_a, tris_b, owner, cell_of = [], [], [], []
    for m, tris in _TABLE.items():
        sel = np.nonzero(mask == m)
        if not tris or not len(sel[0]):
            continue
        for tri in tris:
            pa = np.array([p for p, _ in tri])
            pb = np.array([q for _, q in tri])
            tris_a.append(tet_id[sel][:, pa])
            tris_b.append(tet_id[sel][:, pb])
            owner.append((sel, m, pa, pb))
            cell_of.append(sel[0])
    if not tris_a:
        return np.zeros((0, 2), np.int64), np.zeros(0, bool), np.zeros((0, 3), np.int64), np.zeros(0, np.int64)
    ea, eb = np.concatenate(tris_a), np.concatenate(tris_b)  # (T, 3) ids, a inside
    flip = np.concatenate([_needs_flip(tet_xyz[sel], m, pa, pb) for sel, m, pa, pb in owner])
    key_lo, key_hi = np.minimum(ea, eb), np.maximum(ea, eb)
    n = np.int64(cells.size) ** 3
    uniq, tri = np.unique(key_lo.ravel() * n + key_hi.ravel(), return_inverse=True)
    edges = np.stack([uniq // n, uniq % n], axis=1)
    tri = tri.reshape(-1, 3)
    lo_inside = np.zeros(len(edges), dtype=bool)
    lo_inside[tri.ravel()] = (key_lo == ea).ravel()
    tri[flip] = tri[flip][:, ::-1]
    edge_cell = np.zeros(len(edges), dtype=np.int64)
    edge_cell[tri.ravel()] = np.repeat(np.concatenate(cell_of), 3)
    return edges, lo_inside, tri, edge_cell


def _needs_flip(xyz, mask, pa, pb) -> np.ndarray:
    """Triangles (on the edges' exact midpoints) whose normal points to the inside corners."""
    mid = 0.5 * (xyz[:, pa] + xyz[:, pb]).astype(np.float64)  # (n, 3, 3)
    n = np.cross(mid[:, 1] - mid[:, 0], mid[:, 2] - mid[:, 0])
    w = np.array([1.0 if mask >> i & 1 else -1.0 for i in range(4)])
    w = np.where(w > 0, -1.0 / (w > 0).sum(), 1.0 / (w < 0).sum())
    outward = np.einsum("nkc,k->nc", xyz.astype(np.float64), w)
    return np.einsum("nc,nc->n", n, outward) < 0
