"""clcsg batch: 40 random programs (one broken) on a 2-worker Dask LocalCluster with a worker
killed mid-run, the local process pool on the same scenes (same outputs), restarts that
recompute nothing or only what is missing, Parquet and PLY read back, views equal to
`clcsg render` pixel for pixel, inputs (globs, directories, manifests) and one-line errors."""

from __future__ import annotations

import json
import os
import shutil
import sys

import numpy as np
import pyarrow.parquet as pq
import pytest
from PIL import Image

import clcsg
from clcsg.batching.inputs import jobs
from clcsg.batching.options import DependencyError
from clcsg.batching.task import CRASH_HOOK
from clcsg.cli.app import main
from clcsg.errors import UsageError
from clcsg.writers.ply import read_samples
from clcsg.model.random_programs import random_program

import tree_oracle as T

pytestmark = pytest.mark.filterwarnings("ignore")

N_PROGRAMS = 39
RADIUS = "4%"
CRASHING = "prog_05"
COLUMNS = ["x", "y", "z", "nx", "ny", "nz", "quadric", "primitive", "radius", "clipped"]


@pytest.fixture(scope="module")
def scene_dir(tmp_path_factory):
    """39 random programs (every third as .json, the others as OpenSCAD .csg) and a broken file."""
    d = tmp_path_factory.mktemp("scenes")
    rng = np.random.default_rng(2024)
    for k in range(N_PROGRAMS):
        prog = random_program(rng, max_depth=2)
        if k % 3 == 0:
            clcsg.save(prog.shape, d / f"prog_{k:02d}.json")
        else:
            (d / f"prog_{k:02d}.csg").write_text(prog.csg)
    (d / "broken.csg").write_text("union() { cube(size = [1, 2; }\n")
    return d


def _scene_file(scene_dir, name):
    return next(str(p) for p in scene_dir.iterdir() if p.stem == name)


def _crash_once(marker):
    os.environ[CRASH_HOOK] = f"{CRASHING}:{marker}"


@pytest.fixture(scope="module")
def dask_run(scene_dir, tmp_path_factory):
    """The 40 scenes on a Dask LocalCluster of 2 worker processes (one thread each); the first
    worker that starts prog_05 exits at once (the crash hook), so Dask must reschedule it."""
    out = tmp_path_factory.mktemp("dask_out")
    marker = out.parent / "dask_crash_marker"
    _crash_once(marker)
    try:
        table = clcsg.batch(str(scene_dir), RADIUS, out, dask="local:2", progress=False)
    finally:
        os.environ.pop(CRASH_HOOK, None)
    return table, out, marker


def _rows(table):
    return {r["name"]: r for r in table.to_pylist()}


def _positions(path):
    t = pq.read_table(path)
    a = np.column_stack([t[c].to_numpy() for c in ("x", "y", "z", "nx", "ny", "nz")])
    return a[np.lexsort(a[:, :3].T[::-1])]


def test_dask_cluster_completes_every_scene_on_the_surface(dask_run, scene_dir):
    table, out, marker = dask_run
    rows = _rows(table)
    assert len(rows) == N_PROGRAMS + 1
    bad = rows.pop("broken")
    assert bad["status"] == "error" and bad["error_code"] == 3 and "broken.csg:1:" in bad["error"]
    assert bad["samples_file"] is None and not os.path.exists(out / "samples" / "broken.parquet")
    assert all(r["status"] == "ok" for r in rows.values()), [r["error"] for r in rows.values() if r["error"]]
    # a worker really died on prog_05, and another one ran it to the end
    assert marker.exists() and marker.read_text() != rows[CRASHING]["worker"]
    assert rows[CRASHING]["samples"] > 0
    assert len({r["worker"] for r in rows.values()}) >= 2
    assert (out / "manifest.parquet").exists()
    assert pq.read_table(out / "manifest.parquet").num_rows == N_PROGRAMS + 1
    nonempty = 0
    for name, r in rows.items():
        t = pq.read_table(out / r["samples_file"])
        assert t.column_names == COLUMNS and t.num_rows == r["samples"]
        assert str(t.schema.field("clipped").type) == "bool" and str(t.schema.field("quadric").type) == "int32"
        assert int(t["clipped"].to_numpy().sum()) == r["clipped_samples"]
        assert t.schema.metadata[b"clcsg.scene"].decode() == name
        if not r["samples"]:  # an empty solid (an intersection of disjoint parts): no radius
            assert np.isnan(r["radius"]) and r["diagonal"] == 0
            continue
        assert r["radius"] == pytest.approx(0.04 * r["diagonal"], rel=1e-12)
        nonempty += 1
        scene = clcsg.load(_scene_file(scene_dir, name))
        tape = scene.compile()
        pos = np.column_stack([t[c].to_numpy() for c in "xyz"])
        size = float(np.linalg.norm(tape.bound[1] - tape.bound[0]))
        on_q, on_csg = T.sample_residuals(scene.shape, pos, tape.quadrics[t["quadric"].to_numpy()], tol=1e-9 * size)
        assert on_q.max() <= 1e-6 * size and on_csg.all(), (name, int((~on_csg).sum()))
        assert np.all(t["radius"].to_numpy() <= r["radius"] * (1 + 1e-12))
    assert nonempty >= 30


def test_rerun_recomputes_nothing_then_only_what_is_missing(dask_run, scene_dir):
    table, out, _ = dask_run
    files = sorted((out / "samples").iterdir())
    mtimes = {p.name: p.stat().st_mtime_ns for p in files}
    again = clcsg.batch(str(scene_dir), RADIUS, out, dask="local:2", progress=False)
    rows = _rows(again)
    assert all(r["skipped"] for r in rows.values())  # the broken file's error is final too
    assert {p.name: p.stat().st_mtime_ns for p in sorted((out / "samples").iterdir())} == mtimes
    assert all(r["skipped"] for r in pq.read_table(out / "manifest.parquet").to_pylist())
    # a missing output is redone (on the local engine: the same options, the same hash)
    victim = out / rows["prog_07"]["samples_file"]
    before = _positions(victim)
    victim.unlink()
    third = _rows(clcsg.batch(str(scene_dir), RADIUS, out, workers=1, progress=False))
    assert not third["prog_07"]["skipped"] and third["prog_07"]["status"] == "ok"
    assert sum(not r["skipped"] for r in third.values()) == 1
    assert np.array_equal(_positions(victim), before)
    assert third["prog_08"]["samples"] == rows["prog_08"]["samples"]


def test_local_pool_gives_the_same_outputs_and_survives_a_dead_worker(dask_run, scene_dir, tmp_path):
    _, dask_out, _ = dask_run
    names = ["prog_00", "prog_01", "prog_02", "prog_03", CRASHING, "prog_06"]
    sub = tmp_path / "sub"
    sub.mkdir()
    for n in names:
        shutil.copy(_scene_file(scene_dir, n), sub)
    marker = tmp_path / "crash_marker"
    _crash_once(marker)
    try:
        table = clcsg.batch(str(sub), RADIUS, tmp_path / "out", workers=2, progress=False)
    finally:
        os.environ.pop(CRASH_HOOK, None)
    rows = _rows(table)
    assert marker.exists()  # the pool broke once
    assert rows[CRASHING]["attempts"] == 2 and all(r["attempts"] <= 2 for r in rows.values())
    dask_rows = _rows(pq.read_table(dask_out / "manifest.parquet"))
    for n in names:
        assert rows[n]["status"] == "ok" and rows[n]["samples"] == dask_rows[n]["samples"]
        assert rows[n]["hash"] == dask_rows[n]["hash"]
        assert np.array_equal(_positions(tmp_path / "out" / rows[n]["samples_file"]),
                              _positions(dask_out / dask_rows[n]["samples_file"]))


def test_a_worker_dying_past_the_retries_is_an_error_row_then_redone(scene_dir, tmp_path):
    sub = tmp_path / "sub"
    sub.mkdir()
    for n in ("prog_02", CRASHING):
        shutil.copy(_scene_file(scene_dir, n), sub)
    _crash_once(tmp_path / "marker")
    try:
        rows = _rows(clcsg.batch(str(sub), RADIUS, tmp_path / "out", workers=1, retries=0, progress=False))
    finally:
        os.environ.pop(CRASH_HOOK, None)
    assert rows["prog_02"]["status"] == "ok"
    dead = rows[CRASHING]
    assert dead["status"] == "error" and dead["error_code"] == 1 and "worker process died" in dead["error"]
    # not a final error: the rerun runs it (the hook fires only once) and keeps the other
    rows = _rows(clcsg.batch(str(sub), RADIUS, tmp_path / "out", workers=1, retries=0, progress=False))
    assert rows[CRASHING]["status"] == "ok" and not rows[CRASHING]["skipped"] and rows["prog_02"]["skipped"]


def test_views_equal_clcsg_render_pixel_for_pixel(scene_dir, tmp_path, capsys):
    names = ("prog_01", "prog_03")
    files = [_scene_file(scene_dir, n) for n in names]
    out = tmp_path / "out"
    rc = main(["batch", *files, "-r", RADIUS, "-o", str(out), "--views", "2", "--size", "96x72", "--workers", "1"])
    assert rc == 0
    assert "2 scenes: 2 ok, 0 failed" in capsys.readouterr().out
    rows = _rows(pq.read_table(out / "manifest.parquet"))
    for name, path in zip(names, files):
        r = rows[name]
        cams = json.loads(r["cameras"])
        assert r["views"] == 2 == len(cams) == len(r["images"])
        images = [np.asarray(Image.open(out / img)) for img in r["images"]]
        assert not np.array_equal(images[0], images[1])  # two different views
        for cam, got in zip(cams, images):
            ref = tmp_path / f"{name}.png"
            vec = lambda v: ",".join(repr(float(x)) for x in v)  # noqa: E731
            assert main(["render", path, "-r", repr(r["radius"]), "--eye", vec(cam["eye"]), "--target",
                         vec(cam["target"]), "--up", vec(cam["up"]), "--fov", repr(cam["fov"]), "--size",
                         f"{cam['width']}x{cam['height']}", "-o", str(ref), "-q"]) == 0
            want = np.asarray(Image.open(ref))
            assert got.shape == (72, 96, 4) and (got[..., 3] > 0).any()
            assert np.array_equal(got, want)


def test_manifest_inputs_and_ply_output(dask_run, scene_dir, tmp_path):
    _, dask_out, _ = dask_run
    listing = tmp_path / "list.txt"
    shutil.copy(_scene_file(scene_dir, "prog_04"), tmp_path)
    inline = json.dumps(clcsg.readers.scenefile.scene_to_dict(clcsg.box(1) - clcsg.sphere(0.6)), separators=(",", ":"))
    listing.write_text(f"# scenes\nprog_04.csg\n\n{inline}\nmissing.json\nnotes.md\n")
    table = clcsg.batch(str(listing), RADIUS, tmp_path / "out", fmt="ply", workers=1, progress=False)
    rows = _rows(table)
    assert list(rows) == ["prog_04", "list-4", "missing", "list-6"]
    assert rows["list-4"]["status"] == "ok" and rows["list-4"]["samples"] > 100
    assert rows["missing"]["error_code"] == 3 and "no such file" in rows["missing"]["error"]
    assert rows["list-6"]["status"] == "error" and "not a scene file" in rows["list-6"]["error"]
    ply = read_samples(tmp_path / "out" / rows["prog_04"]["samples_file"])
    got = np.column_stack([ply["positions"], ply["normals"]])
    got = got[np.lexsort(got[:, :3].T[::-1])]
    dask_row = _rows(pq.read_table(dask_out / "manifest.parquet"))["prog_04"]
    assert np.array_equal(got, _positions(dask_out / dask_row["samples_file"]))
    assert rows["prog_04"]["hash"] != dask_row["hash"]  # the format is part of the options


def test_inputs_globs_directories_and_names(tmp_path):
    (tmp_path / "a" / "deep").mkdir(parents=True)
    (tmp_path / "b").mkdir()
    for p in ("a/part.json", "a/deep/part.json", "b/part.csg", "b/other file.csg", "b/readme.txt"):
        clcsg.save(clcsg.sphere(1), tmp_path / "tmp.json")
        shutil.move(tmp_path / "tmp.json", tmp_path / p)
    js = jobs([str(tmp_path / "a"), str(tmp_path / "b" / "*.csg"), str(tmp_path / "a" / "part.json")])
    assert [j.name for j in js] == ["part", "part-2", "other_file", "part-3"]
    assert [os.path.relpath(j.source, tmp_path) for j in js] == ["a/part.json", "a/deep/part.json",
                                                                 "b/other file.csg", "b/part.csg"]
    assert js[0].digest == js[1].digest and all(j.text and j.error is None for j in js)
    import clcsg.batching.task as task  # the package is callable and its modules importable

    assert callable(clcsg.batch) and task.run_job and clcsg.batching.batch.__module__ == "clcsg.batching.api"
    objs = jobs([clcsg.box(1), clcsg.sphere(1)])
    assert [j.name for j in objs] == ["scene-00000", "scene-00001"] and objs[0].kind == ".json"
    for bad in ([str(tmp_path / "nothing")], [str(tmp_path / "*.scad")], [str(tmp_path / "b" / "*.txt")], [42]):
        with pytest.raises(UsageError):
            jobs(bad)


def test_python_api_objects_options_and_hashes(tmp_path):
    shapes = [clcsg.box(1) & clcsg.sphere(0.65), clcsg.sphere(1) & clcsg.sphere(1, center=(5, 0, 0))]
    rows = clcsg.batch(shapes, 0.1, tmp_path, workers=1, progress=False).to_pylist()
    assert [r["name"] for r in rows] == ["scene-00000", "scene-00001"]
    assert rows[0]["samples"] > 50 and rows[0]["radius"] == 0.1
    assert rows[1]["status"] == "ok" and rows[1]["samples"] == 0 and "empty" in rows[1]["warnings"]
    again = clcsg.batch(shapes, 0.05, tmp_path, workers=1, progress=False).to_pylist()  # other options
    assert not any(r["skipped"] for r in again) and again[0]["hash"] != rows[0]["hash"]
    assert again[0]["samples"] > 2 * rows[0]["samples"]
    try:
        import pandas  # noqa: F401
    except ImportError:
        with pytest.raises(DependencyError, match="pandas"):
            clcsg.batch(shapes, 0.05, tmp_path, as_pandas=True)
    else:
        frame = clcsg.batch(shapes, 0.05, tmp_path, as_pandas=True, progress=False)
        assert list(frame["skipped"]) == [True, True]
    # point queries: given points (a .npy file), or random ones in each bound, reproducible
    grid = np.random.default_rng(1).uniform(-1, 1, (500, 3))
    np.save(tmp_path / "points.npy", grid)
    q = clcsg.batch(shapes[:1], 0.1, tmp_path / "q", points=str(tmp_path / "points.npy"), workers=1,
                    progress=False).to_pylist()[0]
    t = pq.read_table(tmp_path / "q" / q["queries_file"])
    assert t.column_names == ["x", "y", "z", "inside", "distance"] and q["query_points"] == 500
    assert np.array_equal(t["inside"].to_numpy(), T.contains(shapes[0], grid))
    assert np.array_equal(t["distance"].to_numpy(), clcsg.distance(shapes[0], grid))
    assert q["inside_fraction"] == pytest.approx(T.contains(shapes[0], grid).mean())
    rnd = [clcsg.batch(shapes[:1], 0.1, tmp_path / d, random_points=300, workers=1, progress=False).to_pylist()[0]
           for d in ("r1", "r2")]
    a, b = (pq.read_table(tmp_path / d / r["queries_file"]) for d, r in zip(("r1", "r2"), rnd))
    assert a.equals(b) and a.num_rows == 300 and 0 < rnd[0]["inside_fraction"] < 1
    xyz = np.column_stack([a[c].to_numpy() for c in "xyz"])
    assert np.abs(xyz).max() <= 0.5 + 0.05 * np.sqrt(3) + 1e-12  # the box's bound, grown by 5% of its diagonal
    os.unlink(tmp_path / "r1" / rnd[0]["queries_file"])  # a missing query file is redone
    assert not clcsg.batch(shapes[:1], 0.1, tmp_path / "r1", random_points=300, workers=1,
                           progress=False).to_pylist()[0]["skipped"]
    with pytest.raises(UsageError):
        clcsg.batch(shapes, "five%", tmp_path)
    with pytest.raises(UsageError):
        clcsg.batch(shapes, 0.1, tmp_path, scheduler="tcp://x:1", dask="local:1")


@pytest.mark.parametrize("argv, code, text", [
    (["-r", "1", "NOFILE"], 2, "no such file or directory"),
    (["-r", "abc", "SCENES"], 2, "--radius must be a number or a percentage"),
    (["-r", "1", "SCENES/*.scad"], 2, "no scene file"),
    (["-r", "1", "--dask", "local:0", "SCENES"], 2, "at least one worker"),
    (["-r", "1", "--size", "0x5", "SCENES"], 2, "--size"),
    (["-r", "1", "--dask", "tcp://h:1", "SCENES"], 2, "a scheduler address goes to --scheduler"),
    (["-r", "1", "--views", "-1", "SCENES"], 2, "views must be >= 0"),
    (["-r", "1", "--retries", "-1", "SCENES"], 2, "retries must be >= 0"),
    (["-r", "1", "--points", "NOFILE", "SCENES"], 2, "cannot read"),
])
def test_cli_errors_are_one_line(argv, code, text, scene_dir, tmp_path, capsys):
    argv = [a.replace("SCENES", str(scene_dir)).replace("NOFILE", str(tmp_path / "none.csg")) for a in argv]
    assert main(["batch", *argv, "-o", str(tmp_path / "out")]) == code
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("clcsg: error: ") and text in err[0], err


def test_missing_pyarrow_is_a_one_line_error(scene_dir, tmp_path, capsys, monkeypatch):
    monkeypatch.setitem(sys.modules, "pyarrow", None)  # what an environment without it imports
    assert main(["batch", str(scene_dir), "-r", "1", "-o", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "pip install 'clcsg[batch]'" in err[0], err
    assert not (tmp_path / "out").exists()
