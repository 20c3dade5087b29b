"""OpenSCAD CSG export reader: grammar, semantics, errors, and equivalence with the Python API."""

from __future__ import annotations

import math
import warnings
from pathlib import Path

import numpy as np
import pytest

from clcsg import box, cone, cylinder, sphere
from clcsg.model.csg import Difference, Intersection, Primitive, Transformed, Union, contains, difference, union, walk
from clcsg.errors import SceneError
from clcsg.compile.dnf import normalize
from clcsg.readers.openscad import WEB_COLORS, OpenScadWarning, load_csg, parse_csg
from clcsg.model.scene import Scene
from clcsg.readers.scenes import load

DATA = Path(__file__).parent / "data" / "openscad"
EXAMPLES = Path(__file__).parent.parent / "examples"


# -- helpers ----------------------------------------------------------------------------------
def quiet_load(path) -> Scene:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", OpenScadWarning)
        return load_csg(path)


def quiet_parse(text: str) -> Scene:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", OpenScadWarning)
        return parse_csg(text, source="t.csg")


def warnings_of(text: str, source="t.csg"):
    with warnings.catch_warnings(record=True) as rec:
        warnings.simplefilter("always")
        scene = parse_csg(text, source=source)
    return scene, [str(w.message) for w in rec if issubclass(w.category, OpenScadWarning)]


def primitives(shape):
    return [n for n in walk(shape) if isinstance(n, Primitive)]


def only_primitive(text: str) -> Primitive:
    shape = quiet_parse(text).shape
    assert isinstance(shape, Primitive), shape
    return shape


def err(text: str, source="t.csg") -> str:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", OpenScadWarning)
        with pytest.raises(SceneError) as info:
            parse_csg(text, source=source)
    msg = str(info.value)
    assert "\n" not in msg
    return msg


def same_dnf(a, b, tol=1e-6, color_tol=None):
    """Same unique quadrics (canonical matrices within ``tol``, any order) and same terms."""
    da, db = normalize(a), normalize(b)
    assert da.n_quadrics == db.n_quadrics, (da.stats, db.stats)
    qa = da.quadrics.reshape(-1, 1, 16)
    qb = db.quadrics.reshape(1, -1, 16)
    diff = np.abs(qa - qb).max(-1)
    perm = diff.argmin(1)
    assert diff[np.arange(len(perm)), perm].max(initial=0.0) < tol
    assert len(set(perm.tolist())) == len(perm)
    ta = {frozenset((int(perm[q]), s) for q, s in t) for t in da.terms}
    tb = {frozenset(t) for t in db.terms}
    assert ta == tb
    if color_tol is not None:
        np.testing.assert_allclose(da.colors, db.colors[perm], atol=color_tol)
    return da, db


def same_membership(a, b, n=6000, margin=1e-4, seed=0):
    """clcsg.csg.contains agrees on random points (away from the surfaces by ``margin``)."""
    db = normalize(b)
    lo, hi = db.bound
    pad = 0.1 * (hi - lo) + 0.5
    pts = np.random.default_rng(seed).uniform(lo - pad, hi + pad, (n, 3))
    if db.n_quadrics:
        dist = np.min([np.abs(db.quadric(i).distance(pts)) for i in range(db.n_quadrics)], axis=0)
        pts = pts[dist > margin]
    ina, inb = contains(a, pts), contains(b, pts)
    assert ina.any() and not ina.all()
    np.testing.assert_array_equal(ina, inb)


def T(shape, x=0.0, y=0.0, z=0.0):
    return shape.translate((x, y, z))


def R(shape, x=0.0, y=0.0, z=0.0):
    """OpenSCAD's rotate([x, y, z]): about x, then y, then z."""
    return shape.rotate((1, 0, 0), x).rotate((0, 1, 0), y).rotate((0, 0, 1), z)


def rgb(name, alpha=1.0):
    return tuple(v / 255 for v in WEB_COLORS[name][:3]) + (alpha,)


# -- Python-API twins of the data files -------------------------------------------------------
def api_primitives():
    c = lambda z: (0, 0, z)  # noqa: E731
    parts = [
        box((1, 2, 3), center=(0.5, 1, 1.5)),
        box(2),
        box((1, 2, 3)),
        box(5, center=(2.5, 2.5, 2.5)),
        box(1, center=(0.5, 0.5, 0.5)),
        sphere(3),
        sphere(2),
        sphere(2),
        sphere(3),
        sphere(1),
        cylinder(10, 2, center=c(5)),
        cylinder(10, 2),
        cone(10, 2, 1, center=c(5)),
        cone(10, 2, 1),
        cylinder(4, 3, center=c(2)),
        cone(4, 3, 0, center=c(2)),
        cone(4, 0, 3),
        cone(3, 2, 1, center=c(1.5)),
        cylinder(1, 1, center=c(0.5)),
        cylinder(6, 2, center=c(3)),
    ]
    return union(*[p if i == 0 else T(p, 10 * i) for i, p in enumerate(parts)])


def api_numbers():
    return union(
        T(box((2.5, 0.5, 5), center=(1.25, 0.25, 2.5)), 1e-5, -350, 0),
        T(sphere(1), z=12.5),
        cylinder(10, 2, center=(0, 0, 5)),
    )


def api_rotations():
    return union(
        T(R(box((4, 2, 1)), z=45), 10),
        T(R(cone(5, 2, 1), 10, 20, 30), y=10),
        T(R(cylinder(3, 1, center=(0, 0, 1.5)), x=90), z=10),
        T(R(box(2), y=45).scale((2, 1, 0.5)), -10),
        R(T(difference(sphere(2), R(cylinder(6, 0.75), x=33)), 5), z=120),
        T(box((1, 2, 3), center=(0.5, 1, 1.5)), y=-10).rotate((1, 1, 1), 60),
    )


def api_modifiers():
    return union(
        box(1, center=(0.5, 0.5, 0.5)),
        T(sphere(1), -5),
        difference(sphere(3), cylinder(10, 1)),
        Intersection([sphere(3), box(5)]),
    )


def api_flange():
    steel, orange = rgb("steelblue"), rgb("darkorange")
    body = union(
        cylinder(8, 40, center=(0, 0, 4), color=steel),
        cylinder(30, 22, center=(0, 0, 15), color=steel),
        T(cone(6, 26, 22, center=(0, 0, 3), color=steel), z=8),
    )
    cuts = [
        T(cylinder(32, 12, center=(0, 0, 16), color=steel), z=-1),
        T(cone(3.01, 12, 15, center=(0, 0, 1.505), color=steel), z=27),
        T(cone(2, 14, 12, center=(0, 0, 1), color=steel), z=-0.01),
    ]
    holes = [R(T(cylinder(32, 4, center=(0, 0, 16), color=steel), 31, 0, -1), z=a) for a in range(0, 301, 60)]
    screw = union(
        cylinder(5, 6, center=(0, 0, 2.5), color=orange),
        T(cone(1, 6, 5, center=(0, 0, 0.5), color=orange), z=5),
        T(cylinder(12, 3.9, center=(0, 0, 6), color=orange), z=-12),
    )
    screws = [R(T(screw, 31, 0, 8), z=a) for a in range(0, 301, 60)]
    return union(Difference([body, *cuts, union(*holes)]), union(*screws))


def api_pawn():
    ivory = rgb("ivory")
    black = (0.1, 0.1, 0.1, 1.0)
    body = union(
        cylinder(3, 12, center=(0, 0, 1.5), color=ivory),
        T(cone(2.5, 12, 9.5, center=(0, 0, 1.25), color=ivory), z=3),
        T(sphere(9.5, color=ivory).scale((1, 1, 0.35)), z=5.5),
        T(cone(21, 7.5, 3.2, center=(0, 0, 10.5), color=ivory), z=5.5),
        T(cylinder(1.6, 6.5, center=(0, 0, 0.8), color=ivory), z=25),
        T(cone(1.2, 6.5, 3, center=(0, 0, 0.6), color=ivory), z=26.6),
        T(sphere(6, color=ivory), z=33),
    )
    hollow = T(cone(4, 8, 6, center=(0, 0, 2), color=ivory), z=-1)
    pad = T(difference(cylinder(0.5, 11.5, center=(0, 0, 0.25), color=black), cylinder(2, 8, color=black)), z=-0.5)
    return union(difference(body, hollow), pad)


# -- files vs. the Python API -----------------------------------------------------------------
@pytest.mark.parametrize(
    "path, twin, tol",
    [
        (DATA / "primitives.csg", api_primitives, 1e-9),
        (DATA / "numbers.csg", api_numbers, 1e-9),
        (DATA / "rotations.csg", api_rotations, 1e-5),
        (DATA / "modifiers.csg", api_modifiers, 1e-9),
        (EXAMPLES / "flange.csg", api_flange, 1e-5),
        (EXAMPLES / "pawn.csg", api_pawn, 1e-9),
    ],
    ids=lambda v: v.stem if isinstance(v, Path) else None,
)
def test_file_matches_python_api(path, twin, tol):
    scene = quiet_load(path)
    assert scene.source == str(path)
    expected = twin()
    same_dnf(scene.shape, expected, tol=tol, color_tol=1e-5 if "examples" in str(path) else None)
    same_membership(scene.shape, expected)


def test_examples_are_realistic_exports():
    for name in ("flange.csg", "pawn.csg"):
        text = (EXAMPLES / name).read_text()
        for node in ("multmatrix(", "color(", "difference(", "cylinder($fn"):
            assert node in text
        with warnings.catch_warnings():
            warnings.simplefilter("error")  # a clean export loads without any warning
            scene = load(EXAMPLES / name)
        assert normalize(scene.shape).n_terms > 0
    assert "group()" in (EXAMPLES / "flange.csg").read_text()


def test_scene_load_dispatches_csg():
    scene = load(DATA / "numbers.csg")
    assert isinstance(scene, Scene) and scene.bound is None


# -- primitives and argument forms ------------------------------------------------------------
@pytest.mark.parametrize(
    "text, kind, params",
    [
        ("cube(size = [1, 2, 3], center = false);", "box", {"size": (1, 2, 3), "center": (0.5, 1, 1.5)}),
        ("cube(size = 2, center = true);", "box", {"size": (2, 2, 2), "center": (0, 0, 0)}),
        ("cube([1, 2, 3], true);", "box", {"size": (1, 2, 3), "center": (0, 0, 0)}),
        ("cube(5);", "box", {"size": (5, 5, 5), "center": (2.5, 2.5, 2.5)}),
        ("cube();", "box", {"size": (1, 1, 1), "center": (0.5, 0.5, 0.5)}),
        ("cube(size = undef, center = undef);", "box", {"size": (1, 1, 1), "center": (0.5, 0.5, 0.5)}),
        ("sphere($fn = 0, $fa = 12, $fs = 2, r = 5);", "sphere", {"radius": 5}),
        ("sphere(5);", "sphere", {"radius": 5}),
        ("sphere(d = 3);", "sphere", {"radius": 1.5}),
        ("sphere();", "sphere", {"radius": 1}),
        ("sphere(r = undef);", "sphere", {"radius": 1}),
        ("cylinder(h = 10, r1 = 2, r2 = 2, center = false);", "cylinder", {"height": 10, "radius": 2, "center": (0, 0, 5)}),
        ("cylinder(h = 10, r = 2, center = true);", "cylinder", {"height": 10, "radius": 2, "center": (0, 0, 0)}),
        ("cylinder(h = 4, d = 6);", "cylinder", {"height": 4, "radius": 3, "center": (0, 0, 2)}),
        ("cylinder();", "cylinder", {"height": 1, "radius": 1, "center": (0, 0, 0.5)}),
        ("cylinder(10, 2, 1);", "cone", {"height": 10, "r1": 2, "r2": 1, "center": (0, 0, 5)}),
        ("cylinder(10, 2, 1, true);", "cone", {"height": 10, "r1": 2, "r2": 1, "center": (0, 0, 0)}),
        ("cylinder(10, 2);", "cone", {"height": 10, "r1": 2, "r2": 1}),  # OpenSCAD: r2 defaults to 1
        ("cylinder(h = 4, d1 = 6, d2 = 0);", "cone", {"height": 4, "r1": 3, "r2": 0}),
        ("cylinder(h = 4, r1 = 0, r2 = 3);", "cone", {"height": 4, "r1": 0, "r2": 3}),
        ("cylinder(h = 3, r = 5, r1 = 2);", "cone", {"height": 3, "r1": 2, "r2": 5}),
        ("cylinder(h = 3, d1 = 4, r1 = 9, r2 = undef);", "cone", {"height": 3, "r1": 2, "r2": 1}),
    ],
)
def test_primitive_forms(text, kind, params):
    p = only_primitive(text)
    assert p.kind == kind
    for k, v in params.items():
        np.testing.assert_allclose(p.params[k], v, err_msg=k)
    assert p.color == (0.8, 0.8, 0.8, 1.0)


def test_cylinder_and_cone_geometry_runs_from_zero_to_h():
    shape = quiet_parse("cylinder(h = 4, r1 = 2, r2 = 0);").shape
    inside = contains(shape, [[0, 0, 0.01], [1.9, 0, 0.01], [0, 0, 3.9], [0.9, 0, 2.1], [0, 0, -0.01], [1.1, 0, 2.0]])
    assert inside.tolist() == [True, True, True, True, False, False]
    cube = quiet_parse("cube([1, 2, 3]);").shape
    assert contains(cube, [[0.99, 1.99, 2.99], [0.01, 0.01, 0.01], [-0.01, 1, 1]]).tolist() == [True, True, False]


def test_ignored_tessellation_and_extra_arguments_warn_only_when_odd():
    _, w = warnings_of("sphere($fn = 100, $fa = 1, $fs = 0.1, r = 2); cylinder($fn = 0, h = 1, r = 1);")
    assert w == []
    _, w = warnings_of("cylinder(h = 2, r = 3, $fn = 6);")
    assert len(w) == 1 and "6-sided" in w[0] and "t.csg:1:24" in w[0]
    _, w = warnings_of("cube(size = 1, colour = 3);\ncube(1, false, 7);")
    assert "t.csg:1:16: cube(): unknown argument 'colour' ignored" in w[0]
    assert "t.csg:2:16: cube(): too many unnamed arguments" in w[1]


def test_bad_argument_values_fall_back_like_openscad():
    scene, w = warnings_of("cube(size = [1, 2]);")
    assert scene.shape.params["size"] == (1.0, 1.0, 1.0) and "unable to convert size" in w[0]
    scene, w = warnings_of("cube(3, center = 1);")
    assert scene.shape.params["center"] == (1.5, 1.5, 1.5) and "not true or false" in w[0]
    scene, w = warnings_of('sphere(r = "big");')
    assert scene.shape.params["radius"] == 1.0 and "not a number" in w[0]
    scene, w = warnings_of("cube(1) { sphere(5); }")
    assert scene.shape.kind == "box" and "does not support child nodes" in w[0]
    scene, w = warnings_of("cylinder(h = 2, r = 1, r1 = 3);")
    assert scene.shape.kind == "cone" and "ambiguous" in w[0]


# -- numbers and values -----------------------------------------------------------------------
def test_numbers_exponents_and_negative_zero():
    p = only_primitive("cube(size = [1e-05, 2., 3.5E+2]);")
    np.testing.assert_allclose(p.params["size"], (1e-5, 2.0, 350.0))
    p = only_primitive("sphere(r = .5e1);")
    assert p.params["radius"] == 5.0
    m = quiet_parse("multmatrix([[1, -0, 0, -3.5E+2], [0, 1, 0, 1e-05], [0, 0, 1, -0], [-0, -0.0, 0, 1]]) sphere(1);")
    assert isinstance(m.shape, Transformed)
    np.testing.assert_array_equal(m.shape.matrix[:3, 3], [-350.0, 1e-5, 0.0])
    assert math.copysign(1.0, m.shape.matrix[2, 3]) == -1.0  # -0 stays negative zero


def test_six_digit_rotation_matrices_load_and_are_not_singular():
    text = (
        "multmatrix([[0.707107, -0.707107, 0, 0], [0.707107, 0.707107, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]]) {\n"
        "\tmultmatrix([[0.813798, -0.44097, 0.378522, 0], [0.469846, 0.882564, 0.0180283, 0], "
        "[-0.34202, 0.163176, 0.925417, 0], [0, 0, 0, 1]]) {\n"
        "\t\tcube(size = [1, 2, 3], center = true);\n\t}\n}\n"
    )
    scene, w = warnings_of(text)
    assert w == []
    outer = scene.shape
    assert isinstance(outer, Transformed) and isinstance(outer.operand, Transformed)
    assert abs(np.linalg.det(outer.matrix[:3, :3]) - 1) < 1e-5
    assert normalize(outer).n_terms == 1


def test_matrix_forms_follow_openscad():
    # missing rows/entries come from the identity; m is divided by m[3][3]
    s = quiet_parse("multmatrix([[1, 0, 0, 5], [0, 1, 0, 0]]) sphere(1);").shape
    np.testing.assert_array_equal(s.matrix[:3, 3], [5, 0, 0])
    s = quiet_parse("multmatrix([[2, 0, 0, 0], [0, 2, 0, 0], [0, 0, 2, 0], [0, 0, 0, 2]]) sphere(1);").shape
    assert isinstance(s, Primitive)  # the identity after dividing by w
    s, w = warnings_of("multmatrix([[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [0.5, 0, 0, 1]]) sphere(1);")
    assert isinstance(s.shape, Primitive) and "projective" in w[0]


def test_strings_escapes_ranges_comments_and_trailing_commas():
    scene, w = warnings_of((DATA / "comments.csg").read_text())
    assert w == []
    kinds = sorted(p.kind for p in primitives(scene.shape))
    assert kinds == ["box", "cylinder", "sphere"]
    sph = next(p for p in primitives(scene.shape) if p.kind == "sphere")
    assert sph.color == (1.0, 0.0, 0.0, 1.0)  # "\x72ed" is "red"
    # ranges and odd values parse (they occur in arguments of nodes clcsg ignores)
    s = quiet_parse('render(convexity = [0 : 2 : 10]) { group(a = [1 : 3], b = "\\"q\\" \\u00e9", c = []) sphere(1); }')
    assert isinstance(s.shape, Primitive)


# -- Booleans, groups and empties -------------------------------------------------------------
def test_group_union_difference_intersection_semantics():
    text = """
    group() { cube(2, true); sphere(1.5); }
    difference() { cube(10, true); sphere(4); cylinder(h = 20, r = 1, center = true); }
    intersection() { sphere(3); cube(4, true); cylinder(h = 10, r = 1.8, center = true); }
    union() { cube(1); }
    render(convexity = 2) { sphere(0.5); sphere(0.25); }
    """
    shape = quiet_parse(text).shape
    assert isinstance(shape, Union) and len(shape.operands) == 5
    g, d, i, u, r = shape.operands
    assert isinstance(g, Union) and len(g.operands) == 2
    assert isinstance(d, Difference) and len(d.operands) == 3
    assert isinstance(i, Intersection) and len(i.operands) == 3
    assert isinstance(u, Primitive)
    assert isinstance(r, Union)
    twin = union(
        union(box(2), sphere(1.5)),
        Difference([box(10), sphere(4), cylinder(20, 1)]),
        Intersection([sphere(3), box(4), cylinder(10, 1.8)]),
        box(1, center=(0.5, 0.5, 0.5)),
        union(sphere(0.5), sphere(0.25)),
    )
    same_dnf(shape, twin)
    same_membership(shape, twin)


def test_multmatrix_applies_to_union_of_children():
    s = quiet_parse("multmatrix([[1, 0, 0, 10], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]]) { cube(1); sphere(1); }").shape
    assert isinstance(s, Transformed) and isinstance(s.operand, Union)
    assert contains(s, [[10.5, 0.5, 0.5], [9.5, 0, 0], [0.5, 0.5, 0.5]]).tolist() == [True, True, False]


def test_empty_groups_and_nodes_give_nothing():
    scene, w = warnings_of((DATA / "empty.csg").read_text(), source="empty.csg")
    assert isinstance(scene.shape, Union) and scene.shape.operands == ()
    assert any("the model is empty" in m for m in w)
    dnf = normalize(scene.shape)
    assert dnf.n_terms == 0 and dnf.n_quadrics == 0
    assert quiet_parse("group();").shape.operands == ()
    assert quiet_parse("").shape.operands == ()
    assert quiet_parse("  // nothing\n").shape.operands == ()


def test_empty_children_are_dropped_like_openscad():
    scene = quiet_load(DATA / "empty_children.csg")
    twin = union(box(1, center=(0.5, 0.5, 0.5)), difference(box(2), sphere(1.25)), union(sphere(0.5)))
    same_dnf(scene.shape, twin)
    same_membership(scene.shape, twin)
    # nothing from the shape tree is an empty union: "nothing" was simplified away
    assert not any(isinstance(n, Union) and not n.operands for n in walk(scene.shape))


def test_empty_first_child_of_difference_and_empty_intersection_operand():
    assert quiet_parse("difference() { cube(0); cube(1); }").shape.operands == ()
    assert quiet_parse("intersection() { cube(1); sphere(0); }").shape.operands == ()
    assert quiet_parse("difference() { cube(1); group(); }").shape.kind == "box"
    assert quiet_parse("difference() { %cube(5); cube(1); }").shape.kind == "box"  # background skipped


def test_degenerate_primitives_warn_with_line_and_column():
    scene, w = warnings_of((DATA / "degenerate.csg").read_text(), source="degenerate.csg")
    assert isinstance(scene.shape, Primitive) and scene.shape.params["size"] == (2.0, 2.0, 2.0)
    where = [m.split(": ")[0] for m in w]
    assert where == [f"degenerate.csg:{line}:1" for line in (2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 15)]
    assert "cube(size = [1, 0, 1]) is empty" in w[1]
    assert "sphere(r = -1) is empty" in w[4]
    assert "cylinder(h = 0) is empty" in w[5]
    assert "singular" in w[10] and "NaN or infinity" in w[11]


# -- colors -----------------------------------------------------------------------------------
def test_colors_by_name_vector_and_hex():
    scene = quiet_load(DATA / "colors.csg")
    got = [p.color for p in quiet_load(DATA / "colors.csg").shape.operands]
    assert len(got) == 11 and scene.shape.operands
    expected = [
        (1, 0, 0, 1),
        rgb("steelblue", 0.5),
        (0, 0, 1, 1),
        (0, 1, 0, 0.25),
        (1, 128 / 255, 0, 1),
        (0, 1, 0, 8 / 15),
        rgb("lightgoldenrodyellow", 0.75),
        (1, 0, 0, 1),  # nested: the outer color wins, as in OpenSCAD
        (0, 1, 0, 1),  # color([-1, -1, -1, 1]) sets nothing: the inner lime applies
        (0, 0, 0, 0),  # "transparent"
        (0.8, 0.8, 0.8, 1),  # uncolored: clcsg's default
    ]
    for g, e in zip(got, expected):
        np.testing.assert_allclose(g, e, atol=1e-12)


def test_color_table_is_complete():
    assert len(WEB_COLORS) == 149  # the 148 CSS Color 4 names (gray/grey twins too) + "transparent"
    for name in ("rebeccapurple", "darkslategrey", "lightgoldenrodyellow", "aqua", "fuchsia"):
        assert name in WEB_COLORS
    for name, value in WEB_COLORS.items():
        p = only_primitive(f'color("{name.upper()}") cube(1);')
        np.testing.assert_allclose(p.color[:3], np.array(value[:3]) / 255)


@pytest.mark.parametrize(
    "arg, expected",
    [
        ('"#FF0000"', (1, 0, 0, 1)),
        ('"#f00"', (1, 0, 0, 1)),
        ('"#f008"', (1, 0, 0, 8 / 15)),
        ('"#00ff0080"', (0, 1, 0, 128 / 255)),
        ('"red", 0.5', (1, 0, 0, 0.5)),
        ("c = [0.2, 0.4, 0.6], alpha = 0.1", (0.2, 0.4, 0.6, 0.1)),
        ("[0.2, 0.4]", (0.2, 0.4, 1, 1)),
        ("[1, 0, 0, 1, 0]", (1, 0, 0, 1)),  # extra components (texture index) ignored
    ],
)
def test_color_forms(arg, expected):
    np.testing.assert_allclose(only_primitive(f"color({arg}) cube(1);").color, expected)


def test_bad_colors_warn_and_set_nothing():
    scene, w = warnings_of('color("no-such-color") color("blue") cube(1);')
    assert scene.shape.color == (0, 0, 1, 1) and "unable to parse color" in w[0]
    scene, w = warnings_of("color([2, 0.5, -0.0]) cube(1);")
    assert scene.shape.color == (1, 0.5, 0, 1) and "clamped" in w[0]
    scene, w = warnings_of("color([1, 0.5, -0.5]) cube(1);")
    assert scene.shape.color == (0.8, 0.8, 0.8, 1) and "negative" in w[0]


# -- modifiers --------------------------------------------------------------------------------
def test_modifiers():
    scene, w = warnings_of((DATA / "modifiers.csg").read_text())
    assert w == []
    ops = scene.shape.operands
    assert len(ops) == 4  # * and % subtrees are left out, # renders normally
    assert contains(scene.shape, [[20.5, 0.5, 0.5], [0, 0, 4.5], [-5, 0, 0]]).tolist() == [False, False, True]


def test_root_modifier_takes_subtree_without_ancestors():
    scene, w = warnings_of((DATA / "root.csg").read_text(), source="root.csg")
    p = scene.shape
    assert isinstance(p, Primitive) and p.kind == "cylinder"
    assert p.color == (0.8, 0.8, 0.8, 1.0)  # the red color() above it is not part of the subtree
    np.testing.assert_allclose(p.params["center"], (0, 0, 1))  # no translation either
    assert len(w) == 1 and w[0].startswith("root.csg:10:2: more than one root modifier") and "root.csg:4:5" in w[0]
    assert quiet_parse("%!cube(1); sphere(1);").shape.operands == ()  # a background root is nothing
    assert quiet_parse("cube(1); #!#sphere(2);").shape.kind == "sphere"
    assert len(quiet_parse("cube(1) !sphere(2); cylinder();").shape.operands) == 2  # children of a primitive are never used
