"""Minkowski sums of a convex polytope with a ball (and of a z-prism with a z-cylinder), exactly.

P + B(r) is the set of points within distance r of P.  The nearest point of P to such a point
lies inside a face, inside an edge or at a vertex, so (for convex P)

    P + B(r) = P | (face prisms) | (edge cylinders) | (vertex balls)

where the prism of face (n, d) is d <= n . x <= d + r inside the planes through the face's
edges perpendicular to it, the cylinder of edge ab has radius r and is cut by the planes
through a and b perpendicular to it, and the ball of vertex v has radius r.  Every piece lies
in the sum, so the union is exact; only the offset planes, the cylinders and the balls reach
the surface.  Flat polytopes (a polygon, a segment, a point) use the same pieces with both
sides of the polygon as faces.

A convex prism along z (faces with normals +z, -z or horizontal, :func:`z_prism`) plus a
cylinder along z is the extrusion of the cross-section offset by the radius (built in
:mod:`clcsg.model.hull`, in the frame of any cylinder axis).
"""

from __future__ import annotations

import numpy as np

from .construction import Construction, ball, plane, tube
from .csg import Complement, Intersection, Union
from .polytope import Polytope, polytope_solid


def polytope_plus_ball(poly: Polytope, radius: float, center=(0, 0, 0), color=None) -> Union:
    """The exact union of pieces of P + B(radius) translated by ``center``."""
    r = float(radius)
    c = np.asarray(center, dtype=np.float64)
    pieces = []
    if poly.dim == 3:
        pieces.append(polytope_solid(Polytope(3, poly.vertices + c, [(n, d + n @ c, lp + c) for n, d, lp in poly.faces]), color))
    for n, d, loop in poly.faces:
        lp = loop + c
        d = d + n @ c
        sides = []
        for i in range(len(lp)):
            a, b = lp[i], lp[(i + 1) % len(lp)]
            m = np.cross(b - a, n)
            m /= np.linalg.norm(m)
            sides.append(plane(m, m @ a, color))
        pieces.append(Intersection([Complement(plane(n, d, color)), plane(n, d + r, color), *sides]))
    for a, b in poly.edges:
        a, b = a + c, b + c
        u = (b - a) / np.linalg.norm(b - a)
        pieces.append(Intersection([tube(a, u, r, color), plane(u, u @ b, color), plane(-u, -(u @ a), color)]))
    for v in poly.vertices:
        pieces.append(ball(v + c, r, color))
    return Union(pieces)


def minkowski_ball(poly: Polytope, radius: float, center=(0, 0, 0), what="a polytope", color=None):
    body = polytope_plus_ball(poly, radius, center, color)
    v = poly.vertices + np.asarray(center, dtype=np.float64)
    return Construction("minkowski", f"minkowski of {what} and a sphere", body, box=(v.min(axis=0) - radius, v.max(axis=0) + radius))


def z_prism(poly: Polytope):
    """(cross-section vertices (k, 2), z0, z1) if ``poly`` is a prism along z, else None."""
    if poly.dim != 3:
        return None
    tops = [lp for n, d, lp in poly.faces if n[2] > 1 - 1e-12]
    for n, d, lp in poly.faces:
        if not (abs(n[2]) <= 1e-12 or abs(abs(n[2]) - 1) <= 1e-12):
            return None
    if len(tops) != 1:
        return None
    z = poly.vertices[:, 2]
    return tops[0][:, :2], float(z.min()), float(z.max())
