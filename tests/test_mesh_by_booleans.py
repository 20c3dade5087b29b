"""``clcsg.mesh`` of scenes with point operands and large mesh operands (the Booleans of
:mod:`clcsg.meshing.operand_booleans`): closed and 2-manifold by manifold3d and trimesh, every
vertex on the exact surface the pieces come from (float64), volumes against analytic values,
colours of the pieces, and the CLI."""

from __future__ import annotations

import manifold3d
import numpy as np
import pytest
import trimesh

import clcsg
from clcsg.cli import app as cli
from clcsg.meshing import operand_booleans
from clcsg.model.surfel_surface import spacing
from test_surfel_surface import bored_cloud_file
from test_surfels import SURFEL_R, sphere_cloud


def closed_manifold(m) -> trimesh.Trimesh:
    """The mesh as trimesh, after checking it is closed, consistently oriented, outward and
    accepted by manifold3d as a 2-manifold."""
    tm = trimesh.Trimesh(m.vertices, m.triangles, process=False)
    assert tm.is_watertight and tm.is_winding_consistent and tm.volume > 0
    mm = manifold3d.Manifold(manifold3d.Mesh64(vert_properties=np.ascontiguousarray(m.vertices),
                                               tri_verts=np.ascontiguousarray(m.triangles, dtype=np.uint64)))
    assert mm.status() == manifold3d.Error.NoError and mm.num_tri() > 0
    return tm


def napkin_ring(radius, hole):
    """Volume of a ball of ``radius`` with a cylindrical hole of radius ``hole`` through its center."""
    return 4.0 / 3.0 * np.pi * (radius ** 2 - hole ** 2) ** 1.5


@pytest.fixture(scope="module")
def cloud():
    p, n = sphere_cloud(20000)
    return clcsg.surfels(p, n, SURFEL_R, color=(0.9, 0.1, 0.1))


def test_cloud_minus_cylinder(cloud):
    """A sphere cloud bored by a cylinder: closed 2-manifold; vertices on the bore within the
    tolerance of the cylinder (and inside the sphere), the others within a grid cube of the
    unit sphere and outside the bore; the volume within the chords' deficit of the napkin
    ring's; the bore's triangles take the cylinder's colour, the rest the cloud's."""
    cyl = clcsg.cylinder(3, 0.4, color=(0.1, 0.1, 0.9))
    m = clcsg.mesh(cloud - cyl)
    tm = closed_manifold(m)
    assert m.stats["method"] == "booleans"
    h = spacing(cloud)
    v = m.vertices
    radial, rr = np.hypot(v[:, 0], v[:, 1]), np.linalg.norm(v, axis=1)
    on_bore = np.abs(radial - 0.4) <= m.tolerance
    assert on_bore.sum() > 50
    assert (rr[on_bore] <= 1.0 + h).all()
    assert (np.abs(rr[~on_bore] - 1.0) <= h).all() and (radial[~on_bore] >= 0.4 - m.tolerance).all()
    exact = napkin_ring(1.0, 0.4)
    assert exact * (1 - 3 * h) <= tm.volume <= exact * 1.001
    a, b, c = (v[m.triangles[:, k]] for k in range(3))
    normal = np.cross(b - a, c - a)
    normal /= np.linalg.norm(normal, axis=1, keepdims=True)
    centroid = (a + b + c) / 3
    axis_out = centroid * [1, 1, 0] / np.hypot(centroid[:, 0], centroid[:, 1])[:, None]
    bore = on_bore[m.triangles].all(axis=1) & (np.einsum("ij,ij->i", normal, axis_out) < -0.9)  # facing the axis
    sphere = np.einsum("ij,ij->i", normal, centroid / np.linalg.norm(centroid, axis=1)[:, None]) > 0.5
    assert bore.sum() > 50 and sphere.sum() > 1000 and not (bore & sphere).any()
    assert np.allclose(m.colors[bore], (0.1, 0.1, 0.9, 1.0)) and np.allclose(m.colors[sphere], (0.9, 0.1, 0.1, 1.0))


def test_complement_and_transformed_cloud(cloud):
    """A box minus a shrunken, shifted cloud written as box & ~cloud (the complement is K
    minus the cloud): a closed box with a spherical cavity, of the analytic volume within
    the grid's resolution."""
    small = cloud.scale(0.5).translate((0.1, 0.0, 0.0))
    m = clcsg.mesh(clcsg.box(2.0) & ~small)
    tm = closed_manifold(m)
    cavity = 4.0 / 3.0 * np.pi * 0.5 ** 3
    assert abs(tm.volume - (8.0 - cavity)) <= 0.05 * cavity
    assert tm.body_count == 2  # the outer shell and the cavity's


def test_large_mesh_operand_minus_cylinders():
    """A 1,280-face icosphere (a mesh operand past MESH_OPERAND_PLANES planes) minus two
    cylinders: closed 2-manifold; every vertex within the tolerance of a cylinder or on a
    face plane of the icosphere (1e-9), never inside a bore; the volume that of manifold3d's
    Boolean with a 1,024-segment cylinder within 0.5%."""
    ico = trimesh.creation.icosphere(subdivisions=3)
    assert len(ico.faces) > operand_booleans.MESH_OPERAND_PLANES
    shape = clcsg.polyhedron(ico.vertices, ico.faces) - clcsg.cylinder(3, 0.3) - clcsg.cylinder(3, 0.25, axis=(1, 0, 0))
    m = clcsg.mesh(shape)
    tm = closed_manifold(m)
    v = m.vertices
    r1, r2 = np.hypot(v[:, 0], v[:, 1]), np.hypot(v[:, 1], v[:, 2])
    on_cyl = (np.abs(r1 - 0.3) <= m.tolerance) | (np.abs(r2 - 0.25) <= m.tolerance)
    a, b, c = (ico.vertices[ico.faces[:, k]] for k in range(3))
    n = np.cross(b - a, c - a)
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    plane_dist = np.abs(np.einsum("vfk,fk->vf", v[:, None, :] - a[None], n))
    on_face = plane_dist.min(axis=1) <= 1e-9
    assert (on_cyl | on_face).all()
    assert (r1 >= 0.3 - m.tolerance).all() and (r2 >= 0.25 - m.tolerance).all()
    ref = manifold3d.Manifold(manifold3d.Mesh64(vert_properties=np.ascontiguousarray(ico.vertices, dtype=np.float64),
                                                tri_verts=np.ascontiguousarray(ico.faces, dtype=np.uint64)))
    c1 = manifold3d.Manifold.cylinder(3, 0.3, 0.3, 1024).translate((0, 0, -1.5))
    c2 = manifold3d.Manifold.cylinder(3, 0.25, 0.25, 1024).translate((0, 0, -1.5)).rotate((0, 90, 0))
    assert abs(tm.volume - (ref - c1 - c2).volume()) <= 0.005 * tm.volume


def test_small_mesh_operand_keeps_the_exact_mesher():
    """A mesh box (6 planes) minus a cylinder stays with the exact mesher: every vertex on
    the box's faces or the cylinder, per-triangle quadrics known."""
    from test_operands import box_mesh

    v, f = box_mesh((-1, -1, -1), (1, 1, 1))
    m = clcsg.mesh(clcsg.polyhedron(v, f) - clcsg.cylinder(3, 0.4))
    assert m.stats.get("method") != "booleans" and (m.quadric >= 0).all()
    closed_manifold(m)


def test_cli_mesh_of_a_surfel_scene(tmp_path):
    bored_cloud_file(tmp_path)
    out = tmp_path / "s.3mf"
    assert cli.main(["mesh", str(tmp_path / "s.json"), "-o", str(out), "-q"]) == 0
    back = trimesh.load(str(out), force="mesh")
    assert back.is_watertight and abs(back.volume - napkin_ring(1.0, 0.4)) <= 0.05 * napkin_ring(1.0, 0.4)
