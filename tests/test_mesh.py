"""``clcsg.mesh`` / ``clcsg mesh``: closed 2-manifold meshes with every vertex on the exact
surface, within the tolerance of the surface both ways, checked against the float64 tree oracle
(``tests/tree_oracle.py``), manifold3d and trimesh."""

from __future__ import annotations

import math
import os
import resource
import subprocess
import sys

import manifold3d
import numpy as np
import pytest
import trimesh
from scipy.spatial import cKDTree

import clcsg
import tree_oracle as oracle
from clcsg.cli.app import main
from clcsg.errors import SceneError, UsageError
from clcsg.meshing.planar import flat_quadrics
from clcsg.meshing.writers import stl_bytes, write
from clcsg.model.random_programs import random_program

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
EXAMPLES = ["examples/zoo/lens.json", "examples/zoo/steinmetz.json", "examples/zoo/drilled_die.json",
            "examples/zoo/bracket.json", "examples/rounded_cube.json", "examples/spheres.json",
            "examples/pawn.csg", "examples/cooling_tower.json"]


#: the other examples that the facets method meshes: the hull of rounded_box.csg meets itself
#: tangentially everywhere (spheres on cylinders on planes); the zoo gear's hub polygon left a
#: vertex inside its top face
MORE_EXAMPLES = ["examples/bracket.json", "examples/drilled_block.json", "examples/flange.csg",
                 "examples/l_bracket.csg", "examples/menger3.csg", "examples/pipe_flange.csg",
                 "examples/plate_12_holes.csg", "examples/project_box.csg", "examples/rook.csg",
                 "examples/rounded_box.csg", "examples/zoo/flange.json", "examples/zoo/gear.json"]


#: the examples that the contour method meshes (a paraboloid, hyperboloids, cones through
#: their apex): slower, 3-12 s each
CONTOUR_EXAMPLES = ["examples/knob.csg", "examples/pen_stand.csg", "examples/rounded_plate.csg",
                    "examples/saddle.json"]


def _scene(path):
    return clcsg.load(os.path.join(ROOT, path))


_CACHE: dict = {}


def _mesh(path, tolerance="0.1%", method="auto"):
    key = (path, tolerance, method)
    if key not in _CACHE:
        sc = _scene(path)
        _CACHE[key] = (sc, clcsg.mesh(sc, tolerance=tolerance, method=method))
    return _CACHE[key]


def check_closed_manifold(m):
    """manifold3d accepts the mesh as a closed 2-manifold; trimesh: watertight, consistently
    wound, positive volume (outward orientation)."""
    mm = manifold3d.Mesh(vert_properties=np.asarray(m.vertices, dtype=np.float32),
                         tri_verts=np.asarray(m.triangles, dtype=np.uint32))
    solid = manifold3d.Manifold(mm)
    assert solid.status() == manifold3d.Error.NoError
    tm = trimesh.Trimesh(m.vertices, m.triangles, process=False)
    assert tm.is_watertight and tm.is_winding_consistent
    assert tm.volume > 0
    edges = np.sort(m.triangles[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2), axis=1)
    _, count = np.unique(edges, axis=0, return_counts=True)
    assert np.all(count == 2)  # every edge in exactly two triangles


def check_vertices_on_surface(scene, m):
    """Every vertex on its quadric to rounding and on the CSG surface (oracle substitution,
    ambiguity only at the rounding level)."""
    tape = scene.compile()
    scale = max(1.0, float(np.abs(tape.bound).max()))
    q = tape.quadrics[m.vertex_quadrics[:, 0]]
    on_q, on_csg = oracle.sample_residuals(scene.shape, m.vertices, q, tol=1e-9 * scale)
    on_q = np.where(_at_apex(q, m.vertices, 1e-10 * scale), 0.0, on_q)
    assert on_q.max() <= 1e-10 * scale
    # at a corner, or where surfaces touch tangentially (a hull's sphere on its cylinder), the
    # oracle's rounding allowance (forcing all ambiguous literals one way) may not decide:
    # there, some of 512 nearby points are inside the solid and some outside
    undecided = ~on_csg
    on_csg[undecided] = _straddles(scene.shape, m.vertices[undecided], 1e-6 * scale)
    assert on_csg.all(), f"{(~on_csg).sum()} of {len(on_csg)} vertices off the CSG surface"
    for k in (1, 2):  # the vertices on curves and corners lie on every one of their quadrics
        sel = m.vertex_quadrics[:, k] >= 0
        if sel.any():
            on_q, _ = oracle.sample_residuals(scene.shape, m.vertices[sel], tape.quadrics[m.vertex_quadrics[sel, k]])
            assert on_q.max() <= 1e-9 * scale


def _at_apex(q, x, eps):
    """Per point whether it is within ``eps`` of its quadric's singular point (a cone's apex:
    the gradient vanishes there, and the first-order distance is 0 / 0)."""
    out = np.zeros(len(x), dtype=bool)
    a, b = q[:, :3, :3], q[:, :3, 3]
    ok = np.abs(np.linalg.det(a)) > 1e-12 * np.abs(a).max(axis=(1, 2)) ** 3
    if ok.any():
        c = np.linalg.solve(a[ok], -b[ok][..., None])[..., 0]
        apex = np.abs(np.einsum("ni,nij,nj->n", np.c_[c, np.ones(len(c))], q[ok], np.c_[c, np.ones(len(c))]))
        out[ok] = (np.linalg.norm(x[ok] - c, axis=1) <= eps) & (apex <= 1e-12 * np.abs(q[ok]).max(axis=(1, 2)))
    return out


def _straddles(shape, x, eps):
    if not len(x):
        return np.zeros(0, dtype=bool)
    # random: none on an axis-aligned face; many: a corner at the tip of a thin spike of the
    # solid (a few per cent of the directions inside) still straddles
    dirs = np.random.default_rng(1).normal(size=(512, 3))
    dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
    ins = oracle.contains(shape, (x[:, None] + eps * dirs[None]).reshape(-1, 3)).reshape(len(x), -1)
    return ins.any(axis=1) & ~ins.all(axis=1)


def point_mesh_distance(points, vertices, triangles):
    """Exact distance from each point to the triangle mesh (candidate triangles by a k-d tree
    on their centroids, then the closest point on each candidate)."""
    tri = vertices[triangles]
    cen = tri.mean(axis=1)
    reach = np.linalg.norm(tri - cen[:, None], axis=2).max()
    tree = cKDTree(cen)
    out = np.full(len(points), np.inf)
    for i, cand in enumerate(tree.query_ball_point(points, reach * 1.01 + 1e-12)):
        if cand:
            d = trimesh.triangles.closest_point(tri[cand], np.repeat(points[i:i + 1], len(cand), 0))
            out[i] = np.linalg.norm(d - points[i], axis=1).min()
    return out


@pytest.mark.parametrize("path", EXAMPLES + MORE_EXAMPLES + CONTOUR_EXAMPLES)
def test_examples_closed_manifold_and_on_surface(path):
    sc, m = _mesh(path)
    check_closed_manifold(m)
    check_vertices_on_surface(sc, m)
    assert len(m.quadric) == len(m.primitive) == len(m.colors) == len(m.triangles)
    assert (m.primitive >= 0).mean() > 0.99


def _quadric_distance(matrices, x):
    """Distance from x to where the quadric's gradient line through x meets it: the root of
    K(x + t n) = K(x) + t |g| + t^2 n^T A n nearest to 0, solved by numpy's polynomial roots
    (an upper bound of the distance, the distance itself on spheres, cylinders and planes; the
    first-order |K| / |g| where the line misses)."""
    xh = np.concatenate([x, np.ones((len(x), 1))], axis=1)
    kx = np.einsum("nij,nj->ni", matrices, xh)
    f = np.einsum("ni,ni->n", kx, xh)
    g = 2.0 * kx[:, :3]
    gn = np.linalg.norm(g, axis=1)
    n = g / gn[:, None]
    bend = np.einsum("ni,nij,nj->n", n, matrices[:, :3, :3], n)
    out = np.abs(f) / gn
    for k in range(len(x)):
        r = np.roots([bend[k], gn[k], f[k]]) if abs(bend[k]) > 0 else np.array([-f[k] / gn[k]])
        r = r[np.isreal(r)].real
        if len(r):
            out[k] = np.abs(r).min()
    return out


@pytest.mark.parametrize("path", EXAMPLES[:5])
def test_mesh_within_tolerance_of_surface(path):
    """Points on the triangles (centroids and edge midpoints) are within the tolerance of the
    quadric the triangle lies on (along its gradient line), for every triangle that lies on one
    quadric (those across a sharp edge are counted in the stats and excluded)."""
    sc, m = _mesh(path)
    assert check_within_tolerance(sc.compile(), m) > 0.98


def check_within_tolerance(tape, m) -> float:
    """Centroids and edge midpoints of the triangles on one quadric within the tolerance of it;
    returns the fraction of triangles on one quadric."""
    s = m.vertex_quadrics[m.triangles]
    on_one = np.array([bool(set(a[a >= 0]) & set(b[b >= 0]) & set(c[c >= 0])) for a, b, c in s])
    v = m.vertices[m.triangles[on_one]]
    pts = np.concatenate([v.mean(axis=1), 0.5 * (v[:, 0] + v[:, 1]), 0.5 * (v[:, 1] + v[:, 2])])
    q = np.tile(tape.quadrics[m.quadric[on_one]], (3, 1, 1))
    assert _quadric_distance(q, pts).max() <= m.tolerance * 1.0 + 1e-12
    return float(on_one.mean())


@pytest.mark.parametrize("path", ["examples/zoo/lens.json", "examples/zoo/drilled_die.json"])
def test_contour_method_on_examples(path):
    """The contour method (the default only for other quadrics) on two zoo models: closed,
    vertices on the surface, triangles within the tolerance of their quadric, the surface
    within the tolerance of the mesh."""
    sc, m = _mesh(path, method="contour")
    assert m.stats["method"] == "contour"
    check_closed_manifold(m)
    check_vertices_on_surface(sc, m)
    assert check_within_tolerance(sc.compile(), m) > 0.98
    sp = oracle.surface_points(sc.shape, sc.compile().bound, n_lines=400, seed=3)
    d = point_mesh_distance(sp.points, m.vertices, m.triangles)
    assert np.quantile(d, 0.99) <= m.tolerance


@pytest.mark.parametrize("path", EXAMPLES[:4])
def test_surface_within_tolerance_of_mesh(path):
    """Exact surface points (roots on random lines, the oracle) lie within the tolerance of the
    mesh, apart from a small fraction at sharp edges the mesh has not split."""
    sc, m = _mesh(path)
    sp = oracle.surface_points(sc.shape, sc.compile().bound, n_lines=400, seed=3)
    assert len(sp) > 100
    d = point_mesh_distance(sp.points, m.vertices, m.triangles)
    assert np.quantile(d, 0.99) <= m.tolerance
    assert d.max() <= 3 * m.tolerance


def _points_on(m, n, seed):
    """``n`` area-weighted random points on the triangles of ``m``."""
    rng = np.random.default_rng(seed)
    a, b, c = (m.vertices[m.triangles[:, k]] for k in range(3))
    area = 0.5 * np.linalg.norm(np.cross(b - a, c - a), axis=1)
    tri = np.minimum(np.searchsorted(np.cumsum(area), rng.random(n) * area.sum()), len(area) - 1)
    u, v = rng.random(n), rng.random(n)
    flip = u + v > 1
    u[flip], v[flip] = 1 - u[flip], 1 - v[flip]
    return a[tri] + u[:, None] * (b[tri] - a[tri]) + v[:, None] * (c[tri] - a[tri])


def check_near_csg_surface(shape, m, n=3000, seed=0):
    """Points on the triangles lie within the tolerance of the CSG surface itself, not merely
    of some quadric (a triangle on a quadric's extension, across a gap the quadric does not
    bound, is near its quadric and far from the solid): around each, the float64 oracle finds
    points inside the solid and outside it at distance ``tolerance`` (64 directions, then
    20,000 round the points those miss: a point 0.99 tolerances from a face sees it only in a
    cap of 8 degrees)."""
    x = _points_on(m, n, seed)
    for count in (64, 20000):
        if not len(x):
            break
        k = np.arange(count) + 0.5
        z = 1.0 - 2.0 * k / count
        phi = k * np.pi * (3.0 - np.sqrt(5.0)) + 0.3
        d = np.stack([np.sqrt(1 - z * z) * np.cos(phi), np.sqrt(1 - z * z) * np.sin(phi), z], axis=1)
        ins = oracle.contains(shape, (x[:, None] + m.tolerance * d[None]).reshape(-1, 3)).reshape(len(x), -1)
        x = x[~(ins.any(axis=1) & ~ins.all(axis=1))]
    assert not len(x), f"{len(x)} of {n} points on the mesh farther than the tolerance from the surface, e.g. {x[:3]}"


def _turret():
    """A tube with six crenels cut through its wall from the top (a chess rook's turret): the
    crenels' corners lie on the outer cylinder on both sides of each gap."""
    tube = clcsg.difference(clcsg.cylinder(height=11.0, radius=10.5),
                            clcsg.cylinder(height=7.5, radius=7.0, center=(0.0, 0.0, 3.25)))
    gaps = [clcsg.box((12.0, 4.2, 6.0), center=(6.0, 0.0, 4.0)).rotate((0, 0, 1), 60.0 * i) for i in range(6)]
    return clcsg.difference(tube, clcsg.union(*gaps))


def _bevelled_hub():
    """A tapered hub whose top is bevelled by a steeper cone that meets the hub's cone below
    the bevel's cap: between them a 0.79-wide annulus on the cap's plane, thinner than the
    grid's cells, and the two cones' own curve lies inside the solid."""
    hub = clcsg.cone(height=56.0, r1=95.0, r2=84.0, center=(0.0, 0.0, 28.0))
    ring = clcsg.difference(clcsg.cylinder(height=5.0, radius=90.0, center=(0.0, 0.0, 54.5)),
                            clcsg.cone(height=5.02, r1=84.0, r2=80.15, center=(0.0, 0.0, 54.5)))
    return clcsg.difference(hub, ring)


@pytest.mark.parametrize("make", [_turret, _bevelled_hub], ids=["turret", "bevelled_hub"])
def test_faces_a_quadric_does_not_bound_are_not_spanned(make):
    """Sharp edges only where both quadrics bound the solid: no triangle crosses a crenel on
    the outer cylinder's extension, and the annulus between two cones gets its own triangles
    (their own curve, inside the solid, is no edge); the mesh stays within the tolerance of
    the CSG surface and no triangle spans a sharp edge."""
    shape = make()
    sc = clcsg.Scene(shape)
    m = clcsg.mesh(sc)
    check_closed_manifold(m)
    check_vertices_on_surface(sc, m)
    assert m.stats["spanning_triangles"] == 0
    check_near_csg_surface(shape, m)


@pytest.mark.parametrize("method", ["auto", "contour"])
@pytest.mark.parametrize("path", ["examples/l_bracket.csg", "examples/zoo/flange.json"])
def test_examples_within_tolerance_of_the_csg_surface(path, method):
    """The countersinks' rims (a cone standing on a cylinder, patch vertices just above the
    rim) and the flange's fillet cone, whose extension below its cap lies inside the disc.
    The contour method spans no sharp edge; the facets method none wider than a quarter of
    the tolerance: l_bracket's fillet lies 0.01 mm (0.13 tolerances) off the upright's face, a
    4-degree crease that a triangle may cross, every vertex within the quarter of its plane."""
    sc, m = _mesh(path, method=method)
    check_near_csg_surface(sc.shape, m)
    if m.stats["method"] == "contour":
        assert m.stats["spanning_triangles"] == 0
    else:
        assert m.stats["spanning_wide_triangles"] == 0 and m.stats["far_triangles"] == 0
        span = ~(m.vertex_quadrics[m.triangles] == m.quadric[:, None, None]).any(axis=2).all(axis=1)
        assert span.sum() == m.stats["spanning_triangles"] <= 0.02 * len(m.triangles)


def test_volume_box_minus_cylinder():
    shape = clcsg.difference(clcsg.box((2.0, 2.0, 1.0)), clcsg.cylinder(radius=0.5, height=3.0))
    sc = clcsg.Scene(shape)
    m = clcsg.mesh(sc, tolerance=0.001)
    check_closed_manifold(m)
    exact = 4.0 - math.pi * 0.25
    area = 2 * 4.0 - 2 * math.pi * 0.25 + 8 * 1.0 + 2 * math.pi * 0.5
    vol = trimesh.Trimesh(m.vertices, m.triangles, process=False).volume
    assert abs(vol - exact) <= area * m.tolerance
    assert vol >= exact - 1e-9  # the hole's chords lie inside the cylinder: less is removed
    # flat faces from their boundary alone: every vertex of a triangle on a plane lies on a
    # sharp edge (two quadrics or more), and the four side faces (rectangles) have at most four
    # triangles each
    flat = flat_quadrics(sc.compile().quadrics)
    on_flat = np.isin(m.quadric, flat)
    assert (m.vertex_quadrics[m.triangles[on_flat]][..., 1] >= 0).all()
    n = np.cross(*(m.vertices[m.triangles][:, k] - m.vertices[m.triangles][:, 0] for k in (1, 2)))
    side = on_flat & (np.abs(n[:, 2]) <= 1e-12 * np.linalg.norm(n, axis=1))
    assert 8 <= side.sum() <= 16


@pytest.mark.parametrize("seed", range(6))
def test_random_programs(seed):
    prog = random_program(np.random.default_rng(seed), max_depth=2)
    sc = clcsg.Scene(prog.shape)
    try:
        m = clcsg.mesh(sc, tolerance="0.2%")
    except SceneError as e:
        assert "empty" in str(e)
        assert not oracle.contains(prog.shape, oracle.lines(sc.compile().bound, 2000, seed)[0]).any()
        return
    check_closed_manifold(m)
    check_vertices_on_surface(sc, m)
    if m.stats["method"] == "facets":
        assert m.stats["spanning_wide_triangles"] == 0 and m.stats["far_triangles"] == 0


@pytest.mark.parametrize("seed", range(6))
def test_random_programs_within_tolerance(seed):
    """The triangles on one quadric within the tolerance of it on random programs (the
    decimation's chord error bound, and the refinement's)."""
    prog = random_program(np.random.default_rng(seed), max_depth=2)
    sc = clcsg.Scene(prog.shape)
    m = clcsg.mesh(sc, tolerance="0.2%")  # none of these programs is empty
    assert check_within_tolerance(sc.compile(), m) > 0.9


def test_counterbore_step_thinner_than_a_cell():
    """A plate with a counterbored hole (two coaxial cylinders of radii 3 and 3.6, the step
    face between them 1.5 below the top): no triangle spans a sharp edge, and exact surface
    points (the oracle's roots on random lines) are all within the tolerance of the mesh."""
    plate = clcsg.box((40.0, 40.0, 10.0))
    through = clcsg.cylinder(height=12.0, radius=3.0)
    bore = clcsg.cylinder(height=3.0, radius=3.6, center=(0.0, 0.0, 5.0))
    sc = clcsg.Scene(clcsg.difference(plate, clcsg.union(through, bore)))
    sp = oracle.surface_points(sc.shape, sc.compile().bound, n_lines=400, seed=3)
    assert len(sp) > 100
    for method in ("contour", "facets"):
        m = clcsg.mesh(sc, method=method)
        check_closed_manifold(m)
        if method == "contour":
            assert m.stats["h"] > 0.6  # the step is thinner than a cell: the case this test is about
        d = point_mesh_distance(sp.points, m.vertices, m.triangles)
        assert m.stats["spanning_triangles"] == 0
        assert d.max() <= m.tolerance


def test_fin_thinner_than_a_cell():
    """A fin 0.5 thick on a plate, with cells 1.25 wide: no grid point need be inside it, so
    marching on the grid alone drops it (the mesh was the plate alone); the edges that cross it
    twice get their tetrahedra bisected until it is seen.  The volume is the exact one, and
    surface points on the fin are within the tolerance of the mesh."""
    base = clcsg.box((40.0, 20.0, 4.0))
    fin = clcsg.box((30.0, 0.5, 6.0), center=(0.0, 0.3, 5.0))
    sc = clcsg.Scene(clcsg.union(base, fin))
    sp = oracle.surface_points(sc.shape, sc.compile().bound, n_lines=400, seed=5)
    on_fin = sp.points[sp.points[:, 2] > 2.0 + 1e-9]
    assert len(on_fin) > 10
    exact = 40 * 20 * 4 + 30 * 0.5 * 6
    for method in ("contour", "facets"):
        m = clcsg.mesh(sc, method=method)
        check_closed_manifold(m)
        if method == "contour":
            assert m.stats["h"] > 2 * 0.5  # the case this test is about
            assert m.stats["bisected_per_round"]
        vol = trimesh.Trimesh(m.vertices, m.triangles, process=False).volume
        assert abs(vol - exact) <= 1e-6 * exact
        assert m.stats["spanning_triangles"] == 0
        assert point_mesh_distance(on_fin, m.vertices, m.triangles).max() <= m.tolerance


# -- bad input -----------------------------------------------------------------------------------

@pytest.mark.parametrize("tol", [0, -1, "0%", "-2%", "nan", "abc"])
def test_bad_tolerance(tol, tmp_path, capsys):
    with pytest.raises(UsageError):
        clcsg.mesh(clcsg.sphere(1.0), tolerance=tol)
    out = tmp_path / "x.stl"
    assert main(["mesh", os.path.join(ROOT, "examples/zoo/lens.json"), "-o", str(out), "-t", str(tol)]) == 2
    assert "tolerance" in capsys.readouterr().err
    assert not out.exists()


def test_empty_solid(tmp_path, capsys):
    """An empty solid is an error (exit code 3, one line) and writes no file."""
    empty = clcsg.intersection(clcsg.sphere(1.0, center=(0, 0, 0)), clcsg.sphere(1.0, center=(5, 0, 0)))
    with pytest.raises(SceneError, match="empty"):
        clcsg.mesh(empty)
    path = tmp_path / "empty.json"
    clcsg.save(empty, path)
    out = tmp_path / "empty.stl"
    assert main(["mesh", str(path), "-o", str(out)]) == 3
    err = capsys.readouterr().err
    assert "empty" in err and len(err.strip().splitlines()) == 1
    assert not out.exists()


def test_formats_checked_before_work(tmp_path, capsys):
    src = os.path.join(ROOT, "examples/zoo/lens.json")
    assert main(["mesh", src, "-o", str(tmp_path / "x.step")]) == 2
    assert "unknown mesh format" in capsys.readouterr().err
    assert main(["mesh", src, "-o", str(tmp_path / "no" / "x.stl")]) == 2
    assert "does not exist" in capsys.readouterr().err
    (tmp_path / "d.stl").mkdir()
    assert main(["mesh", src, "-o", str(tmp_path / "d.stl")]) == 2


def test_failed_write_leaves_nothing(tmp_path):
    """A write that fails half-way (the file size limit) leaves neither a partial file nor a
    temporary one, and an existing file is kept as it was."""
    out = tmp_path / "part.stl"
    out.write_bytes(b"old")

    def limit():
        resource.setrlimit(resource.RLIMIT_FSIZE, (4096, 4096))

    r = subprocess.run([sys.executable, "-m", "clcsg", "mesh", os.path.join(ROOT, "examples/zoo/lens.json"),
                        "-o", str(out)], preexec_fn=limit, capture_output=True, text=True, timeout=300,
                       env={**os.environ, "PYTHONPATH": ROOT})
    assert r.returncode == 2, r.stderr
    assert "cannot write" in r.stderr
    assert out.read_bytes() == b"old"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["part.stl"]


@pytest.mark.parametrize("ext", [".stl", ".3mf", ".obj", ".ply", ".off"])
def test_writers_round_trip(ext, tmp_path):
    _, m = _mesh("examples/zoo/lens.json")
    out = tmp_path / f"lens{ext}"
    write(m, out)
    back = trimesh.load(str(out), process=ext != ".stl", force="mesh")
    if ext == ".stl":
        back.merge_vertices()
    assert len(back.faces) == len(m.triangles)
    assert back.is_watertight
    assert abs(back.volume - trimesh.Trimesh(m.vertices, m.triangles, process=False).volume) < 1e-5
    if ext in (".3mf", ".ply"):
        assert back.visual.face_colors.shape[0] == len(m.triangles)


def test_binary_stl_layout():
    v = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], dtype=float)
    data = stl_bytes(v, np.array([[0, 1, 2]]))
    assert len(data) == 84 + 50
    assert np.frombuffer(data[80:84], "<u4")[0] == 1
    assert np.allclose(np.frombuffer(data[84:96], "<f4"), [0, 0, 1])


@pytest.mark.parametrize("method", ["auto", "contour"])
def test_cli_writes_and_summarises(tmp_path, capsys, method):
    out = tmp_path / "die.3mf"
    assert main(["mesh", os.path.join(ROOT, "examples/zoo/drilled_die.json"), "-o", str(out), "-t", "0.2%",
                 "--method", method]) == 0
    assert "triangles" in capsys.readouterr().out
    back = trimesh.load(str(out), force="mesh")
    assert back.is_watertight


def test_cli_facets_refused_for_a_hyperboloid(tmp_path, capsys):
    """--method facets on a scene with a hyperboloid: one line naming the kind, no file."""
    out = tmp_path / "tower.stl"
    assert main(["mesh", os.path.join(ROOT, "examples/cooling_tower.json"), "-o", str(out), "--method", "facets"]) != 0
    err = capsys.readouterr().err
    assert "hyperboloid_one_sheet" in err and "Traceback" not in err and len(err.strip().splitlines()) == 1
    assert not out.exists()
