"""2-D profiles: regions of the plane as exact Boolean expressions of half-planes and conics.

A :class:`Profile` is a tree whose leaves are

* ``line`` (a, b, d) with a^2 + b^2 = 1: the half-plane a x + b y <= d, and
* ``conic`` C (3x3 symmetric): the set [x y 1] C [x y 1]^T <= 0 (a disk, or an elliptic disk
  after a non-uniform scale),

and whose inner nodes are union, intersection and difference.  Extrusion and revolution map
each leaf to one 3-D quadric (a plane, cylinder or cone) and keep the Boolean structure, so the
solid is exact.

A simple polygon becomes the union of convex pieces (ear-clipping triangulation, then
Hertel-Mehlhorn merging of triangles across diagonals while the union stays convex), each the
intersection of its edge half-planes.  A diagonal's line is built from the same endpoints in
the same order for both pieces it separates, so the two pieces use one plane with opposite
signs and the diagonal is never part of the surface.  ``polygon(points, paths)`` fills by the
even-odd rule (OpenSCAD's): loops nested at even depth add, at odd depth subtract; loops must
not cross themselves or each other.

``offset(r)`` of polygons is the Minkowski sum with a disk: P | edge rectangles | disks at the
convex corners (r > 0), or P - edge rectangles - disks at the reflex corners (r < 0).
``offset(delta)`` moves every edge line by ``delta`` (mitered, or squared off at convex corners
with ``chamfer``), refused when an edge collapses.
"""

from __future__ import annotations

import math

import numpy as np

from ..errors import ParameterError


class ProfileError(ParameterError):
    """A 2-D construction that has no exact quadric form or is malformed."""


class Profile:
    """A region of the plane.  Combine with ``|``, ``&``, ``-``; transform with
    :meth:`transform`, :meth:`translate`, :meth:`rotate`, :meth:`scale`, :meth:`mirror`.

    ``loops`` (polygon loops, filled even-odd) or ``circle`` ((center, radius)) record what a
    plain polygon or disk was made from (offset and hull need it); ``bbox`` is a conservative
    bound (xmin, ymin, xmax, ymax)."""

    __slots__ = ("op", "data", "kids", "loops", "circle", "bbox", "spec")

    def __init__(self, op, data=None, kids=(), loops=None, circle=None, bbox=None, spec=None):
        self.op, self.data, self.kids = op, data, tuple(kids)
        self.loops, self.circle = loops, circle
        self.bbox = bbox
        self.spec = spec  # the scene-file node that builds this profile, or None

    def with_spec(self, spec) -> "Profile":
        return Profile(self.op, self.data, self.kids, self.loops, self.circle, self.bbox, spec)

    # -- Booleans -----------------------------------------------------------------------------
    def __or__(self, other):
        return union2d(self, other)

    def __and__(self, other):
        return intersection2d(self, other)

    def __sub__(self, other):
        return difference2d(self, other)

    # -- transforms ---------------------------------------------------------------------------
    def transform(self, matrix) -> "Profile":
        """Apply a 2-D affine map: a 2x3 or 3x3 matrix (x -> A x + t)."""
        m = np.asarray(matrix, dtype=np.float64)
        if m.shape == (2, 3):
            m = np.vstack([m, [0, 0, 1]])
        if m.shape != (3, 3) or not np.all(np.isfinite(m)) or np.any(m[2] != (0, 0, 1)):
            raise ProfileError(f"a 2-D transform is a finite 2x3 or 3x3 affine matrix, got {m.tolist()}")
        if abs(np.linalg.det(m[:2, :2])) <= 1e-12 * max(np.abs(m[:2, :2]).max(), 1e-300) ** 2:
            raise ProfileError("a 2-D transform must not be singular")
        out = _transform(self, m)
        if self.spec is not None:
            steps = list(self.spec.get("transform", [])) + [{"matrix": m[:2].tolist()}]
            out.spec = {**self.spec, "transform": steps}
        return out

    def translate(self, offset):
        return self.transform([[1, 0, offset[0]], [0, 1, offset[1]]])

    def rotate(self, degrees):
        c, s = math.cos(math.radians(degrees)), math.sin(math.radians(degrees))
        return self.transform([[c, -s, 0], [s, c, 0]])

    def scale(self, factor):
        f = np.broadcast_to(np.asarray(factor, dtype=np.float64), (2,))
        return self.transform([[f[0], 0, 0], [0, f[1], 0]])

    def mirror(self, normal):
        n = np.asarray(normal, dtype=np.float64)
        n = n / np.linalg.norm(n)
        return self.transform(np.hstack([np.eye(2) - 2 * np.outer(n, n), [[0], [0]]]))

    # -- evaluation ---------------------------------------------------------------------------
    def contains(self, points) -> np.ndarray:
        """Membership of (..., 2) points (on the boundary counts as inside)."""
        p = np.asarray(points, dtype=np.float64)
        return _contains(self, p.reshape(-1, 2)).reshape(p.shape[:-1])

    def leaves(self):
        stack, out = [self], []
        while stack:
            n = stack.pop()
            if n.op in ("line", "conic"):
                out.append(n)
            stack.extend(n.kids)
        return out

    def map(self, leaf, union, intersection, difference, empty):
        """Rebuild the tree with ``leaf(node)`` at the leaves and the given combinators."""
        if self.op in ("line", "conic"):
            return leaf(self)
        if self.op == "empty":
            return empty()
        kids = [k.map(leaf, union, intersection, difference, empty) for k in self.kids]
        return {"union": union, "intersection": intersection, "difference": difference}[self.op](kids)

    def describe(self) -> str:
        if self.circle is not None:
            return "a circle"
        if self.loops is not None:
            return f"a polygon of {sum(len(lp) for lp in self.loops)} vertices"
        return "a 2-D Boolean"

    def __repr__(self):
        return f"Profile({self.op}, {len(self.leaves())} leaves)"


# -- leaves and Booleans ------------------------------------------------------------------------
def line_through(p, q) -> Profile:
    """The half-plane left of the directed line p -> q.  Built from the endpoints in a canonical
    order so that the line q -> p is exactly its complement."""
    p, q = np.asarray(p, float), np.asarray(q, float)
    flip = tuple(q) < tuple(p)
    a, b = (q, p) if flip else (p, q)
    d = b - a
    n = np.array([d[1], -d[0]]) / math.hypot(d[0], d[1])  # right of a -> b is outside
    if flip:
        n = -n
    off = float(n @ a)
    return Profile("line", (float(n[0]), float(n[1]), off))


def half_plane(normal, offset) -> Profile:
    n = np.asarray(normal, float)
    k = math.hypot(n[0], n[1])
    return Profile("line", (n[0] / k, n[1] / k, float(offset) / k))


def _bbox_union(boxes):
    boxes = [b for b in boxes if b is not None]
    if not boxes:
        return None
    b = np.array(boxes)
    return (b[:, 0].min(), b[:, 1].min(), b[:, 2].max(), b[:, 3].max())


def _specs(name, ps):
    specs = [p.spec for p in ps]
    return None if any(s is None for s in specs) else {name: specs}


def union2d(*ps) -> Profile:
    ps = [p for p in ps if p.op != "empty"]
    if not ps:
        return Profile("empty", spec={"union": []})
    if len(ps) == 1:
        return ps[0]
    return Profile("union", kids=ps, bbox=_bbox_union([p.bbox for p in ps]), spec=_specs("union", ps))


def intersection2d(*ps) -> Profile:
    if any(p.op == "empty" for p in ps):
        return Profile("empty", spec={"union": []})
    if len(ps) == 1:
        return ps[0]
    b = np.array([p.bbox for p in ps if p.bbox is not None])
    bbox = (b[:, 0].max(), b[:, 1].max(), b[:, 2].min(), b[:, 3].min()) if len(b) else None
    return Profile("intersection", kids=ps, bbox=bbox, spec=_specs("intersection", ps))


def difference2d(first, *rest) -> Profile:
    rest = [p for p in rest if p.op != "empty"]
    if first.op == "empty" or not rest:
        return first
    return Profile("difference", kids=(first, *rest), bbox=first.bbox, spec=_specs("difference", (first, *rest)))


def _convex_piece(pts) -> Profile:
    n = len(pts)
    return Profile("intersection", kids=[line_through(pts[i], pts[(i + 1) % n]) for i in range(n)])


# -- constructors --------------------------------------------------------------------------------
def square(size=1.0, center=False) -> Profile:
    s = np.broadcast_to(np.asarray(size, dtype=np.float64), (2,))
    if not np.all(np.isfinite(s)) or np.any(s <= 0):
        raise ProfileError(f"square size must be positive, got {s.tolist()}")
    lo = -s / 2 if center else np.zeros(2)
    x0, y0 = lo
    x1, y1 = lo + s
    return polygon([(x0, y0), (x1, y0), (x1, y1), (x0, y1)]).with_spec({"square": {"size": s.tolist(), "center": bool(center)}})


def circle(radius=1.0, center=(0.0, 0.0)) -> Profile:
    r = float(radius)
    if not (math.isfinite(r) and r > 0):
        raise ProfileError(f"circle radius must be positive, got {r}")
    cx, cy = (float(v) for v in center)
    c = np.array([[1, 0, -cx], [0, 1, -cy], [-cx, -cy, cx * cx + cy * cy - r * r]]) / r
    return Profile("conic", c, circle=((cx, cy), r), bbox=(cx - r, cy - r, cx + r, cy + r),
                   spec={"circle": {"radius": r, "center": [cx, cy]}})


def polygon(points, paths=None) -> Profile:
    """The even-odd fill of ``paths`` (lists of indices into ``points``; default: all points in
    order), each a simple loop; loops may nest but not cross."""
    pts = np.asarray(points, dtype=np.float64)
    if pts.ndim != 2 or pts.shape[1] != 2 or len(pts) < 3 or not np.all(np.isfinite(pts)):
        raise ProfileError("polygon points must be at least 3 finite [x, y] pairs")
    if paths is None:
        paths = [list(range(len(pts)))]
    loops = []
    for k, path in enumerate(paths):
        try:
            loop = _clean(pts[np.asarray(path, dtype=int)])
        except (IndexError, ValueError):
            raise ProfileError(f"polygon path {k} indexes points that do not exist") from None
        if len(loop) < 3:
            raise ProfileError(f"polygon path {k} has no area (fewer than 3 non-collinear points)")
        loops.append(loop)
    _check_simple(loops)
    spec = {"polygon": {"points": pts.tolist()} | ({} if paths is None else {"paths": [[int(v) for v in q] for q in paths]})}
    return _from_loops(loops).with_spec(spec)


def _clean(loop):
    """Drop repeated and exactly collinear vertices."""
    out = [p for i, p in enumerate(loop) if not np.array_equal(p, loop[i - 1])] if len(loop) else []
    changed = True
    while changed and len(out) >= 3:
        changed = False
        for i in range(len(out)):
            a, b, c = out[i - 1], out[i], out[(i + 1) % len(out)]
            if _cross(b - a, c - b) == 0.0:
                del out[i]
                changed = True
                break
    return np.array(out)


def _cross(u, v):
    return float(u[0] * v[1] - u[1] * v[0])


def signed_area(loop) -> float:
    x, y = loop[:, 0], loop[:, 1]
    return 0.5 * float(np.sum(x * np.roll(y, -1) - np.roll(x, -1) * y))


def _segments_cross(p1, p2, q1, q2):
    d1, d2 = _cross(p2 - p1, q1 - p1), _cross(p2 - p1, q2 - p1)
    d3, d4 = _cross(q2 - q1, p1 - q1), _cross(q2 - q1, p2 - q1)
    if ((d1 > 0 and d2 < 0) or (d1 < 0 and d2 > 0)) and ((d3 > 0 and d4 < 0) or (d3 < 0 and d4 > 0)):
        return True

    def on(a, b, c, d):
        return d == 0 and min(a[0], b[0]) <= c[0] <= max(a[0], b[0]) and min(a[1], b[1]) <= c[1] <= max(a[1], b[1])

    return on(p1, p2, q1, d1) or on(p1, p2, q2, d2) or on(q1, q2, p1, d3) or on(q1, q2, p2, d4)


def _check_simple(loops):
    edges = []
    for k, lp in enumerate(loops):
        n = len(lp)
        edges += [(k, i, lp[i], lp[(i + 1) % n], n) for i in range(n)]
    for i, (k1, j1, a1, b1, n1) in enumerate(edges):
        for k2, j2, a2, b2, n2 in edges[i + 1:]:
            if k1 == k2 and (j2 == j1 + 1 or (j1 == 0 and j2 == n1 - 1)):
                continue  # neighbours share a vertex
            if _segments_cross(a1, b1, a2, b2):
                what = f"path {k1} crosses itself" if k1 == k2 else f"paths {k1} and {k2} cross or touch"
                raise ProfileError(f"polygon {what}: not a simple polygon with holes")


def point_in_loop(p, loop) -> bool:
    """Even-odd (crossing number) test of one point against one loop."""
    x, y = p
    inside = False
    n = len(loop)
    for i in range(n):
        (x1, y1), (x2, y2) = loop[i], loop[(i + 1) % n]
        if (y1 > y) != (y2 > y) and x < x1 + (y - y1) * (x2 - x1) / (y2 - y1):
            inside = not inside
    return inside


def _from_loops(loops) -> Profile:
    depth = [sum(point_in_loop(lp[0], other) for j, other in enumerate(loops) if j != i) for i, lp in enumerate(loops)]
    parts = []
    for i, lp in enumerate(loops):
        if depth[i] % 2:
            continue
        holes = [j for j, other in enumerate(loops) if depth[j] == depth[i] + 1 and point_in_loop(other[0], lp)]
        parts.append(difference2d(simple_polygon(lp), *[simple_polygon(loops[j]) for j in holes]))
    out = union2d(*parts)
    allp = np.vstack(loops)
    oriented = [lp if (signed_area(lp) > 0) == (d % 2 == 0) else lp[::-1] for lp, d in zip(loops, depth)]
    return Profile(out.op, out.data, out.kids, loops=oriented,
                   bbox=(*allp.min(axis=0), *allp.max(axis=0)))


def simple_polygon(loop) -> Profile:
    """A simple loop as the union of convex pieces."""
    lp = loop if signed_area(loop) > 0 else loop[::-1]
    pieces = convex_pieces(lp)
    out = union2d(*[_convex_piece(lp[idx]) for idx in pieces])
    return out


def convex_pieces(lp) -> list[list[int]]:
    """Convex pieces (index lists, counter-clockwise) of a simple counter-clockwise loop."""
    pieces = [list(t) for t in _ear_clip(lp)]
    merged = True
    while merged:
        merged = False
        for i in range(len(pieces)):
            for j in range(i + 1, len(pieces)):
                m = _merge(pieces[i], pieces[j], lp)
                if m is not None:
                    pieces[i] = m
                    del pieces[j]
                    merged = True
                    break
            if merged:
                break
    return pieces


def _ear_clip(lp):
    idx = list(range(len(lp)))
    tris = []
    guard = 0
    while len(idx) > 3:
        guard += 1
        if guard > 10 * len(lp) ** 2:
            raise ProfileError("polygon could not be triangulated (degenerate or not simple)")
        n = len(idx)
        for k in range(n):
            i0, i1, i2 = idx[k - 1], idx[k], idx[(k + 1) % n]
            a, b, c = lp[i0], lp[i1], lp[i2]
            if _cross(b - a, c - b) <= 0:
                continue
            if any(_in_triangle(lp[j], a, b, c) for j in idx if j not in (i0, i1, i2)):
                continue
            tris.append((i0, i1, i2))
            del idx[k]
            break
        else:
            raise ProfileError("polygon could not be triangulated (degenerate or not simple)")
    tris.append(tuple(idx))
    return tris


def _in_triangle(p, a, b, c):
    return _cross(b - a, p - a) >= 0 and _cross(c - b, p - b) >= 0 and _cross(a - c, p - c) >= 0


def _merge(p, q, lp):
    """p and q glued along a shared edge, if the result is strictly convex."""
    n, m = len(p), len(q)
    for i in range(n):
        a, b = p[i], p[(i + 1) % n]
        for j in range(m):
            if q[j] == b and q[(j + 1) % m] == a:
                out = p[: i + 1] + [q[(j + 2 + k) % m] for k in range(m - 2)] + p[i + 1:]
                pts = lp[out]
                k = len(out)
                if all(_cross(pts[t] - pts[t - 1], pts[(t + 1) % k] - pts[t]) > 0 for t in range(k)):
                    return out
                return None
    return None


# -- transforms and evaluation ------------------------------------------------------------------
def _transform(p: Profile, m: np.ndarray) -> Profile:
    inv = np.linalg.inv(m)
    lin = m[:2, :2]
    if p.op == "line":
        a, b, d = p.data
        n = inv[:2, :2].T @ np.array([a, b])
        out = half_plane(n, d + n @ m[:2, 2])
        return out
    bbox = None
    if p.bbox is not None:
        x0, y0, x1, y1 = p.bbox
        c = np.array([[x0, y0], [x1, y0], [x1, y1], [x0, y1]]) @ lin.T + m[:2, 2]
        bbox = (*c.min(axis=0), *c.max(axis=0))
    if p.op == "conic":
        c = inv.T @ p.data @ inv
        circ = None
        if p.circle is not None:
            g = lin.T @ lin
            if abs(g[0, 1]) <= 1e-12 * g[0, 0] and abs(g[0, 0] - g[1, 1]) <= 1e-12 * g[0, 0]:
                (cx, cy), r = p.circle
                circ = (tuple(lin @ (cx, cy) + m[:2, 2]), r * math.sqrt(g[0, 0]))
        return Profile("conic", c / np.abs(c).max(), circle=circ, bbox=bbox)
    kids = [_transform(k, m) for k in p.kids]
    loops = None if p.loops is None else [lp @ lin.T + m[:2, 2] for lp in p.loops]
    if loops is not None and np.linalg.det(lin) < 0:
        loops = [lp[::-1] for lp in loops]
    return Profile(p.op, None, kids, loops=loops, bbox=bbox)


def _contains(p: Profile, x: np.ndarray) -> np.ndarray:
    if p.op == "line":
        a, b, d = p.data
        return a * x[:, 0] + b * x[:, 1] <= d
    if p.op == "conic":
        h = np.hstack([x, np.ones((len(x), 1))])
        return np.einsum("ni,ij,nj->n", h, p.data, h) <= 0
    if p.op == "empty":
        return np.zeros(len(x), bool)
    vals = [_contains(k, x) for k in p.kids]
    if p.op == "union":
        return np.logical_or.reduce(vals)
    if p.op == "intersection":
        return np.logical_and.reduce(vals)
    out = vals[0].copy()
    for v in vals[1:]:
        out &= ~v
    return out
