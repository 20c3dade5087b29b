"""The JSON scene format (clcsg/readers/scenefile.py): round trips, sharing, the example scenes
and the JSON Schema (validation messages: test_scenefile_validation.py)."""

from __future__ import annotations

import glob
import json
import os
import re

import numpy as np
import pytest
from hypothesis import HealthCheck, given, reject, settings
from hypothesis import strategies as st

import clcsg
from clcsg.model import csg, solids
from clcsg.readers import scene_stream, scenefile
from clcsg.errors import DnfLimitError, OutputError, SceneError
from clcsg.model.scene import Scene
from strategies import any_primitives, affine_maps, shapes, shared_nodes

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
EXAMPLES = sorted(glob.glob(os.path.join(ROOT, "examples", "*.json")))
SCHEMA_PATH = os.path.join(ROOT, "clcsg", "readers", "schema", "scene.schema.json")
UB = np.array([[-3.5, -3.5, -3.5], [3.5, 3.5, 3.5]])
N_EXAMPLES = int(os.environ.get("CLCSG_HYPOTHESIS_EXAMPLES", 40))


# -- helpers --------------------------------------------------------------------------------------
def assert_same_graph(a: csg.Shape, b: csg.Shape):
    """Same node types, parameters, colors and matrices, and the same sharing pattern: a node
    shared in ``a`` corresponds to one node in ``b`` that is shared the same way."""
    fwd: dict[int, csg.Shape] = {}
    bwd: dict[int, csg.Shape] = {}
    stack = [(a, b)]
    while stack:
        x, y = stack.pop()
        if id(x) in fwd:
            assert fwd[id(x)] is y, f"{x!r}: shared in the original, not in the copy"
            continue
        assert id(y) not in bwd, f"{y!r}: shared in the copy, not in the original"
        fwd[id(x)] = y
        bwd[id(y)] = x
        assert type(x) is type(y)
        if isinstance(x, csg.Primitive):
            assert x.kind == y.kind
            assert set(x.params) == set(y.params)
            for k in x.params:
                assert np.array_equal(np.asarray(x.params[k], float), np.asarray(y.params[k], float)), k
            assert x.color == y.color
            assert x.quadrics() == y.quadrics()
        if isinstance(x, csg.Transformed):
            assert np.array_equal(x.matrix, y.matrix)
        assert len(x.children()) == len(y.children())
        stack.extend(zip(x.children(), y.children()))


def assert_same_dnf(a: Scene, b: Scene):
    da, db = a.normalize(), b.normalize()
    assert np.array_equal(da.quadrics, db.quadrics)
    assert da.terms == db.terms
    assert np.array_equal(da.colors, db.colors)
    assert np.array_equal(da.term_bounds, db.term_bounds)


def round_trip(scene) -> tuple[Scene, str]:
    text = scenefile.dumps(scenefile.scene_to_dict(scene))
    return scenefile.loads_json(text, "rt.json"), text


# -- round trips ----------------------------------------------------------------------------------
@settings(max_examples=N_EXAMPLES, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(shape=shapes(leaves=any_primitives(), max_translation=1.0), bound=st.booleans(), seed=st.integers(0, 2**32 - 1))
def test_round_trip_keeps_graph_dnf_and_membership(shape, bound, seed):
    scene = Scene(shape, UB.copy() if bound else None)
    loaded, text = round_trip(scene)
    assert loaded.source == "rt.json"
    assert_same_graph(shape, loaded.shape)
    if bound:
        assert np.array_equal(loaded.bound, UB)
    else:
        assert loaded.bound is None
    # saving the loaded scene gives the same text: floats are written exactly
    assert scenefile.dumps(scenefile.scene_to_dict(loaded)) == text
    x = np.random.default_rng(seed).uniform(-3.5, 3.5, (500, 3))
    assert np.array_equal(clcsg.contains(shape, x), clcsg.contains(loaded.shape, x))
    try:
        assert_same_dnf(Scene(shape, UB), Scene(loaded.shape, UB))
    except DnfLimitError:
        reject()
    # one def per shared node, and every def is referenced at least twice
    data = json.loads(text)
    assert len(data.get("defs", {})) == len(shared_nodes(shape))
    for name in data.get("defs", {}):
        assert text.count(json.dumps({"ref": name})[1:-1]) >= 2


def test_a_scene_of_a_file_name_says_how_to_load_it():
    """Scene(shape) takes a Shape: a file name (or anything else) is refused at once with a
    one-line UsageError (a file name with the call that reads it), not a traceback from deep in
    the compiler."""
    from clcsg.errors import UsageError

    with pytest.raises(UsageError, match=r"not str 'examples/menger3.csg'; a scene file is read with clcsg.load"):
        Scene("examples/menger3.csg")
    with pytest.raises(UsageError, match="must be a clcsg Shape, not NoneType"):
        Scene(None)
    assert len(Scene(solids.sphere(1.0)).compile().quadrics) == 1


def test_round_trip_through_files(tmp_path):
    hole = solids.cylinder(3.0, 0.25, color=(0.9, 0.2, 0.1))
    part = solids.box(2.0, color=(0.3, 0.5, 0.8, 0.5)) - hole - hole.rotate((1, 0, 0), 90) - hole.rotate((0, 1, 0), 90)
    scene = Scene(part | solids.sphere(0.3, center=(0, 0, 1.2)).scale((1, 1, 2)), np.array([[-2.0] * 3, [2.5] * 3]))
    path = tmp_path / "part.json"
    clcsg.save(scene, path)
    loaded = clcsg.load(path)
    assert loaded.source == str(path)
    assert_same_graph(scene.shape, loaded.shape)
    assert_same_dnf(scene, loaded)
    assert np.array_equal(loaded.bound, scene.bound)
    scenefile.save_json(part, tmp_path / "bare.json")  # a bare Shape
    assert scene_stream.load_json(tmp_path / "bare.json").bound is None


def test_shared_nodes_stay_shared():
    hole = solids.cylinder(3.0, 0.25)
    moved = hole.translate((0.5, 0, 0))  # a shared Transformed node
    inner = csg.Union([hole, moved])  # a shared operation using the shared nodes
    shape = csg.Difference([solids.box(2.0), inner, inner.rotate((1, 0, 0), 90), moved, csg.Union([hole, hole])])
    data = scenefile.scene_to_dict(shape)
    assert set(data["defs"]) == {"cylinder1", "transformed1", "union1"}
    text = json.dumps(data)
    assert "cylinder" not in json.dumps(data["root"]).replace('"ref": "cylinder1"', "")
    loaded = scenefile.scene_from_dict(json.loads(text), "x").shape
    assert_same_graph(shape, loaded)
    box, inner2, rotated, moved2, twice = loaded.operands
    assert rotated.operand is inner2
    assert inner2.operands[1] is moved2
    assert twice.operands[0] is twice.operands[1] is inner2.operands[0] is moved2.operand


def test_refs_with_transforms_and_nested_defs():
    data = {
        "clcsg": 1,
        "defs": {
            "post": {"cylinder": {"height": 2, "radius": 0.1}},
            "pair": {"union": [{"ref": "post", "transform": [{"translate": [-0.5, 0, 0]}]},
                               {"ref": "post", "transform": [{"translate": [0.5, 0, 0]}]}]},
            "unused": {"sphere": {}},
        },
        "root": {"union": [{"ref": "pair"}, {"ref": "pair", "transform": [{"rotate": {"axis": [0, 0, 1], "degrees": 90}}]}]},
    }
    shape = scenefile.scene_from_dict(data, "defs.json").shape
    a, b = shape.operands
    assert b.operand is a
    assert a.operands[0].operand is a.operands[1].operand
    expected = solids.cylinder(2, 0.1).translate((-0.5, 0, 0)) | solids.cylinder(2, 0.1).translate((0.5, 0, 0))
    expected = expected | expected.rotate((0, 0, 1), 90)
    assert_same_dnf(Scene(shape), Scene(expected))


def test_transform_steps_match_the_python_api():
    steps = [
        {"translate": [1, 2, 3]},
        {"rotate": {"axis": [1, 1, 0], "degrees": 33}},
        {"scale": 2},
        {"scale": [1, 2, 3]},
        {"matrix": [[1, 0.5, 0, 0], [0, 1, 0, 1], [0, 0, 1, 0], [0, 0, 0, 1]]},
        {"matrix": [[1, 0, 0, 2], [0, 1, 0, 0], [0, 0, 1, 0]]},  # 3x4: the affine rows
    ]
    data = {"clcsg": 1, "root": {"box": {}, "transform": steps}}
    got = scenefile.scene_from_dict(data).shape
    m = np.array([[1, 0.5, 0, 0], [0, 1, 0, 1], [0, 0, 1, 0], [0, 0, 0, 1]], float)
    expected = (solids.box().translate((1, 2, 3)).rotate((1, 1, 0), 33).scale(2).scale((1, 2, 3))
                .transform(m).translate((2, 0, 0)))
    expected_primitive = solids.box()
    # same chain of Transformed edges, innermost first
    chain_got, chain_exp = [], []
    for node, chain in ((got, chain_got), (expected, chain_exp)):
        while isinstance(node, csg.Transformed):
            chain.append(node.matrix)
            node = node.operand
    assert len(chain_got) == len(chain_exp) == 6
    for a, b in zip(chain_got, chain_exp):
        assert np.array_equal(a, b)
    assert_same_dnf(Scene(got), Scene(expected))
    assert expected_primitive.kind == "box"


def test_python_values_are_converted():
    shape = csg.Primitive("box", {"size": np.array([1.0, 2.0, 3.0]), "center": (np.float32(0.5), 0, np.int64(1))})
    data = scenefile.scene_to_dict(shape)
    assert data["root"] == {"box": {"size": [1.0, 2.0, 3.0], "center": [0.5, 0, 1]}}
    json.dumps(data, allow_nan=False)
    assert_same_dnf(Scene(shape), scenefile.scene_from_dict(data))


def test_defaults_and_colors():
    data = {"clcsg": 1, "root": {"union": [
        {"sphere": {}},
        {"box": {"size": 0.5}, "color": "#ff8000"},
        {"cone": {"r2": 0.5}, "color": [0.1, 0.2, 0.3, 0.4]},
    ]}}
    sphere, box, cone = scenefile.scene_from_dict(data).shape.operands
    assert sphere.quadrics() == solids.sphere().quadrics()
    assert sphere.color == csg.DEFAULT_COLOR
    assert box.color == (1.0, 128 / 255, 0.0, 1.0)
    assert cone.color == (0.1, 0.2, 0.3, 0.4)
    assert cone.quadrics() == solids.cone(r2=0.5).quadrics()
    out = scenefile.scene_to_dict(csg.Union([sphere, box, cone]))["root"]["union"]
    assert "color" not in out[0] and len(out[1]["color"]) == 3 and len(out[2]["color"]) == 4


def test_dumps_is_readable_json():
    shape = solids.box((1, 2, 3), color=(1, 0, 0)).transform(
        np.array([[0.6, -0.8, 0, 0.1], [0.8, 0.6, 0, 0.2], [0, 0, 1, 0.3], [0, 0, 0, 1]])
    ) - solids.sphere(1.2)
    text = scenefile.dumps(scenefile.scene_to_dict(Scene(shape, np.array([[-2.0] * 3, [2.0] * 3]))))
    assert json.loads(text)["clcsg"] == 1
    assert max(len(line) for line in text.splitlines()) <= scenefile.WIDTH
    assert '"size": [1, 2, 3]' in text  # short arrays on one line
    assert list(json.loads(text)) == ["clcsg", "bound", "root"]


def test_save_errors(tmp_path):
    with pytest.raises(OutputError, match="cannot write"):  # a failed write: exit code 6
        scenefile.save_json(solids.box(), tmp_path / "missing-dir" / "x.json")
    with pytest.raises(SceneError, match="expected a Scene or a Shape"):
        scenefile.scene_to_dict("box")

    class Odd(csg.Shape):
        __slots__ = ()

    with pytest.raises(SceneError, match="unknown CSG node type Odd"):
        scenefile.scene_to_dict(csg.Union([Odd()]))
    with pytest.raises(SceneError, match=r"scenes are saved as \.json"):
        clcsg.save(solids.box(), tmp_path / "x.csg")


# -- examples -------------------------------------------------------------------------------------
def test_the_examples_are_there():
    names = {os.path.basename(p) for p in EXAMPLES}
    assert {"rounded_cube.json", "drilled_block.json", "spheres.json", "bracket.json"} <= names
    kinds = set()
    for p in EXAMPLES:
        kinds |= set(re.findall(r'"(\w+)":', open(p).read()))
    assert kinds & {"hyperboloid_one_sheet", "hyperboloid_two_sheets", "hyperbolic_paraboloid", "elliptic_paraboloid"}


@pytest.mark.parametrize("path", EXAMPLES, ids=os.path.basename)
def test_example_loads_and_normalizes(path):
    scene = clcsg.load(path)
    dnf = scene.normalize()
    assert dnf.n_terms >= 1
    assert np.all(np.isfinite(dnf.bound))
    prims = [n for n in csg.walk(scene.shape) if isinstance(n, csg.Primitive)]
    assert prims and all(p.color != csg.DEFAULT_COLOR for p in prims), "examples use colors"
    # the file round-trips: same graph and DNF after save and load
    loaded, _ = round_trip(scene)
    assert_same_graph(scene.shape, loaded.shape)
    x = np.random.default_rng(5).uniform(dnf.bound[0], dnf.bound[1], (2000, 3))
    inside = dnf.contains(x)
    assert inside.any()
    assert np.array_equal(inside, clcsg.contains(scene.shape, x))


def test_bracket_shares_its_bolt_hole():
    scene = clcsg.load(os.path.join(ROOT, "examples", "bracket.json"))
    assert shared_nodes(scene.shape)
    data = json.load(open(os.path.join(ROOT, "examples", "bracket.json")))
    assert "defs" in data
    assert scene.normalize().bound[1][0] == pytest.approx(40.0)  # millimetres


# -- the JSON Schema ------------------------------------------------------------------------------
def load_schema():
    with open(SCHEMA_PATH, encoding="utf-8") as f:
        return json.load(f)


def all_refs(node):
    if isinstance(node, dict):
        for k, v in node.items():
            if k == "$ref":
                yield v
            else:
                yield from all_refs(v)
    elif isinstance(node, list):
        for v in node:
            yield from all_refs(v)


def test_schema_structure():
    schema = load_schema()
    assert schema["$schema"] == "https://json-schema.org/draft/2020-12/schema"
    assert schema["type"] == "object"
    assert set(schema["required"]) == {"clcsg", "root"}
    assert schema["additionalProperties"] is False
    assert set(schema["properties"]) == set(scenefile.TOP_KEYS)
    assert schema["properties"]["clcsg"]["const"] == scenefile.FORMAT_VERSION
    assert schema["properties"]["root"] == {"$ref": "#/$defs/node"}
    defs = schema["$defs"]
    for ref in all_refs(schema):
        assert ref.startswith("#/$defs/") and ref[len("#/$defs/"):] in defs, ref
    node = defs["node"]
    every_kind = {*solids.KINDS, *scenefile.CONSTRUCTIONS, *scenefile.OPERATIONS, *scenefile.UNARY, "ref"}
    # a node has exactly the keys of one kind (dispatch on the kind key) ...
    assert {k: v["$ref"] for k, v in node["dependentSchemas"].items()} == {k: f"#/$defs/{k}" for k in every_kind}
    assert node["not"] == {"propertyNames": {"enum": list(scenefile.NODE_EXTRA_KEYS)}}  # not only extras: a kind
    assert set(defs[node["propertyNames"]["$ref"].rsplit("/", 1)[1]]["enum"]) == every_kind | set(scenefile.NODE_EXTRA_KEYS)
    for kind in solids.KINDS:
        params = solids.parameters(kind)
        ps = defs["params_" + kind]
        assert set(ps["properties"]) == set(params), kind
        required = {n for n, d in params.items() if d is __import__("inspect").Parameter.empty}
        assert set(ps.get("required", [])) == required, kind
        assert set(defs[kind]["properties"]) == {kind, *scenefile.NODE_EXTRA_KEYS}
        assert defs[kind]["required"] == [kind] and defs[kind]["additionalProperties"] is False
    for kind in scenefile.CONSTRUCTIONS:
        assert set(defs[kind]["properties"]) == {kind, *scenefile.NODE_EXTRA_KEYS}
        assert defs[kind]["required"] == [kind] and defs[kind]["additionalProperties"] is False
    for op in [*scenefile.OPERATIONS, *scenefile.UNARY, "ref"]:
        assert set(defs[op]["properties"]) == {op, "transform", "comment"}
        assert defs[op]["required"] == [op] and defs[op]["additionalProperties"] is False
    # ... and a transform step exactly one key
    step = defs["step"]
    assert step["minProperties"] == step["maxProperties"] == 1
    assert list(step["properties"]) == list(scenefile.TRANSFORM_STEPS)
    assert defs[step["propertyNames"]["$ref"].rsplit("/", 1)[1]]["enum"] == list(scenefile.TRANSFORM_STEPS)


def _validate(instance, schema, root, path="$"):
    """A small JSON Schema (2020-12) validator for the keywords the scene schema uses, so the
    examples are checked against the schema even without the jsonschema package.  Returns a
    list of error strings."""
    known = {"$schema", "$id", "title", "description", "$defs", "$ref", "type", "const", "required",
             "properties", "additionalProperties", "propertyNames", "items", "prefixItems", "minItems",
             "maxItems", "oneOf", "anyOf", "not", "minimum", "maximum", "exclusiveMinimum", "pattern", "minLength",
             "enum", "minProperties", "maxProperties", "dependentSchemas"}
    unknown = set(schema) - known
    assert not unknown, f"the test validator does not know {unknown}"
    errs = []
    if "$ref" in schema:
        target = root
        for part in schema["$ref"][2:].split("/"):
            target = target[part]
        errs += _validate(instance, target, root, path)
    t = schema.get("type")
    types = {"object": dict, "array": list, "string": str}
    if t in ("number", "integer") and (isinstance(instance, bool) or not isinstance(instance, (int, float))):
        return errs + [f"{path}: not a number"]
    if t == "integer" and not float(instance).is_integer():
        return errs + [f"{path}: not an integer"]
    if t in types and not isinstance(instance, types[t]):
        return errs + [f"{path}: not {t}"]
    if "const" in schema and not (instance == schema["const"] and not isinstance(instance, bool)):
        errs.append(f"{path}: not {schema['const']}")
    if "enum" in schema and not any(instance == e and type(instance) is type(e) for e in schema["enum"]):
        errs.append(f"{path}: not one of the enum")
    if isinstance(instance, (int, float)) and not isinstance(instance, bool):
        if "minimum" in schema and instance < schema["minimum"]:
            errs.append(f"{path}: below minimum")
        if "maximum" in schema and instance > schema["maximum"]:
            errs.append(f"{path}: above maximum")
        if "exclusiveMinimum" in schema and instance <= schema["exclusiveMinimum"]:
            errs.append(f"{path}: not above exclusiveMinimum")
    if isinstance(instance, str):
        if "pattern" in schema and not re.search(schema["pattern"], instance):
            errs.append(f"{path}: pattern")
        if "minLength" in schema and len(instance) < schema["minLength"]:
            errs.append(f"{path}: too short")
    if isinstance(instance, dict):
        for k in schema.get("required", []):
            if k not in instance:
                errs.append(f"{path}: missing {k}")
        if len(instance) < schema.get("minProperties", 0) or len(instance) > schema.get("maxProperties", len(instance)):
            errs.append(f"{path}: number of properties")
        for k, sub in schema.get("dependentSchemas", {}).items():
            if k in instance:
                errs += _validate(instance, sub, root, path)
        props = schema.get("properties", {})
        for k, v in instance.items():
            if "propertyNames" in schema:
                errs += _validate(k, schema["propertyNames"] | {"type": "string"}, root, f"{path}.{k}(name)")
            if k in props:
                errs += _validate(v, props[k], root, f"{path}.{k}")
            elif schema.get("additionalProperties") is False:
                errs.append(f"{path}: unexpected {k}")
            elif isinstance(schema.get("additionalProperties"), dict):
                errs += _validate(v, schema["additionalProperties"], root, f"{path}.{k}")
    if isinstance(instance, list):
        if "minItems" in schema and len(instance) < schema["minItems"]:
            errs.append(f"{path}: too few items")
        if "maxItems" in schema and len(instance) > schema["maxItems"]:
            errs.append(f"{path}: too many items")
        prefix = schema.get("prefixItems", [])
        for i, v in enumerate(instance):
            if i < len(prefix):
                errs += _validate(v, prefix[i], root, f"{path}[{i}]")
            elif "items" in schema:
                errs += _validate(v, schema["items"], root, f"{path}[{i}]")
    if "oneOf" in schema:
        ok = [alt for alt in schema["oneOf"] if not _validate(instance, alt, root, path)]
        if len(ok) != 1:
            errs.append(f"{path}: matches {len(ok)} of oneOf")
    if "anyOf" in schema and not any(not _validate(instance, alt, root, path) for alt in schema["anyOf"]):
        errs.append(f"{path}: matches none of anyOf")
    if "not" in schema and not _validate(instance, schema["not"], root, path):
        errs.append(f"{path}: matches not")
    return errs


SCHEMA_BAD = [
    {"clcsg": 2, "root": {"box": {}}},
    {"clcsg": 1},
    {"clcsg": 1, "root": {"torus": {}}},
    {"clcsg": 1, "root": {"box": {"sise": 1}}},
    {"clcsg": 1, "root": {"box": {}, "sphere": {}}},
    {"clcsg": 1, "root": {"sphere": {"radius": -1}}},
    {"clcsg": 1, "root": {"cylinder": {"axis": [0, 0, 0]}}},
    {"clcsg": 1, "root": {"union": [], "color": [1, 0, 0]}},
    {"clcsg": 1, "root": {"box": {}, "color": [1, 2, 0]}},
    {"clcsg": 1, "root": {"box": {}, "transform": [{"scale": 1, "translate": [0, 0, 0]}]}},
    {"clcsg": 1, "root": {"intersection": []}},
    {"clcsg": 1, "root": {"ref": 3}},
    {"clcsg": 1, "root": {}},
    {"clcsg": 1, "root": {"transform": []}},
    {"clcsg": 1, "root": {"box": {}, "transform": [{}]}},
    {"clcsg": 1, "root": {"box": {}, "color": "#12"}},
    {"clcsg": 1, "root": {"box": {}, "color": "steel blue"}},
    {"clcsg": 1, "root": {"difference": [{"box": {}}, {"sphere": {"radius": 0}}]}},
    {"clcsg": 1, "root": {"box": {}}, "defs": {"": {"box": {}}}},
]


def _schema_documents():
    docs = [json.load(open(p)) for p in EXAMPLES]
    hole = solids.cylinder(3, 0.2)
    shape = csg.Union([hole, hole.rotate((1, 0, 0), 90), ~solids.sphere(color=(1, 0, 0, 0.5))])
    prims = [csg.Primitive(k, {}) for k in solids.KINDS if k != "quadric"]
    prims.append(solids.quadric(np.diag([1.0, 1, 1, -1])))
    docs.append(scenefile.scene_to_dict(Scene(csg.Difference([shape, *prims]).scale((1, 2, 3)), UB)))
    docs.append({"clcsg": 1, "root": {"union": [{"box": {}, "color": "SteelBlue"}, {"sphere": {}, "color": "#f9d72c"},
                                                {"cone": {}, "color": "#fa0c"}, {"ellipsoid": {}, "color": "transparent"}]}})
    return docs


def test_examples_match_the_schema_without_jsonschema():
    schema = load_schema()
    for doc in _schema_documents():
        assert _validate(doc, schema, schema) == []
    for doc in SCHEMA_BAD:
        assert _validate(doc, schema, schema), doc


def test_examples_match_the_schema_with_jsonschema():
    jsonschema = pytest.importorskip("jsonschema", reason="jsonschema is not installed (optional)")
    schema = load_schema()
    jsonschema.Draft202012Validator.check_schema(schema)
    validator = jsonschema.Draft202012Validator(schema)
    for doc in _schema_documents():
        errors = list(validator.iter_errors(doc))
        assert not errors, errors[0].message
    for doc in SCHEMA_BAD:
        assert not validator.is_valid(doc), doc


@settings(max_examples=15, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(shape=shapes(leaves=any_primitives()), m=affine_maps())
def test_saved_scenes_match_the_schema(shape, m):
    schema = load_schema()
    doc = scenefile.scene_to_dict(Scene(csg.Transformed(shape, m), UB))
    assert _validate(json.loads(json.dumps(doc)), schema, schema) == []
