"""OpenSCAD CSG export reader: every bad input is a SceneError with its file, line and column
(unsupported nodes, syntax errors, file errors, deep nesting, overflow, fuzzed text)."""

from __future__ import annotations

import warnings
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from clcsg.model.csg import Union, walk
from clcsg.errors import SceneError
from clcsg.readers.openscad import MAX_DEPTH, load_csg, parse_csg
from clcsg.model.scene import Scene

from test_openscad import err, quiet_parse

DATA = Path(__file__).parent / "data" / "openscad"
EXAMPLES = Path(__file__).parent.parent / "examples"


# -- errors -----------------------------------------------------------------------------------
#: nodes without an exact quadric form (or 2-D where a solid is expected): line -> message
UNSUPPORTED = {
    'polyhedron(points = [[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], faces = [[0, 1, 2], [0, 3, 1], [0, 2, 3], [1, 2, 3]], convexity = 1);':
        "polyhedron(): edge 1-2 (1, 0, 0 to 0, 1, 0) is used twice in the same direction (faces 0 and 3): the faces are not consistently oriented",
    "polygon(points = [[0, 0], [1, 0], [0, 1]], paths = undef, convexity = 1);":
        "polygon() is a 2-D shape outside linear_extrude() or rotate_extrude(): it has no volume; nearest exact alternative: linear_extrude() it",
    "square(size = [1, 1], center = false);":
        "square() is a 2-D shape outside linear_extrude() or rotate_extrude(): it has no volume; nearest exact alternative: linear_extrude() it",
    "circle($fn = 0, $fa = 12, $fs = 2, r = 1);":
        "circle() is a 2-D shape outside linear_extrude() or rotate_extrude(): it has no volume; nearest exact alternative: linear_extrude() it",
    "offset(r = 1, $fn = 0, $fa = 12, $fs = 2) { square(size = [1, 1], center = false); }":
        "offset() is a 2-D shape outside linear_extrude() or rotate_extrude(): it has no volume; nearest exact alternative: linear_extrude() it",
    "rotate_extrude(angle = 360, convexity = 2, $fn = 0, $fa = 12, $fs = 2) { multmatrix([[1, 0, 0, 2], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]]) circle(r = 1); }":
        "rotate_extrude(): rotate_extrude() of a circle sweeps a torus, a quartic surface, not a quadric; nearest exact alternative: "
        "a polygon profile (its edges sweep cones and cylinders), or sphere() for a circle centered on the axis",
    "linear_extrude(height = 2, center = false, convexity = 1, twist = 30, scale = [1, 1], $fn = 0, $fa = 12, $fs = 2) { square(1); }":
        "linear_extrude(): twist = 30 sweeps helicoids, which are not quadric surfaces; nearest exact alternative: twist = 0 (rotate the whole extrusion instead)",
    'text(text = "hi", size = 10, spacing = 1, font = "", direction = "ltr", language = "en", script = "Latn", halign = "left", valign = "baseline", $fn = 0, $fa = 12, $fs = 2);':
        "text() is not supported: text() outlines glyphs with Bezier curves, not lines and arcs; nearest exact alternative: none (model lettering with polygons)",
    'import(file = "foo.stl", layer = "", origin = [0, 0], scale = 1, convexity = 1, $fn = 0, $fa = 12, $fs = 2, timestamp = 0);':
        "import(): foo.stl: no such file",
    "hull() { sphere(r = 1); multmatrix([[1, 0, 0, 3], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]]) cylinder(h = 1, r = 1); }":
        "hull(): hull() of 1 sphere and 1 cylinder is not covered exactly (spheres with cylinders or cones off their axis: "
        "the surface between a sphere and a circle is in general no quadric); nearest exact alternative: spheres centered "
        "on the cylinders' common axis, or hull the spheres and the cylinders separately",
    "minkowski(convexity = 0) { sphere(r = 1); cylinder(h = 1, r = 1); }":
        "minkowski(): minkowski() of spheres and cylinders is not covered exactly (it is a rounded cylinder, a torus edge); "
        "nearest exact alternative: a cube or polytope plus a sphere",
    'surface(file = "h.dat", center = false, invert = false, timestamp = 0);': "surface() is not supported: surface() is a height-map mesh",
    "projection(cut = false, convexity = 0) { sphere(r = 1); }":
        "projection() is not supported: projection() of a 3-D solid to 2-D has curved outlines of higher degree",
    "resize(newsize = [1,2,3], auto = [0,0,0], convexity = 0) { sphere(r = 1); }":
        "resize() is not supported: resize() depends on the child's mesh bounding box; nearest exact alternative: scale()",
    'roof(method = "voronoi") { square(1); }': "roof() is not supported: roof() builds a straight skeleton of a polygon, which is not covered",
    "frobnicate(1);": "frobnicate() is not supported: clcsg reads quadric solids only (cube, sphere, cylinder, their Booleans, "
                      "extrusions, hulls and Minkowski sums)",
}


@pytest.mark.parametrize("line", list(UNSUPPORTED), ids=lambda s: s.split("(")[0])
def test_unsupported_nodes(line):
    msg = err("group() {\n  " + line + "\n}\n", source="m.csg")
    assert msg == f"m.csg:2:3: {UNSUPPORTED[line]}"


def test_unsupported_node_in_file_reports_its_position():
    with pytest.raises(SceneError) as info:
        load_csg(DATA / "unsupported.csg")
    assert str(info.value) == (
        f"{DATA / 'unsupported.csg'}:4:3: rotate_extrude(): rotate_extrude() of a circle sweeps a torus, a quartic "
        "surface, not a quadric; nearest exact alternative: a polygon profile (its edges sweep cones and cylinders), "
        "or sphere() for a circle centered on the axis"
    )


def test_unsupported_nodes_in_disabled_or_background_subtrees_are_fine():
    assert quiet_parse("cube(1); *hull() { sphere(1); cube(1); } %text(text = \"x\");").shape.kind == "box"


def test_scad_source_gets_a_hint():
    for text in ("translate([1, 0, 0]) cube(1);", "module m() { cube(1); }", "$fn = 50;", "include <parts.scad>"):
        msg = err(text)
        assert 'openscad -o model.csg model.scad' in msg and msg.startswith("t.csg:1:")


@pytest.mark.parametrize(
    "text, expected",
    [
        ("cube(1)", "t.csg:1:8: syntax error: expected ';' or '{' after cube(...), got end of file"),
        ("group() {\n  cube(1)\n}", "t.csg:3:1: syntax error: expected ';' or '{' after cube(...), got '}'"),
        ("group() {\n  cube(1);\n", "t.csg:3:1: syntax error: expected '}', got end of file"),
        ("cube(1;", "t.csg:1:7: syntax error: expected ',' or ')', got ';'"),
        ("cube(size = );", "t.csg:1:13: syntax error: expected a value (number, string, vector, true, false or undef), got ')'"),
        ("cube(size = [1, 2 3]);", "t.csg:1:19: syntax error: expected ',' or ']' in the vector, got '3'"),
        ("cube(size = x);", "t.csg:1:13: syntax error: expected a value (number, string, vector, true, false or undef), got 'x': variables and expressions do not occur in CSG export"),
        ("sphere(r = -\"a\");", "t.csg:1:12: syntax error: '-' must be followed by a number"),
        ("cube 1;", "t.csg:1:6: syntax error: expected '(' after cube, got '1'"),
        ("}", "t.csg:1:1: syntax error: expected a node such as cube(...), group() or ';', got '}'"),
        ("cube(1); @", "t.csg:1:10: syntax error: unexpected character '@'"),
        ('color("red) cube(1);', "t.csg:1:7: syntax error: unterminated string (missing '\"')"),
        ("/* open", "t.csg:1:1: syntax error: unterminated comment (missing '*/')"),
        ("*;", "t.csg:1:2: syntax error: expected a node name after the modifier, got ';'"),
    ],
)
def test_syntax_errors(text, expected):
    assert err(text) == expected


def test_syntax_error_file():
    with pytest.raises(SceneError) as info:
        load_csg(DATA / "syntax_error.csg")
    assert str(info.value) == f"{DATA / 'syntax_error.csg'}:3:1: syntax error: expected ';' or '{{' after cube(...), got '}}'"


def test_file_errors(tmp_path):
    with pytest.raises(SceneError, match="no such file"):
        load_csg(tmp_path / "missing.csg")
    with pytest.raises(SceneError, match="cannot read"):
        load_csg(tmp_path)
    binary = tmp_path / "model.csg"
    binary.write_bytes(b"solid \x00\xff\xfe")
    with pytest.raises(SceneError, match=r"model.csg:1:7: syntax error: unexpected character"):
        load_csg(binary)
    bom = tmp_path / "bom.csg"
    bom.write_bytes("\ufeffcube(1);".encode())
    assert load_csg(bom).shape.kind == "box"


def test_deep_nesting_loads_and_deep_values_are_refused_cleanly():
    # nodes: explicit stacks, any depth up to MAX_NODE_DEPTH (tests/test_scad.py: 1,000 / 10,000)
    ok = "group() {" * 5000 + "sphere(1);" + "}" * 5000
    assert quiet_parse(ok).shape.kind == "sphere"
    assert quiet_parse("group() " * 5000 + "sphere(1);").shape.kind == "sphere"
    assert "expected '}', got end of file" in err("group() {" * 5000)
    # values: recursive, at most MAX_DEPTH levels
    assert quiet_parse("cube(" + "[" * (MAX_DEPTH - 1) + "]" * (MAX_DEPTH - 1) + ");").shape.kind == "box"
    for text in ("cube(" + "[" * 5000, "sphere(" + "-" * 5000 + "1);"):
        assert "nested deeper than" in err(text)


def test_primitive_overflow_is_a_scene_error():
    msg = err("sphere(r = 1e200);")
    assert msg.startswith("t.csg:1:1: sphere(): ")


# -- fuzz: no input text raises anything but SceneError ---------------------------------------
_SEEDS = sorted(DATA.glob("*.csg")) + sorted(EXAMPLES.glob("*.csg"))
_TEXTS = [p.read_text() for p in _SEEDS]
_CHARS = list(";{}()[],=:-+.eE0123456789\"'*%!#/\\ \n\tabcrxyz$_") + ["\x00", "é", "\u2028", "inf", "undef", "1e999", "-0"]


@st.composite
def mutated(draw):
    text = draw(st.sampled_from(_TEXTS))
    if len(text) > 3000:  # keep examples fast: a window of the big examples
        start = draw(st.integers(0, len(text) - 3000))
        text = text[start : start + 3000]
    for _ in range(draw(st.integers(1, 8))):
        op = draw(st.sampled_from(["delete", "duplicate", "replace", "insert"]))
        n = len(text)
        i = draw(st.integers(0, max(n - 1, 0)))
        j = min(n, i + draw(st.integers(1, 12)))
        c = draw(st.sampled_from(_CHARS))
        if op == "delete":
            text = text[:i] + text[j:]
        elif op == "duplicate":
            text = text[:j] + text[i:j] + text[j:]
        elif op == "replace":
            text = text[:i] + c + text[i + 1 :]
        else:
            text = text[:i] + c + text[i:]
    return text


@settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])
@given(mutated())
def test_fuzz_only_scene_errors(text):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        try:
            scene = parse_csg(text, source="fuzz.csg")
        except SceneError as e:
            msg = str(e)
            assert msg.startswith("fuzz.csg") and "\n" not in msg and "\r" not in msg
            return
    assert isinstance(scene, Scene)
    for node in walk(scene.shape):
        assert not (isinstance(node, Union) and not node.operands) or node is scene.shape


