"""Convex hulls and Minkowski sums of placed solids, as exact quadric CSG.

The operands are read as *items* (unions are opened and transforms composed into them):
points (a box's 8 corners, a convex construction's vertices), spheres (under a similarity),
and cylinders and cones (under a similarity: a circle stays a circle), each the hull of its
two cap disks.

hull:
* points only: the convex polytope of all points (face planes);
* spheres of equal radius r: conv(centers) + B(r) (:mod:`clcsg.model.minkowski`): planes,
  cylinders along the edges, spheres at the corners: the rounded-box idiom;
* spheres of any radii, with points (cubes, polytopes) or without:
  :func:`clcsg.model.round_hull.hull_of_balls`: the face planes, one tangent cone per edge and
  the balls, with one polytope and the frustum caps closing them inside;
* cylinders with parallel axes and the same two cap planes: the extrusion of the 2-D hull of
  their circles (:func:`clcsg.model.profile_ops.hull_disks`: tangent lines and arcs);
* cylinders and cones with parallel axes and any caps, with points or without:
  :func:`clcsg.model.round_hull.hull_of_disks` (oblique cones between the cap circles).

minkowski (associative, and distributive over the union of the first operand):
points + points is the hull of the pairwise sums, spheres add centers and radii, parallel
cylinders and cones add their cap disks pairwise; a polytope plus a ball is
:func:`~clcsg.model.minkowski.polytope_plus_ball`, a polytope plus cylinders or cones is the
hull of the disks placed at its vertices (conv(V) + conv(D) = conv(V + D)), for a prism along
a cylinder's axis the extrusion of the cross-section offset by the radius.

Everything else (spheres with cylinders, cylinders that are not parallel, differences and
intersections inside) is refused with a :class:`ProfileError` that names it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .construction import Construction, ball, bounded, first_color
from .csg import Primitive, Shape, Transformed, Union
from .extrude import extrude
from .minkowski import minkowski_ball, z_prism
from .polytope import convex_polytope, polytope_solid
from .profile import ProfileError, polygon
from .profile_ops import hull_disks, offset_r
from .quadric import frame_z_to
from .round_hull import disk_box, hull_coaxial, hull_of_balls, hull_of_disks


@dataclass
class Item:
    kind: str               # "points", "sphere", "cylinder" (cylinders and cones)
    name: str               # for messages: "cube", "sphere", ...
    points: np.ndarray = None
    center: np.ndarray = None
    radius: float = 0.0      # spheres; cylinders: r0 if r0 == r1
    axis: np.ndarray = None  # unit, cylinders
    p0: np.ndarray = None    # cap centers, cylinders
    p1: np.ndarray = None
    r0: float = 0.0          # cap radii at p0, p1 (cones: one may be 0)
    r1: float = 0.0
    parts: list = None       # "group": the items of a hull() operand (one convex item)


def _similarity(lin):
    g = lin.T @ lin
    s2 = g[0, 0]
    return math.sqrt(s2) if np.allclose(g, s2 * np.eye(3), rtol=0, atol=1e-12 * s2) else None


def _apply(m, p):
    return np.asarray(p, float) @ m[:3, :3].T + m[:3, 3]


def _item(node, m) -> Item:
    if isinstance(node, Construction) and node.vertices is not None:
        return Item("points", node.kind, points=_apply(m, node.vertices))
    if isinstance(node, Construction) and node.disks is not None:
        return _disk_item(node, m)
    if isinstance(node, Construction):
        raise ProfileError(f"a {node.label} inside is not covered (only cubes, spheres, cylinders, cones, points, hulls "
                           "and convex extrusions)")
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
    if node.kind in ("cylinder", "cone"):
        k = _similarity(m[:3, :3])
        if k is None:
            raise ProfileError(f"a non-uniformly scaled {node.kind} is elliptic, which is not covered")
        w = np.asarray(p.get("axis", (0, 0, 1)), float)
        w = w / np.linalg.norm(w)
        c = np.asarray(p.get("center", (0, 0, 0)), float)
        h = float(p.get("height", 1.0))
        a, b = _apply(m, c - w * h / 2), _apply(m, c + w * h / 2)
        if node.kind == "cone":
            r0, r1 = k * float(p.get("r1", 1.0)), k * float(p.get("r2", 0.0))
        else:
            r0 = r1 = k * float(p.get("radius", 1.0))
        return Item("cylinder", node.kind, radius=r0, axis=(b - a) / np.linalg.norm(b - a), p0=a, p1=b, r0=r0, r1=r1)
    raise ProfileError(f"a {node.kind} is not covered (only cubes, spheres, cylinders, points and convex constructions)")


def _disk_item(node, m) -> Item:
    """An extruded circle: the cylinder or cone (oblique when scaled off the origin) between its
    two cap disks, which are perpendicular to the extrusion's z."""
    k = _similarity(m[:3, :3])
    if k is None:
        raise ProfileError("a non-uniformly scaled extruded circle is elliptic, which is not covered")
    (c0, r0), (c1, r1) = node.disks
    a, b = _apply(m, c0), _apply(m, c1)
    w = _apply(m, (0, 0, 1)) - _apply(m, (0, 0, 0))
    return Item("cylinder", "linear_extrude", radius=k * r0, axis=w / np.linalg.norm(w), p0=a, p1=b, r0=k * r0, r1=k * r1)


def items(shape: Shape, m=None) -> list[Item]:
    """The items of ``shape``: unions opened, transforms composed (explicit stack)."""
    out, stack = [], [(shape, np.eye(4) if m is None else m)]
    while stack:
        node, mat = stack.pop()
        if isinstance(node, Construction) and (node.vertices is not None or node.disks is not None):
            out.append(_item(node, mat))
        elif isinstance(node, Construction) and node.kind == "hull" and isinstance(node.spec, tuple):
            out.append(Item("group", "hull", parts=[it for k in node.spec[1] for it in items(k, mat)]))
        elif isinstance(node, Construction) and node.kind != "hull":
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


def _flat(its):
    """A hull of hulls is the hull of all their parts."""
    out = []
    for it in its:
        out += _flat(it.parts) if it.kind == "group" else [it]
    return out


def _hull(solids, color):
    its = _flat([it for s in solids for it in items(s)])
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
    if "sphere" in kinds and "cylinder" not in kinds:
        return _hull_spheres(its, what, color)
    if "cylinder" in kinds and "sphere" not in kinds:
        if kinds == {"cylinder"} and _same_caps(its):
            return _hull_cylinders(its, what, color)
        return _hull_disks(its, what, color)
    coax = _coaxial(its)
    if coax is not None:
        return Construction("hull", what, hull_coaxial(*coax[:4], color=color), box=coax[4])
    raise ProfileError(f"hull() of {_count(its)} is not covered exactly (spheres with cylinders or cones off their "
                       "axis: the surface between a sphere and a circle is in general no quadric); nearest exact "
                       "alternative: spheres centered on the cylinders' common axis, or hull the spheres and the "
                       "cylinders separately")


def _coaxial(its):
    """(balls, disks, axis, origin, box) if every sphere center, cap center and point lies on
    the cylinders' common axis line (a solid of revolution), else None."""
    cyl = [it for it in its if it.kind == "cylinder"]
    w, o = cyl[0].axis, cyl[0].p0
    balls = [(it.center, it.radius) for it in its if it.kind == "sphere"]
    disks = [(p, q) for it in cyl for p, q in ((it.p0, it.r0), (it.p1, it.r1))]
    disks += [(p, 0.0) for it in its if it.kind == "points" for p in it.points]
    size = max(float(np.abs([c for c, _ in balls + disks]).max()), max(r for _, r in balls + disks), 1e-300)
    off = [np.linalg.norm((c - o) - ((c - o) @ w) * w) for c, _ in balls + disks]
    if max(off) > 1e-9 * size or any(abs(abs(it.axis @ w) - 1) > 1e-12 for it in cyl):
        return None
    lo = np.min([c - r for c, r in balls] + [disk_box([c], [r], w)[0] for c, r in disks], axis=0)
    hi = np.max([c + r for c, r in balls] + [disk_box([c], [r], w)[1] for c, r in disks], axis=0)
    return balls, disks, w, o, (lo, hi)
def _hull_spheres(its, what, color):
    """Balls of one radius: conv(centers) + B(r); any radii, with points: :mod:`round_hull`."""
    pts = [it for it in its if it.kind == "points"]
    sph = [it for it in its if it.kind == "sphere"]
    r = np.array([it.radius for it in sph])
    c = np.array([it.center for it in sph])
    if not pts and np.allclose(r, r[0], rtol=1e-12, atol=0) and len(sph) > 1:
        poly = convex_polytope(c)
        return Construction("hull", what, minkowski_ball(poly, r[0], color=color).operands[0])
    if pts:
        p = _extreme(np.vstack([it.points for it in pts]))
        c, r = np.vstack([c, p]), np.r_[r, np.zeros(len(p))]
    body, _ = hull_of_balls(c, r, color)
    box = ((c - r[:, None]).min(axis=0), (c + r[:, None]).max(axis=0))
    return Construction("hull", what, body, box=box)


def _extreme(points):
    """The vertices of conv(points) (all of them if they are flat)."""
    poly = convex_polytope(points)
    return poly.vertices


def _disks(its):
    """(centers, radii, axis) of the disks of cylinder and cone items (points: radius 0)."""
    cyl = [it for it in its if it.kind == "cylinder"]
    w = cyl[0].axis
    if not all(abs(abs(it.axis @ w) - 1) <= 1e-12 for it in cyl):
        raise ProfileError("cylinders and cones whose axes are not parallel are not covered exactly (their hull or "
                           "sum has non-quadric patches); nearest exact alternative: parallel axes")
    c = [p for it in cyl for p in (it.p0, it.p1)]
    r = [q for it in cyl for q in (it.r0, it.r1)]
    pts = [it.points for it in its if it.kind == "points"]
    if pts:
        p = _extreme(np.vstack(pts))
        c, r = c + list(p), r + [0.0] * len(p)
    return np.array(c), np.array(r), w


def _hull_disks(its, what, color):
    c, r, w = _disks(its)
    body, _ = hull_of_disks(c, r, w, color)
    return Construction("hull", what, body, box=disk_box(c, r, w))


def _same_caps(its):
    """Parallel cylinders (equal cap radii) whose caps lie in the same two planes."""
    w = its[0].axis
    if not all(abs(abs(it.axis @ w) - 1) <= 1e-12 and it.r0 == it.r1 for it in its):
        return False
    rot = frame_z_to(w)
    z = np.array([sorted(((rot.T @ it.p0)[2], (rot.T @ it.p1)[2])) for it in its])
    return bool(np.ptp(z[:, 0]) <= 1e-9 * max(1, abs(z[0, 0])) and np.ptp(z[:, 1]) <= 1e-9 * max(1, abs(z[0, 1])))


def _hull_cylinders(its, what, color):
    w = its[0].axis
    rot = frame_z_to(w)
    loc = [(rot.T @ it.p0, rot.T @ it.p1) for it in its]
    z0 = [min(a[2], b[2]) for a, b in loc]
    z1 = [max(a[2], b[2]) for a, b in loc]
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


_MIXED = ("minkowski() of spheres and cylinders is not covered exactly (it is a rounded cylinder, "
          "a torus edge); nearest exact alternative: a cube or polytope plus a sphere")


def _round_set(it):
    """An item as (kind, centers, radii, axis): "points", "balls" or "disks" (the hull of
    them; a hull() operand is the hull of its parts' sets)."""
    if it.kind == "points":
        return "points", it.points, np.zeros(len(it.points)), None
    if it.kind == "sphere":
        return "balls", it.center[None], np.array([it.radius]), None
    if it.kind == "cylinder":
        return "disks", np.array([it.p0, it.p1]), np.array([it.r0, it.r1]), it.axis
    sets = [_round_set(p) for p in it.parts]
    kinds = {k for k, *_ in sets} - {"points"}
    if len(kinds) > 1:
        raise ProfileError(_MIXED)
    axis = next((a for _, _, _, a in sets if a is not None), None)
    _parallel(axis, [a for _, _, _, a in sets])
    return (kinds.pop() if kinds else "points"), np.vstack([c for _, c, _, _ in sets]), np.concatenate([r for _, _, r, _ in sets]), axis


def _parallel(w, axes):
    if any(a is not None and abs(abs(a @ w) - 1) > 1e-12 for a in axes):
        raise ProfileError("cylinders and cones whose axes are not parallel are not covered exactly (their hull or "
                           "sum has non-quadric patches); nearest exact alternative: parallel axes")


def _sum(its, color):
    """The sum of convex items as the hull of one set of balls or of parallel disks: the hull
    of sets adds pairwise (B(c, r) + B(c', r') = B(c + c', r + r'), the same for parallel disks,
    conv(A) + conv(B) = conv(A + B)); points are radius 0."""
    kind, c, r, axis = "points", np.zeros((1, 3)), np.zeros(1), None
    for it in its:
        k, dc, dr, a = _round_set(it)
        if {kind, k} == {"balls", "disks"}:
            raise ProfileError(_MIXED)
        if a is not None:
            _parallel(a, [axis])
            axis = a
        kind = k if kind == "points" else kind
        c, r = _prune((c[:, None, :] + dc[None]).reshape(-1, 3), (r[:, None] + dr[None]).reshape(-1))
    if kind == "points":
        poly = convex_polytope(c)
        if poly.dim < 3:
            raise ProfileError("minkowski() of flat polytopes has no volume")
        return bounded(polytope_solid(poly, color), poly.vertices.min(axis=0), poly.vertices.max(axis=0))
    if kind == "balls":
        if len(c) == 1:
            return ball(c[0], r[0], color)
        if np.ptp(r) <= 1e-12 * r.max():
            return minkowski_ball(convex_polytope(c), r[0], color=color).operands[0]
        body, _ = hull_of_balls(c, r, color)
        return bounded(body, (c - r[:, None]).min(axis=0), (c + r[:, None]).max(axis=0))
    if np.ptp(r) <= 1e-12 * r.max():
        prism = _prism_disks(c, r[0], axis, color)
        if prism is not None:
            return prism
    body, _ = hull_of_disks(c, r, axis, color)
    return bounded(body, *disk_box(c, r, axis))


def _prune(c, r):
    """Items of one radius whose center is not a vertex of the hull of that radius' centers
    lie in the hull of the others (conv(C) + B(r) = conv(C + B(r))): only vertices stay."""
    keep_c, keep_r = [], []
    for q in np.unique(r):
        pts = c[r == q]
        v = convex_polytope(pts).vertices if len(pts) > 2 else np.unique(pts, axis=0)
        keep_c.append(v)
        keep_r.append(np.full(len(v), q))
    return np.vstack(keep_c), np.concatenate(keep_r)


def _prism_disks(c, radius, axis, color):
    """conv(C) + D(radius) for a prism conv(C) along the disks' axis: the extrusion of the
    cross-section offset by the radius, in the axis' frame (None if conv(C) is no such prism)."""
    rot = frame_z_to(axis)
    poly = convex_polytope(c @ rot)
    prism = z_prism(poly)
    if prism is None:
        return None
    xy, z0, z1 = prism
    ext = extrude(offset_r(polygon(xy), radius), z1 - z0, color=color)
    m = np.eye(4)
    m[:3, :3] = rot
    m[:3, 3] = rot @ np.array([0, 0, z0])
    return Transformed(ext, m)
