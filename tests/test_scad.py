"""``.scad`` input through the real ``openscad`` binary, the example models, deep nesting.

* ``clcsg.load("model.scad")`` runs ``openscad -o TMP.csg model.scad`` (clcsg.readers.scad): the
  examples/*.scad models export and load, and the committed examples/*.csg are their exports;
  OpenSCAD's errors, a missing binary and a timeout are one-line SceneErrors.
* Nodes nested 1,000 and 10,000 deep load (parser and evaluator use explicit stacks); JSON
  scenes write deep chains with "defs"/"ref" (Python's json module cannot read ~1000 levels).

Tests that need OpenSCAD fail under CI ($CI set: .ci/run installs it) and are skipped with a
reason elsewhere.
"""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
import time
import warnings
from collections import Counter
from pathlib import Path

import pytest

import clcsg
from clcsg.errors import SceneError
from clcsg.readers import openscad as openscad_module
from clcsg.readers import scenefile
from clcsg.readers.openscad import MAX_NODE_DEPTH, OpenScadWarning, parse_csg
from clcsg.readers.scad import DEFAULT_TIMEOUT, export_csg, find_openscad, load_scad
from clcsg.model.csg import Difference, Primitive, Shape, Transformed, Union, walk

EXAMPLES = Path(__file__).resolve().parent.parent / "examples"

#: the OpenSCAD release that wrote the committed examples/*.csg (Debian 12's package)
EXPORTED_WITH = "2021.01"

#: example -> (primitive count, primitive kinds, colors by name besides the default gray)
MODELS = {
    "pipe_flange": (38, {"cylinder": 36, "cone": 2}, {"slategray"}),
    "rook": (17, {"cylinder": 6, "box": 6, "cone": 4, "sphere": 1}, {"ivory", "darkgreen"}),
    "project_box": (27, {"cylinder": 21, "box": 6}, {"dimgray", "orange"}),
    "l_bracket": (18, {"cylinder": 9, "box": 5, "cone": 4}, {"silver"}),
    "plate_12_holes": (49, {"cylinder": 24, "cone": 24, "box": 1}, {"lightsteelblue"}),
    "menger3": (220, {"box": 220}, {"gold"}),
}

#: what the primitive-only examples above use (the construction examples, rounded_box, rounded_plate,
#: knob and pen_stand, are tested in test_constructions.py)
ALLOWED_MODULES = {"cube", "sphere", "cylinder", "union", "difference", "intersection", "translate",
                   "rotate", "scale", "mirror", "multmatrix", "color"}
UNSUPPORTED = {"hull", "minkowski", "linear_extrude", "rotate_extrude", "polyhedron", "polygon", "text",
               "square", "circle", "import", "surface", "projection", "offset", "resize", "render"}


# -- helpers ------------------------------------------------------------------------------------
def _openscad_or_skip() -> str:
    try:
        return find_openscad()
    except SceneError as e:
        if os.environ.get("CI"):
            pytest.fail(f"CI must test with the real OpenSCAD (.ci/run installs it): {e}")
        pytest.skip(f"OpenSCAD is not installed (apt-get install openscad, or set $OPENSCAD): {e}")


@pytest.fixture(scope="module")
def openscad() -> str:
    return _openscad_or_skip()


@pytest.fixture(scope="module")
def openscad_version(openscad) -> str:
    p = subprocess.run([openscad, "--version"], capture_output=True, text=True, timeout=60)
    m = re.search(r"OpenSCAD version (\S+)", p.stdout + p.stderr)
    return m.group(1) if m else "unknown"


def primitives(shape: Shape) -> list[Primitive]:
    return [n for n in walk(shape) if isinstance(n, Primitive)]


def quiet_load(path):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return clcsg.load(path)


def chain_csg(n: int) -> str:
    """n nested differences as OpenSCAD writes them: a cube minus n spheres, one per level."""
    lines = []
    for i in range(n):
        lines.append("\t" * i + "difference() {")
    lines.append("\t" * n + "cube(size = [10, 10, 10], center = true);")
    for i in reversed(range(n)):
        lines.append("\t" * (i + 1) + f"multmatrix([[1, 0, 0, {i % 9 - 4}], [0, 1, 0, 0], [0, 0, 1, 5], [0, 0, 0, 1]]) {{")
        lines.append("\t" * (i + 2) + "sphere($fn = 0, $fa = 12, $fs = 2, r = 0.5);")
        lines.append("\t" * (i + 1) + "}")
        lines.append("\t" * i + "}")
    return "\n".join(lines) + "\n"


def chain_depth(shape: Shape) -> int:
    depth = 0
    while isinstance(shape, Difference):
        depth += 1
        shape = shape.operands[0]
    return depth


# -- the example models -------------------------------------------------------------------------
@pytest.mark.parametrize("name", sorted(MODELS))
def test_example_uses_only_supported_modules(name):
    text = (EXAMPLES / f"{name}.scad").read_text()
    code = re.sub(r"//[^\n]*|/\*.*?\*/", "", text, flags=re.S)
    called = set(re.findall(r"\b([A-Za-z_]\w*)\s*\(", code))
    defined = set(re.findall(r"\bmodule\s+([A-Za-z_]\w*)", code))
    builtins_used = called - defined - {"for", "if", "let", "atan", "sqrt", "pow", "abs", "len", "max", "min"}
    assert not builtins_used & UNSUPPORTED, builtins_used & UNSUPPORTED
    assert builtins_used <= ALLOWED_MODULES, builtins_used - ALLOWED_MODULES
    assert re.search(r"^\$fn\s*=", code, re.M) or name == "menger3"  # as a user sets it (no curves in a sponge)


@pytest.mark.parametrize("name", sorted(MODELS))
def test_committed_csg_loads(name):
    count, kinds, colors = MODELS[name]
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # a clean export loads without any warning
        scene = clcsg.load(EXAMPLES / f"{name}.csg")
    prims = primitives(scene.shape)
    assert len(prims) == count
    assert Counter(p.kind for p in prims) == kinds
    want = {tuple(round(x * 255) for x in clcsg_color(c)) for c in colors}
    got = {tuple(round(x * 255) for x in p.color[:3]) for p in prims}
    assert want <= got, (want, got)


def clcsg_color(name):
    from clcsg.readers.openscad import WEB_COLORS

    return [x / 255 for x in WEB_COLORS[name][:3]]


@pytest.mark.parametrize("name", sorted(MODELS))
def test_example_scad_exports_like_the_committed_csg(name, openscad, openscad_version, tmp_path):
    fresh = tmp_path / f"{name}.csg"
    t0 = time.perf_counter()
    assert export_csg(EXAMPLES / f"{name}.scad", fresh) == []  # no OpenSCAD warnings
    assert time.perf_counter() - t0 < 60
    committed = (EXAMPLES / f"{name}.csg").read_text()
    if openscad_version == EXPORTED_WITH:
        assert fresh.read_text() == committed, f"re-export with: openscad -o examples/{name}.csg examples/{name}.scad"
    a, b = quiet_load(fresh), quiet_load(EXAMPLES / f"{name}.csg")
    assert [p.kind for p in primitives(a.shape)] == [p.kind for p in primitives(b.shape)]


@pytest.mark.parametrize("name", sorted(MODELS))
def test_example_scad_loads_directly(name, openscad):
    path = EXAMPLES / f"{name}.scad"
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        scene = clcsg.load(path)
    assert scene.source == str(path)
    assert scene.bound is None
    assert len(primitives(scene.shape)) == MODELS[name][0]


def test_scad_parameters_are_real_parameters(openscad, tmp_path):
    # the models are parametric: a user's override goes through OpenSCAD (-D via an include)
    src = tmp_path / "flange8.scad"
    src.write_text(f"include <{(EXAMPLES / 'pipe_flange.scad').as_posix()}>\nbolts = 8;\n")
    scene = clcsg.load(src)
    assert len(primitives(scene.shape)) == 38 - 16


# -- .scad errors -------------------------------------------------------------------------------
def test_syntax_error_is_one_line_naming_file_and_line(openscad, tmp_path):
    bad = tmp_path / "bad.scad"
    bad.write_text("$fn = 32;\ncube(10);\ntranslate([1, 2, 3] sphere(2);\n")
    with pytest.raises(SceneError) as ei:
        clcsg.load(bad)
    msg = str(ei.value)
    assert "\n" not in msg
    assert msg.startswith(f"{bad}: openscad failed (exit code 1): ERROR: ")
    assert re.search(r"syntax error.* bad\.scad, line 3", msg), msg
    assert ei.value.exit_code == 3


def test_runtime_error_fails_even_with_exit_status_0(openscad, tmp_path):
    bad = tmp_path / "assert.scad"
    bad.write_text('wall = 0.4;\nassert(wall >= 1, "walls under 1 mm do not print");\ncube(10);\n')
    with pytest.raises(SceneError, match=r"assert\.scad: openscad .*ERROR: Assertion .* line 2") as ei:
        clcsg.load(bad)
    assert "\n" not in str(ei.value)


def test_openscad_warnings_become_openscad_warnings(openscad, tmp_path):
    src = tmp_path / "typo.scad"
    src.write_text("cube(10);\ntranslate([20, 0, 0]) cylindr(h = 5, r = 2);\n")
    with pytest.warns(OpenScadWarning, match=r"typo\.scad: OpenSCAD: WARNING: Ignoring unknown module 'cylindr'.* line 2"):
        scene = clcsg.load(src)
    assert len(primitives(scene.shape)) == 1


def test_unsupported_node_in_the_export_names_the_scad_file(openscad, tmp_path):
    src = tmp_path / "hull.scad"
    src.write_text("cube(1);\nhull() { cylinder(1); translate([3, 0, 0]) sphere(1); }\n")
    with pytest.raises(SceneError) as ei:
        clcsg.load(src)
    assert str(ei.value).startswith(f"{src} (CSG export):2:1: hull(): hull() of 1 cylinder and 1 sphere is not covered exactly")


def test_empty_model_loads_empty_with_a_warning(openscad, tmp_path):
    src = tmp_path / "empty.scad"
    src.write_text("size = 10;\n")
    with pytest.warns(OpenScadWarning, match="empty"):
        scene = clcsg.load(src)
    assert isinstance(scene.shape, Union) and not scene.shape.operands


def test_openscad_not_found(monkeypatch, tmp_path):
    src = tmp_path / "m.scad"
    src.write_text("cube(1);\n")
    monkeypatch.setenv("OPENSCAD", "/nonexistent")
    with pytest.raises(SceneError) as ei:
        clcsg.load(src)
    msg = str(ei.value)
    assert msg == f"{src}: OpenSCAD not found: $OPENSCAD=/nonexistent is not an executable file; install OpenSCAD or set $OPENSCAD"
    monkeypatch.delenv("OPENSCAD")
    monkeypatch.setenv("PATH", str(tmp_path))
    with pytest.raises(SceneError, match=r"not found: no 'openscad' on PATH; install OpenSCAD or set \$OPENSCAD$"):
        clcsg.load(src)


@pytest.mark.skipif(sys.platform == "win32", reason="uses a shell script as a fake openscad")
def test_timeout_stops_openscad(monkeypatch, tmp_path):
    fake = tmp_path / "slow-openscad"
    fake.write_text("#!/bin/sh\nexec sleep 30\n")
    fake.chmod(0o755)
    src = tmp_path / "m.scad"
    src.write_text("cube(1);\n")
    monkeypatch.setenv("OPENSCAD", str(fake))
    t0 = time.perf_counter()
    with pytest.raises(SceneError, match=r"m\.scad: openscad did not finish within 0\.5 s and was stopped"):
        load_scad(src, timeout=0.5)
    monkeypatch.setenv("CLCSG_OPENSCAD_TIMEOUT", "0.3")
    with pytest.raises(SceneError, match=r"within 0\.3 s"):
        clcsg.load(src)
    assert time.perf_counter() - t0 < 10
    monkeypatch.setenv("CLCSG_OPENSCAD_TIMEOUT", "soon")
    with pytest.raises(SceneError, match=r"CLCSG_OPENSCAD_TIMEOUT must be a positive number of seconds, got 'soon'"):
        clcsg.load(src)
    assert DEFAULT_TIMEOUT == 120


@pytest.mark.skipif(sys.platform == "win32", reason="uses a shell script as a fake openscad")
def test_openscad_that_writes_nothing(monkeypatch, tmp_path):
    fake = tmp_path / "fake-openscad"
    fake.write_text("#!/bin/sh\necho 'Segmentation fault' >&2\nexit 139\n")
    fake.chmod(0o755)
    src = tmp_path / "m.scad"
    src.write_text("cube(1);\n")
    monkeypatch.setenv("OPENSCAD", str(fake))
    with pytest.raises(SceneError, match=r"m\.scad: openscad failed \(exit code 139\): Segmentation fault$"):
        clcsg.load(src)
    fake.write_text("#!/bin/sh\nexit 0\n")
    with pytest.raises(SceneError, match=r"m\.scad: openscad exited without writing m\.csg"):
        clcsg.load(src)


def test_missing_scad_and_unknown_extension(tmp_path):
    with pytest.raises(SceneError, match=r"nope\.scad: no such file"):
        clcsg.load(tmp_path / "nope.scad")
    other = tmp_path / "model.stl"
    other.write_text("solid x\nendsolid x\n")
    with pytest.raises(SceneError, match=r"unknown scene format '\.stl' \(expected \.json, \.csg or \.scad\)"):
        clcsg.load(other)


# -- deep nesting: OpenSCAD ---------------------------------------------------------------------
def test_1000_nested_differences_load():
    scene = parse_csg(chain_csg(1000), "chain.csg")
    assert chain_depth(scene.shape) == 1000
    assert len(primitives(scene.shape)) == 1001
    assert isinstance(scene.shape.operands[1], Transformed)


def test_1000_nested_differences_load_from_a_file(tmp_path):
    path = tmp_path / "chain.csg"
    path.write_text(chain_csg(1000))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        scene = clcsg.load(path)
    assert chain_depth(scene.shape) == 1000


def test_10000_levels_without_recursion_error():
    n = 10_000
    text = "union() {\n" * n + "color(\"red\") multmatrix([[2, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]]) " * 3
    text += "cube(1);\n" + "}\n" * n
    scene = parse_csg(text, "deep.csg")
    (prim,) = primitives(scene.shape)
    assert prim.color == (1.0, 0.0, 0.0, 1.0)
    # single children without braces nest as deeply
    scene = parse_csg("group() " * n + "difference() { cube(2); sphere(1); }", "deep.csg")
    assert isinstance(scene.shape, Difference)
    # errors deep down still name line and column
    with pytest.raises(SceneError, match=r"^deep\.csg:10001:1: hull\(\): hull\(\) of 1 cylinder and 1 sphere is not covered"):
        parse_csg("group() {\n" * n + "hull() { cylinder(h = 1, r = 1); multmatrix([[1, 0, 0, 3], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]]) sphere(1); }" + "}" * n, "deep.csg")
    with pytest.raises(SceneError, match=r"^deep\.csg:1:\d+: syntax error: expected '\}', got end of file"):
        parse_csg("group() {" * n, "deep.csg")


def test_node_depth_limit_is_a_scene_error(monkeypatch):
    assert MAX_NODE_DEPTH >= 10_000
    monkeypatch.setattr(openscad_module, "MAX_NODE_DEPTH", 50)
    assert parse_csg("group() " * 50 + "cube(1);", "deep.csg").shape.kind == "box"
    with pytest.raises(SceneError, match=r"^deep\.csg:1:409: nodes nested deeper than 50 levels are not supported$"):
        parse_csg("group() " * 51 + "cube(1);", "deep.csg")
    with pytest.raises(SceneError, match="nodes nested deeper than 50 levels"):
        parse_csg("group() {" * 51, "deep.csg")
    with pytest.raises(SceneError, match="values nested deeper than 100 levels are not supported"):
        parse_csg("cube(" + "[" * 5000, "deep.csg")


def test_1000_nested_differences_from_scad(openscad, tmp_path):
    n = 1000
    src = tmp_path / "chain.scad"
    src.write_text("difference() {\n" * n + "cube(10, center = true);\n"
                   + "".join(f"translate([{i % 9 - 4}, 0, 5]) sphere(0.5);\n}}\n" for i in range(n)))
    scene = clcsg.load(src)
    assert chain_depth(scene.shape) == n
    assert scene.source == str(src)


# -- deep nesting: JSON scenes ------------------------------------------------------------------
def _chain_dict(n):
    node = {"box": {"size": 10}}
    for i in range(n):
        node = {"difference": [node, {"sphere": {"radius": 0.5, "center": [i % 9 - 4, 0, 5]}}]}
    return node


def test_1000_nested_levels_of_json_text():
    # why deep chains are written with defs: json.loads recurses once per array and object, and
    # Python 3.11's json cannot read the 2000 levels of 1000 nested differences
    text = ('{"clcsg": 1, "root": ' + '{"difference": [' * 1000 + '{"box": {"size": 10}}'
            + ', {"sphere": {"radius": 0.5}}]}' * 1000 + "}")
    try:
        json.loads(text)
    except RecursionError:
        with pytest.raises(SceneError, match=r"^deep\.json: \$: nesting too deep$"):
            scenefile.loads_json(text, "deep.json")
    else:  # a json module that can: then the loader must too
        assert chain_depth(scenefile.loads_json(text, "deep.json").shape) == 1000


def test_json_chain_of_1000_defs_loads(tmp_path):
    n = 1000
    defs = {"d0": {"box": {"size": 10}}}
    for i in range(1, n + 1):
        defs[f"d{i}"] = {"difference": [{"ref": f"d{i - 1}"}, {"sphere": {"radius": 0.5, "center": [i % 9 - 4, 0, 5]}}]}
    path = tmp_path / "chain.json"
    path.write_text(json.dumps({"clcsg": 1, "defs": defs, "root": {"ref": f"d{n}"}}, indent=1))
    scene = clcsg.load(path)
    assert chain_depth(scene.shape) == n
    assert len(primitives(scene.shape)) == n + 1
    # errors deep in the chain keep their JSON path, cycles are still found
    defs["d500"]["difference"][1]["sphere"]["radius"] = -1
    with pytest.raises(SceneError, match=r"^c: \$\.defs\.d500\.difference\[1\]\.sphere\.radius: must be positive, got -1$"):
        scenefile.scene_from_dict({"clcsg": 1, "defs": defs, "root": {"ref": f"d{n}"}}, "c")
    defs["d500"]["difference"][1]["sphere"]["radius"] = 0.5
    defs["d0"] = {"ref": "d1000"}
    with pytest.raises(SceneError, match=r"reference cycle: d1000 -> d999 -> .* -> d0 -> d1000$"):
        scenefile.scene_from_dict({"clcsg": 1, "defs": defs, "root": {"ref": f"d{n}"}}, "c")


def test_deep_python_dict_loads_and_saves_with_defs(tmp_path):
    n = 1000
    scene = scenefile.scene_from_dict({"clcsg": 1, "root": _chain_dict(n)}, "dict")
    assert chain_depth(scene.shape) == n
    path = tmp_path / "saved.json"
    clcsg.save(scene, path)
    text = path.read_text()
    data = json.loads(text)  # readable by json: the chain continues in defs
    assert scenefile.SAVE_DEPTH == 100 and len(data["defs"]) == 9  # root + 9 defs of 100 levels
    back = clcsg.load(path)
    assert chain_depth(back.shape) == n
    assert scenefile.dumps(scenefile.scene_to_dict(back)) == text  # bit for bit
    # a shallow scene is written as before: no defs
    assert "defs" not in scenefile.scene_to_dict(scenefile.scene_from_dict({"clcsg": 1, "root": _chain_dict(50)}))
