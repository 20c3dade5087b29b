"""Point operands on the exact paths: the surface mesh of a cloud (closed, oriented, on the
classification's surface), the exact ray tracer, the point queries and ``clcsg info`` of scenes
with point operands, against the exact solids the clouds were sampled from (float64)."""

from __future__ import annotations

import json

import numpy as np
import pytest
import trimesh
from scipy import ndimage

import clcsg
from clcsg.cli import app as cli
from clcsg.model import surfel_surface
from clcsg.model.surfel_surface import spacing, surface_mesh
from test_surfels import SURFEL_R, box_cloud, depth_edges, sphere_cloud, write_ply


def bored_cloud_file(folder):
    """``folder``/s.json: a 6,000-surfel sphere (``cloud.ply``, radius 0.05) minus a cylinder."""
    p, n = sphere_cloud(6000)
    write_ply(folder / "cloud.ply", p, n, radius=0.05)
    scene = {"clcsg": 1, "root": {"difference": [{"surfels": {"file": "cloud.ply"}},
                                                 {"cylinder": {"height": 3, "radius": 0.4}}]}}
    (folder / "s.json").write_text(json.dumps(scene))
    return folder / "s.json"


def closed_and_oriented(v, f):
    m = trimesh.Trimesh(v, f, process=False)
    return m.is_watertight and m.is_winding_consistent and m.volume > 0, m


def winding_numbers(v, f, x):
    """The winding number of the closed mesh about each point of ``x`` (float64, the sum of
    the triangles' signed solid angles over 4 pi, Van Oosterom and Strackee)."""
    a, b, c = (v[f[:, k]][None, :, :] - x[:, None, :] for k in range(3))
    la, lb, lc = (np.linalg.norm(t, axis=2) for t in (a, b, c))
    det = np.einsum("pij,pij->pi", a, np.cross(b, c))
    den = la * lb * lc + np.einsum("pij,pij->pi", a, b) * lc + np.einsum("pij,pij->pi", b, c) * la \
        + np.einsum("pij,pij->pi", c, a) * lb
    return 2.0 * np.arctan2(det, den).sum(axis=1) / (4.0 * np.pi)


@pytest.fixture(scope="module")
def sphere():
    p, n = sphere_cloud(20000)
    return clcsg.surfels(p, n, SURFEL_R)


def test_sphere_surface_is_closed_and_on_the_sphere(sphere):
    """The mesh of a sphere cloud is a closed, outward 2-manifold whose vertices lie on the
    classification's surface: within h / 2^BISECTIONS plus the tangent planes' offset from the
    unit sphere (float64 distance to the exact sphere), and its volume is the ball's within the
    chords' deficit (edges of at most h sqrt 3 on a unit sphere)."""
    v, f = surface_mesh(sphere)
    h = spacing(sphere)
    ok, m = closed_and_oriented(v, f)
    assert ok
    assert len(f) > 1000
    r = np.linalg.norm(v, axis=1)
    assert np.abs(r - 1.0).max() <= 1e-3 + h * 2.0 ** -surfel_surface.BISECTIONS * 2
    sagitta = 3 * h * h / 8
    assert 4 / 3 * np.pi * (1 - sagitta) ** 3 <= m.volume <= 4 / 3 * np.pi
    assert len(np.unique(np.floor((sphere.points - sphere.points.min(0)) / h), axis=0)) <= surfel_surface.MAX_CUBES


def test_box_surface_keeps_the_box():
    """A cube cloud: closed and oriented; every vertex within one grid cube of the cube's
    surface (edges and corners are rounded off at the grid's resolution only), and grid points
    deep inside and outside are on the right side of the mesh."""
    p, n, r = box_cloud(0.1)
    cloud = clcsg.surfels(p, n, r)
    v, f = surface_mesh(cloud)
    h = spacing(cloud)
    ok, m = closed_and_oriented(v, f)
    assert ok
    d = np.abs(np.abs(v) - 1.0).min(axis=1)
    outside = np.linalg.norm(np.maximum(np.abs(v) - 1.0, 0), axis=1)
    assert max(d.max(), outside.max()) <= h * np.sqrt(3)
    assert abs(m.volume - 8.0) < 8.0 * 3 * h
    probe = np.array([[0, 0, 0], [0.5, -0.5, 0.5], [1.5, 0, 0], [0, -1.6, 1.6]])
    assert (winding_numbers(v, f, probe) > 0.5).tolist() == [True, True, False, False]


def test_open_cloud_is_clipped_to_its_grid():
    """A single surfel is a half-space: its solid is clipped to the grid's box, still closed."""
    cloud = clcsg.surfels([[0.0, 0.0, 0.0]], [[0.0, 0.0, 1.0]], 0.5)
    v, f = surface_mesh(cloud)
    ok, m = closed_and_oriented(v, f)
    assert ok
    assert np.isclose(v[:, 2].max(), 0.0, atol=1e-3) and v[:, 2].min() < -0.5


def bored(solid):
    return solid - clcsg.cylinder(3, 0.4)


def test_raytrace_of_a_cloud_scene_is_the_exact_solid(sphere):
    """The exact ray tracer of a sphere cloud minus a cylinder (the cloud traced as its
    surface mesh) against the ray tracer of the quadric sphere minus the cylinder: the masks
    agree off a 2-pixel band along the silhouette, the depth within the surfel radius off
    the depth edges; the samples' tape traces the same image."""
    cam = clcsg.Camera.look_at((2.2, -2.6, 1.9), (0, 0, 0), width=200, height=150)
    img = clcsg.raytrace(bored(sphere), cam)
    ref = clcsg.raytrace(bored(clcsg.sphere(1.0)), cam)
    a, b = img.ids >= 0, ref.ids >= 0
    band = ndimage.binary_dilation(b ^ ndimage.binary_erosion(b), iterations=2)
    assert b.sum() > 5000 and ((a ^ b) & ~band).sum() == 0
    inner = a & b & ~depth_edges(ref)
    assert inner.sum() > 0.7 * b.sum()
    assert np.abs(img.depth[inner] - ref.depth[inner]).max() <= SURFEL_R
    smp = clcsg.sample(bored(sphere), 0.05)
    again = clcsg.raytrace(smp, cam)
    assert np.array_equal(again.ids >= 0, a) and np.array_equal(again.depth, img.depth)


def test_splats_of_a_cloud_scene_match_its_ray_tracer(sphere):
    """Splats of the cloud's samples against the ray tracer of the same scene: mask equal off
    the silhouette band, depth within the surfel radius plus the mesh's chord off depth edges."""
    cam = clcsg.Camera.look_at((2.2, -2.6, 1.9), (0, 0, 0), width=200, height=150)
    smp = clcsg.sample(bored(sphere), SURFEL_R)
    img = clcsg.render(smp, cam)
    ref = clcsg.raytrace(smp, cam)
    a, b = img.ids >= 0, ref.ids >= 0
    band = ndimage.binary_dilation(b ^ ndimage.binary_erosion(b), iterations=2)
    assert ((a ^ b) & ~band).sum() == 0
    inner = a & b & ~depth_edges(ref)
    h = spacing(sphere)
    assert np.abs(img.depth[inner] - ref.depth[inner]).max() <= SURFEL_R + 3 * h * h / 8


def test_queries_of_a_cloud_scene(sphere):
    """``inside`` and ``distance`` of the cloud scene at random points farther than two grid
    cubes from the exact solid's surface agree with the exact solid's membership (float64);
    the distance is a lower bound of the distance to the mesh, so at most the distance to the
    exact surface (an upper bound: the nearest of dense points on it) plus two cubes."""
    rng = np.random.default_rng(3)
    pts = rng.uniform(-1.3, 1.3, (4000, 3))
    radial, rr = np.hypot(pts[:, 0], pts[:, 1]), np.linalg.norm(pts, axis=1)
    exact_in = (rr <= 1.0) & (radial >= 0.4)
    h = spacing(sphere)
    far = np.minimum(np.abs(rr - 1.0), np.abs(radial - 0.4)) > 2 * h
    scene = bored(sphere)
    got = clcsg.inside(scene, pts)
    assert far.sum() > 1500
    assert np.array_equal(got[far], exact_in[far])
    d = clcsg.distance(scene, pts)
    assert np.array_equal(d[far] < 0, exact_in[far])
    u, _ = sphere_cloud(200000)
    wall_z = np.linspace(-1, 1, 400)
    wall_t = np.linspace(0, 2 * np.pi, 400, endpoint=False)
    zz, tt = [a.ravel() for a in np.meshgrid(wall_z, wall_t)]
    wall = np.stack([0.4 * np.cos(tt), 0.4 * np.sin(tt), zz], 1)
    boundary = np.concatenate([u[np.hypot(u[:, 0], u[:, 1]) >= 0.4], wall[np.linalg.norm(wall, axis=1) <= 1.0]])
    from scipy.spatial import cKDTree

    upper, _ = cKDTree(boundary).query(pts)
    assert (np.abs(d) <= upper + 2 * h).all()


def test_cli_raytrace_and_info_of_a_surfel_scene(tmp_path, capsys):
    bored_cloud_file(tmp_path)
    out = tmp_path / "rt.png"
    assert cli.main(["render", str(tmp_path / "s.json"), "-o", str(out), "--method", "raytrace",
                     "--size", "64x48", "-q", "--ids", str(tmp_path / "ids.npy")]) == 0
    ids = np.load(tmp_path / "ids.npy")
    assert (ids >= 0).sum() > 300
    capsys.readouterr()
    assert cli.main(["info", str(tmp_path / "s.json"), "--json"]) == 0
    info = json.loads(capsys.readouterr().out)
    assert "surfel surface of 6000 points" in json.dumps(info)


def test_viewer_exact_frame_of_a_surfel_scene(tmp_path):
    """The viewer's exact frame of a scene with a point operand traces the cloud's surface
    mesh: its mask equals the splat frame's off the silhouette band."""
    from clcsg.cl.device import context_of
    from clcsg.viewer import frames
    from clcsg.viewer.session import Session

    bored_cloud_file(tmp_path)
    ctx = context_of(None)
    model = Session(tmp_path / "s.json", ctx).load()
    cam = clcsg.Camera.look_at((2.2, -2.6, 1.9), (0, 0, 0), width=120, height=90)
    exact = frames.render(ctx, model, cam, "raytrace")
    splat = frames.render(ctx, model, cam, "splat")
    a, b = splat.ids >= 0, exact.ids >= 0
    band = ndimage.binary_dilation(b ^ ndimage.binary_erosion(b), iterations=2)
    assert b.sum() > 2000 and ((a ^ b) & ~band).sum() == 0
