"""A batch driver killed with SIGKILL mid-run: no worker outlives it by 10 s, every scene whose
files were written is in the journal, and the rerun recomputes only the scenes without
written output; on the local process pool and on a Dask LocalCluster (--dask local:2).  Also:
the journal is folded in and emptied, and the content hash covers a .scad program's includes
and the clcsg version."""

from __future__ import annotations

import json
import os
import shutil
import signal
import subprocess
import sys
import time

import numpy as np
import pytest

import clcsg
from clcsg.batching.manifest import JOURNAL, Manifest
from clcsg.batching.options import Options, Radius
from clcsg.model.random_programs import random_program

pytestmark = pytest.mark.filterwarnings("ignore")

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
N_SCENES = 10


@pytest.fixture(scope="module")
def scenes(tmp_path_factory):
    d = tmp_path_factory.mktemp("durable_scenes")
    rng = np.random.default_rng(7)
    for k in range(N_SCENES):
        (d / f"s{k:02d}.csg").write_text(random_program(rng, max_depth=2).csg)
    return d


def _descendants(pid: int) -> set[int]:
    """Every live process below ``pid`` (from /proc)."""
    children: dict[int, list[int]] = {}
    for entry in os.listdir("/proc"):
        if entry.isdigit():
            try:
                with open(f"/proc/{entry}/stat") as f:
                    ppid = int(f.read().rsplit(")", 1)[1].split()[1])
            except (OSError, IndexError, ValueError):
                continue
            children.setdefault(ppid, []).append(int(entry))
    out, todo = set(), [pid]
    while todo:
        for c in children.get(todo.pop(), []):
            out.add(c)
            todo.append(c)
    return out


def _alive(pid: int) -> bool:
    try:
        with open(f"/proc/{pid}/stat") as f:
            return f.read().rsplit(")", 1)[1].split()[0] not in ("Z", "X")
    except OSError:
        return False


def _written(out) -> set[str]:
    d = out / "samples"
    return {p.name.split(".")[0] for p in d.iterdir() if not p.name.startswith(".")} if d.is_dir() else set()


def _batch_argv(scenes, out, engine):
    return [sys.executable, "-m", "clcsg", "batch", str(scenes), "-r", "4%", "-o", str(out), "-q", *engine]


def _kill_mid_run(scenes, out, engine, at_least=2):
    """Start the batch, SIGKILL the driver once ``at_least`` scenes are written; (written
    scenes, the driver's descendants)."""
    env = {**os.environ, "PYTHONPATH": ROOT + os.pathsep + os.environ.get("PYTHONPATH", "")}
    proc = subprocess.Popen(_batch_argv(scenes, out, engine), env=env, stdout=subprocess.DEVNULL,
                            stderr=subprocess.PIPE)
    workers: set[int] = set()
    deadline = time.monotonic() + 400
    try:
        while len(_written(out)) < at_least:
            assert proc.poll() is None, f"the batch ended before it was killed: {proc.stderr.read().decode()}"
            assert time.monotonic() < deadline, "the batch made no progress"
            workers |= _descendants(proc.pid)
            time.sleep(0.05)
        workers |= _descendants(proc.pid)
        proc.send_signal(signal.SIGKILL)
        proc.wait(30)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert workers, "the driver started no worker process"
    return _written(out), workers


def _check_kill_and_rerun(scenes, out, engine):
    written, workers = _kill_mid_run(scenes, out, engine)
    t0 = time.monotonic()
    while any(_alive(p) for p in workers) and time.monotonic() - t0 < 10:
        time.sleep(0.1)
    survivors = [p for p in workers if _alive(p)]
    for p in survivors:  # do not leak them into the rest of the test run
        os.kill(p, signal.SIGKILL)
    assert not survivors, f"worker processes {survivors} outlived the killed driver by 10 s"
    assert len(written) < N_SCENES, "the driver was killed after the last scene: nothing to test"
    journaled = set(Manifest(str(out)).rows)
    assert written <= journaled, f"written but not journaled: {written - journaled}"
    table = clcsg.batch(str(scenes), "4%", out, workers=2, progress=False)
    rows = {r["name"]: r for r in table.to_pylist()}
    assert len(rows) == N_SCENES and all(r["status"] == "ok" for r in rows.values())
    skipped = {n for n, r in rows.items() if r["skipped"]}
    assert skipped == written, f"recomputed with output written: {written - skipped}; reused without: {skipped - written}"
    assert not (out / JOURNAL).exists()


def test_local_driver_killed_leaves_no_worker_and_loses_no_scene(scenes, tmp_path):
    _check_kill_and_rerun(scenes, tmp_path / "out", ["--workers", "2"])


def test_dask_driver_killed_leaves_no_worker_and_loses_no_scene(scenes, tmp_path):
    pytest.importorskip("distributed")
    _check_kill_and_rerun(scenes, tmp_path / "out", ["--dask", "local:2"])


def test_journal_rows_are_folded_in_and_a_torn_line_is_ignored(scenes, tmp_path):
    out = tmp_path / "out"
    one = str(scenes / "s00.csg")
    clcsg.batch(one, "4%", out, progress=False)
    m = Manifest(str(out))
    row = dict(m.rows["s00"])
    os.unlink(out / "manifest.parquet")
    with open(out / JOURNAL, "w") as f:
        f.write(json.dumps({**row, "finished": None}) + "\n")
        f.write('{"name": "s01", "hash": "torn li')
    folded = Manifest(str(out))
    assert set(folded.rows) == {"s00"} and folded.rows["s00"]["hash"] == row["hash"]
    again = clcsg.batch(one, "4%", out, progress=False).to_pylist()
    assert again[0]["skipped"] and not (out / JOURNAL).exists()


def test_content_hash_covers_scad_includes_and_the_version(tmp_path, monkeypatch):
    if shutil.which(os.environ.get("OPENSCAD", "openscad")) is None:
        pytest.skip("openscad is not installed")
    (tmp_path / "part.scad").write_text("include <dims.scad>\ncube(size);\n")
    (tmp_path / "dims.scad").write_text("size = 2;\n")
    out = tmp_path / "out"
    first = clcsg.batch(str(tmp_path / "part.scad"), "5%", out, progress=False).to_pylist()[0]
    assert first["status"] == "ok", first["error"]
    assert json.loads(first["dependencies"]) == [str(tmp_path / "dims.scad")]
    assert clcsg.batch(str(tmp_path / "part.scad"), "5%", out, progress=False).to_pylist()[0]["skipped"]
    (tmp_path / "dims.scad").write_text("size = 3;\n")
    changed = clcsg.batch(str(tmp_path / "part.scad"), "5%", out, progress=False).to_pylist()[0]
    assert not changed["skipped"] and changed["hash"] != first["hash"]
    assert changed["diagonal"] == pytest.approx(3 * 3**0.5)
    opts = Options(Radius.parse("5%"))
    h = opts.content_hash("digest")
    monkeypatch.setattr(clcsg, "__version__", "0.0.0-other")
    assert opts.content_hash("digest") != h


class _Killed(BaseException):
    """Stands for a SIGKILL at one step of the driver's store (nothing after it runs)."""


def _kill_at(monkeypatch, target, name):
    def die(*args, **kwargs):
        raise _Killed(name)

    monkeypatch.setattr(target, name, die)


@pytest.mark.parametrize("step", ["journal", "publish"])
def test_a_file_is_named_only_after_its_row_is_journaled(scenes, tmp_path, monkeypatch, step):
    """A rerun with other options killed before the row is journaled leaves neither the old
    nor the new file under the scene's name; killed after it, the journaled row's file is
    missing, so the row is not complete and the next run computes the scene again."""
    from clcsg.batching import api

    out = tmp_path / "out"
    one = str(scenes / "s00.csg")
    first = clcsg.batch(one, "4%", out, progress=False).to_pylist()[0]
    assert first["status"] == "ok" and (out / first["samples_file"]).is_file()
    if step == "journal":
        _kill_at(monkeypatch, Manifest, "add")
    else:
        _kill_at(monkeypatch, api, "publish_files")
    with pytest.raises(_Killed):
        clcsg.batch(one, "5%", out, progress=False)
    monkeypatch.undo()
    assert _written(out) == set(), "a file is named without its row in the journal"
    assert not [p for p in (out / "samples").iterdir()], "a temporary was left behind"
    rows = Manifest(str(out)).rows
    if step == "journal":
        assert rows["s00"]["hash"] == first["hash"]
    else:
        assert rows["s00"]["hash"] != first["hash"] and rows["s00"]["status"] == "ok"
    again = clcsg.batch(one, "5%", out, progress=False).to_pylist()[0]
    assert again["status"] == "ok" and not again["skipped"] and (out / again["samples_file"]).is_file()
