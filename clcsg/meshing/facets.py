"""Faceted meshes of primitive instances, each triangle tagged with the literal it lies on.

An instance's solid is the intersection of its literals (:mod:`clcsg.model.solids`); its
faceted mesh is closed, outward, in world coordinates (the instance's matrix applied), and
every triangle carries a *tag*: the index of the literal whose surface it approximates, or -1
for a face that only closes an unbounded kind inside the region of interest.

Curved surfaces are inscribed: every vertex lies on its literal's quadric, and the segment
count of a circle of world radius R is the least n with R (1 - cos(pi / n)) <= tol, the chord
sag of the inscribed n-gon.  Under a linear map A (the instance's transform times the local
radii) a circle's polygon of parameter step d deviates from the image ellipse by at most
sigma_1 R d^2 / 8 (the largest |x''|), so R is taken as sigma_1 R.  A sphere is the geodesic
(icosahedron-based) unit sphere of the lowest frequency whose measured sag is at most
tol sigma_3^2 / sigma_1^3 (the largest normal curvature of the image ellipsoid is
sigma_1 / sigma_3^2 and its edges are at most sigma_1 times longer).

Unbounded kinds (half-spaces, slabs, infinite and elliptic cylinders) are closed by faces
tagged -1 outside the region of interest: a ball (center, radius) in world coordinates that
holds everything the mesh is clipped to.  Kinds without a closed form here (double cones,
paraboloids, hyperboloids, raw quadric matrices) return None: the caller meshes such a scene
another way.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from ..model.quadric import frame_z_to

#: tag of a face that only closes an unbounded kind (no literal of the instance)
CLOSING = -1
#: kinds meshed here
KINDS = ("box", "cylinder", "cone", "sphere", "ellipsoid", "halfspace", "slab", "infinite_cylinder",
         "elliptic_cylinder")
#: the fewest segments of a circle
MIN_SEGMENTS = 3
#: the most segments of a circle or sphere (a tolerance far below the primitive's size)
MAX_SEGMENTS = 4096
#: the chord sag the facets are made for, as a share of the tolerance (the mesh is checked by
#: the distance along the gradient line, exact for a circle's chord; the rest is a margin for
#: rounding)
SAG_SHARE = 0.99


@dataclass
class Facets:
    """A closed, outward triangle mesh in world coordinates, a tag per triangle."""

    vertices: np.ndarray  # (V, 3) float64
    triangles: np.ndarray  # (T, 3) int64
    tags: np.ndarray  # (T,) int64
    #: (key, matrix): the mesh is :func:`unit_mesh` (key) under the affine ``matrix``, or None
    unit: tuple | None = None


def circle_segments(radius: float, tol: float) -> int:
    """The least n >= MIN_SEGMENTS with radius (1 - cos(pi / n)) <= tol."""
    sag = SAG_SHARE * tol
    if not radius > sag:
        return MIN_SEGMENTS
    n = math.ceil(math.pi / math.acos(1.0 - sag / radius))
    return int(min(max(n, MIN_SEGMENTS), MAX_SEGMENTS))


#: the icosahedron: its 12 vertices (unit length) and 20 outward faces
_ICO_T = (1.0 + 5.0 ** 0.5) / 2.0
_ICO_V = np.array([[-1, _ICO_T, 0], [1, _ICO_T, 0], [-1, -_ICO_T, 0], [1, -_ICO_T, 0], [0, -1, _ICO_T],
                   [0, 1, _ICO_T], [0, -1, -_ICO_T], [0, 1, -_ICO_T], [_ICO_T, 0, -1], [_ICO_T, 0, 1],
                   [-_ICO_T, 0, -1], [-_ICO_T, 0, 1]]) / math.sqrt(1.0 + _ICO_T ** 2)
_ICO_F = np.array([[0, 11, 5], [0, 5, 1], [0, 1, 7], [0, 7, 10], [0, 10, 11], [1, 5, 9], [5, 11, 4], [11, 10, 2],
                   [10, 7, 6], [7, 1, 8], [3, 9, 4], [3, 4, 2], [3, 2, 6], [3, 6, 8], [3, 8, 9], [4, 9, 5],
                   [2, 4, 11], [6, 2, 10], [8, 6, 7], [9, 8, 1]])
#: the finest geodesic sphere (20 f^2 triangles)
MAX_FREQUENCY = 512


@lru_cache(maxsize=None)
def _unit_sphere(frequency: int):
    """(vertices, triangles, sag) of the geodesic unit sphere of ``frequency`` f: each face of
    the icosahedron cut into f^2 triangles on a barycentric grid, the points pushed out onto
    the sphere; sag is the largest distance of a triangle's plane below the sphere (its
    deviation bound).  Its triangles are nearly equal, so a sag needs about a tenth fewer of
    them than manifold3d's octahedral sphere."""
    f = int(frequency)
    grid = [(i, j) for i in range(f + 1) for j in range(f + 1 - i)]
    index = {p: k for k, p in enumerate(grid)}
    cells = []
    for i in range(f):
        for j in range(f - i):
            cells.append((index[(i, j)], index[(i + 1, j)], index[(i, j + 1)]))
            if i + j < f - 1:
                cells.append((index[(i + 1, j)], index[(i + 1, j + 1)], index[(i, j + 1)]))
    uv = np.array(grid, dtype=np.float64) / f
    a, b, c = (_ICO_V[_ICO_F[:, k]] for k in range(3))
    pts = (a[:, None] + (b - a)[:, None] * uv[None, :, :1] + (c - a)[:, None] * uv[None, :, 1:]).reshape(-1, 3)
    pts /= np.linalg.norm(pts, axis=1, keepdims=True)
    tri = (np.array(cells)[None] + (np.arange(20) * len(grid))[:, None, None]).reshape(-1, 3)
    _, first, inv = np.unique(np.round(pts * 1e9).astype(np.int64), axis=0, return_index=True, return_inverse=True)
    v, t = pts[first], inv.ravel()[tri]  # points on the icosahedron's shared edges once
    a, b, c = v[t[:, 0]], v[t[:, 1]], v[t[:, 2]]
    n = np.cross(b - a, c - a)
    d = np.abs((n * a).sum(axis=1)) / np.linalg.norm(n, axis=1)
    return v, t.astype(np.int64), float(1.0 - d.min())


def sphere_segments(sag: float) -> int:
    """The lowest frequency of the geodesic unit sphere (:func:`_unit_sphere`) with sag <= ``sag``."""
    # the sag is about 0.29 / f^2: start below
    f = max(1, int(math.sqrt(0.25 / max(sag, 1e-300))))
    f = min(f, MAX_FREQUENCY)
    while f < MAX_FREQUENCY and _unit_sphere(f)[2] > sag:
        f += 1
    return f


def _world(points, m):
    return points @ m[:3, :3].T + m[:3, 3]


def _oriented(v, t, tags, m) -> Facets:
    """Local mesh -> world Facets (triangles reversed under a reflection)."""
    if np.linalg.det(m[:3, :3]) < 0:
        t = t[:, ::-1]
    return Facets(_world(v, m), np.ascontiguousarray(t, dtype=np.int64), np.asarray(tags, dtype=np.int64))


def _prism(bottom, top, n, cap_tags, side_tag=0):
    """A closed mesh between two rings of ``n`` points (counter-clockwise seen from +z; a ring
    may be a single apex point): sides tagged ``side_tag``, caps (top, bottom) ``cap_tags``."""
    nb, nt = len(bottom), len(top)
    v = np.concatenate([bottom, top])
    k = np.arange(n)
    k1 = (k + 1) % n
    tris, tags = [], []
    if nb > 1 and nt > 1:
        tris += [np.stack([k, k1, nb + k1], 1), np.stack([k, nb + k1, nb + k], 1)]
    elif nb > 1:  # apex on top
        tris.append(np.stack([k, k1, np.full(n, nb)], 1))
    else:  # apex at the bottom
        tris.append(np.stack([np.zeros(n, dtype=np.int64), 1 + k1, 1 + k], 1))
    tags.append(np.full(sum(len(x) for x in tris), side_tag))
    fan = np.arange(1, n - 1)
    if nt > 1:
        tris.append(np.stack([np.full(n - 2, nb), nb + fan, nb + fan + 1], 1))
        tags.append(np.full(n - 2, cap_tags[0]))
    if nb > 1:
        tris.append(np.stack([np.zeros(n - 2, dtype=np.int64), fan + 1, fan], 1))
        tags.append(np.full(n - 2, cap_tags[1]))
    return v, np.concatenate(tris).astype(np.int64), np.concatenate(tags)


def _ring(n, rx, ry, z):
    a = 2.0 * np.pi * np.arange(n) / n
    if rx == 0.0 and ry == 0.0:
        return np.array([[0.0, 0.0, z]])
    return np.stack([rx * np.cos(a), ry * np.sin(a), np.full(n, z)], 1)


def _framed(m, axis, center):
    """The instance matrix times the local frame (z along ``axis``, origin at ``center``)."""
    f = np.eye(4)
    f[:3, :3] = frame_z_to(np.asarray(axis, dtype=np.float64))
    f[:3, 3] = np.asarray(center, dtype=np.float64)
    return m @ f


def _sigma(m):
    return np.linalg.svd(m[:3, :3], compute_uv=False)


def _box(p, m):
    s = np.broadcast_to(np.asarray(p.get("size", 1.0), dtype=np.float64), (3,))
    c = np.asarray(p.get("center", (0, 0, 0)), dtype=np.float64)
    return cuboid(c - s / 2, c + s / 2, (0, 1, 2, 3, 4, 5), m)


def cuboid(lo, hi, tags, m) -> Facets:
    """An axis-aligned box [lo, hi] of the local frame; ``tags`` of its faces +x, -x, +y, -y,
    +z, -z (the literal order of a box)."""
    bits = np.array([[(i >> k) & 1 for k in range(3)] for i in range(8)], dtype=bool)
    v = np.where(bits, hi, lo)
    quads = [(1, 3, 7, 5), (0, 4, 6, 2), (2, 6, 7, 3), (0, 1, 5, 4), (4, 5, 7, 6), (0, 2, 3, 1)]
    t = np.array([[a, b, c] for a, b, c, d in quads] + [[a, c, d] for a, b, c, d in quads], dtype=np.int64)
    return _oriented(v, t, np.tile(np.asarray(tags), 2), m)


def _round_shape(p, m, kind):
    """(w: the local frame (z the axis, origin the centre) in ``m``'s frame, height, r1, r2) of a
    cylinder or cone."""
    h = float(p.get("height", 1.0))
    if kind == "cylinder":
        r1 = r2 = float(p.get("radius", 1.0))
    else:
        r1, r2 = float(p.get("r1", 1.0)), float(p.get("r2", 0.0))
    return _framed(m, p.get("axis", (0, 0, 1)), p.get("center", (0, 0, 0))), h, r1, r2


def round_segments(w, h, r1, r2, tol) -> int:
    """The circle segments of a cylinder or cone (local frame ``w``): a point of an inscribed
    ring's chord lies s = R (1 - cos(pi / n)) inside the circle, which is s cos(alpha) from
    a cone of half-angle alpha (tan alpha = |r2 - r1| / h).  Under a non-uniform map the angle
    is not kept: there the whole sag counts."""
    sig = _sigma(w)
    slant = h / math.hypot(h, r2 - r1) if h > 0 and sig[0] - sig[2] <= 1e-9 * sig[0] else 1.0
    return circle_segments(max(r1, r2) * sig[0] * slant, tol)


def _round(p, m, tol, kind, segments=None):
    w, h, r1, r2 = _round_shape(p, m, kind)
    n = segments or round_segments(w, h, r1, r2, tol)
    rm = max(r1, r2)
    if not (h > 0 and rm > 0):
        v, t, tags = _prism(_ring(n, r1, r1, -h / 2), _ring(n, r2, r2, h / 2), n, (1, 2))
        return _oriented(v, t, tags, w)
    key = ("round", n, r1 / rm, r2 / rm)
    affine = w @ np.diag([rm, rm, h, 1.0])
    v, t, tags = unit_mesh(key)
    out = _oriented(v, t, tags, affine)
    out.unit = (key, affine)
    return out


@lru_cache(maxsize=256)
def unit_mesh(key):
    """(vertices, triangles, tags) of a unit primitive: ("sphere", f) the geodesic unit sphere
    of frequency f (tag 0); ("round", n, a, b) the n-gon frustum of radii a (z = -1/2) and b (z = 1/2),
    sides tagged 0, its caps 1 (top) and 2 (bottom).  A cylinder or cone is one of these under
    an affine map, so the Booleans can build each once and place it by a transform."""
    if key[0] == "sphere":
        v, t, _ = _unit_sphere(key[1])
        return v, t, np.zeros(len(t), dtype=np.int64)
    _, n, a, b = key
    return _prism(_ring(n, a, a, -0.5), _ring(n, b, b, 0.5), n, (1, 2))


def _ellipsoid(p, m, tol, kind):
    r = np.broadcast_to(np.asarray(p.get("radii" if kind == "ellipsoid" else "radius", 1.0), dtype=np.float64), (3,))
    w = m @ np.diag([*r, 1.0])
    w[:3, 3] = _world(np.asarray(p.get("center", (0, 0, 0)), dtype=np.float64), m)
    s = _sigma(w)
    key = ("sphere", sphere_segments(SAG_SHARE * tol / s[0]))
    v, t, tags = unit_mesh(key)
    out = _oriented(v, t, tags, w)
    out.unit = (key, w)
    return out


def _reach_local(m, reach):
    """The region of interest (world ball (center, radius)) in the local frame ``m``: a ball
    (center, radius) holding its preimage."""
    c, rad = reach
    inv = np.linalg.inv(m)
    cl = _world(np.asarray(c, dtype=np.float64), inv)
    return cl, float(rad) * float(_sigma(inv)[0])


def _planar(p, m, reach, kind):
    n = np.asarray(p.get("normal", (0, 0, 1)), dtype=np.float64)
    length = float(np.linalg.norm(n))
    n = n / length
    if kind == "halfspace":
        lo, hi = None, float(p.get("offset", 0.0)) / length
    else:
        lo, hi = float(p.get("lo", -0.5)), float(p.get("hi", 0.5))
    f = np.eye(4)
    f[:3, :3] = frame_z_to(n)
    w = m @ f
    cl, rad = _reach_local(w, reach)
    rad = 1.5 * rad + abs(cl[2] - hi) + (0.0 if lo is None else abs(hi - lo)) + 1.0
    bottom = cl[2] - rad if lo is None else lo
    return cuboid(np.array([cl[0] - rad, cl[1] - rad, bottom]), np.array([cl[0] + rad, cl[1] + rad, hi]),
                   (CLOSING, CLOSING, CLOSING, CLOSING, 0, CLOSING if lo is None else 0), w)


def _infinite(p, m, tol, reach, kind):
    w = _framed(m, p.get("axis", (0, 0, 1)), p.get("center", (0, 0, 0)))
    if kind == "infinite_cylinder":
        rx = ry = float(p.get("radius", 1.0))
    else:
        rx, ry = (float(x) for x in p.get("radii", (1.0, 0.5)))
    cl, rad = _reach_local(w, reach)
    z0, z1 = cl[2] - 1.5 * rad - 1.0, cl[2] + 1.5 * rad + 1.0
    n = circle_segments(max(rx, ry) * _sigma(w)[0], tol)
    v, t, tags = _prism(_ring(n, rx, ry, z0), _ring(n, rx, ry, z1), n, (CLOSING, CLOSING))
    return _oriented(v, t, tags, w)


def instance_facets(inst, tol: float, reach, matrix=None, segments=None) -> Facets | None:
    """The faceted mesh of ``inst`` (a :class:`clcsg.compile.tape.Instance`) within ``tol``;
    ``reach``: the ball (center, radius) the unbounded kinds must cover.  ``matrix``: the
    instance's transform into the frame the mesh is built in (default: its world matrix; the
    tolerance and the ball are in that frame); ``segments``: a cylinder's or cone's circle
    segments, at least those ``tol`` needs (:func:`shared_segments`).  None for a kind without
    a closed form here."""
    kind, p = inst.node.kind, inst.node.params
    m = np.asarray(inst.matrix if matrix is None else matrix, dtype=np.float64)
    if kind == "box":
        return _box(p, m)
    if kind in ("cylinder", "cone"):
        return _round(p, m, tol, kind, segments)
    if kind in ("sphere", "ellipsoid"):
        return _ellipsoid(p, m, tol, kind)
    if kind in ("halfspace", "slab"):
        return _planar(p, m, reach, kind)
    if kind in ("infinite_cylinder", "elliptic_cylinder"):
        return _infinite(p, m, tol, reach, kind)
    return None


def shared_segments(instances, tols, matrices, hidden=None) -> dict:
    """Per cylinder or cone instance (index -> n) its circle segments: the fewest within its
    tolerance, raised to the most of those it shares a circle with.  Two share a circle when
    they are coaxial with rings in phase (the same linear part of their local frames, the
    origins on one axis) and an end ring of one lies on the other's side (a countersink's
    cone standing on its bore, two cylinders stacked): then their polygons' vertices coincide
    along the circle, where different counts would cut each other's facets into slivers.

    ``hidden(points)``: per row of ``points`` (K, N, 3: N points on the side of each of K
    instances, in the matrices' frame) whether none lies on the solid's surface.  A member
    above its group's least count whose side is hidden so (a countersink's clearance
    cylinder, all in the air above the part) takes its group's count but does not raise it:
    its chords bound nothing.  Were its side to show between the points, the mesher's check
    finds the chords and refines them."""
    shapes, groups, sets = {}, {}, {}
    for inst, tol, m in zip(instances, tols, matrices):
        kind = inst.node.kind
        if kind in ("cylinder", "cone"):
            w, h, r1, r2 = _round_shape(inst.node.params, np.asarray(m, dtype=np.float64), kind)
            shapes[inst.index] = (w, h, r1, r2, round_segments(w, h, r1, r2, float(tol)))
    scale = max([1.0] + [float(np.abs(s[0]).max()) for s in shapes.values()])
    for i, (w, *_rest) in shapes.items():
        z = w[:3, 2] / np.linalg.norm(w[:3, 2])
        o = w[:3, 3] - np.dot(w[:3, 3], z) * z
        key = np.round(np.concatenate([w[:3, :3].ravel(), o]) / (1e-9 * scale)).astype(np.int64).tobytes()
        groups.setdefault(key, []).append(i)
    out = {i: s[4] for i, s in shapes.items()}
    for members in groups.values():
        if len(members) < 2:
            continue
        parent = {i: i for i in members}

        def root(i):
            while parent[i] != i:
                i = parent[i]
            return i

        for a in members:
            for b in members:
                if a < b and (_ring_on_side(shapes[a], shapes[b]) or _ring_on_side(shapes[b], shapes[a])):
                    parent[root(a)] = root(b)
        for i in members:
            sets.setdefault(root(i), []).append(i)
    mixed = [g for g in sets.values() if len({out[i] for i in g}) > 1]
    tested = sorted(i for g in mixed for i in g if out[i] > min(out[j] for j in g)) if hidden else []
    shown = {}
    if tested:
        gone = hidden(np.stack([side_points(*shapes[i][:4]) for i in tested]))
        shown = {i: not bool(h) for i, h in zip(tested, gone)}
    for group in mixed:
        counts = [out[i] for i in group if shown.get(i, True)]
        for i in group:
            out[i] = max(counts)
    return out


#: the side points a visibility test looks at: rings at these heights (fractions of the side)
SIDE_HEIGHTS = (0.25, 0.75)
#: points per ring
SIDE_ANGLES = 8


def side_points(w, h, r1, r2) -> np.ndarray:
    """Points on the side of a cylinder or cone (local frame ``w``, height h, end radii r1 at
    z = -h/2 and r2 at h/2), in ``w``'s frame: :data:`SIDE_ANGLES` per ring at
    :data:`SIDE_HEIGHTS`, half a step out of phase with the polygon's vertices."""
    f = np.asarray(SIDE_HEIGHTS)[:, None]
    phi = 2.0 * np.pi * (np.arange(SIDE_ANGLES) + 0.5) / SIDE_ANGLES
    r = r1 + (r2 - r1) * f
    x, y = r * np.cos(phi), r * np.sin(phi)
    local = np.stack([x, y, np.broadcast_to(h * (f - 0.5), x.shape)], axis=-1)
    return _world(local.reshape(-1, 3), w)


def _ring_on_side(a, b) -> bool:
    """Does an end ring of round shape ``a`` lie on the side of ``b`` (same linear frame, the
    origins on one axis)?"""
    wa, ha, a1, a2, _ = a
    wb, hb, b1, b2, _ = b
    z = wb[:3, 2]
    t = float(np.dot(wa[:3, 3] - wb[:3, 3], z) / np.dot(z, z))  # a's local z + t = b's local z
    eps = 1e-9 * max(1.0, abs(t), ha, hb, a1, a2, b1, b2)
    for za, ra in ((-ha / 2, a1), (ha / 2, a2)):
        zb = za + t
        if -hb / 2 - eps <= zb <= hb / 2 + eps and ra > 0:
            rb = b1 + (b2 - b1) * (zb + hb / 2) / hb if hb > 0 else b1
            if abs(ra - rb) <= eps:
                return True
    return False
