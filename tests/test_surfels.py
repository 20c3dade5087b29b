"""Point operands (surfels): the two-nearest-surfel classification against exact solids, CSG
sampling with surfel leaves rendered against the exact ray tracer, readers (PLY, scene file,
OpenSCAD ``import()``), bad input and the CLI."""

from __future__ import annotations

import json

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

import clcsg
from clcsg.cli import app as cli
from clcsg.errors import LimitError, ParameterError, SceneError
from clcsg.compile.interpret import member
from clcsg.model.csg import rotation_matrix
from clcsg.model.quadric import affine
from clcsg.model.surfels import Surfels
from clcsg.readers.openscad import load_csg
from scipy import ndimage  # the test extra includes scipy, as the surfels extra does


# -- clouds sampled from exact solids ----------------------------------------------------------

def box_cloud(h=0.1, half=1.0):
    """Surfels on the faces of the cube [-half, half]^3, on a grid of spacing h (centers at the
    grid cells' centers: no surfel on an edge), exact normals, radius 0.75 h (they overlap)."""
    t = np.arange(-half + h / 2, half, h)
    u, v = [a.ravel() for a in np.meshgrid(t, t)]
    pts, nrm = [], []
    for axis in range(3):
        for s in (-1.0, 1.0):
            p = np.zeros((len(u), 3))
            others = [k for k in range(3) if k != axis]
            p[:, axis], p[:, others[0]], p[:, others[1]] = s * half, u, v
            n = np.zeros_like(p)
            n[:, axis] = s
            pts.append(p)
            nrm.append(n)
    return np.concatenate(pts), np.concatenate(nrm), 0.75 * h


def sphere_cloud(n, radius=1.0):
    """A Fibonacci sampling of the sphere with its exact normals."""
    i = np.arange(n) + 0.5
    phi = np.arccos(1 - 2 * i / n)
    th = np.pi * (1 + 5 ** 0.5) * i
    u = np.stack([np.cos(th) * np.sin(phi), np.sin(th) * np.sin(phi), np.cos(phi)], 1)
    return radius * u, u


def near_edges(rng, n, width):
    """Points within ``width`` of the 12 edges of the unit cube [-1, 1]^3 (both sides)."""
    axis = rng.integers(0, 3, n)
    p = rng.uniform(-1, 1, (n, 3))
    corner = rng.choice([-1.0, 1.0], (n, 3))
    off = rng.uniform(-width, width, (n, 3))
    q = corner + off
    q[np.arange(n), axis] = p[np.arange(n), axis]
    return q


def box_distance(p):
    """Exact distance of points to the surface of the cube [-1, 1]^3."""
    d = np.abs(p) - 1.0
    outside = np.linalg.norm(np.maximum(d, 0), axis=1)
    inside = np.minimum(d.max(axis=1), 0)
    return np.abs(outside + inside)


@pytest.mark.parametrize("concave", [False, True])
def test_classification_near_box_edges(concave):
    """Near the cube's convex edges (and the concave ones of its complement: the same surfels
    with their normals flipped) the two-surfel rule gives the exact membership at every point
    off the surface by more than a tenth of the spacing."""
    p, n, r = box_cloud()
    s = Surfels(p, -n if concave else n, r)
    rng = np.random.default_rng(3)
    x = near_edges(rng, 20000, 0.15)
    x = x[box_distance(x) > 0.01]
    exact = np.all(np.abs(x) <= 1.0, axis=1)
    if concave:
        exact = ~exact
    got = s.contains(x)
    assert np.array_equal(got, exact), f"{(got != exact).sum()} of {len(x)} misclassified"


@settings(max_examples=15, deadline=None)
@given(axis=st.tuples(*[st.floats(-1, 1)] * 3).filter(lambda v: np.linalg.norm(v) > 0.1),
       angle=st.floats(0, 360), shift=st.tuples(*[st.floats(-5, 5)] * 3), scale=st.floats(0.2, 5),
       concave=st.booleans())
def test_classification_under_similarities(axis, angle, shift, scale, concave):
    """The cube's cloud moved by a random similarity (Surfels.transformed) classifies points
    near its edges like the moved exact cube (float64 oracle in the cube's own frame)."""
    p, n, r = box_cloud()
    m = affine(scale * rotation_matrix(axis, angle), np.asarray(shift))
    s = Surfels(p, -n if concave else n, r).transformed(m)
    x = near_edges(np.random.default_rng(1), 5000, 0.15)
    x = x[box_distance(x) > 0.01]
    exact = np.all(np.abs(x) <= 1.0, axis=1) != concave
    world = x @ m[:3, :3].T + m[:3, 3]
    assert np.array_equal(s.contains(world), exact)
    assert np.allclose(s.radii, r * scale)


@pytest.mark.parametrize("build", ["rim", "crease"])
def test_classification_of_sampled_quadric_models(build):
    """Surfels from the exact sampler's output of a quadric model classify points within two
    radii of the cloud and off the surface by more than a sixth of a radius like the exact
    solid: all of them at the concave crease of two overlapping spheres; at the convex rim of
    a sphere minus a cylinder all but a few in the bore's mouth next to the rim, where the
    two nearest surfels are both on the sphere (the limitation the paper shows in its
    figure 6)."""
    r = 0.03
    if build == "rim":
        shape = clcsg.sphere(1.0) - clcsg.cylinder(3, 0.4)
    else:
        shape = clcsg.sphere(1.0, center=(-0.5, 0, 0)) | clcsg.sphere(1.0, center=(0.5, 0, 0))
    smp = clcsg.sample(shape, r)
    s = clcsg.surfels(smp.positions, smp.normals, smp.radii)
    x = np.random.default_rng(11).uniform(-1.6, 1.6, (200000, 3))
    dn, _ = s.nearest(x, 1)
    x = x[(dn[:, 0] < 2 * r) & (np.abs(clcsg.distance(shape, x)) > r / 6)]
    assert len(x) > 5000
    exact = clcsg.contains(shape, x)
    bad = s.contains(x) != exact
    if build == "crease":
        assert not bad.any(), f"{bad.sum()} of {len(x)} misclassified"
        return
    xb = x[bad]
    rim = np.hypot(np.hypot(xb[:, 0], xb[:, 1]) - 0.4, np.abs(xb[:, 2]) - np.sqrt(1 - 0.4 ** 2))
    assert bad.sum() <= 1e-3 * len(x) and np.all(rim < 2 * r) and not exact[bad].any()


# -- sampling and rendering --------------------------------------------------------------------

SURFEL_R = 0.03


def depth_edges(ref, jump=0.05, pixels=2):
    """Pixels within ``pixels`` of the reference's silhouette or of a depth jump above ``jump``."""
    b = ref.ids >= 0
    d = np.where(b, ref.depth, 0.0)
    edge = b ^ ndimage.binary_erosion(b)
    g0 = np.abs(np.diff(d, axis=0)) > jump
    g1 = np.abs(np.diff(d, axis=1)) > jump
    edge[1:] |= g0
    edge[:-1] |= g0
    edge[:, 1:] |= g1
    edge[:, :-1] |= g1
    return ndimage.binary_dilation(edge, iterations=pixels)


@pytest.fixture(scope="module")
def bored_sphere():
    p, n = sphere_cloud(20000)
    cyl = clcsg.cylinder(3, 0.4)
    smp = clcsg.sample(clcsg.surfels(p, n, SURFEL_R) - cyl, SURFEL_R)
    return smp, cyl


def test_surfel_difference_renders_like_the_exact_solid(bored_sphere):
    """Sphere cloud minus a cylinder: the splat mask equals the exact ray tracer's of the
    quadric sphere minus the cylinder except within 2 pixels of the silhouette, the depth is
    within the surfel radius away from depth edges, and every visible point of a surfel
    splat lies outside the cylinder (no splat crosses the bore's rim)."""
    smp, cyl = bored_sphere
    assert smp.stats["point_operands"] == 1 and smp.stats["runs"] == 2
    cam = clcsg.Camera.look_at((2.2, -2.6, 1.9), (0, 0, 0), width=240, height=180)
    img = clcsg.render(smp, cam)
    ref = clcsg.raytrace(clcsg.sphere(1.0) - cyl, cam)
    a, b = img.ids >= 0, ref.ids >= 0
    band = ndimage.binary_dilation(b ^ ndimage.binary_erosion(b), iterations=2)
    assert b.sum() > 10000
    assert ((a ^ b) & ~band).sum() == 0
    assert (a ^ b).sum() < 0.01 * b.sum()
    inner = a & b & ~depth_edges(ref)
    assert inner.sum() > 0.7 * b.sum()
    assert np.abs(img.depth[inner] - ref.depth[inner]).max() <= SURFEL_R
    o, d = cam.rays()
    on_surfel = a & (img.ids >= smp.tape.first_surfel_quadric)
    assert on_surfel.sum() > 5000
    pts = o[on_surfel] + d[on_surfel] * img.depth[on_surfel][:, None].astype(np.float64)
    radial = np.hypot(pts[:, 0], pts[:, 1])
    assert radial.min() >= 0.4 - 1e-4, radial.min()
    # the cylinder's samples kept are those inside the sphere (its bore wall)
    wall = smp.quadrics < smp.tape.first_surfel_quadric
    assert wall.sum() > 0
    assert np.linalg.norm(smp.positions[wall], axis=1).max() <= 1.0 + SURFEL_R


@pytest.mark.parametrize("op", ["union", "intersection", "box minus cloud"])
def test_cloud_and_box_render_like_the_exact_solid(op):
    """Sphere cloud with a box: union (concave edges), intersection (convex), the box minus the
    cloud (a concave spherical cavity seen through the cut face): the mask equals the exact ray
    tracer's off a 2-pixel band along the silhouette, depth within the surfel radius off the
    depth edges, and surfel splats are visible."""
    p, n = sphere_cloud(20000)
    cube = clcsg.box(1.2, center=(0.7, 0.5, 0.4))
    build = {"union": lambda a: a | cube, "intersection": lambda a: a & cube, "box minus cloud": lambda a: cube - a}[op]
    smp = clcsg.sample(build(clcsg.surfels(p, n, SURFEL_R)), SURFEL_R)
    eye, target = ((0.7, -3.0, 0.4), (0.7, 0.5, 0.4)) if op == "box minus cloud" else ((2.6, -2.4, 1.9), (0.2, 0, 0))
    cam = clcsg.Camera.look_at(eye, target, width=240, height=180)
    img = clcsg.render(smp, cam)
    ref = clcsg.raytrace(build(clcsg.sphere(1.0)), cam)
    a, b = img.ids >= 0, ref.ids >= 0
    band = ndimage.binary_dilation(b ^ ndimage.binary_erosion(b), iterations=2)
    assert b.sum() > 3000 and ((a ^ b) & ~band).sum() == 0
    inner = a & b & ~depth_edges(ref)
    assert inner.sum() > 0.6 * b.sum()
    assert np.abs(img.depth[inner] - ref.depth[inner]).max() <= SURFEL_R
    assert (inner & (img.ids >= smp.tape.first_surfel_quadric)).sum() > 1000


def _kept_by_program(smp, i, x) -> bool:
    """Does sample i's clip program keep the point ``x`` of its splat (float64 interpreter)?"""
    if smp.clip_count[i] == 0:
        return True
    rows = smp.clip_ops[smp.clip_first[i]: smp.clip_first[i] + smp.clip_count[i]]
    lo, hi = member(rows, smp.tape.quadrics, x.reshape(1, 3), int(smp.quadrics[i]))
    return bool(lo[0] != hi[0])


def test_no_gap_along_the_rim(bored_sphere):
    """Points of the exact surface next to the bore's rim, on the wall just inside the sphere
    and on the sphere just outside the wall, are covered by a kept splat of their own surface
    whose clip program keeps them (the cut falls on the rim, not a radius short of it)."""
    smp, _ = bored_sphere
    rng = np.random.default_rng(5)
    first = smp.tape.first_surfel_quadric
    wall = np.flatnonzero((smp.quadrics < first) & (np.abs(np.hypot(smp.positions[:, 0], smp.positions[:, 1]) - 0.4) < 1e-6))
    mine = np.flatnonzero(smp.quadrics >= first)
    zr = np.sqrt(1 - 0.4 ** 2)
    for _ in range(150):
        th = rng.uniform(0, 2 * np.pi)
        z = rng.choice([-1, 1]) * rng.uniform(zr - 0.05, zr - 1e-3)
        x = np.array([0.4 * np.cos(th), 0.4 * np.sin(th), z])
        near = wall[np.linalg.norm(smp.positions[wall] - x, axis=1) <= smp.radii[wall]]
        assert any(_kept_by_program(smp, i, x) for i in near), x
        rho = rng.uniform(0.4 + 1e-3, 0.45)
        y = np.array([rho * np.cos(th), rho * np.sin(th), np.sign(z) * np.sqrt(1 - rho ** 2)])
        ok = False
        for i in mine[np.linalg.norm(smp.positions[mine] - y, axis=1) <= 2 * SURFEL_R]:
            c, nn = smp.positions[i], smp.normals[i]
            yp = y - np.dot(y - c, nn) * nn  # y seen on the splat's plane
            if np.linalg.norm(yp - c) <= smp.radii[i] and _kept_by_program(smp, i, yp):
                ok = True
                break
        assert ok, y


def test_surfels_kept_by_the_tree(bored_sphere):
    """A surfel is kept iff it lies outside the cylinder (switching the operand switches the
    solid there), or its center is inside but its disk reaches out (its clip program cuts it
    at the wall); its outward normal is the surfel's."""
    smp, _ = bored_sphere
    mine = smp.quadrics >= smp.tape.first_surfel_quadric
    p, n = sphere_cloud(20000)
    rho = np.hypot(p[:, 0], p[:, 1])
    kept = smp.positions[mine]
    kept_rho = np.hypot(kept[:, 0], kept[:, 1])
    assert (kept_rho > 0.4).sum() == (rho > 0.4).sum()
    assert kept_rho.min() > 0.4 - SURFEL_R
    assert (mine & (smp.clip_count > 0)).sum() >= (kept_rho <= 0.4).sum() > 0
    assert np.allclose(smp.normals[mine], smp.positions[mine], atol=1e-9)


def test_transformed_cloud_in_a_tree():
    """A cloud under transforms (scaled by 2, moved) intersected with a box: the surfels kept
    are the moved ones inside the box, with outward normals; the box's samples kept are those
    inside the moved sphere, and every kept box sample lies on the box."""
    p, n = sphere_cloud(4000)
    cloud = clcsg.surfels(p, n, 0.06).scale(2.0).translate((1.0, 0.0, 0.0))
    cube = clcsg.box(2.4, center=(1.0, 0.0, 0.0))
    smp = clcsg.sample(cloud & cube, 0.06)
    world = 2.0 * p + [1.0, 0.0, 0.0]
    inside = np.all(np.abs(world - [1.0, 0, 0]) <= 1.2, axis=1)
    mine = smp.quadrics >= smp.tape.first_surfel_quadric
    got = smp.positions[mine]
    in_box = np.all(np.abs(got - [1.0, 0, 0]) <= 1.2, axis=1)
    assert np.allclose(np.sort(got[in_box], axis=0), np.sort(world[inside], axis=0))
    outside = np.linalg.norm(np.maximum(np.abs(got[~in_box] - [1.0, 0, 0]) - 1.2, 0), axis=1)
    assert np.all(outside < 2.0 * 0.06)  # disks that reach into the box (radius scaled by 2)
    assert np.allclose(smp.normals[mine], (got - [1.0, 0, 0]) / 2.0, atol=1e-9)
    faces = smp.positions[~mine]
    assert len(faces) > 0
    assert np.all(np.linalg.norm(faces - [1.0, 0, 0], axis=1) <= 2.0 + 0.06)
    assert np.allclose(np.abs(faces - [1.0, 0, 0]).max(axis=1), 1.2)


def test_two_point_operands_cut_by_partner_planes():
    """Sphere cloud minus a smaller sphere cloud (4 runs): the mask equals the exact ray
    tracer's of the two quadric spheres except within 2 pixels of the silhouette; where the
    surfaces meet, each operand's splats are cut by the other's nearest tangent plane, so the
    visible points of the big sphere's splats lie outside the small sphere and those of the
    small one's inside the big one, up to the tangent planes' sag (r^2 / 2R)."""
    pa, na = sphere_cloud(20000)
    pb, nb = sphere_cloud(8000, 0.6)
    cb = np.array([0.8, 0.0, 0.0])
    smp = clcsg.sample(clcsg.surfels(pa, na, SURFEL_R) - clcsg.surfels(pb + cb, nb, SURFEL_R), SURFEL_R)
    assert smp.stats["point_operands"] == 2 and smp.stats["runs"] == 4
    cam = clcsg.Camera.look_at((2.6, -2.4, 1.6), (0, 0, 0), width=240, height=180)
    img = clcsg.render(smp, cam)
    ref = clcsg.raytrace(clcsg.sphere(1.0) - clcsg.sphere(0.6, center=cb), cam)
    a, b = img.ids >= 0, ref.ids >= 0
    band = ndimage.binary_dilation(b ^ ndimage.binary_erosion(b), iterations=2)
    assert b.sum() > 8000 and ((a ^ b) & ~band).sum() == 0
    o, d = cam.rays()
    sag = SURFEL_R ** 2 / (2 * 0.6)
    kinds = set()
    for inst in np.unique(img.primitives[a]):
        sel = a & (img.primitives == inst)
        pts = o[sel] + d[sel] * img.depth[sel][:, None].astype(np.float64)
        assert inst in smp.tape.operand_instances  # only surfels are visible
        big = inst == smp.tape.operand_instances[0]
        if big:
            assert np.linalg.norm(pts - cb, axis=1).min() >= 0.6 - sag
        else:
            assert np.linalg.norm(pts, axis=1).max() <= 1.0 + sag
            assert np.abs(np.linalg.norm(pts - cb, axis=1) - 0.6).max() <= sag + 1e-3
        kinds.add(big)
    assert kinds == {True, False}
    inner = a & b & ~depth_edges(ref)
    assert inner.sum() > 0.7 * b.sum()
    assert np.abs(img.depth[inner] - ref.depth[inner]).max() <= SURFEL_R


# -- readers, bad input, CLI -------------------------------------------------------------------

def write_ply(path, points, normals=None, radius=None):
    props = ["x", "y", "z"] + (["nx", "ny", "nz"] if normals is not None else []) + (["radius"] if radius is not None else [])
    cols = [points] + ([normals] if normals is not None else []) + ([np.full((len(points), 1), radius)] if radius is not None else [])
    rows = np.concatenate(cols, axis=1) if len(points) else np.zeros((0, len(props)))
    head = ["ply", "format ascii 1.0", f"element vertex {len(points)}"] + [f"property float {p}" for p in props]
    text = "\n".join(head + ["end_header"] + [" ".join(f"{v:.9g}" for v in r) for r in rows]) + "\n"
    path.write_text(text)


def test_ply_scene_file_and_import(tmp_path):
    """A PLY of points with normals is a point operand in ``load_mesh``, a scene file's
    ``surfels`` node and OpenSCAD's ``import()``; without a radius property the radius is the
    distance to the sixth nearest point."""
    p, n = sphere_cloud(2000)
    write_ply(tmp_path / "cloud.ply", p, n)
    s = clcsg.load_mesh(tmp_path / "cloud.ply")
    assert isinstance(s, Surfels) and len(s) == 2000
    assert np.allclose(s.points, p, atol=1e-6) and np.all(s.radii > 0.03) and np.all(s.radii < 0.2)
    scene = {"clcsg": 1, "root": {"difference": [{"surfels": {"file": "cloud.ply"}}, {"cylinder": {"height": 3, "radius": 0.4}}]}}
    (tmp_path / "s.json").write_text(json.dumps(scene))
    loaded = clcsg.load(tmp_path / "s.json")
    assert isinstance(loaded.shape.operands[0], Surfels)
    inline = {"clcsg": 1, "root": {"surfels": {"points": p[:10].tolist(), "normals": n[:10].tolist(), "radii": 0.1}}}
    (tmp_path / "i.json").write_text(json.dumps(inline))
    assert len(clcsg.load(tmp_path / "i.json").shape) == 10
    (tmp_path / "m.csg").write_text('difference() {\n  import(file = "cloud.ply", layer = "", origin = [0, 0], '
                                    'scale = 1, convexity = 1, $fn = 0, $fa = 12, $fs = 2, timestamp = 0);\n'
                                    '  cylinder($fn = 0, $fa = 12, $fs = 2, h = 3, r1 = 0.4, r2 = 0.4, center = true);\n}\n')
    clcsg.save(loaded, tmp_path / "saved.json")  # saved inline: points, normals, radii
    again = clcsg.load(tmp_path / "saved.json").shape.operands[0]
    assert np.array_equal(again.points, s.points) and np.array_equal(again.radii, s.radii)
    csg = load_csg(tmp_path / "m.csg")
    assert any(isinstance(o, Surfels) for o in clcsg.model.csg.walk(csg.shape))


@pytest.mark.parametrize("what, args, message", [
    ("nan", (np.array([[0, 0, 0], [np.nan, 0, 0]]), np.ones((2, 3)), 0.1), "point 1 is not finite"),
    ("zero points", (np.zeros((0, 3)), np.zeros((0, 3)), 0.1), "no points"),
    ("zero radius", (np.zeros((2, 3)), np.ones((2, 3)), [0.1, 0.0]), "radius 1 is 0; radii must be positive"),
    ("negative radius", (np.zeros((1, 3)), np.ones((1, 3)), -1.0), "radius 0 is -1"),
    ("zero normal", (np.zeros((2, 3)), np.array([[0, 0, 1], [0, 0, 0]]), 0.1), "normal 1 is zero"),
    ("shape", (np.zeros((2, 2)), np.ones((2, 2)), 0.1), "points must be an (n, 3) array"),
])
def test_bad_surfels(what, args, message):
    with pytest.raises(ParameterError) as e:
        clcsg.surfels(*args)
    assert message in str(e.value) and "\n" not in str(e.value)


def test_too_many_point_operands():
    clouds = [clcsg.surfels([[float(k), 0, 0]], [[0, 0, 1]], 0.5) for k in range(5)]
    with pytest.raises(LimitError) as e:
        clcsg.sample(clcsg.union(*clouds), 0.1)
    assert "5 point operands; at most 4" in str(e.value) and "\n" not in str(e.value)


def test_bad_ply_files(tmp_path):
    p, n = sphere_cloud(50)
    write_ply(tmp_path / "bare.ply", p)
    bad = p.copy()
    bad[3] = np.nan
    write_ply(tmp_path / "nan.ply", bad, n, radius=0.1)
    write_ply(tmp_path / "none.ply", np.zeros((0, 3)), np.zeros((0, 3)), radius=0.1)
    write_ply(tmp_path / "zero.ply", p, n, radius=0.0)
    cases = {"bare.ply": "no normals (vertex properties nx, ny, nz)", "nan.ply": "point 3 is not finite",
             "none.ply": "no points", "zero.ply": "radii must be positive"}
    for name, message in cases.items():
        with pytest.raises(SceneError) as e:
            clcsg.load_mesh(tmp_path / name)
        assert name in str(e.value) and message in str(e.value) and "\n" not in str(e.value), str(e.value)


def test_cli_render_and_sample_a_surfel_scene(tmp_path, capsys):
    p, n = sphere_cloud(6000)
    write_ply(tmp_path / "cloud.ply", p, n, radius=0.05)
    scene = {"clcsg": 1, "root": {"difference": [{"surfels": {"file": "cloud.ply"}}, {"cylinder": {"height": 3, "radius": 0.4}}]}}
    (tmp_path / "s.json").write_text(json.dumps(scene))
    out = tmp_path / "s.png"
    assert cli.main(["render", str(tmp_path / "s.json"), "-o", str(out), "-r", "0.05", "--size", "96x72",
                     "-q"]) == 0
    from PIL import Image

    im = np.asarray(Image.open(out))
    assert im.shape[:2] == (72, 96) and (im[..., :3] < 250).any()
    assert cli.main(["sample", str(tmp_path / "s.json"), "-r", "0.05", "-o", str(tmp_path / "s.ply"),
                     "-q"]) == 0
    assert (tmp_path / "s.ply").stat().st_size > 1000
    assert cli.main(["sample", str(tmp_path / "s.json"), "-r", "0.05", "-o", str(tmp_path / "s.npz"), "-q"]) == 0
    assert cli.main(["render", str(tmp_path / "s.npz"), "-o", str(tmp_path / "again.png"), "--size", "96x72",
                     "-q"]) == 0
    again = np.asarray(Image.open(tmp_path / "again.png"))
    assert again.shape == im.shape and (again[..., :3] < 250).any()
    capsys.readouterr()
    rt = tmp_path / "rt.png"  # the exact ray tracer traces the cloud's surface mesh (test_surfel_surface.py)
    assert cli.main(["render", str(tmp_path / "s.json"), "-o", str(rt), "--method", "raytrace", "--size", "32x24",
                     "-q"]) == 0
    assert (np.asarray(Image.open(rt))[..., :3] < 250).any()
    write_ply(tmp_path / "bare.ply", p)
    (tmp_path / "b.json").write_text(json.dumps({"clcsg": 1, "root": {"surfels": {"file": "bare.ply"}}}))
    code = cli.main(["render", str(tmp_path / "b.json"), "-o", str(out)])
    err = capsys.readouterr().err
    assert code == SceneError.exit_code and "no normals" in err and err.count("\n") == 1
