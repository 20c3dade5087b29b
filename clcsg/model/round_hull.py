"""Convex hulls of balls, or of disks perpendicular to one axis, exactly (a point is radius 0).

An item k is a ball B(c_k, r_k), or a disk of center c_k and radius r_k in the plane through
c_k perpendicular to the unit axis w (all disks share w; in the frame where w is +z).  With
the metric |v|_D = |v| for balls and |v|_D = |(v_x, v_y)| for disks, the support function of
the hull H is h(v) = max_k (v . c_k + r_k |v|_D), and

* a *face* is a plane v . x = h(v) touching three or more items: with |v|_D = 1 the two
  linear equations v . (c_j - c_i) = r_i - r_j, v . (c_k - c_i) = r_i - r_k leave a line of v,
  which meets |v|_D = 1 in at most two points (:func:`_faces`); it touches item m at the
  contact point T_m = c_m + r_m v (balls) or c_m + r_m (v_x, v_y, 0) (disks);
* an *edge* is a pair (i, j) whose support set {v : i and j maximal} is not empty: a side of
  a face polygon, or a full ring no face ends (:func:`_edges`).  Its patch lies on the
  common tangent cone of the two balls (a circular cone or cylinder), or on the cone through
  the two parallel circles (the homothety of one circle onto the other: an oblique circular
  cone, or an oblique cylinder for equal radii).  Both are quadrics.

H is C^1 off the points and disk rims, and every boundary point y with outer normal n has an
inner segment to its *center*: the ball's center (sphere patches), the point (1 - s) c_i +
s c_j (edge patches, y = (1 - s) T_i + s T_j), sum l_m c_m (faces, y = sum l_m T_m by a
triangulation of the face polygon), for disk rims the disk's center (the segment stays in the
disk); the flat cap faces of disks sweep inside their plane.  Moving every y along its segment
is a homotopy from the boundary to a surface inside conv(C) (C the centers of the items on
the boundary), so by the degree of the boundary around a point x in H outside conv(C) the
segments sweep x.  Each segment lies in the ball, in the pair hull hull(item_i, item_j), or
in conv(T_f | C_f) of its face, hence

    H = conv(C | T) | U_edges hull(item_i, item_j) | U_balls B_i

with T all contact points: one polytope (the face planes and the facets that close it inside),
one frustum per edge (its cone and the two planes of the tangent circles) and one sphere per
ball.  Every surface of H is among them, and a ball, an edge or a face that H does not have
brings nothing.
"""

from __future__ import annotations

import math

import numpy as np

from .construction import ball, plane, raw, tube
from .csg import Intersection, Primitive, Shape, Transformed, Union
from .profile import ProfileError
from .profile_ops import common_tangent
from .quadric import frame_z_to

_TOL = 1e-10  # in the normalized coordinates (centers around 0, size 1)
_CHUNK = 4096


class RoundHull:
    """The hull's combinatorics: faces (unit-D normal v, offset h, touching items), edges."""

    def __init__(self, centers, radii, disks: bool):
        c = np.asarray(centers, dtype=np.float64).reshape(-1, 3)
        r = np.asarray(radii, dtype=np.float64).reshape(-1)
        self.mean = c.mean(axis=0)
        self.scale = max(float(np.abs(c - self.mean).max()), float(r.max()), 1e-300)
        self.c, self.r = (c - self.mean) / self.scale, r / self.scale
        self.disks = disks
        self.d = np.diag([1.0, 1.0, 0.0]) if disks else np.eye(3)
        self.faces = _faces(self)
        self.edges = _edges(self)
        self.used = sorted({m for _, _, t in self.faces for m in t} | {m for e in self.edges for m in e})

    def contact(self, m, v):
        """The point where the plane with normal v touches item m (normalized coordinates)."""
        return self.c[m] + self.r[m] * (v @ self.d)

    def world(self, p):
        return np.asarray(p) * self.scale + self.mean


def _tangent_normals(hc, tri):
    """Candidate face normals (|v|_D = 1) of the planes tangent to the triples ``tri``."""
    c, r, d = hc.c, hc.r, hc.d
    i, j, k = tri.T
    a0, a1 = c[j] - c[i], c[k] - c[i]
    b0, b1 = r[i] - r[j], r[i] - r[k]
    g00, g01, g11 = (a0 * a0).sum(1), (a0 * a1).sum(1), (a1 * a1).sum(1)
    det = g00 * g11 - g01 * g01
    ok = det > 1e-20 * np.maximum(g00 * g11, 1e-300)
    det = np.where(ok, det, 1.0)
    y0, y1 = (g11 * b0 - g01 * b1) / det, (g00 * b1 - g01 * b0) / det
    p0 = y0[:, None] * a0 + y1[:, None] * a1  # the point of the solution line nearest 0
    w = np.cross(a0, a1)
    dw = w @ d
    qa, qb, qc = (w * dw).sum(1), (p0 * dw).sum(1), (p0 * (p0 @ d)).sum(1) - 1.0
    ok &= qa > 1e-20 * np.maximum((w * w).sum(1), 1e-300)
    qa = np.where(ok, qa, 1.0)
    disc = qb * qb - qa * qc
    ok &= disc >= 0
    root = np.sqrt(np.maximum(disc, 0.0))
    out = [p0 + ((-qb + s * root) / qa)[:, None] * w for s in (1.0, -1.0)]
    return np.vstack(out)[np.r_[ok, ok]], np.r_[tri, tri][np.r_[ok, ok]]


def _faces(hc):
    """(v, h, touching items) of every face plane of the hull."""
    n = len(hc.c)
    if n < 3:
        return []
    tri = np.array([(i, j, k) for i in range(n) for j in range(i + 1, n) for k in range(j + 1, n)])
    faces, seen = [], set()
    for s in range(0, len(tri), _CHUNK):
        v, t = _tangent_normals(hc, tri[s:s + _CHUNK])
        if not len(v):
            continue
        h = (v * hc.c[t[:, 0]]).sum(1) + hc.r[t[:, 0]]
        sup = hc.c @ v.T + hc.r[:, None]  # (n, candidates)
        keep = np.flatnonzero(sup.max(axis=0) <= h + _TOL)
        for q in keep:
            touch = tuple(np.flatnonzero(sup[:, q] >= h[q] - _TOL).tolist())
            key = (touch, tuple(np.round(v[q] / np.linalg.norm(v[q]), 7)))
            if key not in seen:
                seen.add(key)
                faces.append((v[q], float(h[q]), touch))
    return faces


def _sides(hc, v, touch):
    """Pairs of a face's items whose contact points span a side of the face polygon."""
    if len(touch) == 3:
        return [(touch[0], touch[1]), (touch[0], touch[2]), (touch[1], touch[2])]
    p = np.array([hc.contact(m, v) for m in touch])
    nrm = v / np.linalg.norm(v)
    out = []
    for a in range(len(touch)):
        for b in range(a + 1, len(touch)):
            e = p[b] - p[a]
            if np.linalg.norm(e) <= _TOL:
                continue
            side = (p - p[a]) @ np.cross(nrm, e)
            if np.all(side >= -_TOL) or np.all(side <= _TOL):
                out.append((touch[a], touch[b]))
    return out


def _ring_normal(hc, i, j):
    """A normal on the bisector of items i, j (both supports equal), or None."""
    c, r = hc.c, hc.r
    if hc.disks:
        dz = c[i, 2] - c[j, 2]
        if abs(dz) <= _TOL:
            return None  # coplanar disks: their hull is flat
        u = np.array([1.0, 0.0])
        return np.r_[u, (r[j] - r[i] - (c[i, :2] - c[j, :2]) @ u) / dz]
    dvec = c[i] - c[j]
    length = np.linalg.norm(dvec)
    if length <= abs(r[i] - r[j]) + _TOL:
        return None  # one ball holds the other
    a = (r[j] - r[i]) / length
    e = np.cross(dvec, [1.0, 0, 0] if abs(dvec[0]) < 0.9 * length else [0, 1.0, 0])
    e /= np.linalg.norm(e)
    return a * dvec / length + math.sqrt(max(0.0, 1 - a * a)) * e


def _edges(hc):
    """Pairs with a patch: the sides of the face polygons, and full rings (no face on them)."""
    edges = set()
    for v, _, touch in hc.faces:
        edges |= {tuple(sorted(e)) for e in _sides(hc, v, touch)}
    n = len(hc.c)
    for i in range(n):
        for j in range(i + 1, n):
            if (i, j) in edges:
                continue
            v = _ring_normal(hc, i, j)
            if v is not None:
                sup = hc.c @ v + hc.r
                if sup.max() <= sup[i] + _TOL and abs(sup[i] - sup[j]) <= _TOL:
                    edges.add((i, j))
    return sorted(edges)


def _facet_planes(points):
    """The facet planes (unit normal, offset) of conv(points), coplanar triangles merged."""
    from scipy.spatial import ConvexHull  # the caller checked scipy (convex_polytope)

    eq = ConvexHull(points).equations
    eq = eq / np.linalg.norm(eq[:, :3], axis=1, keepdims=True)
    out = []
    for e in eq:
        if not any(np.abs(e - o).max() <= 1e-9 for o in out):
            out.append(e)
    return [(e[:3], -e[3]) for e in out]


def _core(hc, color):
    """conv(C | T) as the intersection of its facet half-spaces, or None if it is flat."""
    pts = [hc.c[m] for m in hc.used] + [hc.contact(m, v) for v, _, t in hc.faces for m in t]
    pts = np.unique(np.round(np.array(pts), 14), axis=0)
    if len(pts) < 4 or np.linalg.matrix_rank(pts - pts.mean(axis=0), tol=1e-9) < 3:
        return None
    planes = _facet_planes(pts)
    return Intersection([plane(n, d * hc.scale + n @ hc.mean, color) for n, d in planes])


def ball_pair(c1, r1, c2, r2, color=None) -> Shape | None:
    """hull(B1, B2) without the balls: the frustum of the common tangent cone between the two
    tangent circles (at distance r_i sin(alpha) from each center towards the smaller ball,
    sin(alpha) = (r1 - r2) / |c2 - c1|), a finite cylinder for equal radii; None when one ball
    holds the other or both are points."""
    if r1 < r2:
        c1, r1, c2, r2 = c2, r2, c1, r1
    d = np.asarray(c2, float) - np.asarray(c1, float)
    length = float(np.linalg.norm(d))
    if length <= r1 - r2 or r1 <= 0:
        return None
    u = d / length
    if r1 == r2:
        return Intersection([tube(c1, u, r1, color), plane(u, u @ c2, color), plane(-u, -(u @ c1), color)])
    sin = (r1 - r2) / length
    apex = c1 + u * r1 / sin
    cone = Primitive("double_cone", {"apex": apex.tolist(), "axis": u.tolist(), "slope": sin / math.sqrt(1 - sin * sin)}, color)
    return Intersection([cone, plane(u, u @ c2 + r2 * sin, color), plane(-u, -(u @ c1 + r1 * sin), color)])


def disk_pair(p1, r1, p2, r2, color=None) -> Shape | None:
    """hull of two disks perpendicular to z at heights z1 < z2: inside the slab, the cone
    |(x, y) - q(z)| <= rho(z) with the center q and the radius rho linear in z (an oblique
    circular cone, or an oblique cylinder for r1 = r2); None for coplanar disks or two points."""
    if p1[2] > p2[2]:
        p1, r1, p2, r2 = p2, r2, p1, r1
    dz = float(p2[2] - p1[2])
    if dz <= 0 or (r1 <= 0 and r2 <= 0):
        return None
    t = np.array([0.0, 0.0, 1.0 / dz, -p1[2] / dz])  # (z - z1) / dz as a row over (x, y, z, 1)
    l1 = np.array([1.0, 0, 0, -p1[0]]) - (p2[0] - p1[0]) * t
    l2 = np.array([0, 1.0, 0, -p1[1]]) - (p2[1] - p1[1]) * t
    l3 = np.array([0, 0, 0, r1]) + (r2 - r1) * t
    m = np.outer(l1, l1) + np.outer(l2, l2) - np.outer(l3, l3)
    return Intersection([raw(m, color), plane((0, 0, 1), p2[2], color), plane((0, 0, -1), -p1[2], color)])


def _pieces(hc, color):
    pieces = []
    core = _core(hc, color)
    if core is not None:
        pieces.append(core)
    world = [hc.world(p) for p in hc.c]
    radii = hc.r * hc.scale
    pair = disk_pair if hc.disks else ball_pair
    for i, j in hc.edges:
        piece = pair(world[i], radii[i], world[j], radii[j], color)
        if piece is not None:
            pieces.append(piece)
    if not hc.disks:
        pieces += [ball(world[m], radii[m], color) for m in hc.used if radii[m] > 0]
    return pieces


def hull_of_balls(centers, radii, color=None) -> tuple[Shape, dict]:
    """The exact hull of balls (radius 0: points) and its counts (faces, edges, balls)."""
    c = np.asarray(centers, dtype=np.float64).reshape(-1, 3)
    r = np.asarray(radii, dtype=np.float64).reshape(-1)
    for i in range(len(c)):  # a ball holding all others is the hull
        if np.all(np.linalg.norm(c - c[i], axis=1) + r <= r[i] * (1 + 1e-15)):
            return ball(c[i], r[i], color), {"faces": 0, "edges": 0, "balls": 1}
    hc = RoundHull(c, r, disks=False)
    if not hc.used:
        raise ProfileError("the hull has no volume")
    counts = {"faces": len(hc.faces), "edges": len(hc.edges), "balls": sum(1 for m in hc.used if r[m] > 0)}
    return Union(_pieces(hc, color)), counts


def hull_of_disks(centers, radii, axis, color=None) -> tuple[Shape, dict]:
    """The exact hull of disks perpendicular to ``axis`` (radius 0: points)."""
    rot = frame_z_to(axis)
    loc = np.asarray(centers, dtype=np.float64).reshape(-1, 3) @ rot  # rot^T p for each row
    hc = RoundHull(loc, radii, disks=True)
    body = Union(_pieces(hc, color))
    if not body.operands:
        raise ProfileError("the hull is flat: it has no volume")
    m = np.eye(4)
    m[:3, :3] = rot
    counts = {"faces": len(hc.faces), "edges": len(hc.edges), "disks": len(hc.used)}
    return Transformed(body, m), counts


def disk_box(centers, radii, axis):
    """The bounding box of disks perpendicular to ``axis``."""
    w = np.asarray(axis, dtype=np.float64) / np.linalg.norm(axis)
    c = np.asarray(centers, dtype=np.float64).reshape(-1, 3)
    ext = np.asarray(radii, dtype=np.float64).reshape(-1, 1) * np.sqrt(np.maximum(0.0, 1 - w * w))
    return (c - ext).min(axis=0), (c + ext).max(axis=0)


def hull_coaxial(balls, disks, axis, origin, color=None) -> Shape:
    """The hull of balls centered on the line ``origin + t axis`` and of disks perpendicular
    to it and centered on it: a solid of revolution.  Its meridian in the half-plane
    (rho >= 0, z) is the right half of the 2-D hull of the balls' circles (centers (0, z)) and
    the disks' rim points (r, z); a boundary segment of it (a common tangent with outer normal
    rho > 0) turns into a cone frustum or a cylinder from the axis out, and its region between
    the axis and an arc lies in that arc's ball.  So the hull is the union of those frustums and
    the balls.  ``balls`` and ``disks``: lists of (center, radius)."""
    w = np.asarray(axis, dtype=np.float64) / np.linalg.norm(axis)
    o = np.asarray(origin, dtype=np.float64)
    circ = [(np.array([0.0, (np.asarray(c) - o) @ w]), float(r)) for c, r in balls]
    circ += [(np.array([float(r), (np.asarray(c) - o) @ w]), 0.0) for c, r in disks]
    cen = np.array([c for c, _ in circ])
    rad = np.array([r for _, r in circ])
    scale = max(np.abs(cen).max() + rad.max(), 1e-300)
    pieces, used = [], set()
    for i in range(len(circ)):
        for j in range(len(circ)):
            t = common_tangent(cen[i], rad[i], cen[j], rad[j]) if i != j else None
            if t is None or t[0][0] <= 1e-12:
                continue
            n, ti, tj = t
            if np.any(cen @ n + rad > n @ ti + 1e-12 * scale):
                continue
            used |= {i, j}
            (ra, za), (rb, zb) = sorted((ti, tj), key=lambda p: p[1])
            if zb - za > 1e-12 * scale and max(ra, rb) > 0:
                mid = o + w * (za + zb) / 2
                pieces.append(Primitive("cylinder", {"height": zb - za, "radius": ra, "center": mid.tolist(), "axis": w.tolist()}, color)
                              if abs(ra - rb) <= 1e-15 * scale else
                              Primitive("cone", {"height": zb - za, "r1": max(ra, 0.0), "r2": max(rb, 0.0),
                                                 "center": mid.tolist(), "axis": w.tolist()}, color))
    k = len(balls)
    if not used and k:  # one ball holds everything
        used = {int(np.argmax(rad[:k]))}
    pieces += [ball(balls[i][0], balls[i][1], color) for i in sorted(used) if i < k]
    if not pieces:
        raise ProfileError("the hull is flat: it has no volume")
    return Union(pieces)
