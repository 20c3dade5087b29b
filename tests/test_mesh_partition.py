"""Large meshes as k-d trees of local BSPs (``clcsg/model/mesh_partition.py``): the solid is
the mesh's (the float64 winding number decides), samples and splats are those of the same mesh
written as one BSP, split planes carry no samples, and a region's tapes hold only the planes
of the cells it meets."""

from __future__ import annotations

import numpy as np
import pytest

import clcsg
import clcsg.model.mesh_partition as MP
import clcsg.model.polyhedron as P
from clcsg.model.polyhedron import FacePlane

from test_constructions import check_against
from test_operands import winding_number


def _torus(major=24, minor=12):
    import trimesh

    m = trimesh.creation.torus(1.0, 0.4, major_sections=major, minor_sections=minor)
    return np.asarray(m.vertices, dtype=np.float64), np.asarray(m.faces, dtype=np.int64)


def _icosphere(s=2):
    import trimesh

    m = trimesh.creation.icosphere(s)
    return np.asarray(m.vertices, dtype=np.float64), np.asarray(m.faces, dtype=np.int64)


@pytest.fixture
def partitioned(monkeypatch):
    """Meshes of more than 16 face planes as k-d trees of leaves of at most 6 planes."""
    monkeypatch.setattr(P, "PARTITION_PLANES", 16)
    monkeypatch.setattr(MP, "LEAF_PLANES", 6)


def _face_planes(shape):
    out, stack, seen = [], [shape], set()
    while stack:
        n = stack.pop()
        if id(n) in seen:
            continue
        seen.add(id(n))
        if isinstance(n, FacePlane):
            out.append(n)
        stack.extend(n.children())
    return out


def _split(p: FacePlane) -> bool:
    return bool(np.all(p.face_box[0] > p.face_box[1]))


@pytest.mark.parametrize("name", ["icosphere", "torus"])
def test_partitioned_membership_equals_the_winding_number(partitioned, name):
    v, f = _icosphere(2) if name == "icosphere" else _torus()
    shape = clcsg.polyhedron(v, f)
    planes = _face_planes(shape)
    splits = [p for p in planes if _split(p)]
    assert len(splits) >= 8, "the mesh is a k-d tree"
    rng = np.random.default_rng(3)
    lo, hi = v.min(axis=0), v.max(axis=0)
    near = v[rng.integers(0, len(v), 2000)] + rng.normal(0, 2e-3, (2000, 3))  # about the surface
    on_splits = np.array([[p.params["offset"] if k == int(np.argmax(np.abs(p.params["normal"]))) else 0.0
                           for k in range(3)] for p in splits[:200]])
    pts = np.vstack([rng.uniform(lo - 0.1, hi + 0.1, (3000, 3)), near,
                     # points on split planes: the two cells' expressions meet there
                     np.where(on_splits != 0, on_splits, rng.uniform(lo, hi, on_splits.shape))])
    w = winding_number(v, f, pts)
    sharp = np.abs(w - np.round(w)) < 1e-6
    inside = clcsg.contains(shape, pts)
    assert sharp.mean() > 0.99
    bad = sharp & ((w > 0.5) != inside)
    assert not bad.any(), f"{bad.sum()} points disagree, e.g. {pts[bad][:3].tolist()}"


def test_cells_hold_few_planes_and_supports_hold_their_faces(partitioned):
    v, f = _torus(32, 16)
    tri = v[f]
    shape = clcsg.polyhedron(v, f)
    planes = _face_planes(shape)
    faces = [p for p in planes if not _split(p)]
    assert all(p.support is not None for p in planes)
    for p in faces:  # a face's pieces lie in its cell
        assert np.all(p.support[0] <= p.face_box[0] + 1e-12) and np.all(p.face_box[1] <= p.support[1] + 1e-12)
    per_cell: dict = {}
    for p in faces:
        per_cell.setdefault((tuple(p.support[0]), tuple(p.support[1])), set()).add(
            (round(p.params["offset"], 12), tuple(np.round(p.params["normal"], 12))))
    sizes = np.array([len(s) for s in per_cell.values()])
    # a cell about a point where many faces meet cannot be split apart: few such cells
    assert (sizes <= 6).mean() >= 0.9 and sizes.max() <= 24, np.bincount(sizes)
    # the pieces of every triangle are in the cells: each triangle's centroid lies in the cell of
    # a face plane of its own plane
    cen = tri.mean(axis=1)
    n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    boxes = np.array([[p.support[0], p.support[1]] for p in faces])
    pn = np.array([p.params["normal"] for p in faces])
    for k in np.random.default_rng(0).choice(len(tri), 40, replace=False):
        inside = np.all((boxes[:, 0] <= cen[k]) & (cen[k] <= boxes[:, 1]), axis=1)
        assert np.any(inside & (np.abs(pn @ n[k]) > 1 - 1e-9))


def test_partitioned_mesh_samples_and_renders_like_one_bsp(partitioned, cl_context, monkeypatch):
    """A torus (not convex) minus a cylinder: its samples lie on the surface of the same mesh
    written as one BSP (the float64 tree oracle), cover it, and the splats equal that solid's
    exact ray tracing; no sample lies on a split plane."""
    v, f = _torus(20, 10)
    cutter = clcsg.cylinder(2, 0.35, center=(1.0, 0.0, 0.0))
    shape = clcsg.polyhedron(v, f) - cutter
    monkeypatch.setattr(P, "PARTITION_PLANES", 10 ** 9)
    reference = clcsg.polyhedron(v, f) - cutter
    monkeypatch.setattr(P, "PARTITION_PLANES", 16)
    check_against(shape, reference, cl_context)
    s = clcsg.sample(shape, 0.05, device=cl_context, progress=False)
    Q = s.tape.quadrics[s.quadrics]
    axis_planes = np.all(Q[:, :3, :3] == 0, axis=(1, 2)) & (np.sum(Q[:, :3, 3] != 0, axis=1) == 1)
    offsets = {round(p.params["offset"], 9) for p in _face_planes(shape) if _split(p)}
    c = -Q[axis_planes, 3, 3] / (2 * Q[axis_planes, :3, 3].sum(axis=1))
    assert not ({round(x, 9) for x in c.tolist()} & offsets)


def test_root_tapes_of_a_partitioned_mesh_stay_local(cl_context):
    """A sphere of 5,120 faces (a k-d tree at the default threshold) minus a cylinder: the root
    tapes hold the planes of the cells near each task, not the mesh's thousands of rows."""
    v, f = _icosphere(4)
    assert len(f) > P.PARTITION_PLANES
    shape = clcsg.polyhedron(v, f) - clcsg.cylinder(3, 0.1, center=(0.3, 0.2, 0.0))
    s = clcsg.sample(shape, 0.05, device=cl_context, progress=False)
    assert len(s) > 1000
    first = s.stats["tape_mean_per_level"][0]
    assert first < 0.1 * s.stats["tape_instructions"], (first, s.stats["tape_instructions"])
