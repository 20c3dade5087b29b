"""Samples as the point clouds of other libraries: Open3D and trimesh (optional imports; ``pip
install 'clcsg[interop]'`` installs both)."""

from __future__ import annotations

import numpy as np


def _require(module: str, package: str, what: str):
    import importlib

    try:
        return importlib.import_module(module)
    except ImportError as e:
        raise ImportError(f"{what} needs the {package!r} package: pip install {package} "
                          f"(or pip install 'clcsg[interop]'); importing {module} failed: {e}") from None


def to_open3d(samples):
    """An ``open3d.geometry.PointCloud`` with the positions, normals and colours (RGB in [0, 1])."""
    o3d = _require("open3d", "open3d", "clcsg.to_open3d()")
    vec = o3d.utility.Vector3dVector
    pc = o3d.geometry.PointCloud()
    pc.points = vec(np.ascontiguousarray(samples.positions, dtype=np.float64))
    pc.normals = vec(np.ascontiguousarray(samples.normals, dtype=np.float64))
    pc.colors = vec(np.ascontiguousarray(samples.colors[:, :3], dtype=np.float64))
    return pc


def to_trimesh(samples):
    """A ``trimesh.PointCloud`` with the positions and RGBA colours (uint8); normals, radii and
    quadric / primitive ids are in its ``metadata``."""
    trimesh = _require("trimesh", "trimesh", "clcsg.to_trimesh()")
    rgba = np.round(255 * np.clip(samples.colors, 0.0, 1.0)).astype(np.uint8).reshape(-1, 4)
    meta = {"normals": np.asarray(samples.normals), "radii": np.asarray(samples.radii),
            "quadrics": np.asarray(samples.quadrics), "primitives": np.asarray(samples.primitives),
            "radius": float(samples.radius)}
    return trimesh.PointCloud(np.asarray(samples.positions, dtype=np.float64), colors=rgba, metadata=meta)
