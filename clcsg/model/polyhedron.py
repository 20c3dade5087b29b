"""Closed triangle meshes as CSG operands: ``clcsg.polyhedron(vertices, faces)``.

A mesh is accepted if it bounds a solid: finite points, at least 4 faces, faces of at least
3 distinct points with no zero area, every edge used by exactly two faces in opposite
directions (closed and consistently oriented), one fan of faces around every point
(2-manifold), no shell without volume or wrongly nested, and no two faces that share no point crossing
each other (:mod:`clcsg.model.mesh_intersections`).  Either orientation is taken (OpenSCAD lists
faces clockwise seen from outside, STL counter-clockwise): the faces are turned outward by the
sign of the enclosed volume.  The first failing check is one :class:`MeshError` naming the
source and the first bad face or edge.

The solid is exact: :func:`clcsg.model.bsp.bsp_expression` writes it as a Boolean expression of
its face planes, which the rest of the pipeline samples, prunes and ray traces like any planes
(a mesh box is the quadric box).  Coplanar faces share one plane.  A mesh of many planes is a
k-d tree of such expressions, one per cell (:mod:`clcsg.model.mesh_partition`), so that the
planes a region's tapes hold are those of the cells near it.
"""

from __future__ import annotations

import itertools

import numpy as np

from ..errors import LimitError, SceneError
from .bsp import bsp_expression, triangle_planes
from .mesh_partition import partition_expression
from .construction import Construction
from .mesh_intersections import first_bad_shell, first_intersection
from .csg import Complement, Intersection, Primitive, Union


class MeshError(SceneError):
    """A mesh that does not bound a solid (open, inconsistently oriented, degenerate)."""


#: relative tolerance (of the mesh's size) for points on a plane
PLANE_EPS = 1e-9
#: the most distinct face planes a mesh operand may have
MAX_FACE_PLANES = 1 << 20
#: a mesh of more distinct face planes than this is a k-d tree of local BSPs
#: (:mod:`clcsg.model.mesh_partition`), so that a region's tapes hold the planes near it only
PARTITION_PLANES = 2048
#: relative tolerance below which two triangles' planes are one face plane
FACE_PLANE_EPS = 1e-6
#: relative depth by which two faces must cross to be a self-intersection (above float32's
#: rounding: many meshes are written in single precision)
CROSSING_EPS = 1e-6


def _arrays(vertices, faces, source):
    try:
        v = np.asarray(vertices, dtype=np.float64)
    except (TypeError, ValueError):
        raise MeshError(f"{source}: mesh points are not numbers") from None
    if v.ndim != 2 or v.shape[1] != 3:
        raise MeshError(f"{source}: mesh points must be [x, y, z] triples, got shape {v.shape}")
    bad = np.flatnonzero(~np.all(np.isfinite(v), axis=1))
    if len(bad):
        raise MeshError(f"{source}: mesh point {bad[0]} is not finite: {v[bad[0]].tolist()}")
    fs = [list(f) for f in faces]
    if len(fs) < 4:
        raise MeshError(f"{source}: a closed mesh needs at least 4 faces, got {len(fs)}")
    for k, f in enumerate(fs):
        if len(f) < 3 or any(int(i) != i or not 0 <= i < len(v) for i in f):
            raise MeshError(f"{source}: face {k} = {f} is not a list of at least 3 point indices below {len(v)}")
    return v, [[int(i) for i in f] for f in fs]


def _triangulate(v, faces, source):
    """Fan triangles (k, 3) of convex planar polygons; a non-convex or non-planar face is an
    error (triangulate it first)."""
    tris, owner = [], []
    scale = max(float(np.abs(v).max()), 1e-300)
    for k, f in enumerate(faces):
        if len(set(f)) != len(f):
            raise MeshError(f"{source}: face {k} = {f} repeats a point")
        fan = [(f[0], f[i], f[i + 1]) for i in range(1, len(f) - 1)]
        tris.extend(fan)
        owner.extend([k] * len(fan))
    t = np.array(tris, dtype=np.int64)
    n = np.cross(v[t[:, 1]] - v[t[:, 0]], v[t[:, 2]] - v[t[:, 0]])
    area = np.linalg.norm(n, axis=1)
    zero = np.flatnonzero(area <= 1e-12 * scale * scale)
    if len(zero):
        raise MeshError(f"{source}: face {owner[zero[0]]} has no area (its points are on a line)")
    unit = n / area[:, None]
    owner = np.array(owner)
    for k in np.unique(owner[np.r_[False, owner[1:] == owner[:-1]]]):
        sel = owner == k
        if np.any(unit[sel] @ unit[sel][0] < 1 - 1e-9):
            raise MeshError(f"{source}: face {k} is not a flat convex polygon; triangulate it")
    return t, owner


def _check_edges(v, faces, source):
    """Every edge in exactly two faces, in opposite directions."""
    count: dict = {}
    for k, f in enumerate(faces):
        for i in range(len(f)):
            e = (f[i], f[(i + 1) % len(f)])
            if e in count:
                a, b = e
                raise MeshError(f"{source}: edge {a}-{b} {_pts(v, a, b)} is used twice in the same direction "
                                f"(faces {count[e]} and {k}): the faces are not consistently oriented")
            count[e] = k
    for (a, b), k in count.items():
        if (b, a) not in count:
            raise MeshError(f"{source}: edge {a}-{b} {_pts(v, a, b)} of face {k} has no opposite face: "
                            "the mesh is open (not closed)")


def _check_vertices(v, faces, source):
    """Around every point its faces form one fan (the link is one cycle): two solids touching
    at a point, or a fin hanging from one, are no 2-manifold.  With the edges checked, the
    link's edges (next -> previous corner of each face at the point) form cycles."""
    link: dict = {}
    for f in faces:
        for i, p in enumerate(f):
            link.setdefault(p, {})[f[(i + 1) % len(f)]] = f[i - 1]
    for p, nxt in link.items():
        start = next(iter(nxt))
        q, n = nxt[start], 1
        while q != start:
            q, n = nxt[q], n + 1
        if n != len(nxt):
            x = ", ".join(f"{c:g}" for c in v[p])
            raise MeshError(f"{source}: point {p} ({x}) joins {len(nxt)} faces in more than one fan: "
                            "the mesh is not a 2-manifold there (solids touching at a point)")


def _pts(v, a, b):
    return f"({', '.join(f'{x:g}' for x in v[a])} to {', '.join(f'{x:g}' for x in v[b])})"


def check_mesh(vertices, faces, source: str = "polyhedron"):
    """(points (n, 3), triangles (k, 3) turned outward) of a mesh that bounds a solid; else a
    one-line :class:`MeshError` naming ``source`` and the first bad face or edge."""
    v, fs = _arrays(vertices, faces, source)
    _check_edges(v, fs, source)
    _check_vertices(v, fs, source)
    t, owner = _triangulate(v, fs, source)
    a, b, c = v[t[:, 0]], v[t[:, 1]], v[t[:, 2]]
    volume = float(np.einsum("ij,ij->i", a, np.cross(b, c)).sum()) / 6.0
    scale = float(np.ptp(v, axis=0).max())
    if not abs(volume) > 1e-12 * scale ** 3:
        raise MeshError(f"{source}: the mesh encloses no volume")
    hit = first_intersection(v, t, CROSSING_EPS * max(float(np.abs(v).max()), 1e-300))
    if hit is not None:
        fi, fj = (int(owner[k]) for k in hit)
        raise MeshError(f"{source}: faces {fi} and {fj} cross each other: the mesh intersects itself")
    t = t if volume > 0 else t[:, ::-1].copy()
    shell = first_bad_shell(v, t, PLANE_EPS * max(float(np.abs(v).max()), 1e-300))
    if shell is not None:
        raise MeshError(f"{source}: the shell of face {int(owner[shell])} encloses no volume, or is nested in a shell of "
                        "the same orientation (or is an inward shell outside all others): the mesh bounds no solid")
    return v, t


def _merge_neighbours(keys):
    """Labels of grid keys (k, 4) where keys one step apart on every axis are one plane (so a
    plane near a rounding boundary is not split in two)."""
    index = {tuple(row): i for i, row in enumerate(keys.tolist())}
    parent = list(range(len(keys)))

    def find(x):
        while parent[x] != x:
            parent[x] = parent[parent[x]]
            x = parent[x]
        return x

    steps = [s for s in itertools.product((-1, 0, 1), repeat=4) if any(s)]
    for i, row in enumerate(keys.tolist()):
        for s in steps:
            j = index.get((row[0] + s[0], row[1] + s[1], row[2] + s[2], row[3] + s[3]))
            if j is not None:
                parent[find(j)] = find(i)
    roots = [find(i) for i in range(len(keys))]
    return np.unique(roots, return_inverse=True)[1].reshape(-1)


def _planes(tri, scale):
    """Unique face planes (normals, offsets), each triangle's plane index, and the largest
    distance of a corner from its plane.  Triangles whose planes agree to FACE_PLANE_EPS (on a
    grid: normals, and offsets relative to ``scale``) share one plane: their area-weighted
    mean normal, through the mean of their centroids along it.  Meshes written in float32 put
    the triangles of one flat face about 1e-7 apart; they are one face of the solid."""
    n, d = triangle_planes(tri)
    area = np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1)
    key = np.round(np.c_[n, d / scale] / FACE_PLANE_EPS).astype(np.int64)
    keys, inverse = np.unique(key, axis=0, return_inverse=True)
    inverse = _merge_neighbours(keys)[inverse.reshape(-1)]
    k = int(inverse.max()) + 1
    normals = np.zeros((k, 3))
    np.add.at(normals, inverse, n * area[:, None])
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    centre = tri.mean(axis=1)
    offsets = np.zeros(k)
    np.add.at(offsets, inverse, np.einsum("ij,ij->i", normals[inverse], centre) * area)
    weight = np.zeros(k)
    np.add.at(weight, inverse, area)
    offsets /= weight
    dev = np.abs(np.einsum("tki,ti->tk", tri, normals[inverse]) - offsets[inverse, None]).max()
    return normals, offsets, inverse, float(dev)


class FacePlane(Primitive):
    """A mesh's face plane: the half-space of :func:`~clcsg.model.construction.plane`, and
    ``face_box`` (lo, hi), the box of the mesh's triangles on that plane.  The mesh's solid is
    bounded by the plane only on those triangles, so the bounds take the plane's face there
    (:func:`~clcsg.compile.bounds.exact_boxes.kind_face_boxes`): the sampler's tasks on the
    plane start from that box, not from the mesh's, and their tapes hold only the face planes
    near it.  ``support`` (lo, hi), for a face plane of a k-d cell of a large mesh
    (:mod:`clcsg.model.mesh_partition`): the cell, outside which the expression holding the
    plane is never used, so that the primitive's box is the cell (a region that misses it
    prunes the plane away).  Saved, it is a plain half-space (the mesh is saved as its points
    and faces)."""

    __slots__ = ("face_box", "support")

    def __init__(self, normal, offset, face_box, color=None, support=None):
        super().__init__("halfspace", {"normal": [float(v) for v in normal], "offset": float(offset)}, color)
        self.face_box = (np.asarray(face_box[0], dtype=np.float64), np.asarray(face_box[1], dtype=np.float64))
        self.support = None if support is None else (np.asarray(support[0], dtype=np.float64),
                                                     np.asarray(support[1], dtype=np.float64))


def split_plane(axis: int, c: float, cell, color=None) -> FacePlane:
    """The half-space x_axis <= c of a k-d split of ``cell`` (lo, hi), its support
    (:mod:`clcsg.model.mesh_partition`): it bounds no surface, so its face box is empty and the
    sampler starts no task on it."""
    n = np.zeros(3)
    n[axis] = 1.0
    return FacePlane(n, c, (np.full(3, np.inf), np.full(3, -np.inf)), color, support=cell)


def _face_boxes(tri, owner, k, pad):
    """(lo, hi) (k, 3) of the triangles on each of the k face planes, padded by ``pad``."""
    lo, hi = np.full((k, 3), np.inf), np.full((k, 3), -np.inf)
    np.minimum.at(lo, owner, tri.min(axis=1))
    np.maximum.at(hi, owner, tri.max(axis=1))
    return lo - pad, hi + pad


def _shape(expr, normals, offsets, color, faces, leaves=None, splits=None, pad=0.0):
    """The nested tuple expression of :func:`bsp_expression` (or of
    :func:`~clcsg.model.mesh_partition.partition_expression`, whose ``leaves`` give each
    cell's box and its planes' face boxes and ``splits`` each split cell's box, all padded by
    ``pad``) as Shapes (without recursion); ``faces`` ((k, 3), (k, 3)): each face plane's
    triangles' box."""
    made = {}

    def leaf(e):
        key = e[1:]
        if key not in made:
            if e[0] == "split":
                lo, hi = splits[e[3]]
                made[key] = split_plane(e[1], e[2], (lo - pad, hi + pad), color)
            elif e[0] == "face":
                lo, hi, boxes = leaves[e[2]]
                flo, fhi = boxes[e[1]]
                made[key] = FacePlane(normals[e[1]], offsets[e[1]], (flo - pad, fhi + pad), color,
                                      support=(lo - pad, hi + pad))
            else:
                made[key] = FacePlane(normals[e[1]], offsets[e[1]], (faces[0][e[1]], faces[1][e[1]]), color)
        return made[key]

    out: dict = {}
    stack = [(expr, False)]
    while stack:
        e, done = stack.pop()
        if not done and id(e) in out:  # shared (the consensus terms): built once
            continue
        if e[0] in ("plane", "face", "split"):
            out[id(e)] = leaf(e)
        elif not done:
            stack.append((e, True))
            stack.extend((c, False) for c in (e[1] if e[0] in ("and", "or") else [e[1]]))
        elif e[0] == "not":
            out[id(e)] = Complement(out[id(e[1])])
        else:
            kids = [out[id(c)] for c in e[1]]
            out[id(e)] = Intersection(kids) if e[0] == "and" else Union(kids)
    return out[id(expr)]


def polyhedron(vertices, faces, color=None, source: str = "polyhedron", label: str | None = None,
               max_planes: int = MAX_FACE_PLANES) -> Construction:
    """The solid bounded by a closed, consistently oriented mesh (faces: lists of point
    indices, convex planar polygons, either orientation), exactly: a Boolean expression of its
    face planes (:mod:`clcsg.model.bsp`; past :data:`PARTITION_PLANES` of them a k-d tree of
    local ones, :mod:`clcsg.model.mesh_partition`), bounded by the mesh's box.  More than
    ``max_planes`` distinct face planes is a :class:`~clcsg.errors.LimitError`."""
    v, t = check_mesh(vertices, faces, source)
    scale = float(np.abs(v).max()) or 1.0
    tri = v[t]
    normals, offsets, owner, dev = _planes(tri, scale)
    if len(normals) > max_planes:
        raise LimitError(f"{source}: the mesh has {len(normals)} distinct face planes; at most {max_planes} are "
                         "sampled (a mesh operand is an expression of its face planes): simplify or decimate the mesh")
    eps = max(PLANE_EPS * scale, 2.0 * dev)
    lo, hi = v.min(axis=0), v.max(axis=0)
    if len(normals) > PARTITION_PLANES:
        grow = 2e-3 * np.linalg.norm(hi - lo) + 4.0 * eps  # past the box of `bounded`
        expr, leaves, splits = partition_expression(tri, owner, normals, offsets, eps, lo - grow, hi + grow)
        body = _shape(expr, normals, offsets, color, None, leaves, splits, 2.0 * eps)
    else:
        expr = bsp_expression(tri, owner, normals, offsets, eps)
        body = _shape(expr, normals, offsets, color, _face_boxes(tri, owner, len(normals), 2.0 * eps))
    what = label or f"mesh of {len(t)} triangles"
    c = Construction("mesh", what, body, v, (lo, hi), surfaces={"plane": len(normals)})
    if len(normals) > PARTITION_PLANES:  # the bounds see the mesh's (grown) box, its bound
        c.bounds_proxy = c.operands[0].operands[1]
    c.spec = {"mesh": {"points": v.tolist(), "faces": t.tolist()}}
    return c
