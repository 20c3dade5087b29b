"""Streamed reading of large scene files: the OpenSCAD reader's chunks and events, the JSON
reader's node-by-node stream, and the memory both stay within.

The streamed OpenSCAD reader is checked against itself in the other two ways it can read a
file: the text in chunks of a few characters (every token, string and comment then crosses a
chunk boundary) and the file parsed into a whole syntax tree before it is evaluated (the way
it reads a file with a root modifier).  The streamed JSON reader is checked against the
document loader (``loads_json``: the whole text parsed by Python's ``json`` and validated top
down).  Equal means: the same compiled tape (quadrics and instructions, bit for bit), the
same model (its repr), the same warnings and the same error message.
"""

from __future__ import annotations

import glob
import math
import os
import tracemalloc
import warnings
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

from bench.load import write_csg, write_json
from clcsg.errors import SceneError
from clcsg.readers import scene_stream, scenefile
from clcsg.readers.openscad import _file_chunks, _read, load_csg, parse_csg
from clcsg.readers.openscad_tokens import UNDEF, Parser, Source, chunks_of
from clcsg.readers.scene_schema import scene_schema

HERE = Path(__file__).parent
CSG_FILES = sorted(glob.glob(str(HERE.parent / "examples" / "*.csg")) + glob.glob(str(HERE / "data" / "openscad" / "*.csg")))
JSON_FILES = sorted(glob.glob(str(HERE.parent / "examples" / "*.json")))


def outcome(read):
    """(tape bytes and model repr, or the error message; the warnings) of ``read()``."""
    with warnings.catch_warnings(record=True) as rec:
        warnings.simplefilter("always")
        try:
            scene = read()
            tape = scene.compile()
            result = ("ok", np.asarray(tape.quadrics).tobytes(), np.asarray(tape.ops).tobytes(), repr(scene.shape))
        except SceneError as e:
            result = ("error", str(e))
    return result, [(str(w.message), w.lineno) for w in rec]


def read_chunked(path, size: int, tree: bool = False):
    """The file in chunks of ``size`` characters; parsed into a tree first if ``tree`` or if it
    has a root modifier (as load_csg does)."""
    with open(path, "rb") as f:
        tree = tree or b"!" in f.read()
        f.seek(0)
        return _read(_file_chunks(f, size), path, path, tree)


# -- OpenSCAD ---------------------------------------------------------------------------------
@pytest.mark.parametrize("path", CSG_FILES, ids=os.path.basename)
def test_csg_files_read_the_same_streamed_in_tiny_chunks_and_as_a_tree(path):
    streamed = outcome(lambda: load_csg(path))
    assert streamed == outcome(lambda: read_chunked(path, 7 if os.path.getsize(path) < 20_000 else 61))
    assert streamed == outcome(lambda: read_chunked(path, 1 << 16, tree=True))
    with open(path, encoding="utf-8", errors="replace") as f:
        text = f.read()
    assert streamed == outcome(lambda: parse_csg(text, source=path))


BAD = [
    ("cube(1);\n/* never closed\ncube(2);\n", "t.csg:2:1: syntax error: unterminated comment (missing '*/')"),
    ('color("red) cube(1);\n', "t.csg:1:7: syntax error: unterminated string (missing '\"')"),
    ("group() {\n\tcube(1);\n", "t.csg:3:1: syntax error: expected '}', got end of file"),
    ("multmatrix([[1, 0, 0, 0], [0, 1, 0, 0]]) [1, 2];\n",
     "t.csg:1:42: syntax error: expected ';' or '{' after multmatrix(...), got '['"),
    ("cube([1, 2, 3]) cube(1) [4];", "t.csg:1:25: syntax error: expected ';' or '{' after cube(...), got '['"),
    ("include <parts.scad>\n", "t.csg:1:1: syntax error: unexpected 'include': this is OpenSCAD source"),
    ("polyhedron_x();\ncube(1) @;\n", "t.csg:2:9: syntax error: unexpected character '@'"),
    ("frob(1);\ncube(1);\n", "t.csg:1:1: frob() is not supported"),
    ("frob(1);\ncube(1) }\n", "t.csg:2:9: syntax error"),  # a syntax error anywhere comes first
]


@pytest.mark.parametrize("text,message", BAD)
def test_bad_csg_gets_the_same_one_line_error_whatever_the_chunks(text, message):
    results = set()
    for size in (1, 2, 5, 1 << 16):
        with pytest.raises(SceneError) as e:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                _read(chunks_of(text, size), "t.csg", None, False)
        results.add(str(e.value))
    assert len(results) == 1
    got = results.pop()
    assert got.startswith(message) and "\n" not in got


def test_a_syntax_error_after_a_warning_drops_the_warning():
    """The file parsed before it was evaluated gave no warnings with a syntax error; the
    streamed reader collects them and drops them then."""
    with warnings.catch_warnings(record=True) as rec:
        warnings.simplefilter("always")
        with pytest.raises(SceneError, match="t.csg:2:"):
            parse_csg("cube(-1);\ncube(1) ]\n", source="t.csg")
    assert rec == []
    with warnings.catch_warnings(record=True) as rec:
        warnings.simplefilter("always")
        with pytest.raises(SceneError, match="frob"):
            parse_csg("cube(-1);\nfrob();\n", source="t.csg")
    assert len(rec) == 1 and "t.csg:1:1: cube(size = [-1, -1, -1]) is empty" in str(rec[0].message)


_number = st.one_of(st.integers(-10**6, 10**6).map(str),
                    st.floats(allow_nan=False, allow_infinity=False, width=64).map(repr),
                    st.floats(0, 1e3).map(lambda x: f"{x:.3e}"), st.sampled_from([".5", "+2", "-0", "1.", "1e-05", "-.25E+2"]))
_space = st.sampled_from(["", " ", "\n\t", "  "])


@st.composite
def _vector(draw, depth=2):
    """(text, value): a number or a vector of up to ``depth`` levels, and its value by
    Python's float() of each number's text."""
    if depth == 0 or draw(st.booleans()):
        t = draw(_number)
        return t, float(t)
    items = draw(st.lists(_vector(depth - 1), min_size=1, max_size=5))
    sp = draw(_space)
    return "[" + sp + ("," + sp).join(t for t, _ in items) + draw(_space) + "]", [v for _, v in items]


@settings(max_examples=300)
@given(_vector(), st.integers(1, 9))
def test_vectors_read_as_one_token_have_the_values_of_their_numbers(vector, size):
    text, value = vector
    src = Source(chunks_of(f"m(v = {text});", size), "t.csg")
    (_, node), = Parser(src, 10, 10).events()
    got = node.args[0].value
    assert got == value
    assert [math.copysign(1, x) for x in _flat(got)] == [math.copysign(1, x) for x in _flat(value)]  # -0 stays -0


def _flat(v):
    return [y for x in v for y in _flat(x)] if isinstance(v, list) else [v]


def test_vector_depth_limit_names_the_bracket_that_passes_it():
    for text, col in (("m([[1, 2]]);", 4), ("m([1, 2]);", None), ("m([[[1]]]);", 4)):
        src = Source([text], "t.csg")
        if col is None:
            (_, node), = Parser(src, 10, 1).events()
            assert node.args[0].value == [1.0, 2.0]
            continue
        with pytest.raises(SceneError, match=rf"t.csg:1:{col}: values nested deeper than 1 levels"):
            list(Parser(src, 10, 1).events())


def test_undef_and_strings_still_read_inside_arguments():
    (_, node), = Parser(Source(chunks_of('c(c = "a\\"b", alpha = undef, v = [1, undef]);', 3), "t"), 10, 10).events()
    assert [a.value for a in node.args][:2] == ['a"b', UNDEF] and node.args[2].value[1] is UNDEF


def _peak_ratio(read, path):
    """(peak of Python's allocations while ``read(path)`` runs per byte of the file, its scene)."""
    size = os.path.getsize(path)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        tracemalloc.start()
        try:
            scene = read(path)
            peak = tracemalloc.get_traced_memory()[1]
        finally:
            tracemalloc.stop()
    return peak / size, scene


def test_a_large_csg_file_loads_within_ten_times_its_size(tmp_path):
    path = str(tmp_path / "big.csg")
    n = write_csg(path, 3_000_000)
    load_csg(HERE.parent / "examples" / "pen_stand.csg")  # imports and caches: not the file's memory
    ratio, scene = _peak_ratio(load_csg, path)
    assert ratio <= 10.0, f"peak {ratio:.1f} times the file's size"
    assert len(scene.shape.operands) == n


def test_the_guard_factors_bound_the_streamed_readers():
    from clcsg.readers import budget

    assert budget.CSG_FACTOR <= 10 and budget.JSON_FACTOR <= 10 < budget.WHOLE_JSON_FACTOR


# -- JSON -------------------------------------------------------------------------------------
def _loads(path):
    with open(path, encoding="utf-8-sig") as f:
        return scenefile.loads_json(f.read(), str(path))


@pytest.mark.parametrize("path", JSON_FILES, ids=os.path.basename)
def test_json_files_read_the_same_streamed_and_whole(path):
    assert outcome(lambda: scene_stream.load_json(path)) == outcome(lambda: _loads(path))


def test_generated_json_reads_the_same_streamed_and_whole(tmp_path):
    path = tmp_path / "g.json"
    write_json(str(path), 200_000)
    assert outcome(lambda: scene_stream.load_json(path)) == outcome(lambda: _loads(path))


GOOD_JSON = [
    # defs after root: the stream cannot resolve the ref; the document loader reads it
    '{"clcsg": 1, "root": {"union": [{"ref": "a"}, {"ref": "a", "transform": [{"translate": [1, 0, 0]}]}]},'
    ' "defs": {"a": {"sphere": {"radius": 1}}}}',
    '{"clcsg": 1, "defs": {"b": {"ref": "a"}, "a": {"box": {"size": 2}}, "unused": {"sphere": {}}},'
    ' "root": {"difference": [{"ref": "b"}, {"complement": {"ref": "a"}}]}}',
    '{"bound": [[-1, -1, -1], [1, 1, 1]], "root": {"intersection": [{"halfspace": {}}, {"hull": [{"sphere": {}}, '
    '{"box": {}, "transform": [{"rotate": {"axis": [0, 0, 1], "degrees": 30}}]}]}]}, "clcsg": 1}',
]

BAD_JSON = [
    '{"clcsg": 1, "root": {"sphere": {"radius": NaN}}}',
    '{"clcsg": 1, "root": {"sphere": {"radius": 1, "radius": 2}}}',
    '{"clcsg": 1, "root": {"union": [{"box": {}}, {"sphere": {"radius": -1}}]}}',
    '{"clcsg": 1, "root": {"union": [{"box": {}}, {"ref": "nope"}]}}',
    '{"clcsg": 1, "root": {"union": [{"box": {}, "colour": 1}]}, "extra": 2}',
    '{"clcsg": 1.0, "root": {"box": {}}}',
    '{"clcsg": 1, "root": {"box": {}}} trailing',
    '{"clcsg": 1, "root": {"box": {"size": 1e999}}}',
    '{"clcsg": 1, "root": {"box": {"size": 10000000000000000000000000000000000000000000000000000000000000000000000'
    '000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000'
    '00000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000'
    '000000000000000000000000000000000000000000000}}}',
    '{"clcsg": 1, "defs": {"a": {"ref": "b"}, "b": {"ref": "a"}}, "root": {"ref": "a"}}',
    '{"clcsg": 1, "root": {"union": [{"box": {}, "transform": [{"scale": 0}]}]}}',
    '[1, 2]',
    '{"clcsg": 1, "root": {"union": [{"box": {}}, ]}}',
]


@pytest.mark.parametrize("text", GOOD_JSON + BAD_JSON)
def test_json_streamed_and_whole_agree_on_scenes_and_errors(tmp_path, text):
    path = tmp_path / "s.json"
    path.write_text(text)
    streamed = outcome(lambda: scene_stream.load_json(path))
    assert streamed == outcome(lambda: scenefile.loads_json(text, str(path)))
    assert streamed[0][0] == ("ok" if text in GOOD_JSON else "error")
    if streamed[0][0] == "error":
        assert streamed[0][1].startswith(str(path)) and "\n" not in streamed[0][1]


def test_defs_shared_by_refs_stay_one_object_when_streamed(tmp_path):
    path = tmp_path / "s.json"
    path.write_text('{"clcsg": 1, "defs": {"a": {"sphere": {"radius": 1}}}, "root": {"union": [{"ref": "a"}, {"ref": "a"}]}}')
    a, b = scene_stream.load_json(path).shape.operands
    assert a is b


def test_a_large_json_file_loads_within_ten_times_its_size(tmp_path):
    path = str(tmp_path / "big.json")
    n = write_json(path, 3_000_000)
    scene_schema()
    scene_stream.load_json(HERE.parent / "examples" / "bracket.json")  # imports and validators
    ratio, scene = _peak_ratio(scene_stream.load_json, path)
    assert ratio <= 10.0, f"peak {ratio:.1f} times the file's size"
    assert len(scene.shape.operands) == n


def test_an_invalid_file_too_large_to_read_whole_reports_what_the_stream_met(tmp_path, monkeypatch):
    from clcsg.readers import budget

    path = tmp_path / "s.json"
    path.write_text('{"clcsg": 1, "root": {"union": [{"box": {}}, {"sphere": {"radius": -1}}]}}' + " " * 10_000)
    monkeypatch.setattr(budget, "available_memory", lambda: 10_100 * budget.JSON_FACTOR)
    with pytest.raises(SceneError) as e:
        scene_stream.load_json(path)
    msg = str(e.value)
    assert msg.startswith(f"{path}: $.root.union[1].sphere.radius: must be positive") and "\n" not in msg

