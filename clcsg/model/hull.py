"""Convex hulls and Minkowski sums of placed solids, as exact quadric CSG.

The operands are read as *items* (unions are opened and transforms composed into them):
points (a box's 8 corners, a convex construction's vertices), spheres (under a similarity),
and cylinders (under a similarity: a circle stays a circle).

hull:
* points only: the convex polytope of all points (face planes);
* spheres of equal radius r: conv(centers) + B(r) (:mod:`clcsg.model.minkowski`): planes,
  cylinders along the edges, spheres at the corners: the rounded-box idiom;
* two spheres of different radii: both balls and the frustum of their common tangent cone
  between the two tangent circles (at distance r_i sin(alpha) from each center towards the
  smaller one, sin(alpha) = (r1 - r2) / |c2 - c1|);
* three or more spheres of any radii: a star decomposition from the centroid of the centers
  (:func:`_many_spheres`);
* cylinders with parallel axes and the same two cap planes: the extrusion of the 2-D hull of
  their circles (:func:`clcsg.model.profile_ops.hull_disks`: tangent lines and arcs).

minkowski (associative, and distributive over the union of the first operand):
points + points is the hull of the pairwise sums, spheres add centers and radii, a polytope
plus a ball is :func:`~clcsg.model.minkowski.polytope_plus_ball`, a z-prism plus a z-cylinder
is the extrusion of the cross-section offset by the radius.

Everything else (mixed operands, skew cylinders,
differences and intersections inside) is refused with a :class:`ProfileError` that names it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .construction import Construction, ball, bounded, first_color, plane, tube
from .csg import Intersection, Primitive, Shape, Transformed, Union
from .extrude import extrude
from .minkowski import minkowski_ball, z_prism
from .polytope import convex_polytope, polytope_solid
from .profile import ProfileError, polygon
from .profile_ops import hull_disks, offset_r
from .quadric import frame_z_to


@dataclass
class Item:
    kind: str               # "points", "sphere", "cylinder"
    name: str               # for messages: "cube", "sphere", ...
    points: np.ndarray = None
    center: np.ndarray = None
    radius: float = 0.0
    axis: np.ndarray = None  # unit, cylinders
    p0: np.ndarray = None    # cap centers, cylinders
    p1: np.ndarray = None


def _similarity(lin):
    g = lin.T @ lin
    s2 = g[0, 0]
    return math.sqrt(s2) if np.allclose(g, s2 * np.eye(3), rtol=0, atol=1e-12 * s2) else None


def _apply(m, p):
    return np.asarray(p, float) @ m[:3, :3].T + m[:3, 3]


def _item(node, m) -> Item:
    if isinstance(node, Construction) and node.vertices is not None:
        return Item("points", node.kind, points=_apply(m, node.vertices))
    if not isinstance(node, Primitive):
        raise ProfileError(f"a {type(node).__name__.lower()} inside is not covered (only cubes, spheres, "
                           "cylinders, points and convex extrusions or hulls)")
    p = node.params
    if node.kind == "box":
        s, c = np.broadcast_to(np.asarray(p.get("size", 1.0), float), (3,)), np.asarray(p.get("center", (0, 0, 0)), float)
        corners = c + s / 2 * np.array([[i, j, k] for i in (-1, 1) for j in (-1, 1) for k in (-1, 1)])
        return Item("points", "cube", points=_apply(m, corners))
    if node.kind == "sphere":
        k = _similarity(m[:3, :3])
        if k is None:
            raise ProfileError("a scaled sphere is an ellipsoid, which is not covered")
        return Item("sphere", "sphere", center=_apply(m, p.get("center", (0, 0, 0))), radius=k * float(p.get("radius", 1.0)))
    if node.kind == "cylinder":
        k = _similarity(m[:3, :3])
        if k is None:
            raise ProfileError("a non-uniformly scaled cylinder is elliptic, which is not covered")
        w = np.asarray(p.get("axis", (0, 0, 1)), float)
        w = w / np.linalg.norm(w)
        c = np.asarray(p.get("center", (0, 0, 0)), float)
        h = float(p.get("height", 1.0))
        a, b = _apply(m, c - w * h / 2), _apply(m, c + w * h / 2)
        return Item("cylinder", "cylinder", radius=k * float(p.get("radius", 1.0)), axis=(b - a) / np.linalg.norm(b - a), p0=a, p1=b)
    raise ProfileError(f"a {node.kind} is not covered (only cubes, spheres, cylinders, points and convex constructions)")


def items(shape: Shape, m=None) -> list[Item]:
    """The items of ``shape``: unions opened, transforms composed (explicit stack)."""
    out, stack = [], [(shape, np.eye(4) if m is None else m)]
    while stack:
        node, mat = stack.pop()
        if isinstance(node, Construction) and node.vertices is not None:
            out.append(_item(node, mat))
        elif isinstance(node, Union):
            stack.extend((k, mat) for k in reversed(node.operands))
        elif isinstance(node, Transformed):
            stack.append((node.operand, mat @ node.matrix))
        else:
            out.append(_item(node, mat))
    return out


def _count(its):
    names = {}
    for it in its:
        names[it.name] = names.get(it.name, 0) + 1
    return " and ".join(f"{n} {k}{'s' if n != 1 else ''}" for k, n in names.items())


def hull(*solids: Shape, color=None) -> Construction:
    """The exact convex hull of ``solids`` (OpenSCAD's ``hull()``)."""
    out = _hull(solids, first_color(solids) if color is None else color)
    out.spec = ("hull", tuple(solids))
    return out


def _hull(solids, color):
    its = [it for s in solids for it in items(s)]
    if not its:
        raise ProfileError("hull() of nothing")
    kinds = {it.kind for it in its}
    what = f"hull of {_count(its)}"
    if kinds == {"points"}:
        poly = convex_polytope(np.vstack([it.points for it in its]))
        if poly.dim < 3:
            raise ProfileError("hull() of flat points (coplanar) has no volume")
        box = (poly.vertices.min(axis=0), poly.vertices.max(axis=0))
        return Construction("hull", what, polytope_solid(poly, color), poly.vertices, box)
    if kinds == {"sphere"}:
        return _hull_spheres(its, what, color)
    if kinds == {"cylinder"}:
        return _hull_cylinders(its, what, color)
    raise ProfileError(f"hull() of {_count(its)} is not covered exactly (hulls of cubes and points, of spheres, "
                       "or of parallel cylinders with the same caps are); nearest exact alternative: "
                       "hull the spheres, the cubes or the cylinders separately")


def _hull_spheres(its, what, color):
    r = np.array([it.radius for it in its])
    c = np.array([it.center for it in its])
    if np.allclose(r, r[0], rtol=1e-12, atol=0):
        poly = convex_polytope(c)
        return Construction("hull", what, minkowski_ball(poly, r[0], color=color).operands[0])
    box = ((c - r[:, None]).min(axis=0), (c + r[:, None]).max(axis=0))
    if len(its) == 2:
        return Construction("hull", what, _two_spheres(c[0], r[0], c[1], r[1], color), box=box)
    return Construction("hull", what, _many_spheres(c, r, color), box=box)


def _two_spheres(c1, r1, c2, r2, color):
    if r1 < r2:
        c1, r1, c2, r2 = c2, r2, c1, r1
    d = c2 - c1
    length = np.linalg.norm(d)
    if length + r2 <= r1:
        return ball(c1, r1, color)
    u = d / length
    balls = [ball(p, q, color) for p, q in ((c1, r1), (c2, r2)) if q > 0]
    if r1 == r2:
        return Union(balls + [Intersection([tube(c1, u, r1, color), plane(u, u @ c2, color), plane(-u, -(u @ c1), color)])])
    sin = (r1 - r2) / length
    apex = c1 + u * r1 / sin
    slope = sin / math.sqrt(1 - sin * sin)
    cone = Primitive("double_cone", {"apex": apex.tolist(), "axis": u.tolist(), "slope": slope}, color)
    lo, hi = u @ c1 + r1 * sin, u @ c2 + r2 * sin
    frustum = Intersection([cone, plane(u, hi, color), plane(-u, -lo, color)])
    return Union(balls + [frustum])


def _tangent_planes(c, r, i, j, k):
    """Unit normals n with n . c_m + r_m equal for m = i, j, k (0, 1 or 2 of them)."""
    a = np.array([c[j] - c[i], c[k] - c[i]])
    b = np.array([r[i] - r[j], r[i] - r[k]])
    w = np.cross(a[0], a[1])
    if np.linalg.norm(w) <= 1e-12 * np.linalg.norm(a[0]) * np.linalg.norm(a[1]):
        return []
    p0 = np.linalg.lstsq(a, b, rcond=None)[0]  # the point of the solution line nearest 0
    w = w / np.linalg.norm(w)
    q = 1 - p0 @ p0
    if q < 0:
        return []
    return [p0 + s * math.sqrt(q) * w for s in (1, -1)]


def _pair(c, r, a, b, color):
    """hull(B_a, B_b) without the balls: a cone frustum, or a finite cylinder (r = 0: a point,
    the cone from it tangent to the other ball)."""
    if np.linalg.norm(c[a] - c[b]) <= abs(r[a] - r[b]):
        return Union([])  # one contains the other
    return _two_spheres(c[a], r[a], c[b], r[b], color).operands[-1]


def _faces(c, r):
    """The hull's face planes: (normal, indices of the balls touching it), each plane tangent to
    three balls with every ball on its inner side."""
    n, scale = len(c), float(np.abs(c).max() + r.max())
    out, seen = [], set()
    for i in range(n):
        for j in range(i + 1, n):
            for k in range(j + 1, n):
                for nrm in _tangent_planes(c, r, i, j, k):
                    h = nrm @ c[i] + r[i]
                    if np.all(c @ nrm + r <= h + 1e-12 * scale):
                        touch = tuple(m for m in range(n) if c[m] @ nrm + r[m] >= h - 1e-12 * scale)
                        key = (touch, tuple(np.round(nrm, 9)))
                        if key not in seen:
                            seen.add(key)
                            out.append((nrm, touch))
    return out


def _three(c, r, color):
    """hull of three balls (radii may be 0): conv(tangent points of its two tangent planes),
    the balls and the three pair hulls."""
    pieces = [ball(c[m], r[m], color) for m in range(3) if r[m] > 0]
    pieces += [_pair(c, r, a, b, color) for a, b in ((0, 1), (0, 2), (1, 2))]
    pts = [c[m] + r[m] * nrm for nrm, touch in _faces(c, r) for m in touch]
    if len(pts) >= 4:
        poly = convex_polytope(np.array(pts))
        if poly.dim == 3:
            pieces.append(polytope_solid(poly, color))
    return Union(pieces)


def _many_spheres(c, r, color):
    """Hull of three or more balls of different radii, star-shaped from O (the centroid of the
    centers, inside the hull): every hull point is on a segment from O to a boundary point, on
    a face triangle, on the cone patch of an edge (i, j) or on the sphere patch of a ball i, so

        hull = U conv(O, face) | U hull(O, B_i, B_j) | U hull(O, B_i)

    over the faces, edges and balls of the boundary; each piece lies in the hull.  hull(O, B_i)
    is B_i and the cone from O tangent to it; hull(O, B_i, B_j) is the three-ball case."""
    keep = [i for i in range(len(c)) if not any(j != i and np.linalg.norm(c[i] - c[j]) + r[i] <= r[j] for j in range(len(c)))]
    c, r = c[keep], r[keep]
    if len(c) == 1:
        return ball(c[0], r[0], color)
    if len(c) == 2:
        return _two_spheres(c[0], r[0], c[1], r[1], color)
    faces = _faces(c, r)
    if not faces:  # collinear centers: the balls and all pair hulls
        n = len(c)
        return Union([ball(c[m], r[m], color) for m in range(n)]
                     + [_pair(c, r, a, b, color) for a in range(n) for b in range(a + 1, n)])
    o = c.mean(axis=0)
    pieces, edges, used = [], set(), set()
    for nrm, touch in faces:
        pts = np.array([o] + [c[m] + r[m] * nrm for m in touch])
        poly = convex_polytope(pts)
        if poly.dim == 3:
            pieces.append(polytope_solid(poly, color))
        edges |= {(a, b) for a in touch for b in touch if a < b}
        used |= set(touch)
    for a, b in sorted(edges):
        pieces.append(_three(np.array([o, c[a], c[b]]), np.array([0.0, r[a], r[b]]), color))
    for m in sorted(used):
        pieces += [ball(c[m], r[m], color), _pair(np.array([o, c[m]]), np.array([0.0, r[m]]), 0, 1, color)]
    return Union(pieces)


def _frame(w):
    return frame_z_to(w)


def _hull_cylinders(its, what, color):
    w = its[0].axis
    rot = _frame(w)
    loc = [(rot.T @ it.p0, rot.T @ it.p1) for it in its]
    z0 = [min(a[2], b[2]) for a, b in loc]
    z1 = [max(a[2], b[2]) for a, b in loc]
    if not all(abs(abs(it.axis @ w) - 1) <= 1e-12 for it in its) or np.ptp(z0) > 1e-9 * max(1, abs(z0[0])) or np.ptp(z1) > 1e-9 * max(1, abs(z1[0])):
        raise ProfileError("hull() of cylinders is covered for parallel axes and the same two cap planes only")
    prof = hull_disks([a[:2] for a, _ in loc], [it.radius for it in its])
    ext = extrude(prof, z1[0] - z0[0], color=color)
    m = np.eye(4)
    m[:3, :3] = rot
    m[:3, 3] = rot @ np.array([0, 0, z0[0]])
    return Construction("hull", what, Transformed(ext, m))


def minkowski(*solids: Shape, color=None) -> Construction:
    """The exact Minkowski sum of ``solids`` (OpenSCAD's ``minkowski()``)."""
    out = _minkowski(solids, first_color(solids) if color is None else color)
    out.spec = ("minkowski", tuple(solids))
    return out


def _minkowski(solids, color):
    if not solids:
        raise ProfileError("minkowski() of nothing")
    first = items(solids[0])
    rest = [items(s) for s in solids[1:]]
    for group in rest:
        if len(group) != 1:
            raise ProfileError("minkowski(): operands after the first must each be one convex solid "
                               "(a cube, sphere, cylinder or convex hull)")
    others = [g[0] for g in rest]
    pieces = [_sum([it, *others], color) for it in first]
    what = f"minkowski of {_count(first)} and {_count(others)}" if others else f"minkowski of {_count(first)}"
    return Construction("minkowski", what, pieces[0] if len(pieces) == 1 else Union(pieces))


def _sum(its, color):
    pts = [it.points for it in its if it.kind == "points"]
    sph = [it for it in its if it.kind == "sphere"]
    cyl = [it for it in its if it.kind == "cylinder"]
    center = sum((s.center for s in sph), np.zeros(3))
    radius = sum(s.radius for s in sph)
    if not pts:
        if cyl:
            raise ProfileError("minkowski() of spheres and cylinders is not covered exactly (it is a rounded cylinder, "
                               "a torus edge); nearest exact alternative: a cube or polytope plus a sphere")
        return ball(center, radius, color)
    sums = pts[0]
    for p in pts[1:]:
        sums = (sums[:, None, :] + p[None, :, :]).reshape(-1, 3)
    poly = convex_polytope(sums)
    if cyl and sph:
        raise ProfileError("minkowski() of a polytope, a sphere and a cylinder is not covered exactly")
    if sph:
        return minkowski_ball(poly, radius, center, color=color).operands[0]
    if cyl:
        return _prism_cylinder(poly, cyl, color)
    if poly.dim < 3:
        raise ProfileError("minkowski() of flat polytopes has no volume")
    return bounded(polytope_solid(poly, color), poly.vertices.min(axis=0), poly.vertices.max(axis=0))


def _prism_cylinder(poly, cyl, color):
    if len(cyl) != 1 or abs(abs(cyl[0].axis[2]) - 1) > 1e-12:
        raise ProfileError("minkowski() with a cylinder is covered for one cylinder along z and a prism along z "
                           "(a cube or a straight extrusion); nearest exact alternative: a sphere")
    prism = z_prism(poly)
    if prism is None:
        raise ProfileError("minkowski() with a cylinder is covered for prisms along z only (a cube or a straight "
                           "extrusion of a convex polygon)")
    xy, z0, z1 = prism
    c = cyl[0]
    lo, hi = sorted((c.p0[2], c.p1[2]))
    prof = offset_r(polygon(xy), c.radius).translate(c.p0[:2])
    ext = extrude(prof, (z1 - z0) + (hi - lo), color=color)
    return Transformed(ext, np.array([[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, z0 + lo], [0, 0, 0, 1.0]]))
