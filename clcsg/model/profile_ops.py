"""2-D offsets and hulls of profiles, exactly (lines and arcs).

* ``offset(r)``: the Minkowski sum with a disk of radius r > 0 is
  P | (rectangle of each edge, width 2r) | (disk at each convex corner); for r < 0 it is
  P - (rectangles) - (disks at the reflex corners), the complement's sum.  Corners are convex
  or reflex with respect to the filled side (outer loops counter-clockwise, holes clockwise).
* ``offset(delta)``: every edge line moves by delta, consecutive lines meet at the new
  corners (mitered); ``chamfer`` cuts convex corners by the line perpendicular to the corner's
  bisector at distance |delta| (OpenSCAD's square joins).  Refused when an edge would turn
  around (a collapsed edge changes the polygon's topology).
* The hull of disks c_i, r_i (any radii; polygon vertices are disks of radius 0) is
  conv(T) | disks, T the tangent points of the hull's common tangent lines: each arc of the
  boundary bounds a circular segment inside its disk.
"""

from __future__ import annotations

import math

import numpy as np

from .polytope import hull2d
from .profile import Profile, ProfileError, circle, difference2d, polygon, union2d


def _rect(a, b, r) -> Profile:
    u = (b - a) / np.linalg.norm(b - a)
    n = np.array([u[1], -u[0]]) * r
    return polygon([a + n, b + n, b - n, a - n])


def offset_r(p: Profile, r: float) -> Profile:
    """Rounded offset (OpenSCAD ``offset(r = ...)``)."""
    r = float(r)
    if p.circle is not None:
        (cx, cy), rc = p.circle
        return circle(rc + r, (cx, cy)) if rc + r > 0 else Profile("empty")
    if p.loops is None:
        raise ProfileError("offset() of a 2-D Boolean result has no exact form here; "
                           "nearest exact alternative: offset each square, circle or polygon before combining")
    if r == 0:
        return p
    rects, disks = [], []
    for lp in p.loops:
        n = len(lp)
        for i in range(n):
            a, b, c = lp[i - 1], lp[i], lp[(i + 1) % n]
            rects.append(_rect(b, c, abs(r)))
            turn = (b - a)[0] * (c - b)[1] - (b - a)[1] * (c - b)[0]
            if (turn > 0) == (r > 0):
                disks.append(circle(abs(r), b))
    if r > 0:
        out = union2d(p, *rects, *disks)
    else:
        out = difference2d(p, *rects, *disks)
    x0, y0, x1, y1 = p.bbox
    return Profile(out.op, out.data, out.kids, bbox=(x0 - r, y0 - r, x1 + r, y1 + r) if r > 0 else p.bbox)


def _meet(n1, d1, n2, d2):
    m = np.array([n1, n2])
    return np.linalg.solve(m, [d1, d2])


def offset_delta(p: Profile, delta: float, chamfer: bool = False) -> Profile:
    """Sharp (or chamfered) offset (OpenSCAD ``offset(delta = ...)``)."""
    delta = float(delta)
    if p.circle is not None:
        (cx, cy), rc = p.circle
        return circle(rc + delta, (cx, cy)) if rc + delta > 0 else Profile("empty")
    if p.loops is None:
        raise ProfileError("offset() of a 2-D Boolean result has no exact form here; "
                           "nearest exact alternative: offset each square, circle or polygon before combining")
    loops = []
    for lp in p.loops:
        k = len(lp)
        normals = []
        for i in range(k):
            e = lp[(i + 1) % k] - lp[i]
            normals.append(np.array([e[1], -e[0]]) / np.linalg.norm(e))
        out = []
        for i in range(k):
            n0, n1 = normals[i - 1], normals[i]
            v = lp[i]
            turn = n0[0] * n1[1] - n0[1] * n1[0]
            if chamfer and (turn > 0) == (delta > 0) and n0 @ n1 < 1 - 1e-12:
                bis = (n0 + n1) / np.linalg.norm(n0 + n1) * math.copysign(1, delta)
                out.append(_meet(n0, n0 @ v + delta, bis, bis @ v + abs(delta)))
                out.append(_meet(bis, bis @ v + abs(delta), n1, n1 @ v + delta))
            else:
                out.append(_meet(n0, n0 @ v + delta, n1, n1 @ v + delta))
        out = np.array(out)
        if not chamfer:
            for i in range(k):
                if (out[(i + 1) % k] - out[i]) @ (lp[(i + 1) % k] - lp[i]) <= 0:
                    raise ProfileError(f"offset(delta = {delta:g}) collapses an edge of the polygon; "
                                       "nearest exact alternative: offset(r = ...) or a smaller delta")
        loops.append(out)
    pts = np.vstack(loops)
    idx, start = [], 0
    for lp in loops:
        idx.append(list(range(start, start + len(lp))))
        start += len(lp)
    return polygon(pts, idx)


def common_tangent(ci, ri, cj, rj):
    """The outer common tangent with the disks on its left, going from disk i to disk j:
    (unit outward normal, tangent point on i, tangent point on j) or None."""
    d = cj - ci
    length = np.linalg.norm(d)
    if length <= abs(ri - rj):
        return None
    u = d / length
    w = np.array([u[1], -u[0]])  # right of i -> j
    cos = (ri - rj) / length
    n = cos * u + math.sqrt(max(0.0, 1 - cos * cos)) * w
    return n, ci + ri * n, cj + rj * n


def hull_disks(centers, radii) -> Profile:
    c = np.asarray(centers, dtype=np.float64).reshape(-1, 2)
    r = np.asarray(radii, dtype=np.float64).reshape(-1)
    scale = max(np.abs(c).max() + r.max(), 1e-300)
    for i in range(len(c)):  # a disk containing all others is the hull
        if np.all(np.linalg.norm(c - c[i], axis=1) + r <= r[i] * (1 + 1e-15)):
            return circle(r[i], c[i])
    tangents, used = [], set()
    for i in range(len(c)):
        for j in range(len(c)):
            if i == j:
                continue
            t = common_tangent(c[i], r[i], c[j], r[j])
            if t is None:
                continue
            n, ti, tj = t
            h = n @ ti
            if np.all(c @ n + r <= h + 1e-12 * scale):
                tangents += [ti, tj]
                used |= {i, j}
    poly = hull2d(np.array(tangents))
    disks = [circle(r[i], c[i]) for i in sorted(used) if r[i] > 0]
    out = union2d(polygon(poly), *disks)
    lo, hi = (c - r[:, None]).min(axis=0), (c + r[:, None]).max(axis=0)
    return Profile(out.op, out.data, out.kids, bbox=(*lo, *hi))


def hull2d_of(*profiles: Profile) -> Profile:
    """The 2-D hull of polygons (and squares), or of circles (any radii)."""
    if all(k.circle is not None for k in profiles):
        out = hull_disks([k.circle[0] for k in profiles], [k.circle[1] for k in profiles])
    elif all(k.loops is not None for k in profiles):
        out = hull_points(np.vstack([np.vstack(k.loops) for k in profiles]))
    elif all(k.loops is not None or k.circle is not None for k in profiles):
        # polygon vertices are disks of radius 0: conv(tangent points) | the circles
        pts = hull2d(np.vstack([np.vstack(k.loops) for k in profiles if k.loops is not None]))
        circ = [k.circle for k in profiles if k.circle is not None]
        out = hull_disks([c for c, _ in circ] + list(pts), [r for _, r in circ] + [0.0] * len(pts))
    else:
        raise ProfileError("2-D hull() is covered for squares, circles and polygons, not for 2-D Boolean results; "
                           "nearest exact alternative: hull the shapes before combining them")
    specs = [k.spec for k in profiles]
    return out if any(s is None for s in specs) else out.with_spec({"hull": specs})


def hull_points(points) -> Profile:
    pts = hull2d(points)
    if len(pts) < 3:
        raise ProfileError("2-D hull of collinear points has no area")
    return polygon(pts)


def offset(profile: Profile, r: float | None = None, delta: float | None = None, chamfer: bool = False) -> Profile:
    """OpenSCAD's ``offset``: rounded by ``r``, or sharp (``chamfer``: squared) by ``delta``."""
    if (r is None) == (delta is None):
        raise ProfileError("offset needs exactly one of r and delta")
    out = offset_r(profile, r) if r is not None else offset_delta(profile, delta, chamfer)
    if profile.spec is None:
        return out
    args = {"r": float(r)} if r is not None else {"delta": float(delta), "chamfer": bool(chamfer)}
    return out.with_spec({"offset": {"profile": profile.spec, **args}})


def minkowski2d(*profiles: Profile) -> Profile:
    """2-D Minkowski sums: a region plus a disk is its rounded offset by the radius, moved by
    the disk's center (P + D(c, r) = offset_r(P, r) + c, exact for any polygon with holes);
    disks add centers and radii; convex polygons give the hull of their pairwise vertex sums."""
    if not profiles:
        raise ProfileError("2-D minkowski() of nothing")
    disks = [p for p in profiles if p.circle is not None]
    rest = [p for p in profiles if p.circle is None]
    center = np.sum([np.asarray(d.circle[0], float) for d in disks], axis=0) if disks else np.zeros(2)
    radius = sum(float(d.circle[1]) for d in disks)
    if len(rest) > 1:
        if not all(p.loops is not None and len(p.loops) == 1 and _convex_loop(p.loops[0]) for p in rest):
            raise ProfileError("2-D minkowski() of two polygons is covered for convex ones only; nearest exact "
                               "alternative: a polygon plus a circle (offset)")
        pts = np.zeros((1, 2))
        for p in rest:
            pts = (pts[:, None, :] + p.loops[0][None]).reshape(-1, 2)
        rest = [hull_points(pts)]
    if not rest:
        return circle(radius, center)
    if radius == 0:
        return rest[0].translate(center)
    if rest[0].loops is None:
        raise ProfileError("2-D minkowski() of a 2-D Boolean result and a circle has no exact form here; nearest exact "
                           "alternative: the sum of each square, circle or polygon before combining")
    return offset_r(rest[0], radius).translate(center)


def _convex_loop(lp):
    d = np.roll(lp, -1, axis=0) - lp
    c = d[:, 0] * np.roll(d[:, 1], -1) - d[:, 1] * np.roll(d[:, 0], -1)
    return bool(np.all(c >= 0) or np.all(c <= 0))
