"""The JSON scene format (clcsg/readers/scenefile.py): validation, every bad file a one-line
SceneError naming the file, the node and the reason."""

from __future__ import annotations

import glob
import os
import re

import numpy as np
import pytest

import clcsg
from clcsg.model import csg, solids
from clcsg.readers import scene_stream, scenefile
from clcsg.errors import SceneError, TransformError
from test_scenefile import assert_same_graph

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
EXAMPLES = sorted(glob.glob(os.path.join(ROOT, "examples", "*.json")))
SCHEMA_PATH = os.path.join(ROOT, "clcsg", "readers", "schema", "scene.schema.json")
UB = np.array([[-3.5, -3.5, -3.5], [3.5, 3.5, 3.5]])
N_EXAMPLES = int(os.environ.get("CLCSG_HYPOTHESIS_EXAMPLES", 40))



# -- validation -----------------------------------------------------------------------------------
def S(root, **top):
    """A scene document with ``root`` (a JSON text fragment) and extra top-level keys."""
    extra = "".join(f', "{k}": {v}' for k, v in top.items())
    return f'{{"clcsg": 1{extra}, "root": {root}}}'


BOX = '{"box": {}}'

BAD = [
    # syntax (line and column, no JSON path)
    ('{"clcsg": 1,', "line 1, column 13: invalid JSON: Expecting property name"),
    ('{\n  "clcsg": 1,\n  "root": {"box": {}},,\n}', "line 3, column 23: invalid JSON"),
    ("", "line 1, column 1: invalid JSON: Expecting value"),
    ('{"clcsg": 1, "root": {"box": {}}} trailing', "line 1, column 35: invalid JSON: Extra data"),
    # values Python's json accepts but JSON does not have
    (S('{"sphere": {"radius": NaN}}'), "$.root.sphere.radius: NaN is not allowed"),
    (S('{"sphere": {"center": [0, Infinity, 0]}}'), "$.root.sphere.center[1]: Infinity is not allowed"),
    (S('{"box": {"size": -Infinity}}'), "$.root.box.size: -Infinity is not allowed"),
    (S('{"sphere": {"radius": 1e999}}'), "$.root.sphere.radius: number out of range"),
    (S('{"sphere": {"radius": 1, "radius": 2}}'), "$.root.sphere.radius: duplicate key 'radius'"),
    # top level
    ("[1, 2]", "$: a scene file holds a JSON object, got array of 2"),
    ('{"root": {"box": {}}}', '$: missing key "clcsg"'),
    ('{"clcsg": 2, "root": {"box": {}}}', "$.clcsg: unsupported format version 2 (this clcsg reads version 1)"),
    ('{"clcsg": "1", "root": {"box": {}}}', "$.clcsg: the format version must be the integer 1, got string"),
    ('{"clcsg": true, "root": {"box": {}}}', "$.clcsg: the format version must be the integer 1, got boolean"),
    ('{"clcsg": 1.0, "root": {"box": {}}}', "$.clcsg: the format version must be the integer 1"),
    ('{"clcsg": 1}', '$: missing key "root"'),
    ('{"clcsg": 1, "roots": {"box": {}}}', "$.roots: unknown key 'roots' (did you mean 'root'?)"),
    (S(BOX, comment="3"), "$.comment: a comment must be a string, got number"),
    # bound
    (S(BOX, bound="[1, 2]"), "$.bound[0]: expected 3 numbers [x, y, z], got number"),
    (S(BOX, bound="[[0, 0, 0]]"), "$.bound: expected two corners"),
    (S(BOX, bound='[[0, 0, "a"], [1, 1, 1]]'), "$.bound[0][2]: expected a number, got string"),
    (S(BOX, bound="[[0, 0, 0], [1, 0, 1]]"), "$.bound: the lower corner [0, 0, 0] must be below the upper corner"),
    # nodes
    (S("[1]"), "$.root: expected a node object, got array of 1"),
    (S("{}"), "$.root: node has no kind; known primitives: box, cone, cylinder"),
    (S('{"transform": []}'), "$.root: node has no kind"),
    (S('{"cilinder": {}}'), "$.root.cilinder: unknown node kind 'cilinder' (did you mean 'cylinder'?); known primitives: box, cone, cylinder"),
    (S('{"torus": {}}'), "$.root.torus: unknown node kind 'torus'; known primitives: box,"),
    (S('{"box": {}, "sphere": {}}'), "$.root: a node has exactly one kind, this one has 'box' and 'sphere'"),
    (S('{"box": {}, "colour": [1, 0, 0]}'), "$.root.colour: unknown key 'colour' (did you mean 'color'?) in a box node"),
    (S('{"union": [], "colour": 1}'), "$.root.colour: unknown key 'colour' in a union node"),
    (S('{"box": {}, "comment": ["a"]}'), "$.root.comment: a comment must be a string"),
    # primitive parameters
    (S('{"box": [1, 2, 3]}'), "$.root.box: expected an object of box parameters (size, center), got array of 3"),
    (S('{"box": {"sise": 1}}'), "$.root.box.sise: unknown box parameter 'sise' (did you mean 'size'?); box takes size, center"),
    (S('{"quadric": {}}'), "$.root.quadric: missing quadric parameter 'matrix'"),
    (S('{"sphere": {"radius": "1"}}'), "$.root.sphere.radius: expected a positive number, got string"),
    (S('{"sphere": {"radius": true}}'), "$.root.sphere.radius: expected a positive number, got boolean"),
    (S('{"sphere": {"radius": null}}'), "$.root.sphere.radius: expected a positive number, got null"),
    (S('{"sphere": {"radius": 0}}'), "$.root.sphere.radius: must be positive, got 0"),
    (S('{"box": {"size": [1, -2, 1]}}'), "$.root.box.size[1]: must be positive, got -2"),
    (S('{"box": {"size": [1, 2]}}'), "$.root.box.size: expected a positive number or 3 positive numbers, got array of 2"),
    (S('{"box": {"size": -1}}'), "$.root.box.size: must be positive, got -1"),
    (S('{"difference": [{"box": {}}, {"cylinder": {"radius": -1}}]}'), "$.root.difference[1].cylinder.radius: must be positive, got -1"),
    (S('{"union": [{"box": {}}, {"difference": [{"box": {}}, {"sphere": {"center": [0, 0]}}]}]}'),
     "$.root.union[1].difference[1].sphere.center: expected 3 numbers [x, y, z], got array of 2"),
    (S('{"cylinder": {"axis": [0, 0, 0]}}'), "$.root.cylinder.axis: a direction must not be the zero vector"),
    (S('{"cone": {"r1": -1}}'), "$.root.cone.r1: must be non-negative, got -1"),
    (S('{"cone": {"r1": 0, "r2": 0}}'), "$.root.cone: cone needs r1 > 0 or r2 > 0"),
    (S('{"slab": {"lo": 1, "hi": 0}}'), "$.root.slab: slab needs lo < hi"),
    (S('{"ellipsoid": {"radii": [1, 0, 1]}}'), "$.root.ellipsoid.radii[1]: must be positive, got 0"),
    (S('{"elliptic_cylinder": {"radii": [1, 1, 1]}}'), "$.root.elliptic_cylinder.radii: expected 2 positive numbers, got array of 3"),
    (S('{"hyperboloid_one_sheet": {"radii": 1}}'), "$.root.hyperboloid_one_sheet.radii: expected 3 positive numbers, got number"),
    (S('{"halfspace": {"offset": "x"}}'), "$.root.halfspace.offset: expected a number, got string"),
    (S('{"quadric": {"matrix": [[1, 0, 0], [0, 1, 0], [0, 0, 1]]}}'), "$.root.quadric.matrix: expected a symmetric 4x4 matrix"),
    (S('{"quadric": {"matrix": [[1, 2, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, -1]]}}'),
     "$.root.quadric.matrix: quadric matrix must be symmetric"),
    (S('{"quadric": {"matrix": [[0, 0, 0, 0], [0, 0, 0, 0], [0, 0, 0, 0], [0, 0, 0, 0]]}}'),
     "$.root.quadric.matrix: quadric matrix must not be zero"),
    (S('{"quadric": {"matrix": [0, 0, 0, 0, 0, 0, 0, 0, 0, 0]}}'), "$.root.quadric.matrix: quadric matrix must not be zero"),
    (S('{"quadric": {"matrix": [1, 0, 0, 0, 1, 0, 0, 1, 0]}}'), "$.root.quadric.matrix: expected a symmetric 4x4 matrix (4 rows of 4 numbers) or 10 coefficients, got array of 9"),
    # colors
    (S('{"box": {}, "color": [1, 0]}'), '$.root.color: expected [r, g, b], [r, g, b, a], a color name or "#rrggbb[aa]", got array of 2'),
    (S('{"box": {}, "color": [1, 2, 0]}'), "$.root.color[1]: color components must be in [0, 1], got 2"),
    (S('{"box": {}, "color": [1, 0, 0, -0.5]}'), "$.root.color[3]: color components must be in [0, 1], got -0.5"),
    (S('{"box": {}, "color": [1, "0", 0]}'), "$.root.color[1]: expected a number, got string"),
    (S('{"box": {}, "color": "reddish"}'), "$.root.color: unknown color name 'reddish'"),
    (S('{"box": {}, "color": "stelblue"}'), "$.root.color: unknown color name 'stelblue' (did you mean 'steelblue'?)"),
    (S('{"box": {}, "color": "#12"}'), '$.root.color: expected a color name or "#rgb", "#rgba", "#rrggbb" or "#rrggbbaa", got \'#12\''),
    (S('{"box": {}, "color": "#12345"}'), "$.root.color: expected a color name or"),
    (S('{"box": {}, "color": 7}'), '$.root.color: expected [r, g, b], [r, g, b, a], a color name or "#rrggbb[aa]", got number'),
    (S('{"union": [], "color": [1, 0, 0]}'), "$.root.color: color is only allowed on primitives, not on a union node"),
    # transforms
    (S('{"box": {}, "transform": {"translate": [1, 2, 3]}}'), "$.root.transform: expected a list of transform steps"),
    (S('{"box": {}, "transform": [{"translate": [1, 2, 3], "scale": 2}]}'),
     "$.root.transform[0]: a transform step is an object with one key (translate, rotate, scale, matrix), got an object with 2 keys"),
    (S('{"box": {}, "transform": ["scale"]}'), "$.root.transform[0]: a transform step is an object with one key"),
    (S('{"box": {}, "transform": [{"rotat": {}}]}'), "$.root.transform[0].rotat: unknown transform step 'rotat' (did you mean 'rotate'?)"),
    (S('{"box": {}, "transform": [{"translate": [1, 2]}]}'), "$.root.transform[0].translate: expected 3 numbers [x, y, z], got array of 2"),
    (S('{"box": {}, "transform": [{"translate": [0, 0, 1]}, {"scale": 0}]}'), "$.root.transform[1].scale: transform is singular"),
    (S('{"box": {}, "transform": [{"scale": [1, 0, 1]}]}'), "$.root.transform[0].scale: transform is singular"),
    (S('{"box": {}, "transform": [{"scale": "2"}]}'), "$.root.transform[0].scale: expected a number or 3 numbers [sx, sy, sz], got string"),
    (S('{"box": {}, "transform": [{"rotate": {"axis": [0, 0, 1]}}]}'), "$.root.transform[0].rotate: rotate needs 'degrees'"),
    (S('{"box": {}, "transform": [{"rotate": {"axis": [0, 0, 0], "degrees": 9}}]}'),
     "$.root.transform[0].rotate.axis: a direction must not be the zero vector"),
    (S('{"box": {}, "transform": [{"rotate": {"axis": [0, 0, 1], "degree": 9}}]}'),
     "$.root.transform[0].rotate.degree: unknown rotate key 'degree' (did you mean 'degrees'?)"),
    (S('{"box": {}, "transform": [{"rotate": [0, 0, 1]}]}'), "$.root.transform[0].rotate: expected {\"axis\": [x, y, z], \"degrees\": d}"),
    (S('{"box": {}, "transform": [{"matrix": [[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 0, 0], [0, 0, 0, 1]]}]}'),
     "$.root.transform[0].matrix: transform is singular"),
    (S('{"box": {}, "transform": [{"matrix": [[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 1, 1]]}]}'),
     "$.root.transform[0].matrix: transform is not affine: last row is [0.0, 0.0, 1.0, 1.0]"),
    (S('{"box": {}, "transform": [{"matrix": [[1, 0, 0], [0, 1, 0], [0, 0, 1], [0, 0, 0]]}]}'),
     "$.root.transform[0].matrix[0]: expected a row of 4 numbers, got array of 3"),
    (S('{"box": {}, "transform": [{"matrix": [[1, 0, 0, 0]]}]}'), "$.root.transform[0].matrix: expected a 4x4 matrix"),
    (S('{"union": [{"box": {}, "transform": [{"scale": 0}]}]}'), "$.root.union[0].transform[0].scale: transform is singular"),
    # operations
    (S('{"union": {"box": {}}}'), "$.root.union: expected a list of nodes, got object"),
    (S('{"intersection": []}'), "$.root.intersection: intersection needs at least one operand"),
    (S('{"difference": []}'), "$.root.difference: difference needs at least one operand"),
    (S('{"complement": [{"box": {}}]}'), "$.root.complement: expected a node object, got array of 1"),
    (S('{"union": [{"box": {}}, 3]}'), "$.root.union[1]: expected a node object, got number"),
    # refs and defs
    (S('{"ref": "hole"}'), "$.root.ref: undefined ref 'hole'; the scene has no \"defs\""),
    (S('{"ref": "hol"}', defs='{"hole": {"box": {}}}'), "$.root.ref: undefined ref 'hol' (did you mean 'hole'?); defined: 'hole'"),
    (S('{"ref": 3}'), "$.root.ref: expected the name of a definition, got number"),
    (S('{"ref": "a", "color": [1, 0, 0]}', defs='{"a": {"box": {}}}'), "$.root.color: color is only allowed on primitives, not on a ref node"),
    (S('{"ref": "a"}', defs='{"a": {"ref": "a"}}'), "$.defs.a.ref: reference cycle: a -> a"),
    (S('{"ref": "a"}', defs='{"a": {"union": [{"ref": "b"}]}, "b": {"complement": {"ref": "a"}}}'),
     "$.defs.b.complement.ref: reference cycle: a -> b -> a"),
    (S(BOX, defs='{"a": {"ref": "b"}, "b": {"ref": "c"}, "c": {"ref": "b"}}'), "$.defs.c.ref: reference cycle: b -> c -> b"),
    (S(BOX, defs="[]"), "$.defs: expected an object mapping names to nodes, got array of 0"),
    (S(BOX, defs='{"": {"box": {}}}'), '$.defs[""]: a definition name must not be empty'),
    (S(BOX, defs='{"unused": {"sphere": {"radius": -1}}}'), "$.defs.unused.sphere.radius: must be positive, got -1"),
    (S(BOX, defs='{"my hole": {"sphere": {"radius": -1}}}'), '$.defs["my hole"].sphere.radius: must be positive'),
]


@pytest.mark.parametrize("text, expected", BAD, ids=[f"{i:02d}" for i in range(len(BAD))])
def test_bad_input_names_the_place(tmp_path, text, expected):
    path = tmp_path / "bad.json"
    path.write_text(text, encoding="utf-8")
    with pytest.raises(SceneError) as info:
        clcsg.load(path)
    msg = str(info.value)
    assert "\n" not in msg
    assert msg.startswith(f"{path}: "), msg
    assert expected in msg, msg
    assert info.value.exit_code == 3
    # the same through the string and dict entry points
    with pytest.raises(SceneError, match=re.escape(expected)):
        scenefile.loads_json(text, "s.json")


def test_transform_errors_are_transform_errors():
    with pytest.raises(TransformError, match=r"^t\.json: \$\.root\.transform\[0\]\.scale: transform is singular"):
        scenefile.loads_json(S('{"box": {}, "transform": [{"scale": 0}]}'), "t.json")


def test_unknown_kind_lists_every_kind():
    with pytest.raises(SceneError) as info:
        scenefile.loads_json(S('{"torus": {}}'), "k.json")
    msg = str(info.value)
    for kind in [*solids.KINDS, "union", "intersection", "difference", "complement", "ref"]:
        assert kind in msg


def test_file_level_errors(tmp_path):
    with pytest.raises(SceneError, match="no such file"):
        scene_stream.load_json(tmp_path / "nope.json")
    bad = tmp_path / "latin1.json"
    bad.write_bytes(b'{"clcsg": 1, "comment": "\xe9", "root": {"box": {}}}')
    with pytest.raises(SceneError, match=r"latin1\.json: not UTF-8 text"):
        scene_stream.load_json(bad)
    bom = tmp_path / "bom.json"
    bom.write_bytes(b"\xef\xbb\xbf" + S(BOX).encode())
    assert scene_stream.load_json(bom).shape.kind == "box"
    deep = tmp_path / "deep.json"
    deep.write_text(S('{"complement": ' * 5000 + BOX + "}" * 5000))
    with pytest.raises(SceneError, match="nesting too deep"):
        scene_stream.load_json(deep)


def test_deep_chains_load_without_recursion():
    """1,000 nested differences: saved with a def every SAVE_DEPTH levels, validated against
    the schema one node at a time (no recursion per level), loaded back to the same graph."""
    shape = solids.box(2.0)
    for i in range(1000):
        shape = csg.Difference([shape, solids.sphere(0.1, center=(i / 1000, 0, 0))])
    text = scenefile.dumps(scenefile.scene_to_dict(shape))
    loaded = scenefile.loads_json(text, "deep.json").shape
    assert_same_graph(shape, loaded)
    bad = text.replace('"radius": 0.1', '"radius": -0.1', 1)  # the innermost sphere, deep down
    with pytest.raises(SceneError, match=r"sphere\.radius: must be positive, got -0\.1$"):
        scenefile.loads_json(bad, "deep.json")


def test_dict_entry_point_checks_python_values():
    with pytest.raises(SceneError, match=r"^d: \$\.root\.sphere\.radius: number NaN is not allowed"):
        scenefile.scene_from_dict({"clcsg": 1, "root": {"sphere": {"radius": float("nan")}}}, "d")
    with pytest.raises(SceneError, match=r"\$\.root\.sphere\.center\[0\]: number out of range"):
        scenefile.scene_from_dict({"clcsg": 1, "root": {"sphere": {"center": (float("inf"), 0, 0)}}}, "d")
    sc = scenefile.scene_from_dict({"clcsg": 1, "root": {"box": {"size": (1, 2, 3)}}}, "d")
    assert sc.shape.quadrics() == solids.box((1, 2, 3)).quadrics()
