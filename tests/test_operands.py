"""Meshes as CSG operands: ``clcsg.polyhedron``, ``clcsg.load_mesh``, OpenSCAD's ``polyhedron()``
and ``import()``, the scene file's ``mesh`` node.  A mesh is exact (its face planes), so a mesh
model is checked against the equivalent quadric model: samples on the quadric model's surface
(float64 tree oracle), covering it, splats equal to its exact ray-traced image."""

from __future__ import annotations

import numpy as np
import pytest

import clcsg
from clcsg.errors import SceneError

from test_constructions import check_against, export, needs_openscad


def box_mesh(lo, hi):
    """The box lo..hi as 12 outward (counter-clockwise) triangles."""
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    v = np.array([[(hi if (i >> k) & 1 else lo)[k] for k in range(3)] for i in range(8)])
    quads = [(0, 2, 3, 1), (4, 5, 7, 6), (0, 1, 5, 4), (2, 6, 7, 3), (0, 4, 6, 2), (1, 3, 7, 5)]
    faces = [t for a, b, c, d in quads for t in ((a, b, c), (a, c, d))]
    return v, np.array(faces)


def prism_mesh(poly, z0, z1):
    """A z-prism over a counter-clockwise simple polygon, as triangles (the polygon fanned
    from each convex corner is not enough for an L: ear-clipped by hand below)."""
    poly = np.asarray(poly, float)
    n = len(poly)
    v = np.r_[np.c_[poly, np.full(n, z0)], np.c_[poly, np.full(n, z1)]]
    faces = []
    for i in range(n):
        j = (i + 1) % n
        faces += [(i, j, n + j), (i, n + j, n + i)]
    return v, faces


# the L: (0,0) (2,0) (2,1) (1,1) (1,2) (0,2), its caps as two rectangles' triangles
L_POLY = [(0, 0), (2, 0), (2, 1), (1, 1), (1, 2), (0, 2)]
L_CAP = [(0, 1, 2), (0, 2, 3), (0, 3, 4), (0, 4, 5)]  # fans from (0,0): every triangle inside the L


def l_prism():
    v, faces = prism_mesh(L_POLY, 0.0, 1.0)
    faces += [(c, b, a) for a, b, c in L_CAP] + [(a + 6, b + 6, c + 6) for a, b, c in L_CAP]
    return v, faces


def test_mesh_box_minus_cylinder_equals_quadric_box(cl_context):
    v, f = box_mesh((-1, -1, -1), (1, 1, 1))
    cut = clcsg.cylinder(3, 0.5)
    check_against(clcsg.polyhedron(v, f) - cut, clcsg.box(2) - cut, cl_context)


def test_l_prism_union_sphere(cl_context):
    v, f = l_prism()
    ref = clcsg.box((2, 1, 1), center=(1, 0.5, 0.5)) | clcsg.box((1, 2, 1), center=(0.5, 1, 0.5))
    ball = clcsg.sphere(0.6, (1.0, 1.0, 1.0))
    check_against(clcsg.polyhedron(v, f) | ball, ref | ball, cl_context)


def test_either_orientation_and_the_box_is_six_planes():
    v, f = box_mesh((0, 0, 0), (1, 2, 3))
    a, b = clcsg.polyhedron(v, f), clcsg.polyhedron(v, f[:, ::-1])
    assert a.describe() == b.describe() == "mesh of 12 triangles: 6 planes"
    pts = np.random.default_rng(1).uniform(-0.5, 3.5, (2000, 3))
    inside = np.all((pts >= 0) & (pts <= [1, 2, 3]), axis=1)
    assert np.array_equal(clcsg.contains(a, pts), inside)
    assert np.array_equal(clcsg.contains(b, pts), inside)


# -- membership against an independent oracle: the winding number ---------------------------------
def winding_number(v, faces, pts):
    """The generalized winding number of points (Van Oosterom and Strackee's solid angles, in
    float64): 1 inside a closed outward mesh, 0 outside."""
    t = np.asarray(faces, dtype=np.int64)
    a, b, c = (v[t[:, k]][None, :, :] - pts[:, None, :] for k in range(3))
    la, lb, lc = (np.linalg.norm(x, axis=2) for x in (a, b, c))
    det = np.einsum("pti,pti->pt", a, np.cross(b, c))
    den = la * lb * lc + np.einsum("pti,pti->pt", a, b) * lc + np.einsum("pti,pti->pt", b, c) * la \
        + np.einsum("pti,pti->pt", c, a) * lb
    return np.arctan2(det, den).sum(axis=1) / (2 * np.pi)


@pytest.mark.parametrize("name", ["l_prism", "dented_tetra", "annulus", "two_boxes_touching"])
def test_membership_equals_the_winding_number(name):
    import trimesh

    if name == "l_prism":
        v, f = l_prism()
    elif name == "dented_tetra":  # the non-convex polyhedron the reader refused before
        v = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1], [0.1, 0.1, 0.1]], float)
        f = [[2, 1, 0], [1, 3, 0], [3, 2, 0], [4, 3, 1], [2, 4, 1], [2, 3, 4]]
    elif name == "annulus":
        m = trimesh.creation.annulus(0.5, 1.0, 0.6, sections=24)
        v, f = m.vertices, m.faces
    else:  # an L of two boxes that share part of a face: the shared part is inside
        (v1, f1), (v2, f2) = box_mesh((0, 0, 0), (2, 1, 1)), box_mesh((0, 1, 0), (1, 2, 1))
        m = trimesh.boolean.union([trimesh.Trimesh(v1, f1), trimesh.Trimesh(v2, f2)], engine="manifold")
        v, f = m.vertices, m.faces
    v = np.asarray(v, float)
    shape = clcsg.polyhedron(v, f)
    lo, hi = v.min(axis=0), v.max(axis=0)
    pts = np.random.default_rng(7).uniform(lo - 0.1, hi + 0.1, (3000, 3))
    w = winding_number(v, f, pts)
    inside = clcsg.contains(shape, pts)
    assert np.all((w > 0.5) == inside), f"{np.sum((w > 0.5) != inside)} points disagree"
    assert np.all(np.abs(w - np.round(w)) < 1e-6)  # no point on the surface: the test is sharp


# -- files: every format, OpenSCAD, the scene file ------------------------------------------------
def write_box(path, lo=(-1, -1, -1), hi=(1, 1, 1), **kw):
    import trimesh

    v, f = box_mesh(lo, hi)
    trimesh.Trimesh(v, f, process=False).export(str(path), **kw)
    return path


@pytest.mark.parametrize("name,kw", [("box.stl", {}), ("ascii.stl", {"file_type": "stl_ascii"}), ("box.off", {}),
                                     ("box.obj", {}), ("box.3mf", {}), ("box.ply", {})])
def test_load_mesh_formats(name, kw, tmp_path):
    shape = clcsg.load_mesh(write_box(tmp_path / name, (0, 0, 0), (1, 2, 3), **kw))
    assert shape.describe() == f"mesh {name} of 12 triangles: 6 planes"
    pts = np.random.default_rng(2).uniform(-0.5, 3.5, (2000, 3))
    assert np.array_equal(clcsg.contains(shape, pts), np.all((pts >= 0) & (pts <= [1, 2, 3]), axis=1))


@needs_openscad
def test_openscad_import_and_polyhedron_equal_the_quadric_model(tmp_path, cl_context):
    sub = tmp_path / "parts"
    sub.mkdir()
    write_box(sub / "block.stl")
    v, f = l_prism()
    pts = ", ".join(f"[{x:g}, {y:g}, {z:g}]" for x, y, z in v)
    faces = ", ".join(f"[{c}, {b}, {a}]" for a, b, c in f)  # OpenSCAD: clockwise seen from outside
    scad = (f'difference() {{ import("parts/block.stl"); cylinder(h = 3, r = 0.5, center = true); }}\n'
            f"translate([3, 0, 0]) polyhedron(points = [{pts}], faces = [{faces}]);")
    cut = clcsg.cylinder(3, 0.5)
    l_ref = clcsg.box((2, 1, 1), center=(4, 0.5, 0.5)) | clcsg.box((1, 2, 1), center=(3.5, 1, 0.5))
    check_against(export(scad, tmp_path).shape, (clcsg.box(2) - cut) | l_ref, cl_context)
    (tmp_path / "model.scad").write_text(scad)
    scene = clcsg.load(tmp_path / "model.scad")  # relative to the .scad, not the working directory
    assert np.allclose(scene.compile().bound, [[-1, -1, -1], [5, 2, 1]])


def test_import_scale_and_path_relative_to_the_csg_file(tmp_path, monkeypatch):
    from clcsg.readers.openscad import load_csg

    (tmp_path / "parts").mkdir()
    write_box(tmp_path / "parts" / "block.stl", (0, 0, 0), (1, 1, 1))
    (tmp_path / "m.csg").write_text('multmatrix([[1, 0, 0, 5], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]]) {\n'
                                    '  import(file = "parts/block.stl", layer = "", origin = [0, 0], scale = 2, '
                                    'convexity = 1, $fn = 0, $fa = 12, $fs = 2, timestamp = 0);\n}\n')
    monkeypatch.chdir(tmp_path / "parts")  # not where the .csg is
    scene = load_csg(tmp_path / "m.csg")
    pts = np.random.default_rng(5).uniform(-1, 8, (3000, 3))
    expect = np.all((pts >= [5, 0, 0]) & (pts <= [7, 2, 2]), axis=1)
    assert np.array_equal(clcsg.contains(scene.shape, pts), expect)


def test_scene_file_mesh_nodes_round_trip(tmp_path):
    write_box(tmp_path / "block.stl")
    (tmp_path / "s.json").write_text('{"clcsg": 1, "root": {"difference": [{"mesh": {"file": "block.stl"}, "color": "red"}, '
                                     '{"mesh": {"points": [[0,0,0],[2,0,0],[0,2,0],[0,0,2]], '
                                     '"faces": [[0,2,1],[0,1,3],[0,3,2],[1,2,3]]}}]}}')
    scene = clcsg.load(tmp_path / "s.json")
    clcsg.save(scene, tmp_path / "t.json")
    again = clcsg.load(tmp_path / "t.json")
    pts = np.random.default_rng(3).uniform(-1.5, 1.5, (3000, 3))
    expect = np.all(np.abs(pts) <= 1, axis=1) & ~(np.all(pts >= 0, axis=1) & (pts.sum(axis=1) <= 2))
    assert np.array_equal(clcsg.contains(scene.shape, pts), expect)
    assert np.array_equal(clcsg.contains(again.shape, pts), expect)


# -- bad input: one line, naming the file and the first bad edge ------------------------------------
def _cli_error(path):
    import subprocess
    import sys

    p = subprocess.run([sys.executable, "-m", "clcsg", "info", str(path)], capture_output=True, text=True, timeout=120)
    lines = [ln for ln in p.stderr.splitlines() if ln.startswith("clcsg: error:")]
    assert p.returncode == 3 and len(lines) == 1 and "Traceback" not in p.stderr, p.stderr
    return lines[0]


def _scene_with(tmp_path, node):
    import json

    (tmp_path / "s.json").write_text(json.dumps({"clcsg": 1, "root": node}))
    return tmp_path / "s.json"


def test_bad_meshes_are_one_line_errors(tmp_path):
    import trimesh

    v, f = box_mesh((0, 0, 0), (1, 1, 1))
    trimesh.Trimesh(v, f[:-1], process=False).export(str(tmp_path / "open.stl"))
    (tmp_path / "odd.xyz").write_text("1 2 3\n")
    (tmp_path / "empty.off").write_text("OFF\n0 0 0\n")
    trimesh.PointCloud(v).export(str(tmp_path / "cloud.ply"))
    flipped = f.copy()
    flipped[0] = flipped[0][::-1]
    nan = v.copy()
    nan[3, 1] = np.nan
    cases = {
        "missing": ({"mesh": {"file": "nope.stl"}}, f"{tmp_path / 'nope.stl'}: no such file"),
        "format": ({"mesh": {"file": "odd.xyz"}}, "unknown mesh format '.xyz'; known: .3mf, .obj, .off, .ply, .stl"),
        "open": ({"mesh": {"file": "open.stl"}}, "has no opposite face: the mesh is open"),
        "zero faces": ({"mesh": {"file": "empty.off"}}, "the file has no faces"),
        "points only": ({"mesh": {"file": "cloud.ply"}}, "the point cloud has no normals (vertex properties nx, ny, nz): a point operand needs outward normals"),
        "orientation": ({"mesh": {"points": v.tolist(), "faces": flipped.tolist()}},
                        "edge 0-3 (0, 0, 0 to 1, 1, 0) is used twice in the same direction (faces 0 and 1): the faces are not consistently oriented"),
    }
    for name, (node, expected) in cases.items():
        line = _cli_error(_scene_with(tmp_path, node))
        assert str(tmp_path / "s.json") in line and expected in line, (name, line)
    with pytest.raises(SceneError) as info:
        clcsg.polyhedron(nan, f, source="part")
    assert str(info.value) == "part: mesh point 3 is not finite: [1.0, nan, 0.0]"
    with pytest.raises(clcsg.ClcsgError, match=r"^part: the mesh has 6 distinct face planes; at most 5 are sampled") as info:
        clcsg.polyhedron(v, f, source="part", max_planes=5)
    assert info.value.exit_code == 5
    with pytest.raises(SceneError, match="at least 4 faces, got 0"):
        clcsg.polyhedron(v, [])


# -- the front ends take them unchanged ---------------------------------------------------------
def test_cli_render_sample_and_viewer_files(tmp_path, cl_context):
    import subprocess
    import sys

    from clcsg.viewer.session import Session

    write_box(tmp_path / "block.stl")
    scene = _scene_with(tmp_path, {"difference": [{"mesh": {"file": "block.stl"}},
                                                  {"cylinder": {"height": 3, "radius": 0.5}}]})
    for args in (["sample", str(scene), "-r", "2%", "-o", str(tmp_path / "s.ply")],
                 ["render", str(scene), "--size", "64x48", "-o", str(tmp_path / "s.png")],
                 ["render", str(scene), "--method", "raytrace", "--size", "64x48", "-o", str(tmp_path / "e.png")]):
        p = subprocess.run([sys.executable, "-m", "clcsg", *args], capture_output=True, text=True, timeout=300)
        assert p.returncode == 0, p.stderr
    assert (tmp_path / "s.ply").stat().st_size > 1000
    session = Session(scene, cl_context)
    session.read()
    assert session.files == [str(scene), str(tmp_path / "block.stl")]  # the viewer reloads on either


def _two_shells(outer, inner, inner_flipped):
    (v1, f1), (v2, f2) = box_mesh(*outer), box_mesh(*inner)
    f2 = f2[:, ::-1] if inner_flipped else f2
    return np.r_[v1, v2], np.r_[f1, f2 + 8]


def test_self_intersecting_and_nested_meshes_are_refused():
    v, f = _two_shells(((0, 0, 0), (2, 2, 2)), ((1, 1, 1), (3, 3, 3)), False)
    with pytest.raises(SceneError) as info:
        clcsg.polyhedron(v, f, source="two.stl")
    assert str(info.value).startswith("two.stl: faces ") and str(info.value).endswith(
        "cross each other: the mesh intersects itself")
    v, f = _two_shells(((0, 0, 0), (4, 4, 4)), ((1, 1, 1), (2, 2, 2)), False)
    with pytest.raises(SceneError, match="two.stl: the shell of face 12 encloses no volume, or is nested in a shell"):
        clcsg.polyhedron(v, f, source="two.stl")
    v, f = _two_shells(((0, 0, 0), (1, 1, 1)), ((1, 1, 1), (2, 2, 2)), False)
    f[f == 8] = 7  # the second box's corner (1, 1, 1) is the first one's: they touch at a point
    with pytest.raises(SceneError, match=r"touch.stl: point 7 \(1, 1, 1\) joins 12 faces in more than one fan"):
        clcsg.polyhedron(v, f, source="touch.stl")
    v, f = box_mesh((0, 0, 0), (1, 1, 1))  # and a triangle with its reverse, apart: a fin of no volume
    v = np.r_[v, [[3, 0, 0], [4, 0, 0], [3, 1, 0]]]
    f = np.r_[f, [[8, 9, 10], [8, 10, 9]]]
    with pytest.raises(SceneError, match="fin.off: the shell of face 12 encloses no volume"):
        clcsg.polyhedron(v, f, source="fin.off")


def test_a_cavity_is_an_inward_shell(cl_context):
    v, f = _two_shells(((-2, -2, -2), (2, 2, 2)), ((-1, -1, -1), (1, 1, 1)), True)
    shape = clcsg.polyhedron(v, f)
    pts = np.random.default_rng(4).uniform(-2.5, 2.5, (4000, 3))
    expect = np.all(np.abs(pts) <= 2, axis=1) & ~np.all(np.abs(pts) <= 1, axis=1)
    assert np.array_equal(clcsg.contains(shape, pts), expect)
    ref = clcsg.box(4) - clcsg.box(2)
    cut = clcsg.box((4, 4, 4), center=(2, 2, 2))  # opens the cavity to the camera
    check_against(shape - cut, ref - cut, cl_context)


@pytest.mark.parametrize("seed", range(4))
def test_random_unions_of_boxes_equal_the_winding_number(seed):
    """Non-convex meshes with many face planes in general position (unions and differences of
    rotated boxes by manifold3d): the BSP expression contains exactly the points the winding
    number puts inside."""
    v, f = _random_mesh(seed)
    rng = np.random.default_rng(100 + seed)
    shape = clcsg.polyhedron(v, f)
    pts = rng.uniform(v.min(axis=0) - 0.1, v.max(axis=0) + 0.1, (1500, 3))
    w = winding_number(v, f, pts)
    sharp = np.abs(w - np.round(w)) < 1e-3
    assert sharp.mean() > 0.99
    assert np.array_equal(clcsg.contains(shape, pts[sharp]), w[sharp] > 0.5)


def test_plate_with_bosses_equals_the_union_of_boxes(cl_context):
    """A manifold3d mesh (a plate and 4 bosses): many triangles on few planes, concave edges."""
    import manifold3d as mf

    m = mf.Manifold.cube([4.0, 4.0, 1.0])
    for i in range(2):
        for j in range(2):
            m = m + mf.Manifold.cube([1.0, 1.0, 1.0]).translate([2.0 * i + 0.5, 2.0 * j + 0.5, 0.5])
    mesh = m.to_mesh()
    v, f = np.asarray(mesh.vert_properties, dtype=np.float64)[:, :3], np.asarray(mesh.tri_verts, dtype=np.int64)
    ref = clcsg.union(clcsg.box((4.0, 4.0, 1.0), center=(2, 2, 0.5)),
                      *[clcsg.box(1.0, center=(2.0 * i + 1.0, 2.0 * j + 1.0, 1.0)) for i in range(2) for j in range(2)])
    cut = clcsg.cylinder(4, 0.4, center=(1, 1, 0))
    check_against(clcsg.polyhedron(v, f) - cut, ref - cut, cl_context)


def _random_mesh(seed):
    import manifold3d as mf

    rng = np.random.default_rng(seed)
    m = mf.Manifold.cube([2.0, 2.0, 2.0], center=True)
    for k in range(6):
        part = mf.Manifold.cube(rng.uniform(0.4, 1.5, 3).tolist(), center=True)
        part = part.rotate(rng.uniform(0, 90, 3).tolist()).translate(rng.uniform(-1.2, 1.2, 3).tolist())
        m = m + part if k % 2 == 0 else m - part
    mesh = m.to_mesh()
    return np.asarray(mesh.vert_properties, dtype=np.float64)[:, :3], np.asarray(mesh.tri_verts, dtype=np.int64)


def test_a_float32_mesh_in_general_position_samples_and_renders_exactly(cl_context):
    """Rotated boxes cut from and added to a cube by manifold3d (float32 points): the samples
    lie on the mesh solid's surface by the float64 tree oracle, cover it, and the splats equal
    the exact ray tracer's image."""
    v, f = _random_mesh(2)
    shape = clcsg.polyhedron(v, f) - clcsg.cylinder(4, 0.3)
    check_against(shape, shape, cl_context)


def test_a_rotated_l_prism_subtracted_from_a_sphere(cl_context):
    """The mesh as the subtracted operand (its expression complemented to the leaves) and under
    a rotation: against the same boxes subtracted."""
    v, f = l_prism()
    ref = clcsg.box((2, 1, 1), center=(1, 0.5, 0.5)) | clcsg.box((1, 2, 1), center=(0.5, 1, 0.5))
    ball = clcsg.sphere(1.2, (0.8, 0.8, 0.6))
    check_against(ball - clcsg.polyhedron(v, f).rotate((1, 1, 0), 25), ball - ref.rotate((1, 1, 0), 25), cl_context)


def faceted_sphere(levels=3):
    """An octahedron subdivided ``levels`` times onto the unit sphere: 8 * 4^levels outward
    triangles, each on its own plane."""
    v = [np.array(p, float) for p in ((1, 0, 0), (-1, 0, 0), (0, 1, 0), (0, -1, 0), (0, 0, 1), (0, 0, -1))]
    faces = [(0, 2, 4), (2, 1, 4), (1, 3, 4), (3, 0, 4), (2, 0, 5), (1, 2, 5), (3, 1, 5), (0, 3, 5)]
    for _ in range(levels):
        mid, out = {}, []

        def m(a, b):
            key = (min(a, b), max(a, b))
            if key not in mid:
                p = v[a] + v[b]
                v.append(p / np.linalg.norm(p))
                mid[key] = len(v) - 1
            return mid[key]

        for a, b, c in faces:
            ab, bc, ca = m(a, b), m(b, c), m(c, a)
            out += [(a, ab, ca), (ab, b, bc), (ca, bc, c), (ab, bc, ca)]
        faces = out
    return np.array(v), np.array(faces)


def test_a_mesh_face_plane_is_sampled_only_over_its_triangles(cl_context):
    """A faceted sphere of 512 face planes minus a cylinder: each face plane's sampling tasks
    start from the box of its own triangles (a FacePlane's face_box), not from the mesh's box,
    and the samples still lie on the solid's surface and cover it."""
    from clcsg.model.polyhedron import FacePlane
    from clcsg.sampling.sampler import quadric_boxes

    v, f = faceted_sphere(3)
    shape = clcsg.polyhedron(v, f) - clcsg.cylinder(3, 0.3)
    tape = clcsg.Scene(shape).compile()
    boxes = quadric_boxes(tape)
    owners = tape.owners()
    checked = 0
    for q, (lo, hi) in boxes.items():
        nodes = [tape.instances[i].node for i in owners[q]]
        if not all(isinstance(n, FacePlane) for n in nodes):
            continue
        flo = np.min([n.face_box[0] for n in nodes], axis=0)
        fhi = np.max([n.face_box[1] for n in nodes], axis=0)
        assert np.all(lo >= flo - 1e-6) and np.all(hi <= fhi + 1e-6), (q, lo, hi, flo, fhi)
        assert np.max(hi - lo) < 0.5  # a face's box, far below the mesh's (2 x 2 x 2)
        checked += 1
    assert checked >= 400
    check_against(shape, shape, cl_context)
