"""Robustness: bad input gets one documented error line, degenerate input a correct result.

* the error table: CLI argv (through ``clcsg.cli.main`` and, for a few, ``python -m clcsg``)
  and Python calls, each with its exit code / exception type and a substring of the message;
* empty results: a warning and valid empty outputs;
* degenerate geometry (coincident faces, tangencies, a plane through an axis, a cone apex on
  another surface, coordinates from 1e-3 to 1e4) stays exact: bounded subdivision, no NaN,
  samples on the surface and covering it, renders equal to the ray tracer;
* nothing is lost: tiny forced sampler buffers give identical samples.

The gaps these tests found (an unwritable PLY path, the CLI on empty solids) are fixed and the
tests stay as regression tests.
"""

from __future__ import annotations

import math
import os
import subprocess
import sys
import types
import warnings

import numpy as np
import pytest

import clcsg
from clcsg.cli import app as cli
from clcsg.rendering.camera import Camera
from clcsg.errors import (
    ClcsgError,
    DeviceError,
    DnfLimitError,
    LimitError,
    SceneError,
    TransformError,
    UsageError,
)
from clcsg.cl.device import DeviceInfo, choose, require_int64_atomics
from clcsg.sampling.sampler import sample
from clcsg import raytrace, render
from clcsg.writers.ply import read_samples as read_ply

import tree_oracle as T
from coverage import assert_same_samples, uncovered
from image_check import compare as compare_with_oracle
from test_sampler import SCENES as SAMPLER_SCENES
from test_splat import check as check_splats
from test_splat import views

EXAMPLES = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "examples")

# -- scene files for the error table ------------------------------------------------------------

FILES = {
    "ok.json": '{"clcsg": 1, "root": {"sphere": {"radius": 1}}}',
    "nan.json": '{"clcsg": 1, "root": {"sphere": {"radius": NaN}}}',
    "inf.json": '{"clcsg": 1, "root": {"sphere": {"radius": 1e309}}}',
    "neg.json": '{"clcsg": 1, "root": {"sphere": {"radius": -1}}}',
    "zero.json": '{"clcsg": 1, "root": {"box": {"size": [1, 0, 1]}}}',
    "string.json": '{"clcsg": 1, "root": {"sphere": {"radius": "1"}}}',
    "list.json": '{"clcsg": 1, "root": [1, 2]}',
    "singular.json": '{"clcsg": 1, "root": {"sphere": {"radius": 1}, "transform": [{"scale": [1, 0, 1]}]}}',
    "projective.json": '{"clcsg": 1, "root": {"sphere": {"radius": 1}, "transform": '
                       '[{"matrix": [[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 1, 1]]}]}}',
    "nan_matrix.json": '{"clcsg": 1, "root": {"sphere": {"radius": 1}, "transform": '
                       '[{"matrix": [[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, NaN], [0, 0, 0, 1]]}]}}',
    "truncated.json": '{"clcsg": 1, "root": {"sphere": {"radius": 1}',
    "empty_file.json": "",
    "unknown_kind.json": '{"clcsg": 1, "root": {"spere": {"radius": 1}}}',
    "unbounded.json": '{"clcsg": 1, "root": {"halfspace": {"normal": [0, 0, 1]}}}',
    "empty_solid.json": '{"clcsg": 1, "root": {"difference": [{"sphere": {"radius": 1}}, {"sphere": {"radius": 2}}]}}',
    "many_terms.json": '{"clcsg": 1, "root": {"difference": [{"box": {"size": 2}}, '
                       + ", ".join(f'{{"box": {{"size": 0.2, "center": [{x}, {y}, 0]}}}}'
                                   for x in (-0.5, 0, 0.5) for y in (-0.5, 0, 0.5)) + "]}}",
    "ok.csg": "sphere(r = 1);",
    "truncated.csg": "sphere(r = 1",
    "garbage.csg": "cube([1, 1, 1]) }}} ;;",
    "unsupported.csg": "rotate_extrude() multmatrix([[1, 0, 0, 2], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]]) circle(1);",
    "scene.txt": "sphere(1);",
}


@pytest.fixture
def files(tmp_path):
    for name, text in FILES.items():
        (tmp_path / name).write_text(text)
    return tmp_path


def _oclgrind_listed() -> bool:
    try:
        return any(i.is_oclgrind for i in clcsg.devices())
    except DeviceError:
        return False



# (argv, exit code, substring of the one-line message); {d} is the directory of FILES, {o} an
# output directory.  Exit codes: 2 bad command line, 3 bad input, 4 device, 5 limit.
CLI_ERRORS = [
    # files and formats
    ("info {d}/missing.json", 3, "no such file"),
    ("sample {d}/missing.csg -r 0.1 -o {o}/x.ply", 3, "no such file"),
    ("render {d}/missing.json -o {o}/x.png", 3, "no such file"),
    ("info {d}/scene.txt", 3, "unknown scene format"),
    # JSON syntax, types, values
    ("info {d}/truncated.json", 3, "invalid JSON"),
    ("info {d}/empty_file.json", 3, "line 1, column 1"),
    ("info {d}/string.json", 3, "$.root.sphere.radius"),
    ("info {d}/list.json", 3, "$.root"),
    ("info {d}/unknown_kind.json", 3, "spere"),
    ("info {d}/nan.json", 3, "NaN"),
    ("info {d}/inf.json", 3, "finite"),
    ("info {d}/neg.json", 3, "must be positive"),
    ("info {d}/zero.json", 3, "$.root.box.size"),
    ("info {d}/singular.json", 3, "singular"),
    ("info {d}/projective.json", 3, "not affine"),
    ("info {d}/nan_matrix.json", 3, "$.root.transform[0].matrix"),
    ("info {d}/unbounded.json", 3, "unbounded"),
    # OpenSCAD syntax and content
    ("info {d}/truncated.csg", 3, "syntax error"),
    ("info {d}/garbage.csg", 3, "syntax error"),
    ("info {d}/unsupported.csg", 3, "sweeps a torus, a quartic surface"),
    # options
    ("sample {d}/ok.json -r 0 -o {o}/x.ply", 2, "--radius must be a positive"),
    ("sample {d}/ok.json -r -1 -o {o}/x.ply", 2, "--radius must be a positive"),
    ("sample {d}/ok.json -r nan -o {o}/x.ply", 2, "must be a positive finite number"),
    ("sample {d}/ok.json -r inf -o {o}/x.ply", 2, "must be a positive finite number"),
    ("sample {d}/ok.json -r abc -o {o}/x.ply", 2, "must be a number or a percentage"),
    ("sample {d}/ok.json -r 0.1 --floor 0 -o {o}/x.ply", 2, "--floor"),
    ("sample {d}/ok.json -r 0.1 --bound 1,1,1,0,0,0 -o {o}/x.ply", 2, "--bound"),
    ("info {d}/ok.json --bound nan,0,0,1,1,1", 2, "--bound"),
    ("render {d}/ok.json -o {o}/x.png -r 0", 2, "--radius must be a positive"),
    ("render {d}/ok.json -o {o}/x.png --size 0x10", 2, "--size"),
    ("render {d}/ok.json -o {o}/x.png --size 10x0", 2, "--size"),
    ("render {d}/ok.json -o {o}/x.png --size 0x0", 2, "--size"),
    ("render {d}/ok.json -o {o}/x.png --size axb", 2, "--size"),
    ("render {d}/ok.json -o {o}/x.png --size 100000x100000", 2, "too large"),
    ("render {d}/ok.json -o {o}/x.png --fov 0", 2, "fov"),
    ("render {d}/ok.json -o {o}/x.png --fov 180", 2, "fov"),
    ("render {d}/ok.json -o {o}/x.png --fov nan", 2, "--fov"),
    ("render {d}/ok.json -o {o}/x.png --eye 1,1", 2, "--eye"),
    ("render {d}/ok.json -o {o}/x.png --eye 0,0,0 --target 0,0,0", 2, "eye and target"),
    ("render {d}/ok.json -o {o}/x.png --up 0,0,0", 2, "up"),
    ("render {d}/ok.json -o {o}/x.png --background 0,0", 2, "--background"),
    ("render {d}/ok.json -o {o}/x.png --background 0,0,-1", 2, "--background"),
    ("render {d}/ok.json -o {o}/x.xyz --method raytrace --size 8x6", 2, "unknown image format"),
    ("render {d}/ok.json -o {o}/no/such/dir/x.png --method raytrace --size 8x6", 2, "cannot write there"),
    ("sample {d}/ok.json -r 0.5 -o {o}/no/such/dir/x.ply", 2, "cannot write"),
    # devices
    ("info {d}/ok.json --device nosuch", 4, "unknown device 'nosuch'"),
    ("sample {d}/ok.json -r 0.1 -o {o}/x.ply --device 9:9", 4, "out of range"),
    ("render {d}/ok.json -o {o}/x.png --device 0:99", 4, "out of range"),
    ("devices --device nosuch", 4, "unknown device"),
    pytest.param("render {d}/ok.json -o {o}/x.png --device oclgrind", 4, "Oclgrind is not installed",
                 marks=pytest.mark.skipif(_oclgrind_listed(), reason="Oclgrind is installed here")),
    # limits
    ("info {d}/many_terms.json --normal-form dnf --term-limit 50", 5, "--term-limit"),
    ("sample {d}/ok.json -r 1e-5 -o {o}/x.ply", 5, "raise --max-samples"),
    ("sample {d}/ok.json -r 1e-300 -o {o}/x.ply", 5, "use a larger --radius"),
    ("sample {d}/ok.json -r 0.01 --max-samples 100 -o {o}/x.ply", 5, "limit of 100 samples"),
    ("render {d}/ok.json -o {o}/x.png -r 1e-5", 5, "use a larger --radius"),
    ("render {d}/ok.json -o {o}/x.png -r 0.01 --max-samples 10", 5, "limit of 10 samples"),
]

#: argparse errors: usage lines, then one "clcsg ...: error: ..." line, exit code 2
ARGPARSE_ERRORS = [
    ("nosuch", "invalid choice"),
    ("info", "required"),
    ("sample {d}/ok.json -r 0.1", "--output"),
    ("info {d}/ok.json --term-limit 0", "--term-limit"),
    ("sample {d}/ok.json -r 0.1 -o {o}/x.ply --max-samples 0", "--max-samples"),
    ("render {d}/ok.json -o {o}/x.png --method nope", "--method"),
    ("info {d}/ok.json --nosuch", "unrecognized arguments"),
]


def _argv(text, d, o):
    return text.format(d=d, o=o).split()


@pytest.mark.parametrize("argv, code, message", CLI_ERRORS)
def test_cli_error_table(files, tmp_path, capsys, argv, code, message):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        rc = cli.main(_argv(argv, files, tmp_path))
    out, err = capsys.readouterr()
    lines = err.strip().splitlines()
    assert rc == code, f"exit code {rc}, stderr: {err}"
    assert len(lines) == 1, f"expected one line, got: {err!r}"
    assert lines[0].startswith("clcsg: error: ")
    assert message in lines[0]
    assert "Traceback" not in err and "internal error" not in err


@pytest.mark.parametrize("argv, message", ARGPARSE_ERRORS)
def test_cli_argparse_errors(files, tmp_path, capsys, argv, message):
    rc = cli.main(_argv(argv, files, tmp_path))
    _, err = capsys.readouterr()
    assert rc == 2
    last = err.strip().splitlines()[-1]
    assert "error:" in last and message in last
    assert "Traceback" not in err


@pytest.mark.parametrize(
    "argv, code, message",
    [
        ("info {d}/missing.json", 3, "no such file"),
        ("info {d}/nan.json", 3, "NaN"),
        ("sample {d}/ok.json -r 0 -o {o}/x.ply", 2, "--radius"),
        ("info {d}/ok.json --device nosuch", 4, "unknown device"),
        ("sample {d}/ok.json -r 1e-6 -o {o}/x.ply", 5, "--max-samples"),
    ],
)
def test_cli_errors_in_a_subprocess(files, tmp_path, argv, code, message):
    p = subprocess.run([sys.executable, "-m", "clcsg", *_argv(argv, files, tmp_path)],
                       capture_output=True, text=True, timeout=120)
    assert p.returncode == code, p.stderr
    assert "Traceback" not in p.stderr
    lines = p.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("clcsg: error: ") and message in lines[0], p.stderr


def test_debug_shows_the_traceback(files, capsys):
    with pytest.raises(SceneError):
        cli.main(["--debug", "info", str(files / "nan.json")])


# -- the Python API -----------------------------------------------------------------------------

S = clcsg.sphere(1.0)
NAN = float("nan")

PYTHON_ERRORS = [
    ("sphere(-1)", lambda: clcsg.sphere(-1), ValueError, "radius"),
    ("sphere(nan)", lambda: clcsg.sphere(NAN), ValueError, "radius"),
    ("box(0)", lambda: clcsg.box(0), ValueError, "box size"),
    ("box([1, 1])", lambda: clcsg.box([1, 1]), ValueError, "box size"),
    ("cylinder(inf)", lambda: clcsg.cylinder(math.inf, 1), ValueError, "height"),
    ("cone(1, 0, 0)", lambda: clcsg.cone(1, 0, 0), ValueError, "r1 > 0 or r2 > 0"),
    ("color out of range", lambda: clcsg.sphere(1, color=(2, 0, 0)), ValueError, "color"),
    ("quadric zero", lambda: clcsg.quadric(np.zeros((4, 4))), ValueError, "zero"),
    ("quadric not symmetric", lambda: clcsg.quadric(np.arange(16.0).reshape(4, 4)), ValueError, "symmetric"),
    ("translate nan", lambda: S.translate((NAN, 0, 0)), ValueError, "finite"),
    ("rotate about 0", lambda: S.rotate((0, 0, 0), 30), ValueError, "axis"),
    ("scale 0", lambda: S.scale(0), TransformError, "singular"),
    ("scale [1, 0, 1]", lambda: S.scale([1, 0, 1]), TransformError, "singular"),
    ("rotate nan degrees", lambda: S.rotate((0, 0, 1), NAN), TransformError, "NaN"),
    ("projective matrix", lambda: S.transform([[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [1, 0, 0, 1]]),
     TransformError, "not affine"),
    ("3x3 matrix", lambda: S.transform(np.eye(3)), TransformError, "4x4"),
    ("operand not a shape", lambda: S | 3, TypeError, "Shape"),
    ("sample radius 0", lambda: sample(S, 0), UsageError, "radius"),
    ("sample radius -1", lambda: sample(S, -1), UsageError, "radius"),
    ("sample radius nan", lambda: sample(S, NAN), UsageError, "radius"),
    ("sample radius text", lambda: sample(S, "a"), UsageError, "radius"),
    ("sample radius 1e-300", lambda: sample(S, 1e-300), LimitError, "larger --radius"),
    ("sample radius 1e-5", lambda: sample(S, 1e-5), LimitError, "--max-samples"),
    ("sample max_samples", lambda: sample(S, 0.01, max_samples=10), LimitError, "limit of 10"),
    ("sample max_samples 0", lambda: sample(S, 0.1, max_samples=0), UsageError, "max_samples"),
    ("sample max_memory", lambda: sample(S, 0.01, max_memory=1000), LimitError, "max_memory"),
    ("sample floor nan", lambda: sample(S, 0.1, floor=NAN), UsageError, "floor"),
    ("sample bound inverted", lambda: sample(S, 0.1, bound=[[1, 1, 1], [0, 0, 0]]), SceneError, "bound"),
    ("sample an int", lambda: sample(42, 0.1), SceneError, "expected a Shape"),
    ("sample a missing file", lambda: sample("missing.json", 0.1), SceneError, "no such file"),
    ("sample on an unknown device", lambda: sample(S, 0.1, device="nosuch"), DeviceError, "unknown device"),
    ("load .txt", lambda: clcsg.load(__file__), SceneError, "unknown scene format"),
    ("save .csg", lambda: clcsg.save(S, "x.csg"), SceneError, ".json"),
    ("camera size 0", lambda: Camera.look_at((5, 0, 0), (0, 0, 0), width=0, height=10), UsageError, "image size"),
    ("camera fov 180", lambda: Camera.look_at((5, 0, 0), (0, 0, 0), fov=180), UsageError, "fov"),
    ("camera eye nan", lambda: Camera.look_at((NAN, 0, 0), (0, 0, 0)), UsageError, "finite"),
    ("camera fit nan bound", lambda: Camera.fit([[0, 0, 0], [NAN, 1, 1]]), UsageError, "bound"),
    ("raytrace with a bad camera", lambda: raytrace(S, camera="x"), UsageError, "Camera"),
    ("render a shape", lambda: render(S), UsageError, "Samples"),
    ("DNF term limit", lambda: clcsg.Scene(clcsg.box(2) - clcsg.union(
        *[clcsg.box(0.1, center=(x, 0, 0)) for x in np.linspace(-0.8, 0.8, 9)])).normalize(20),
     DnfLimitError, "past the limit of 20"),
]


@pytest.mark.parametrize("what, call, exc, message", PYTHON_ERRORS, ids=[r[0] for r in PYTHON_ERRORS])
def test_python_error_table(cl_context, what, call, exc, message):
    with pytest.raises(exc) as e:
        call()
    text = str(e.value)
    assert message in text
    assert "\n" not in text and text.strip() == text
    if issubclass(exc, ClcsgError):
        assert e.value.exit_code == {UsageError: 2, SceneError: 3, TransformError: 3, DeviceError: 4,
                                     LimitError: 5, DnfLimitError: 5}[exc]


def _info(**kw) -> DeviceInfo:
    base = dict(platform_index=0, device_index=0, platform="Synthetic", name="Test Device", type="gpu",
                compute_units=8, fp64=True, int64_atomics=True, is_oclgrind=False,
                max_mem_alloc=1 << 30, global_mem=4 << 30)
    base.update(kw)
    return DeviceInfo(**base)


def test_device_without_64_bit_atomics_is_refused():
    require_int64_atomics(_info(), "the splat renderer")  # fine
    with pytest.raises(DeviceError, match="cl_khr_int64_extended_atomics") as e:
        require_int64_atomics(_info(int64_atomics=False), "the splat renderer")
    assert e.value.exit_code == 4 and "Test Device" in str(e.value) and "--device" in str(e.value)
    # choose() on synthetic lists: unknown names and indices are DeviceErrors too
    infos = [_info(), _info(platform_index=1, platform="Oclgrind", name="Oclgrind Simulator", is_oclgrind=True)]
    assert choose(infos, None, {}) == 0 and choose(infos, "oclgrind", {}) == 1
    for spec in ("nosuch", "5:0", "0:7"):
        with pytest.raises(DeviceError):
            choose(infos, spec, {})
    with pytest.raises(DeviceError, match="never chosen by default"):
        choose(infos[1:], None, {})


def test_dnf_past_its_limit_is_caught_in_seconds(tmp_path, capsys):
    """A box minus a union of hundreds of small boxes: 6^n terms; the limit stops it early."""
    rng = np.random.default_rng(0)
    small = [clcsg.box(0.05, center=c) for c in rng.uniform(-0.9, 0.9, (300, 3))]
    path = tmp_path / "holes.json"
    clcsg.save(clcsg.box(2) - clcsg.union(*small), path)
    rc = cli.main(["info", str(path), "--normal-form", "dnf"])
    err = capsys.readouterr().err
    assert rc == 5 and "--term-limit" in err and len(err.strip().splitlines()) == 1


def _tape(shape):
    return clcsg.as_scene(shape).compile()


# -- empty results ------------------------------------------------------------------------------

A = clcsg.box(1.0) - clcsg.cylinder(2.0, 0.3)
EMPTY = {
    "sphere(1) - sphere(2)": clcsg.sphere(1) - clcsg.sphere(2),
    "A - A": A - A,
    "disjoint boxes": clcsg.box(1.0) & clcsg.box(1.0, center=(3, 0, 0)),
    "empty union": clcsg.union(),
}


@pytest.mark.parametrize("name", sorted(EMPTY))
def test_empty_solids_warn_and_give_empty_results(cl_context, name):
    tape = _tape(EMPTY[name])
    assert tape.empty
    with pytest.warns(UserWarning, match="empty"):
        s = sample(EMPTY[name], 0.1, device=cl_context)
    assert len(s) == 0 and s.positions.shape == (0, 3)
    cam = Camera.look_at((4, -3, 2), (0, 0, 0), width=16, height=12)
    for img in (render(s, cam, device=cl_context, background=(0, 0, 1)),
                raytrace(tape, cam, device=cl_context, background=(0, 0, 1))):
        assert not img.mask.any() and np.all(np.isinf(img.depth))
        assert np.all(img.rgba[..., :3] == [0, 0, 255])


EMPTY_FILES = {
    "empty.csg": "",
    "empty_group.csg": "group() { }",
    "zero_scale.csg": "multmatrix([[1, 0, 0, 0], [0, 0, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]]) sphere(1);",
    "a_minus_a.json": '{"clcsg": 1, "defs": {"a": {"box": {"size": 1}}}, '
                      '"root": {"difference": [{"ref": "a"}, {"ref": "a"}]}}',
}


@pytest.mark.parametrize("name", sorted(EMPTY_FILES))
def test_empty_files_info_reports_zero_terms(tmp_path, capsys, name):
    path = tmp_path / name
    path.write_text(EMPTY_FILES[name])
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        assert cli.main(["info", str(path), "--json"]) == 0
    import json

    info = json.loads(capsys.readouterr().out)
    assert info["dnf_terms"] == 0 and info["bound"] is None


@pytest.mark.parametrize("name", ["empty.csg", "a_minus_a.json"])
def test_cli_sample_of_an_empty_solid_writes_an_empty_ply(tmp_path, capsys, name):
    path = tmp_path / name
    path.write_text(EMPTY_FILES[name])
    out = tmp_path / "e.ply"
    with warnings.catch_warnings(record=True) as w:
        warnings.simplefilter("always")
        rc = cli.main(["sample", str(path), "-r", "0.1", "-o", str(out)])
    err = capsys.readouterr().err
    assert any("empty" in str(x.message) for x in w)
    assert rc == 0, err
    assert len(read_ply(out)["positions"]) == 0


@pytest.mark.parametrize("method", ["splat", "raytrace"])
def test_cli_render_of_an_empty_solid_writes_the_background(tmp_path, capsys, method):
    path = tmp_path / "a_minus_a.json"
    path.write_text(EMPTY_FILES["a_minus_a.json"])
    out = tmp_path / "e.png"
    with warnings.catch_warnings(record=True) as w:
        warnings.simplefilter("always")
        rc = cli.main(["render", str(path), "-o", str(out), "--size", "16x12", "--method", method,
                       "--background", "0,0,255"])
    assert rc == 0, capsys.readouterr().err
    assert any("empty" in str(x.message) for x in w)
    from PIL import Image as PILImage

    rgba = np.asarray(PILImage.open(out))
    assert rgba.shape == (12, 16, 4) and np.all(rgba[..., :3] == [0, 0, 255])


# -- degenerate geometry stays exact ------------------------------------------------------------

DRILLED = clcsg.box(2) - clcsg.cylinder(3, 0.5) - clcsg.cylinder(3, 0.5, axis=(1, 0, 0))

DEGENERATE = {
    # coincident faces (OpenSCAD's z-fighting cases)
    "box_union_itself": (clcsg.box(1.0) | clcsg.box(1.0), 0.08),
    "boxes_sharing_a_face": (clcsg.box(1.0) | clcsg.box(1.0, center=(1.0, 0, 0)), 0.08),
    "flush_pocket": (clcsg.box(2.0) - clcsg.box((1.0, 1.0, 1.0), center=(0, 0, 0.5)), 0.1),
    "flush_through_hole": (clcsg.box(2.0) - clcsg.box((1.0, 1.0, 2.0)), 0.1),
    "overlapping_flush_tops": (clcsg.box(1.0) | clcsg.box(1.0, center=(0.5, 0.5, 0)), 0.06),
    # tangencies
    "tangent_spheres": (clcsg.sphere(1.0) | clcsg.sphere(1.0, center=(2.0, 0, 0)), 0.1),
    "internally_tangent": (clcsg.sphere(1.0) - clcsg.sphere(0.5, center=(0.5, 0, 0)), 0.08),
    # a plane through a cylinder's axis
    "plane_through_axis": (clcsg.cylinder(2.0, 0.8) & clcsg.halfspace((1, 0, 0), 0.0), 0.08),
    # a cone apex on a plane and on a sphere
    "apex_on_plane": (clcsg.cone(1.0, 0.8, 0.0) | clcsg.box(1.5, center=(0, 0, 1.25)), 0.08),
    "apex_on_sphere": (clcsg.cone(1.0, 0.6, 0.0, center=(0, 0, -0.5)) | clcsg.sphere(0.5, center=(0, 0, 0.5)), 0.06),
    # coordinates from 1e-3 to 1e4
    "scaled_1e-3": (DRILLED.scale(1e-3), 0.1e-3),
    "scaled_1e4": (DRILLED.scale(1e4), 0.1e4),
    "far_from_origin": (DRILLED.translate((1e4, -1e4, 5e3)), 0.1),
}


@pytest.mark.parametrize("name", sorted(DEGENERATE))
def test_degenerate_geometry_stays_exact(cl_context, name):
    shape, r = DEGENERATE[name]
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        s = sample(shape, r, device=cl_context, progress=False)
    st = s.stats
    # bounded subdivision
    assert 0 < len(s) and st["levels"] < 60
    assert st["cells"] < 200 * len(s), st["cells"]
    # no NaN anywhere
    for a in (s.positions, s.normals, s.radii):
        assert np.all(np.isfinite(a))
    assert np.allclose(np.linalg.norm(s.normals, axis=1), 1.0)
    # every sample on the surface, the surface covered
    tape = s.tape
    size = float(np.linalg.norm(tape.bound[1] - tape.bound[0]))
    Q = tape.quadrics[s.quadrics]
    on_q, on_csg = T.sample_residuals(shape, s.positions, Q)
    assert on_q.max() <= 1e-5 * size and on_csg.all()
    pad = 1e-3 * size
    ref = T.surface_points(shape, tape.bound + [[-pad], [pad]], n_lines=10000)
    assert len(ref) > 100
    ids = T.quadric_table(shape).match(tape.quadrics)
    mapped = types.SimpleNamespace(positions=s.positions, quadrics=ids[s.quadrics])
    missing = uncovered(ref.points, ref.quadrics, mapped, r, slack=1e-5)
    assert len(missing) == 0, f"{len(missing)} surface points uncovered, e.g. {ref.points[missing[:3]].tolist()}"
    # renders: the ray tracer equals the float64 oracle away from fragile pixels, the splats
    # equal the ray tracer
    for cam in views(tape, 48, 36)[:2]:
        ref_img = raytrace(tape, cam, device=cl_context)
        assert np.all(np.isfinite(ref_img.depth[ref_img.mask]))
        compare_with_oracle(ref_img, shape, tape, cam)
        for sa, bf in [(True, True), (False, False)]:
            img = render(s, cam, device=cl_context, surface_aligned=sa, backface_culling=bf)
            assert np.all(np.isfinite(img.depth[img.mask]))
            o, d = cam.rays()
            fragile = T.fragile(shape, o, d, rel=1e-9)
            agree = (img.mask == ref_img.mask)[~fragile].mean()
            assert agree >= 0.999, f"masks agree on {agree:.5f} of the non-fragile pixels"
            check_splats(img, ref_img)


# -- nothing lost: forced tiny buffers ----------------------------------------------------------

CAPACITY_SCENES = ["sphere", "rounded_cube", "sharp_tips", "flush_tops", "cone_frustum", "hyperboloid_two_sheets",
                   "shared_surface"]


def _same_samples(big, tiny):
    assert len(big) > 0
    assert_same_samples(big, tiny, ("distance_queries", "leaf_distances", "unresolved", "filled", "single",
                                     "discarded", "split", "levels"))


@pytest.mark.parametrize("name", CAPACITY_SCENES)
def test_tiny_buffers_lose_nothing(cl_context, name):
    shape, r = SAMPLER_SCENES[name]
    big = sample(shape, r, device=cl_context, capacity=(1 << 20, 1 << 20, 1 << 22, 1 << 20))
    tiny = sample(shape, r, device=cl_context, capacity=(2, 2, 2, 2))
    assert tiny.stats["buffer_growths"]["cells"] > 0 and tiny.stats["buffer_growths"]["samples"] > 0
    assert big.stats["buffer_growths"] == {"cells": 0, "samples": 0, "arena": 0}
    _same_samples(big, tiny)


def test_tiny_buffers_lose_nothing_on_an_example(cl_context):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        sc = clcsg.load(os.path.join(EXAMPLES, "flange.csg"))
    b = sc.compile().bound
    r = float(np.linalg.norm(b[1] - b[0])) / 40
    _same_samples(sample(sc, r, device=cl_context), sample(sc, r, device=cl_context, capacity=(2, 2, 2, 2)))


def test_renderer_has_no_capacity_limited_buffer(cl_context):
    """The renderer's buffers are sized from their inputs (W x H framebuffer and outputs, one
    record per sample, the clip list): a render of many samples into a tiny image and of few
    samples into a big one both match the ray tracer."""
    shape, r = SAMPLER_SCENES["drilled_block"]
    many = sample(shape, r / 3, device=cl_context)
    few = sample(shape, 0.6, device=cl_context)
    for s, (w, h) in ((many, (8, 6)), (few, (160, 120))):
        cam = Camera.fit(s.tape, w, h)
        ref = raytrace(s.tape, cam, device=cl_context)
        img = render(s, cam, device=cl_context)
        assert img.stats["splats_drawn"] + img.stats["splats_offscreen"] + img.stats["splats_culled"] == len(s)
        assert (img.mask == ref.mask).mean() >= 0.99


@pytest.mark.parametrize(
    "build",
    [
        lambda: clcsg.sphere(-1.0),
        lambda: clcsg.box((1, 0, 1)),
        lambda: clcsg.cylinder(1.0, 0.5, axis=(0, 0, 0)),
        lambda: clcsg.cone(1.0, 0.0, 0.0),
        lambda: clcsg.quadric(np.arange(16.0).reshape(4, 4)),
        lambda: clcsg.sphere(1.0).rotate((0, 0, 0), 30),
        lambda: clcsg.sphere(1.0, color=(2, 0, 0)),
        lambda: clcsg.intersection(),
    ],
    ids=["radius", "box-size", "axis", "cone-radii", "asymmetric", "rotation-axis", "color", "no-operands"],
)
def test_python_constructors_raise_the_package_error(build):
    """Bad parameters in the Python API raise a ClcsgError (ParameterError, also a ValueError)
    with a one-line message, like the file readers."""
    from clcsg.errors import ParameterError

    with pytest.raises(ParameterError) as info:
        build()
    assert isinstance(info.value, clcsg.ClcsgError) and isinstance(info.value, ValueError)
    assert "\n" not in str(info.value) and str(info.value)


def test_a_non_shape_operand_raises_the_package_error():
    from clcsg.errors import OperandError

    with pytest.raises(OperandError, match="Shape"):
        clcsg.union(clcsg.sphere(1.0), "sphere")
