"""Mesh files: binary STL (numpy), 3MF, OBJ, PLY and OFF (trimesh), with per-triangle colour
where the format has it (3MF, PLY, OBJ).

Files are written to a temporary file in the target's folder and renamed over the target when
complete, so a failed write leaves nothing half-written.
"""

from __future__ import annotations

import os
import tempfile

import numpy as np

from ..errors import UsageError

#: formats by file extension
FORMATS = (".stl", ".3mf", ".obj", ".ply", ".off")


def check_output(path) -> str:
    """The format (extension) of ``path``; UsageError for an unknown one or a folder that does
    not exist or cannot be written — checked before any work."""
    ext = os.path.splitext(str(path))[1].lower()
    if ext not in FORMATS:
        raise UsageError(f"{path}: unknown mesh format {ext or '(none)'!r}; use one of {', '.join(FORMATS)}")
    folder = os.path.dirname(os.path.abspath(str(path)))
    if not os.path.isdir(folder):
        raise UsageError(f"{path}: the folder {folder} does not exist")
    if not os.access(folder, os.W_OK):
        raise UsageError(f"{path}: the folder {folder} is not writable")
    if os.path.isdir(str(path)):
        raise UsageError(f"{path}: is a folder")
    return ext


def stl_bytes(vertices, triangles) -> bytes:
    """Binary STL: an 80-byte header, the triangle count, per triangle its unit normal, three
    corners (float32) and a zero attribute word."""
    v = np.asarray(vertices, dtype=np.float64)[np.asarray(triangles)]
    n = np.cross(v[:, 1] - v[:, 0], v[:, 2] - v[:, 0])
    ln = np.linalg.norm(n, axis=1, keepdims=True)
    n = np.divide(n, ln, out=np.zeros_like(n), where=ln > 0)
    rec = np.zeros(len(v), dtype=[("n", "<f4", 3), ("v", "<f4", (3, 3)), ("attr", "<u2")])
    rec["n"], rec["v"] = n, v
    header = b"clcsg mesh".ljust(80, b" ")
    return header + np.uint32(len(v)).tobytes() + rec.tobytes()


def _trimesh_bytes(mesh, ext: str) -> bytes:
    import trimesh

    tm = trimesh.Trimesh(mesh.vertices, mesh.triangles, process=False)
    rgba = np.clip(np.round(np.asarray(mesh.colors) * 255), 0, 255).astype(np.uint8)
    if ext in (".3mf", ".ply", ".obj"):
        tm.visual.face_colors = rgba
    out = tm.export(file_type=ext[1:])
    return out if isinstance(out, bytes) else out.encode()


def write(mesh, path) -> int:
    """Write ``mesh`` (a :class:`~clcsg.meshing.mesher.Mesh`) to ``path``; returns the bytes
    written.  The format comes from the extension (:data:`FORMATS`)."""
    ext = check_output(path)
    data = stl_bytes(mesh.vertices, mesh.triangles) if ext == ".stl" else _trimesh_bytes(mesh, ext)
    folder = os.path.dirname(os.path.abspath(str(path)))
    fd, tmp = tempfile.mkstemp(prefix=".clcsg-mesh-", suffix=ext, dir=folder)
    try:
        with os.fdopen(fd, "wb") as f:
            f.write(data)
        os.replace(tmp, str(path))
    except OSError as e:
        _remove(tmp)
        raise UsageError(f"{path}: cannot write the mesh: {e.strerror or e}") from None
    except BaseException:
        _remove(tmp)
        raise
    return len(data)


def _remove(tmp) -> None:
    try:
        os.unlink(tmp)
    except FileNotFoundError:
        pass
