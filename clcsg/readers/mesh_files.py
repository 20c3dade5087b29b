"""Mesh files as CSG operands: ``clcsg.load_mesh(path)`` (STL ASCII and binary, OFF, OBJ, 3MF,
PLY with faces), read with trimesh, then checked and turned into an exact solid by
:func:`clcsg.model.polyhedron.polyhedron`; a PLY of points with normals and no faces is a point
operand (:class:`~clcsg.model.surfels.Surfels`).

Points that are exactly equal are one point (STL stores each triangle's corners on their own),
so the edge check sees the mesh's real connectivity.  Every failure is one line naming the file.
"""

from __future__ import annotations

import os

import numpy as np

from ..errors import SceneError
from ..model.construction import Construction
from ..model.csg import walk
from ..model.polyhedron import MeshError, polyhedron
from ..model.surfels import Surfels

#: without a ``radius`` property a surfel's radius is the distance to its k-th nearest center
#: (6: the ring of neighbours on a regular sampling, so the disks overlap)
RADIUS_NEIGHBOUR = 6


class PointCloud(Exception):
    """Raised inside :func:`read_mesh` when the file holds points and no faces."""

    def __init__(self, cloud):
        self.cloud = cloud

#: file extension -> trimesh's file type
MESH_FORMATS = {".stl": "stl", ".off": "off", ".obj": "obj", ".3mf": "3mf", ".ply": "ply"}


def resolve(path, base: str | None) -> str:
    """``path`` as given if absolute, else relative to the folder of the file ``base`` (the
    scene or .scad file that names it), else to the working directory."""
    p = os.fspath(path)
    if os.path.isabs(p) or not base:
        return p
    return os.path.join(os.path.dirname(base), p)


def read_mesh(path, source: str | None = None):
    """(points (n, 3), faces (k, 3)) of a mesh file; ``source`` prefixes the errors (default
    the path)."""
    p = os.fspath(path)
    who = p if source is None else f"{source}: {p}"
    ext = os.path.splitext(p)[1].lower()
    if ext not in MESH_FORMATS:
        raise SceneError(f"{who}: unknown mesh format {ext or '(no extension)'!r}; "
                         f"known: {', '.join(sorted(MESH_FORMATS))}")
    if not os.path.isfile(p):
        raise SceneError(f"{who}: no such file")
    try:
        import trimesh  # a well-kept reader of every mesh format named here
    except ImportError:
        raise SceneError(f"{who}: reading mesh files needs trimesh: pip install 'clcsg[mesh]'") from None
    try:
        m = trimesh.load(p, file_type=MESH_FORMATS[ext], process=False)
        if isinstance(m, trimesh.PointCloud):
            raise PointCloud(m)
        if isinstance(m, trimesh.Scene):  # 3MF, OBJ with several objects: one mesh
            m = trimesh.load(p, file_type=MESH_FORMATS[ext], force="mesh", process=False)
    except (MeshError, PointCloud):
        raise
    except Exception as e:  # trimesh raises many types for malformed files
        raise SceneError(f"{who}: cannot read the mesh: {str(e).splitlines()[0] if str(e) else type(e).__name__}") from None
    v = np.asarray(getattr(m, "vertices", np.zeros((0, 3))), dtype=np.float64).reshape(-1, 3)
    f = np.asarray(getattr(m, "faces", np.zeros((0, 3))), dtype=np.int64).reshape(-1, 3)
    if not len(f) and not len(v) and ext == ".ply":
        raise MeshError(f"{who}: the file has no points (a point operand needs at least one, a mesh 4 faces)")
    if not len(f):
        raise MeshError(f"{who}: the file has no faces (a closed mesh needs at least 4)")
    v, inverse = np.unique(v, axis=0, return_inverse=True)
    return v, inverse.reshape(-1)[f]


def surfels_of(cloud, who: str, color=None) -> Surfels:
    """The point operand of a PLY point cloud: its points, normals ``nx ny nz`` (required) and
    radii (a ``radius`` property, else the distance to the :data:`RADIUS_NEIGHBOUR`-th nearest
    point)."""
    data = cloud.metadata.get("_ply_raw", {}).get("vertex", {}).get("data", {})
    if getattr(data, "dtype", None) is not None:  # binary files: one structured array
        data = {k: data[k] for k in (data.dtype.names or ())}
    points = np.asarray(cloud.vertices, dtype=np.float64).reshape(-1, 3)
    if not len(points):
        raise SceneError(f"{who}: the point cloud has no points")
    if not all(k in data for k in ("nx", "ny", "nz")):
        raise SceneError(f"{who}: the point cloud has no normals (vertex properties nx, ny, nz): a point operand "
                         "needs outward normals")
    normals = np.stack([np.asarray(data[k], dtype=np.float64).reshape(-1) for k in ("nx", "ny", "nz")], axis=1)
    if "radius" in data:
        radii = np.asarray(data["radius"], dtype=np.float64).reshape(-1)
    elif len(points) < 2:
        raise SceneError(f"{who}: a single point without a radius property")
    else:
        from scipy.spatial import cKDTree  # an optional dependency: only point operands need it

        k = min(RADIUS_NEIGHBOUR, len(points) - 1)
        with np.errstate(invalid="ignore"):
            finite = np.isfinite(points).all(axis=1)
        d, _ = cKDTree(points[finite] if finite.any() else points[:1]).query(np.nan_to_num(points), k=k + 1)
        radii = np.asarray(d).reshape(len(points), -1)[:, -1]
    try:
        return Surfels(points, normals, radii, color, source=who)
    except SceneError:
        raise
    except (ValueError, TypeError) as e:
        raise SceneError(f"{who}: {e}") from None


def load_mesh(path, color=None, source: str | None = None):
    """The exact solid bounded by the closed, consistently oriented mesh in ``path``; a PLY
    file of points with normals and no faces is a point operand (:func:`surfels_of`)."""
    p = os.fspath(path)
    who = p if source is None else f"{source}: {p}"
    try:
        v, f = read_mesh(path, source)
    except PointCloud as cloud:
        return surfels_of(cloud.cloud, who, color)
    shape = polyhedron(v, f, color=color, source=who, label=f"mesh {os.path.basename(p)} of {len(f)} triangles")
    shape.spec = {"mesh": {"file": os.path.abspath(p)}}
    return shape


def mesh_files(shape) -> list[str]:
    """The mesh files a shape was read from (absolute paths, first-use order), for watchers."""
    out: list = []
    for node in walk(shape):
        spec = getattr(node, "spec", None) if isinstance(node, Construction) else None
        if isinstance(spec, dict) and "file" in spec.get("mesh", {}) and spec["mesh"]["file"] not in out:
            out.append(spec["mesh"]["file"])
    return out
