"""The surface of a point operand as a closed triangle mesh, for the paths that need the
solid's geometry rather than its samples: the exact ray tracer, ``clcsg.mesh``, the point
queries and ``clcsg info``.  Sampling and splatting use the surfels themselves
(:mod:`clcsg.sampling.surfel_csg`).

A cloud's solid S is known only through its membership test (the two-nearest-surfel rule of
:meth:`~clcsg.model.surfels.Surfels.contains`).  Its surface is extracted on a grid of spacing
h by marching tetrahedra (:mod:`~clcsg.model.marching_tetrahedra`) on the labels ``x in S`` of
the grid points:

* h is :data:`SPACING` times the median surfel radius, grown (:func:`spacing`) until the cubes
  that hold a surfel center number at most :data:`MAX_CUBES` (the mesh then has a few
  triangles per such cube, so its face planes stay within what a mesh operand samples and
  traces quickly);
* only cubes near the surfels are labelled: those within the largest radius plus a cube of a
  center, then every cube across a face of the region whose four corners disagree, until no
  face of the region's boundary is crossed, so the triangles of the region are closed;
* the grid is the cloud's box grown by two cubes and its outermost points count as outside:
  the solid is S clipped to that box (an open cloud, a single surfel's half-space, so becomes
  a bounded solid);
* each vertex is found on its crossing edge by :data:`BISECTIONS` halvings of the bracket of
  the membership change and put at the bracket's middle, strictly inside the edge, so the
  mesh keeps marching tetrahedra's topology: closed, consistently oriented, a 2-manifold,
  without self-intersections (every triangle lies in its own tetrahedron).

The mesh is within about h of the classification's surface (a feature thinner than h can be
missed, as by any grid) and within h / 2^BISECTIONS along the grid edges.
"""

from __future__ import annotations

import numpy as np

from .marching_tetrahedra import CORNERS, KUHN, triangulate

#: grid spacing in median surfel radii
SPACING = 2.0
#: the most grid cubes that hold a surfel center (the spacing grows until they fit)
MAX_CUBES = 1000
#: halvings of a crossing edge's bracket
BISECTIONS = 10

_FACES = (  # per axis: the corners of a cube's low face on that axis, and the step to its neighbour
    (np.array([0, 1, 2, 3]), np.array([1, 0, 0])),
    (np.array([0, 1, 4, 5]), np.array([0, 1, 0])),
    (np.array([0, 2, 4, 6]), np.array([0, 0, 1])),
)


def _held(points, lo, h) -> np.ndarray:
    """The grid cubes (m, 3) of spacing ``h`` from ``lo`` that hold a point (one sort of int64 keys)."""
    ijk = np.floor((points - lo) / h).astype(np.int64)
    n = ijk.max(axis=0) + 1
    keys = np.unique((ijk[:, 0] * n[1] + ijk[:, 1]) * n[2] + ijk[:, 2])
    return np.stack([keys // (n[1] * n[2]), keys // n[2] % n[1], keys % n[2]], axis=1)


def spacing(surfels) -> float:
    """The grid spacing h of ``surfels`` (see the module docstring).  A surface's held cubes
    fall about as h^-2, so a count over the limit first jumps h by the square root of the
    excess, then grows it by steps of 2^(1/3) while the limit is passed."""
    h = SPACING * float(np.median(surfels.radii))
    lo = surfels.points.min(axis=0)
    count = len(_held(surfels.points, lo, h))
    if count > MAX_CUBES:
        h *= 0.9 * np.sqrt(count / MAX_CUBES)
        while len(_held(surfels.points, lo, h)) > MAX_CUBES:
            h *= 2.0 ** (1.0 / 3.0)
    return h


class _Grid:
    """Integer grid points ijk (0 <= ijk <= n) at ``lo + ijk h``, their keys and labels."""

    def __init__(self, surfels, h: float):
        lo, hi = surfels.box()
        self.surfels, self.h = surfels, h
        self.lo = lo - 2.0 * h
        self.n = np.ceil((hi + 2.0 * h - self.lo) / h).astype(np.int64)
        self.labels: dict = {}

    def key(self, ijk):
        n1 = self.n + 1
        return (ijk[..., 0] * n1[1] + ijk[..., 1]) * n1[2] + ijk[..., 2]

    def xyz(self, ijk):
        return self.lo + ijk * self.h

    def label(self, ijk) -> np.ndarray:
        """Membership of grid points ``ijk`` (..., 3); the grid's outermost points are outside."""
        flat = ijk.reshape(-1, 3)
        keys = self.key(flat)
        uk, first, inv = np.unique(keys, return_index=True, return_inverse=True)
        known = np.array([k in self.labels for k in uk.tolist()], dtype=bool)
        if not known.all():
            pts = flat[first[~known]]
            rim = (pts == 0).any(axis=1) | (pts == self.n).any(axis=1)
            got = self.surfels.contains(self.xyz(pts)) & ~rim
            self.labels.update(zip(uk[~known].tolist(), got.tolist()))
        out = np.fromiter((self.labels[k] for k in uk.tolist()), dtype=bool, count=len(uk))
        return out[inv].reshape(ijk.shape[:-1])


def _region(grid: _Grid) -> np.ndarray:
    """The cubes (m, 3) whose triangles make a closed surface (see the module docstring)."""
    s = grid.surfels
    reach = int(np.ceil(float(s.radii.max()) / grid.h)) + 1
    held = _held(s.points, grid.lo, grid.h)
    steps = np.arange(-reach, reach + 1)
    offsets = np.stack(np.meshgrid(steps, steps, steps, indexing="ij"), axis=-1).reshape(-1, 3)
    cubes = np.unique((held[:, None, :] + offsets).reshape(-1, 3), axis=0)
    cubes = cubes[((cubes >= 0) & (cubes < grid.n)).all(axis=1)]
    while True:
        keys = set(grid.key(cubes).tolist())
        grow = []
        for corners, step in _FACES:
            for side, shift in ((0, -step), (1, step)):  # the low face, then the high face
                nb = cubes + shift
                inside_grid = ((nb >= 0) & (nb < grid.n)).all(axis=1)
                free = inside_grid & ~np.fromiter((k in keys for k in grid.key(nb).tolist()), bool, len(nb))
                if not free.any():
                    continue
                face = cubes[free][:, None, :] + CORNERS[corners] + side * step
                lab = grid.label(face)
                crossed = lab.any(axis=1) & ~lab.all(axis=1)
                grow.append(nb[free][crossed])
        new = np.concatenate(grow) if grow else np.zeros((0, 3), np.int64)
        if not len(new):
            return cubes
        cubes = np.unique(np.concatenate([cubes, new]), axis=0)


def surface_mesh(surfels, h: float | None = None) -> tuple[np.ndarray, np.ndarray]:
    """(vertices (n, 3), triangles (k, 3) oriented outward) of the surface of ``surfels``'s
    solid on a grid of spacing ``h`` (default :func:`spacing`); see the module docstring."""
    grid = _Grid(surfels, spacing(surfels) if h is None else float(h))
    cubes = _region(grid)
    corners = cubes[:, None, :] + CORNERS  # (m, 8, 3)
    lab = grid.label(corners)
    mixed = lab.any(axis=1) & ~lab.all(axis=1)
    tets = corners[mixed][:, KUHN]  # (m', 6, 4, 3)
    tets = tets.reshape(-1, 4, 3)
    tet_lab = lab[mixed][:, KUHN].reshape(-1, 4)
    edges, lo_inside, tri, _, _ = triangulate(grid.key(tets), tets, tet_lab)
    n1 = grid.n + 1
    ijk = np.stack([edges // (n1[1] * n1[2]), edges // n1[2] % n1[1], edges % n1[2]], axis=-1)  # (E, 2, 3)
    a = grid.xyz(np.where(lo_inside[:, None], ijk[:, 0], ijk[:, 1]))  # inside end
    b = grid.xyz(np.where(lo_inside[:, None], ijk[:, 1], ijk[:, 0]))  # outside end
    for _ in range(BISECTIONS):
        m = 0.5 * (a + b)
        ins = surfels.contains(m)
        a = np.where(ins[:, None], m, a)
        b = np.where(ins[:, None], b, m)
    return 0.5 * (a + b), tri
