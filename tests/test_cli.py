"""The ``clcsg`` command line: in-process through ``main`` and as ``python -m clcsg``."""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys

import numpy as np
import pytest

import clcsg
from clcsg.cli import app as cli
from clcsg.errors import SceneError, UsageError
from clcsg.model.scene import Scene


def run(capsys, *argv):
    code = cli.main(list(argv))
    out, err = capsys.readouterr()
    return code, out, err


def run_module(*argv, env=None):
    e = dict(os.environ)
    e.update(env or {})
    return subprocess.run(
        [sys.executable, "-m", "clcsg", *argv], capture_output=True, text=True, timeout=120, env=e
    )


def demo_scene() -> Scene:
    part = (clcsg.box(2) - clcsg.cylinder(3, 0.5)) | clcsg.sphere(1, center=(3, 0, 0))
    return Scene(part, source="demo")


# -- parse_floats -------------------------------------------------------------------------------


def test_parse_floats():
    assert cli.parse_floats("1,2,3", 3, "--eye") == (1.0, 2.0, 3.0)
    assert cli.parse_floats(" -1, 2.5e1 ,3 ", 3, "--eye") == (-1.0, 25.0, 3.0)
    assert cli.parse_floats("1 2", 2, "--size") == (1.0, 2.0)


@pytest.mark.parametrize("text", ["1,2", "1,2,3,4", "1,x,3", "1,nan,3", "inf,0,0", "", "1,,2"])
def test_parse_floats_rejects(text):
    with pytest.raises(UsageError, match="^--target: ") as e:
        cli.parse_floats(text, 3, "--target")
    assert e.value.exit_code == 2


def test_negative_vectors_need_no_equals_sign():
    assert cli.join_negative_vectors(["info", "s.json", "--bound", "-1,-1,-1,1,1,1"]) == [
        "info",
        "s.json",
        "--bound=-1,-1,-1,1,1,1",
    ]
    assert cli.join_negative_vectors(["--term-limit", "-1"]) == ["--term-limit", "-1"]
    assert cli.join_negative_vectors(["--", "--bound", "-1,0"]) == ["--", "--bound", "-1,0"]


# -- help, errors, exit codes -------------------------------------------------------------------


def test_help(capsys):
    code, out, _ = run(capsys, "--help")
    assert code == 0
    for name in cli.COMMANDS:
        assert name in out
    assert "examples:" in out


@pytest.mark.parametrize("name", list(cli.COMMANDS))
def test_subcommand_help(capsys, name):
    code, out, _ = run(capsys, name, "--help")
    assert code == 0
    assert "--device" in out and "PYOPENCL_CTX" in out
    assert "examples:" in out


def test_no_command_is_usage_error(capsys):
    code, _, err = run(capsys)
    assert code == 2 and "usage:" in err


def test_unknown_option(capsys):
    code, _, err = run(capsys, "devices", "--frobnicate")
    assert code == 2 and "Traceback" not in err


def test_version(capsys):
    code, out, _ = run(capsys, "--version")
    assert code == 0 and clcsg.__version__ in out


def test_error_handling(capsys, monkeypatch):
    def boom(args):
        raise SceneError("scene.json: node 3: radius must be > 0")

    monkeypatch.setitem(cli.COMMANDS, "devices", (cli.COMMANDS["devices"][0], boom))
    code, out, err = run(capsys, "devices")
    assert code == 3
    assert err == "clcsg: error: scene.json: node 3: radius must be > 0\n"

    def bug(args):
        raise ZeroDivisionError("division by zero")

    monkeypatch.setitem(cli.COMMANDS, "devices", (cli.COMMANDS["devices"][0], bug))
    code, out, err = run(capsys, "devices")
    assert code == 1
    assert err == (
        "clcsg: internal error: ZeroDivisionError: division by zero (run with --debug for the traceback)\n"
    )
    with pytest.raises(ZeroDivisionError):
        cli.main(["--debug", "devices"])
    with pytest.raises(ZeroDivisionError):
        cli.main(["devices", "--debug"])

    def interrupted(args):
        raise KeyboardInterrupt

    monkeypatch.setitem(cli.COMMANDS, "devices", (cli.COMMANDS["devices"][0], interrupted))
    code, out, err = run(capsys, "devices")
    assert code == 130


# -- devices ------------------------------------------------------------------------------------


def test_devices(capsys, monkeypatch):
    monkeypatch.delenv("PYOPENCL_CTX", raising=False)
    code, out, err = run(capsys, "devices")
    assert code == 0, err
    infos = clcsg.devices()
    for i in infos:
        assert i.spec in out and i.name in out
    marked = [line for line in out.splitlines() if re.match(r"^\*\s+\d+:\d+\s", line)]
    assert len(marked) == 1
    from clcsg.cl.device import choose

    assert infos[choose(infos, None, {})].spec in marked[0]
    assert "64-bit atomics" in out and "fp64" in out


def test_devices_json(capsys):
    code, out, _ = run(capsys, "devices", "--json", "--device", "0:0")
    assert code == 0
    rows = json.loads(out)
    assert rows[0]["selected"] and rows[0]["spec"] == "0:0"
    assert {"platform_index", "device_index", "name", "type", "fp64", "int64_atomics", "is_oclgrind"} <= set(rows[0])


def test_bad_device_in_process(capsys):
    code, out, err = run(capsys, "devices", "--device", "nonsense")
    assert code == 4
    assert err.count("\n") == 1 and err.startswith("clcsg: error: unknown device 'nonsense'")


def test_bad_pyopencl_ctx_still_lists(capsys, monkeypatch):
    monkeypatch.setenv("PYOPENCL_CTX", "77:0")
    code, out, err = run(capsys, "devices")
    assert code == 4
    assert "0:0" in out and "PYOPENCL_CTX='77:0'" in err


def test_python_m_devices():
    r = run_module("devices")
    assert r.returncode == 0, r.stderr
    assert "P:D" in r.stdout and "*" in r.stdout
    assert "Traceback" not in r.stderr


@pytest.mark.parametrize("name", ["", *cli.COMMANDS])
def test_python_m_help(name):
    r = run_module(*([name] if name else []), "--help")
    assert r.returncode == 0, r.stderr
    assert r.stdout.startswith("usage: clcsg")


@pytest.mark.parametrize("argv", [["devices", "--device", "9:9"], ["info", "x.json", "--device", "tpu"]])
def test_python_m_bad_device(argv, tmp_path):
    r = run_module(*argv)
    assert r.returncode == 4
    assert r.stderr.count("\n") == 1 and r.stderr.startswith("clcsg: error: ")
    assert "Traceback" not in r.stderr


# -- info ---------------------------------------------------------------------------------------


def test_scene_info_programmatic():
    from clcsg.cli.info import format_info
    from clcsg.compile.summary import scene_info

    info = scene_info(demo_scene(), normal_form="dnf", listing=True)
    t = info["tape"]
    assert t["primitives"] == 3 and info["unique_quadrics"] == 10
    assert t["leaves"] == 10 and t["instructions"] == 19 and t["registers"] >= 2 and t["depth"] == 4
    # (box & ~cyl & ~cap & ~cap) | sphere: 3 + 1 terms if distributed, 2 after pruning
    assert info["dnf_terms"] == 4 and info["dnf"]["stats"]["terms"] == 2
    # the solid's box, to rounding (closed-form primitive boxes are padded by a few ulps of the size)
    assert np.allclose(info["bound"], [[-1.0, -1.0, -1.0], [4.0, 1.0, 1.0]], rtol=0, atol=1e-7)
    assert np.all(np.array(info["bound"][0]) <= [-1, -1, -1]) and np.all(np.array(info["bound"][1]) >= [4, 1, 1])
    json.dumps(info)
    text = format_info(info)
    for key in ("primitives:", "unique quadrics:", "tape:", "DNF terms:", "DNF built:", "tape listing:", "scene bound:"):
        assert key in text
    assert "4 (counted, not built)" in text and "19 instructions, 10 leaves" in text


def test_scene_info_counts_huge_dnfs_without_building_them():
    from clcsg.compile.summary import scene_info

    plate = clcsg.box((40, 30, 2))
    holes = [clcsg.cylinder(4, 0.5, center=(x, y, 0)) | clcsg.cone(1, 1.2, 0.5, center=(x, y, 0.6))
             for x in range(-15, 16, 5) for y in (-10, 0, 10)]
    info = scene_info(plate - clcsg.union(*holes))
    assert info["dnf_terms"] > 10**9
    # the cap planes of all holes are the same four quadrics, each leaf computed once
    assert info["unique_quadrics"] == 6 + 2 * len(holes) + 4 == info["tape"]["leaves"]
    assert info["user_bound_from"] is None


def test_scene_info_bound_override_and_unbounded():
    from clcsg.compile.summary import scene_info

    with pytest.raises(SceneError, match="unbounded"):
        scene_info(~clcsg.sphere(1))
    info = scene_info(~clcsg.sphere(1), bound=[[-2, -2, -2], [2, 2, 2]])
    assert info["bound"] == [[-2.0] * 3, [2.0] * 3] and info["user_bound_from"] == "--bound"


@pytest.fixture
def scene_loader(monkeypatch):
    """``clcsg.readers.scenes.load`` returning demo_scene() for '*.demo' paths (the file formats are
    tested elsewhere; this tests the CLI around the loader)."""
    import clcsg.readers.scenes

    real = clcsg.readers.scenes.load

    def load(path):
        if str(path).endswith(".demo"):
            return demo_scene()
        return real(path)

    monkeypatch.setattr(clcsg.readers.scenes, "load", load)


def test_info_text(capsys, scene_loader):
    code, out, err = run(capsys, "info", "part.demo")
    assert code == 0, err
    assert "DNF terms:" in out and "4 (counted, not built)" in out and "DNF built" not in out
    assert "scene bound:" in out and "(4, 1, 1)" in out


def test_info_json_and_options(capsys, scene_loader):
    code, out, err = run(capsys, "info", "part.demo", "--json", "--normal-form", "dnf", "--term-limit", "1000",
                         "--bound", "-5,-5,-5,5,5,5")
    assert code == 0, err
    info = json.loads(out)
    assert info["dnf"]["stats"]["terms"] == 2 and info["tape"]["leaves"] == 10
    assert info["user_bound"] == [[-5.0] * 3, [5.0] * 3]


def test_info_term_limit(capsys, scene_loader):
    code, out, err = run(capsys, "info", "part.demo", "--normal-form", "dnf", "--term-limit", "1")
    assert code == 5
    assert err.startswith("clcsg: error: ") and "limit" in err and err.count("\n") == 1


@pytest.mark.parametrize(
    "bound", ["1,2,3", "0,0,0,1,1,nan", "0,0,0,1,1,inf", "1,1,1,0,0,0", "a,b,c,d,e,f"]
)
def test_info_bad_bound(capsys, scene_loader, bound):
    code, out, err = run(capsys, "info", "part.demo", "--bound", bound)
    assert code == 2
    assert err.startswith("clcsg: error: --bound: ") and err.count("\n") == 1


@pytest.mark.parametrize("argv", [["--term-limit", "0"], ["--term-limit", "x"], ["--bound"]])
def test_info_bad_options(capsys, scene_loader, argv):
    code, _, err = run(capsys, "info", "part.demo", *argv)
    assert code == 2 and "Traceback" not in err


def test_info_missing_file(capsys):
    code, _, err = run(capsys, "info", "no/such/scene.json")
    assert code == 3
    assert err == "clcsg: error: no/such/scene.json: no such file\n"


def test_info_json_file(capsys, tmp_scene):
    path = tmp_scene(demo_scene())
    code, out, err = run(capsys, "info", str(path), "--normal-form", "dnf")
    assert code == 0, err
    assert "2 terms after pruning" in out


def test_python_m_info_json_file(tmp_scene):
    path = tmp_scene(demo_scene())
    r = run_module("info", str(path), "--json")
    assert r.returncode == 0, r.stderr
    assert json.loads(r.stdout)["tape"]["primitives"] == 3
    r = run_module("info", str(path), "--bound", "1,2")
    assert r.returncode == 2 and "Traceback" not in r.stderr


def test_sample_writes_ply_and_stats(tmp_path):
    import json as _json

    from clcsg.cli import main as _main
    from clcsg.writers.ply import read_samples

    out, stats = tmp_path / "s.ply", tmp_path / "s.json"
    scene = tmp_path / "scene.json"
    import clcsg as _c

    _c.save(_c.box(2) - _c.sphere(1.2), scene)
    assert _main(["sample", str(scene), "-r", "0.1", "-o", str(out), "--stats", str(stats), "--no-progress"]) == 0
    back = read_samples(out)
    st = _json.loads(stats.read_text())
    assert len(back["positions"]) == st["samples"] > 0
    assert {"distance_queries", "leaf_distances", "clip_rows", "levels", "cells_per_level"} <= set(st)
    assert st["normal_form"] == "tree"
    assert _main(["sample", str(scene), "-r", "0.1", "-o", str(out), "--normal-form", "dnf", "--float32",
                  "--no-progress"]) == 0
    assert len(read_samples(out)["positions"]) == st["samples"]


def test_program_flushes_everything_before_its_fast_exit(tmp_path):
    """``python -m clcsg`` ends with os._exit (no interpreter teardown): its piped output, JSON
    events and files are complete, and the exit code is the command's."""
    from clcsg.writers.ply import read_samples

    scene, out, stats = tmp_path / "scene.json", tmp_path / "s.ply", tmp_path / "s.json"
    clcsg.save(clcsg.box(2) - clcsg.sphere(1.2), scene)
    r = run_module("sample", str(scene), "-r", "0.1", "-o", str(out), "--stats", str(stats), "--progress", "json")
    assert r.returncode == 0, r.stderr
    events = [json.loads(line) for line in r.stderr.splitlines()]
    assert events[-1]["samples"] == json.loads(stats.read_text())["samples"] == len(read_samples(out)["positions"]) > 0
    assert r.stdout.endswith("\n") and f"{events[-1]['samples']:,} samples" in r.stdout
    r = run_module("sample", str(tmp_path / "missing.csg"), "-o", str(out))
    assert r.returncode != 0 and r.stderr.startswith("clcsg: error: ") and r.stderr.endswith("\n")


def test_sample_rejects_bad_radius(tmp_path, capsys):
    from clcsg.cli import main as _main

    scene = tmp_path / "scene.json"
    import clcsg as _c

    _c.save(_c.sphere(1), scene)
    assert _main(["sample", str(scene), "-r", "0", "-o", str(tmp_path / "x.ply")]) == 2
    err = capsys.readouterr().err
    assert "radius" in err and "Traceback" not in err and len(err.strip().splitlines()) == 1


def test_radius_relative_to_the_scene_diagonal(tmp_path):
    """``-r 2%`` is 2% of the bound's diagonal, for sample as for render: the same samples as
    the absolute radius."""
    import clcsg
    from clcsg.writers.ply import read_samples

    path = tmp_path / "s.json"
    clcsg.save(clcsg.box(2.0) - clcsg.sphere(1.2), path)
    diag = float(np.linalg.norm(np.subtract(*clcsg.load(path).compile().bound[::-1])))
    assert cli.main(["sample", str(path), "-r", "2%", "-o", str(tmp_path / "a.ply"), "--quiet"]) == 0
    assert cli.main(["sample", str(path), "-r", repr(0.02 * diag), "-o", str(tmp_path / "b.ply"), "--quiet"]) == 0
    a, b = read_samples(tmp_path / "a.ply"), read_samples(tmp_path / "b.ply")
    assert len(a["positions"]) > 100 and np.array_equal(np.sort(a["positions"], axis=0), np.sort(b["positions"], axis=0))
    assert cli.main(["render", str(path), "-r", "3%", "-o", str(tmp_path / "a.png"), "--size", "64x48", "--quiet"]) == 0


def test_sample_radius_defaults_to_one_percent_of_the_diagonal(tmp_path):
    """Without ``-r`` the coverage radius is 1% of the bound's diagonal, as for render."""
    import clcsg
    from clcsg.writers.ply import read_samples

    path = tmp_path / "s.json"
    clcsg.save(clcsg.box(2.0) - clcsg.sphere(1.2), path)
    assert cli.main(["sample", str(path), "-o", str(tmp_path / "a.ply"), "--quiet", "--stats", str(tmp_path / "a.json")]) == 0
    assert cli.main(["sample", str(path), "-r", "1%", "-o", str(tmp_path / "b.ply"), "--quiet"]) == 0
    a, b = read_samples(tmp_path / "a.ply"), read_samples(tmp_path / "b.ply")
    assert len(a["positions"]) > 100 and np.array_equal(np.sort(a["positions"], axis=0), np.sort(b["positions"], axis=0))
    diag = float(np.linalg.norm(np.subtract(*clcsg.load(path).compile().bound[::-1])))
    assert np.isclose(json.loads((tmp_path / "a.json").read_text())["radius"], 0.01 * diag)
