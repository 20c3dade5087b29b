"""Extrusions, revolutions, hulls, Minkowski sums and offsets, read from OpenSCAD (the real
``openscad`` exports the .scad) and built with the Python API, against equivalent models
written with primitives only: the construction's samples lie on the other model's surface
(float64 tree oracle), cover it (every surface point on random lines has a sample on its
quadric within r), and the splat image equals the other model's exact ray-traced image."""

from __future__ import annotations

import os
import shutil
import subprocess
import types
import warnings
from pathlib import Path

import numpy as np
import pytest

import clcsg
from clcsg import Camera, raytrace, render, sample
from clcsg.readers.openscad import OpenScadWarning, load_csg
from clcsg.model.construction import Construction
from clcsg.model.csg import walk

import tree_oracle as T
from coverage import uncovered

EXAMPLES = Path(__file__).parent.parent / "examples"
HAVE_OPENSCAD = bool(shutil.which("openscad")) or bool(os.environ.get("CI"))
needs_openscad = pytest.mark.skipif(not HAVE_OPENSCAD, reason="openscad is not installed (.ci/run installs it)")
W, H = 72, 54


# -- primitives-only equivalents -----------------------------------------------------------------
def rounded_box(lo, hi, r):
    """The box lo..hi plus a ball of radius r: 3 boxes, 12 cylinders, 8 spheres."""
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    c, s = (lo + hi) / 2, hi - lo
    parts = [clcsg.box(s + 2 * r * np.eye(3)[k], center=c) for k in range(3)]
    for k in range(3):
        a, b = [i for i in range(3) if i != k]
        for ua in (lo[a], hi[a]):
            for ub in (lo[b], hi[b]):
                p = c.copy()
                p[a], p[b] = ua, ub
                parts.append(clcsg.cylinder(s[k], r, center=p, axis=np.eye(3)[k]))
    parts += [clcsg.sphere(r, (x, y, z)) for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])]
    return clcsg.union(*parts)


def rounded_rect_plate(x0, y0, x1, y1, r, t):
    """offset(r) of the rectangle x0..x1, y0..y1, extruded 0..t."""
    cx, cy = (x0 + x1) / 2, (y0 + y1) / 2
    parts = [clcsg.box((x1 - x0 + 2 * r, y1 - y0, t), center=(cx, cy, t / 2)),
             clcsg.box((x1 - x0, y1 - y0 + 2 * r, t), center=(cx, cy, t / 2))]
    parts += [clcsg.cylinder(t, r, center=(x, y, t / 2)) for x in (x0, x1) for y in (y0, y1)]
    return clcsg.union(*parts)


def _plate():
    holes = [clcsg.cylinder(5, 1.6, center=(x, y, 1.5)) for x in (0, 32) for y in (0, 16)]
    return clcsg.difference(rounded_rect_plate(0, 0, 32, 16, 4, 3), *holes)


def _knob():
    body = clcsg.cylinder(2, 6, center=(0, 0, 1)) | clcsg.cone(3, 6, 4, center=(0, 0, 3.5))
    return body - clcsg.cylinder(10, 1, center=(0, 0, 0)) - clcsg.cylinder(3, 1.5, center=(0, 0, 4.5))


def _two_spheres():
    sin = 0.2
    cos = np.sqrt(1 - sin * sin)
    return clcsg.sphere(2) | clcsg.sphere(1, (5, 0, 0)) | clcsg.cone(4.8, 2 * cos, cos, center=(2.8, 0, 0), axis=(1, 0, 0))


#: name -> (.scad text or examples/ file, primitives-only equivalent)
CASES = {
    "rounded_box": ("rounded_box.scad", lambda: rounded_box((3, 3, 3), (27, 17, 7), 3)),
    "rounded_plate": ("rounded_plate.scad", _plate),
    "knob": ("knob.scad", _knob),
    "minkowski_cube_sphere": ("minkowski() { cube([4, 3, 2]); sphere(0.5); }", lambda: rounded_box((0, 0, 0), (4, 3, 2), 0.5)),
    "extrude_l_polygon": ("linear_extrude(2) polygon([[0,0],[4,0],[4,1],[1,1],[1,3],[0,3]]);",
                          lambda: clcsg.box((4, 1, 2), center=(2, 0.5, 1)) | clcsg.box((1, 3, 2), center=(0.5, 1.5, 1))),
    "extrude_scaled_circle": ("linear_extrude(height = 4, scale = 0.5) circle(2);", lambda: clcsg.cone(4, 2, 1, center=(0, 0, 2))),
    "revolve_quarter": ("rotate_extrude(angle = 90) translate([2, 0]) square([1, 1]);",
                        lambda: (clcsg.cylinder(1, 3, center=(0, 0, 0.5)) - clcsg.cylinder(3, 2, center=(0, 0, 0.5)))
                        & clcsg.box((4, 4, 3), center=(2, 2, 0.5))),
    "hull_two_spheres": ("hull() { sphere(2); translate([5, 0, 0]) sphere(1); }", _two_spheres),
    "hull_coaxial_cylinders": ("hull() { cylinder(h = 1, r = 2); translate([0, 0, 3]) cylinder(h = 1, r = 1); }",
                               lambda: clcsg.cylinder(1, 2, center=(0, 0, 0.5)) | clcsg.cone(3, 2, 1, center=(0, 0, 2.5))),
    "minkowski_cube_x_cylinder": ("minkowski() { cube([4, 3, 2]); rotate([0, 90, 0]) cylinder(h = 1, r = 0.5, center = true); }",
                                  lambda: clcsg.union(clcsg.box((5, 4, 2), center=(2, 1.5, 1)), clcsg.box((5, 3, 3), center=(2, 1.5, 1)),
                                                      *[clcsg.cylinder(5, 0.5, center=(2, y, z), axis=(1, 0, 0))
                                                        for y in (0, 3) for z in (0, 2)])),
    "hull_bullet": ("hull() { cylinder(h = 3, r = 1); translate([0, 0, 3]) sphere(1); }",
                    lambda: clcsg.cylinder(3, 1, center=(0, 0, 1.5)) | clcsg.sphere(1, (0, 0, 3))),
    "minkowski_2d_square_circle": ("linear_extrude(2) minkowski() { square([4, 2]); translate([1, 0]) circle(0.5); }",
                                   lambda: rounded_rect_plate(1, 0, 5, 2, 0.5, 2)),
    # the reference is the 3-D hull (tested against the dense-point oracle in test_round_hull.py)
    "hull_2d_square_circle": ("linear_extrude(1) hull() { square([2, 2]); translate([5, 1]) circle(1); }",
                              lambda: clcsg.hull(clcsg.box((2, 2, 1), center=(1, 1, 0.5)), clcsg.cylinder(1, 1, center=(5, 1, 0.5)))),
    "hull_slot": ("hull() { cylinder(h = 2, r = 1); translate([5, 0, 0]) cylinder(h = 2, r = 1); }",
                  lambda: clcsg.box((5, 2, 2), center=(2.5, 0, 1)) | clcsg.cylinder(2, 1, center=(0, 0, 1))
                  | clcsg.cylinder(2, 1, center=(5, 0, 1))),
}


def export(source: str, tmp_path) -> clcsg.Scene:
    """Run the real openscad on an examples/ file or a .scad text and load its CSG export."""
    scad = EXAMPLES / source if source.endswith(".scad") else tmp_path / "model.scad"
    if not source.endswith(".scad"):
        scad.write_text(source + "\n")
    out = tmp_path / "model.csg"
    subprocess.run(["openscad", "-o", str(out), str(scad)], check=True, capture_output=True, timeout=120)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", OpenScadWarning)
        return load_csg(out)


def oracle_ids(shape, s):
    ids = T.quadric_table(shape).match(s.tape.quadrics)
    return types.SimpleNamespace(positions=s.positions, quadrics=ids[s.quadrics])


def check_against(construction, reference, cl_context, n_lines=6000):
    """Samples of ``construction`` against the oracle of ``reference``; splats against its ray
    tracer.  Returns (number of samples, number of reference surface points)."""
    tape = clcsg.Scene(reference).compile()
    lo, hi = tape.bound
    size = float(np.linalg.norm(hi - lo))
    r = size / 40
    s = sample(construction, r, device=cl_context)
    assert len(s) > 100
    np.testing.assert_allclose(s.bound, tape.bound, atol=2e-3 * size)
    Q = s.tape.quadrics[s.quadrics]
    on_q, on_csg = T.sample_residuals(reference, s.positions, Q, tol=1e-9 * size)
    assert on_q.max() <= 1e-6 * size
    assert on_csg.all(), f"{(~on_csg).sum()} samples off the reference surface, e.g. {s.positions[~on_csg][:3].tolist()}"
    pad = 1e-3 * size
    ref = T.surface_points(reference, tape.bound + [[-pad], [pad]], n_lines=n_lines)
    assert len(ref) > 100
    missing = uncovered(ref.points, ref.quadrics, oracle_ids(reference, s), r, slack=1e-5)
    assert len(missing) == 0, f"{len(missing)} of {len(ref)} reference surface points uncovered, e.g. {ref.points[missing[:3]].tolist()}"
    cam = Camera.fit(tape, W, H)
    img, exact = render(s, cam, device=cl_context), raytrace(tape, cam, device=cl_context)
    assert exact.mask.sum() > 500
    assert (img.mask == exact.mask).mean() >= 0.998
    both = img.mask & exact.mask
    rel = np.abs(img.depth[both].astype(np.float64) - exact.depth[both]) / exact.depth[both]
    assert rel.max() <= 1e-4
    return len(s), len(ref)


@needs_openscad
@pytest.mark.parametrize("name", sorted(CASES))
def test_openscad_construction_equals_primitives(name, tmp_path, cl_context):
    source, reference = CASES[name]
    scene = export(source, tmp_path)
    assert any(isinstance(n, Construction) for n in walk(scene.shape))
    check_against(scene.shape, reference(), cl_context)


def test_python_api_constructions_equal_primitives(cl_context):
    rb = clcsg.hull(*[clcsg.sphere(0.5, (x, y, z)) for x in (0, 2) for y in (0, 1) for z in (0, 1)])
    assert rb.describe() == "hull of 8 spheres: 12 planes, 12 cylinders, 8 spheres"
    check_against(rb, rounded_box((0, 0, 0), (2, 1, 1), 0.5), cl_context, n_lines=3000)
    tube = clcsg.revolve(clcsg.square((1, 2)).translate((1, 0)))
    check_against(tube, clcsg.cylinder(2, 2, center=(0, 0, 1)) - clcsg.cylinder(3, 1, center=(0, 0, 1)), cl_context, n_lines=3000)


@pytest.mark.parametrize("name", sorted(CASES))
def test_api_and_reference_contain_the_same_points(name, tmp_path):
    """Host-only: the construction and its equivalent agree on random points (a quick check
    that also runs where openscad is missing, through the Python API)."""
    source, reference = CASES[name]
    shape = export(source, tmp_path).shape if HAVE_OPENSCAD else None
    if shape is None:
        pytest.skip("openscad is not installed")
    ref = reference()
    lo, hi = clcsg.Scene(ref).compile().bound
    pts = np.random.default_rng(3).uniform(lo - 0.5, hi + 0.5, (20000, 3))
    np.testing.assert_array_equal(T.contains(shape, pts), T.contains(ref, pts))


def test_info_names_each_construction(capsys):
    from clcsg.cli import app as cli

    assert cli.main(["info", str(EXAMPLES / "rounded_box.csg")]) == 0
    out = capsys.readouterr().out
    assert "constructions:        hull of 8 spheres: 12 planes, 12 cylinders, 8 spheres" in out


# -- refusals ---------------------------------------------------------------------------------
REFUSALS = {
    "rotate_extrude() of a circle": (
        "rotate_extrude() translate([2, 0]) circle(1);",
        "rotate_extrude(): rotate_extrude() of a circle sweeps a torus, a quartic surface, not a quadric"),
    "twist": ("linear_extrude(height = 2, twist = 90) square(1);",
              "linear_extrude(): twist = 90 sweeps helicoids, which are not quadric surfaces; nearest exact alternative"),
    "text": ('linear_extrude(1) text("hi");', "text() is not supported: text() outlines glyphs with Bezier curves"),
    "hull of mixed shapes": ("hull() { sphere(1); translate([3, 0, 0]) cylinder(h = 1, r = 1); }",
                             "hull(): hull() of 1 sphere and 1 cylinder is not covered exactly"),
    "hull of skew cylinders": ("hull() { cylinder(h = 1, r = 1); rotate([90, 0, 0]) cylinder(h = 1, r = 1); }",
                               "hull(): cylinders and cones whose axes are not parallel are not covered exactly"),
    "minkowski of a non-convex operand": ("minkowski() { difference() { cube(2); cube(1); } sphere(0.2); }",
                                          "minkowski(): a difference inside is not covered"),
    "minkowski of spheres and cylinders": ("minkowski() { sphere(1); cylinder(h = 1, r = 1); }",
                                           "minkowski(): minkowski() of spheres and cylinders is not covered exactly"),
    "open polyhedron": ("polyhedron([[0,0,0],[1,0,0],[0,1,0],[0,0,1],[0.1,0.1,0.1]], [[0,1,2],[0,3,1],[0,2,3],[1,3,4],[1,4,2]]);",
                        "polyhedron(): edge 2-3 (0, 1, 0 to 0, 0, 1) of face 2 has no opposite face: the mesh is open"),
    "2-D at top level": ("square(1);", "square() is a 2-D shape outside linear_extrude() or rotate_extrude()"),
}


@needs_openscad
@pytest.mark.parametrize("name", sorted(REFUSALS))
def test_refusals_are_one_line_exit_3(name, tmp_path):
    source, expected = REFUSALS[name]
    scad = tmp_path / "model.scad"
    scad.write_text(source + "\n")
    p = subprocess.run(["python", "-m", "clcsg", "info", str(scad)], capture_output=True, text=True, timeout=120)
    assert p.returncode == 3, p.stderr
    lines = [ln for ln in p.stderr.splitlines() if ln.startswith("clcsg: error:")]
    assert len(lines) == 1 and "Traceback" not in p.stderr, p.stderr
    assert f"{scad} (CSG export):" in lines[0] and expected in lines[0], lines[0]


# -- scene files --------------------------------------------------------------------------------
def _api_models():
    return {
        "extrude": clcsg.extrude(clcsg.offset(clcsg.square([3, 2]), r=0.5) - clcsg.circle(0.3).translate((1, 1)), 2,
                                 scale=0.8, color=(1, 0, 0)),
        "revolve": clcsg.revolve(clcsg.polygon([(1, 0), (2, 0), (1.5, 1)]).rotate(10), 200),
        "hull": clcsg.hull(clcsg.sphere(1), clcsg.sphere(0.5, (3, 0, 0))).translate((0, 1, 0)),
        "minkowski": clcsg.minkowski(clcsg.box(1), clcsg.sphere(0.2, color=(0, 0, 1))),
    }


@pytest.mark.parametrize("name", ["extrude", "revolve", "hull", "minkowski"])
def test_scene_file_round_trip(name, tmp_scene):
    shape = _api_models()[name]
    path = tmp_scene(shape)
    text = path.read_text()
    assert f'"{name}"' in text
    back = clcsg.load(path).shape
    built = [n.describe() for n in walk(back) if isinstance(n, Construction)]
    assert built == [n.describe() for n in walk(shape) if isinstance(n, Construction)] and built
    pts = np.random.default_rng(5).uniform(-4, 4, (20000, 3))
    np.testing.assert_array_equal(T.contains(back, pts), T.contains(shape, pts))
    assert {n.color for n in walk(back) if hasattr(n, "color")} == {n.color for n in walk(shape) if hasattr(n, "color")}


@pytest.mark.parametrize("root, message", [
    ({"extrude": {"profile": {"square": {"size": 1}, "circle": {"radius": 1}}, "height": 1}},
     "$.root.extrude.profile: a profile needs exactly one of square, circle, polygon, offset, hull, union, intersection, difference, got 2"),
    ({"extrude": {"profile": {"polygon": {"points": [[0, 0], [2, 2], [2, 0], [0, 2]]}}}},
     "$.root.extrude.profile.polygon: polygon path 0 crosses itself: not a simple polygon with holes"),
    ({"revolve": {"profile": {"circle": {"radius": 1, "center": [3, 0]}}}},
     "$.root.revolve: rotate_extrude() of a circle sweeps a torus, a quartic surface, not a quadric"),
    ({"hull": [{"cylinder": {"radius": 1}}, {"sphere": {"radius": 1, "center": [3, 0, 0]}}]}, "$.root.hull: hull() of 1 cylinder and 1 sphere is not covered exactly"),
    ({"extrude": {"height": 1}}, "$.root.extrude"),
])
def test_scene_file_construction_errors(root, message):
    from clcsg.errors import SceneError
    from clcsg.readers.scenefile import scene_from_dict

    with pytest.raises(SceneError) as info:
        scene_from_dict({"clcsg": 1, "root": root}, "part.json")
    assert str(info.value).startswith(f"part.json: {message}"), str(info.value)
    assert "\n" not in str(info.value)


def test_hull_of_spheres_of_different_radii():
    """conv(U B(c_i, r_i)) is the union of the balls B(sum l_i c_i, sum l_i r_i) over weights l
    in the simplex: a point is inside iff some l certifies it (SLSQP on the convex function
    |x - C l| - r . l), and outside if a direction n has n . x > max_i (n . c_i + r_i)."""
    from scipy.optimize import minimize

    rng = np.random.default_rng(11)
    c, r = rng.uniform(-2, 2, (5, 3)), np.array([0.4, 1.2, 0.7, 1.0, 0.3])
    solid = clcsg.hull(*[clcsg.sphere(r[i], c[i]) for i in range(5)])
    assert solid.describe().startswith("hull of 5 spheres: ")
    pts = rng.uniform(-4, 4, (4000, 3))
    got = T.contains(solid, pts)
    n = rng.normal(size=(20000, 3))
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    outside = (pts @ n.T - (n @ c.T + r).max(axis=1)).max(axis=1) > 1e-9
    assert not np.any(got & outside)
    cons = ({"type": "eq", "fun": lambda w: w.sum() - 1},)
    for x in pts[~outside][:120]:
        res = minimize(lambda w: np.linalg.norm(x - w @ c) - w @ r, np.full(5, 0.2), bounds=[(0, 1)] * 5,
                       constraints=cons, method="SLSQP", options={"ftol": 1e-12, "maxiter": 500})
        if res.fun < -1e-6:  # certified inside
            assert T.contains(solid, x[None])[0]
        elif res.fun > 1e-6:
            assert not T.contains(solid, x[None])[0]


@needs_openscad
def test_pen_stand_example(tmp_path, cl_context):
    """examples/pen_stand.scad: a hull of a cube and a parallel cylinder with other caps, a hull
    of spheres of three radii and a sum of a turned cube with a cylinder across it (their sets
    are checked against the dense-point oracle in test_round_hull.py): the samples lie on the
    tree oracle's surface, cover it, and the splats equal the ray tracer."""
    scene = export("pen_stand.scad", tmp_path)
    labels = sorted(n.label for n in walk(scene.shape) if isinstance(n, Construction))
    assert labels == ["hull of 1 cube and 1 cylinder", "hull of 3 spheres", "minkowski of 1 cube and 1 cylinder"]
    check_against(scene.shape, scene.shape, cl_context, n_lines=3000)
