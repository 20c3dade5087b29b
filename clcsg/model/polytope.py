"""Convex polytopes from points: faces (outward unit normal, offset, boundary loop), edges and
vertices, for the full-dimensional case (scipy's Qhull, coplanar triangles merged into
faces) and the flat ones (a polygon, a segment, a point).

The solid of a full-dimensional polytope is the intersection of its face half-spaces
n . x <= d; :func:`polytope_solid` builds it.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .construction import Construction, plane
from .csg import Intersection
from .profile import ProfileError


@dataclass
class Polytope:
    dim: int
    vertices: np.ndarray                            # (m, 3) extreme points
    faces: list = field(default_factory=list)       # (normal, offset, loop (k, 3)), counter-clockwise seen from outside
    edges: list = field(default_factory=list)       # (a, b) point pairs


def _affine_rank(p, scale):
    c = p - p.mean(axis=0)
    s = np.linalg.svd(c, compute_uv=False) if len(p) > 1 else np.zeros(1)
    return int(np.sum(s > 1e-10 * scale)), c


def convex_polytope(points) -> Polytope:
    try:
        from scipy.spatial import ConvexHull  # heavy: only when a hull or a Minkowski sum is built
    except ImportError:
        raise ProfileError("hulls and Minkowski sums of polytopes need scipy (Qhull): pip install 'clcsg[hull]'") from None

    p = np.unique(np.asarray(points, dtype=np.float64).reshape(-1, 3), axis=0)
    if not np.all(np.isfinite(p)):
        raise ProfileError("hull points must be finite")
    scale = max(np.abs(p).max(), 1e-300)
    rank, c = _affine_rank(p, scale)
    if rank == 0:
        return Polytope(0, p[:1])
    if rank == 1:
        u = np.linalg.svd(c)[2][0]
        t = c @ u
        a, b = p[np.argmin(t)], p[np.argmax(t)]
        return Polytope(1, np.array([a, b]), edges=[(a, b)])
    if rank == 2:
        return _flat(p, c)
    hull = ConvexHull(p)
    groups: dict = {}
    for simplex, eq in zip(hull.simplices, hull.equations):
        key = tuple(np.round(eq / np.linalg.norm(eq[:3]), 9))
        groups.setdefault(key, []).append(simplex)
    faces, edges = [], {}
    for key, simplices in groups.items():
        n = np.array(key[:3])
        n /= np.linalg.norm(n)
        loop = _boundary_loop(simplices, p, n)
        pts = p[loop]
        d = float(np.max(pts @ n))
        faces.append((n, d, pts))
        for i in range(len(loop)):
            e = tuple(sorted((loop[i], loop[(i + 1) % len(loop)])))
            edges[e] = True
    return Polytope(3, p[hull.vertices], faces, [(p[a], p[b]) for a, b in edges])


def _boundary_loop(simplices, p, n):
    count: dict = {}
    for s in simplices:
        for i in range(3):
            e = tuple(sorted((s[i], s[(i + 1) % 3])))
            count[e] = count.get(e, 0) + 1
    verts = sorted({v for e, k in count.items() if k == 1 for v in e})
    return _ccw(verts, p, n)


def _ccw(verts, p, n):
    """Vertex indices around their centroid, counter-clockwise seen from the side n points to;
    points not extreme in the plane (on an edge) are dropped by a 2-D hull."""
    pts = p[verts]
    c = pts.mean(axis=0)
    u = np.cross(n, [1.0, 0, 0]) if abs(n[0]) < 0.9 else np.cross(n, [0, 1.0, 0])
    u /= np.linalg.norm(u)
    v = np.cross(n, u)
    xy = np.c_[(pts - c) @ u, (pts - c) @ v]
    keep = _hull2d_indices(xy)
    return [verts[i] for i in keep]


def _hull2d_indices(xy):
    """Andrew's monotone chain: indices of the strictly convex hull, counter-clockwise."""
    order = sorted(range(len(xy)), key=lambda i: (xy[i][0], xy[i][1]))

    def cross(o, a, b):
        return (xy[a][0] - xy[o][0]) * (xy[b][1] - xy[o][1]) - (xy[a][1] - xy[o][1]) * (xy[b][0] - xy[o][0])

    span = max(np.ptp(xy[:, 0]), np.ptp(xy[:, 1]), 1e-300)
    tol = 1e-12 * span * span
    lower, upper = [], []
    for i in order:
        while len(lower) >= 2 and cross(lower[-2], lower[-1], i) <= tol:
            lower.pop()
        lower.append(i)
    for i in reversed(order):
        while len(upper) >= 2 and cross(upper[-2], upper[-1], i) <= tol:
            upper.pop()
        upper.append(i)
    return lower[:-1] + upper[:-1]


def hull2d(points) -> np.ndarray:
    """The strictly convex hull of 2-D points, counter-clockwise."""
    xy = np.unique(np.asarray(points, dtype=np.float64).reshape(-1, 2), axis=0)
    return xy[_hull2d_indices(xy)]


def _flat(p, c):
    n = np.linalg.svd(c)[2][2]
    loop = _ccw(list(range(len(p))), p, n)
    pts = p[loop]
    d = float(np.mean(pts @ n))
    faces = [(n, d, pts), (-n, -d, pts[::-1])]
    edges = [(pts[i], pts[(i + 1) % len(pts)]) for i in range(len(pts))]
    return Polytope(2, pts, faces, edges)


def polytope_solid(poly: Polytope, color=None):
    if poly.dim < 3:
        raise ProfileError("the points span no volume (they are coplanar): the hull is flat")
    return Intersection([plane(n, d, color) for n, d, _ in poly.faces])


def convex_polyhedron(points, faces, color=None):
    """A polyhedron given by points and faces, if it is convex: the intersection of its hull's
    face planes.  Convex means every face lies in one face plane of the hull of its points and
    every point on the hull's boundary (a closed surface inside the hull's boundary is all of
    it); otherwise a :class:`ProfileError`."""
    poly = convex_polytope(points)
    if poly.dim < 3:
        raise ProfileError("polyhedron() is flat: it has no volume")
    scale = float(np.abs(points).max())
    tol = 1e-9 * scale
    planes = np.array([np.r_[n, d] for n, d, _ in poly.faces])
    dist = points @ planes[:, :3].T - planes[:, 3]
    on = np.abs(dist) <= tol
    if not np.all(on.any(axis=1)):
        raise ProfileError("polyhedron() is not convex (a point lies inside its hull); nearest exact alternative: "
                           "a union of convex polyhedra or hull()")
    for k, f in enumerate(faces):
        if len(f) < 3 or not np.any(np.all(on[f], axis=0)):
            raise ProfileError(f"polyhedron() is not convex (face {k} is not on its hull); nearest exact alternative: "
                               "a union of convex polyhedra or hull()")
    box = (poly.vertices.min(axis=0), poly.vertices.max(axis=0))
    return Construction("polyhedron", f"convex polyhedron of {len(faces)} faces", polytope_solid(poly, color),
                        poly.vertices, box)
