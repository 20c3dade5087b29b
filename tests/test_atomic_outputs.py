"""Outputs are atomic: a full disk or a SIGKILL in the middle of a write leaves the previous
file intact and no temporary behind; a failed write exits 6 with one line; output paths
(a directory, a missing folder) are refused before any work."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys

import numpy as np
import pytest

from clcsg.batching.outputs import write_atomic
from clcsg.errors import OutputError
from clcsg import atomic
from clcsg.atomic import atomic_open
from clcsg.writers.output_files import write_image, write_json, write_npy

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
SCENE = os.path.join(ROOT, "examples", "drilled_block.json")
OLD = b"the previous file\n"


def clcsg(*argv, timeout=300):
    env = {**os.environ, "PYTHONPATH": ROOT + os.pathsep + os.environ.get("PYTHONPATH", "")}
    return subprocess.run([sys.executable, "-m", "clcsg", *argv], capture_output=True, text=True, timeout=timeout,
                          env=env)


@pytest.fixture
def small_disk(tmp_path):
    """A 64 KiB tmpfs (skipped where it cannot be mounted)."""
    d = tmp_path / "disk"
    d.mkdir()
    r = subprocess.run(["mount", "-t", "tmpfs", "-o", "size=64k", "tmpfs", str(d)], capture_output=True, text=True)
    if r.returncode != 0:
        pytest.skip(f"cannot mount a small tmpfs to fill: {r.stderr.strip() or r.returncode}")
    try:
        yield d
    finally:
        subprocess.run(["umount", "-l", str(d)], capture_output=True)


def _only(folder, names):
    assert sorted(os.listdir(folder)) == sorted(names), os.listdir(folder)


def _noise(n):
    return np.random.default_rng(0).integers(0, 256, (n, n, 4), dtype=np.uint8)


WRITERS = {
    "png": lambda p: write_image(_noise(256), p),
    "jpg": lambda p: write_image(_noise(512), p),
    "npy": lambda p: write_npy(p, np.random.default_rng(1).random((200, 200))),
    "json": lambda p: write_json(p, {"x": list(range(40000))}),
    "parquet": lambda p: write_atomic(str(p), os.urandom(100_000)),
}


@pytest.mark.parametrize("ext", sorted(WRITERS))
def test_full_disk_keeps_the_previous_file_and_leaves_no_temporary(small_disk, ext):
    target = small_disk / f"out.{ext}"
    target.write_bytes(OLD)
    with pytest.raises(OutputError, match="cannot write") as e:
        WRITERS[ext](target)
    assert "\n" not in str(e.value) and str(target) in str(e.value)
    assert target.read_bytes() == OLD
    _only(small_disk, [target.name])


def test_full_disk_from_the_cli_exits_6_with_one_line(small_disk, tmp_path, cl_context):
    target = small_disk / "samples.npz"
    target.write_bytes(OLD)
    stats = small_disk / "stats.json"
    r = clcsg("sample", SCENE, "-r", "3%", "-o", str(target), "--stats", str(stats))
    assert r.returncode == 6, r.stderr
    lines = [ln for ln in r.stderr.splitlines() if ln.strip()]
    assert len(lines) == 1 and lines[0].startswith("clcsg: error: ") and "No space left" in lines[0], r.stderr
    assert target.read_bytes() == OLD
    _only(small_disk, [target.name])


def test_samples_writers_on_a_full_disk(small_disk, cl_context):
    import clcsg

    s = clcsg.sample(SCENE, 0.05, device=cl_context)
    for name in ("s.ply", "s.npz"):
        target = small_disk / name
        target.write_bytes(OLD)
        with pytest.raises(OutputError):
            clcsg.write_samples(s, target)
        assert target.read_bytes() == OLD
        target.unlink()
    _only(small_disk, [])


_SLOW_WRITER = """
import sys, time
from clcsg.atomic import atomic_open
with atomic_open(sys.argv[1], "wb") as f:
    for k in range(10000):
        f.write(b"x" * 65536)
        f.flush()
        if k == 3:
            print("writing", flush=True)
        time.sleep(0.01)
"""


@pytest.mark.parametrize("unnamed", [True, False], ids=["o_tmpfile", "named_temporary"])
def test_sigkill_during_the_write_keeps_the_previous_file(tmp_path, unnamed):
    target = tmp_path / "out.bin"
    target.write_bytes(OLD)
    code = _SLOW_WRITER if unnamed else "import clcsg.atomic as a; a._open_unnamed = lambda folder: None\n" + _SLOW_WRITER
    env = {**os.environ, "PYTHONPATH": ROOT + os.pathsep + os.environ.get("PYTHONPATH", "")}
    proc = subprocess.Popen([sys.executable, "-c", code, str(target)], stdout=subprocess.PIPE, env=env)
    assert proc.stdout.readline() == b"writing\n"
    proc.send_signal(signal.SIGKILL)
    proc.wait(30)
    assert target.read_bytes() == OLD
    left = sorted(os.listdir(tmp_path))
    if unnamed:  # the file had no name yet: nothing at all is left
        assert left == ["out.bin"]
    else:  # a named temporary is hidden; the next successful write is unaffected
        assert [n for n in left if not n.startswith(".out.bin.")] == ["out.bin"]
    with atomic_open(target, "wb") as f:
        f.write(b"new")
    assert target.read_bytes() == b"new"


def test_a_failing_writer_leaves_the_old_file_on_both_paths(tmp_path, monkeypatch):
    target = tmp_path / "out.json"
    target.write_bytes(OLD)
    for unnamed in (True, False):
        if not unnamed:
            monkeypatch.setattr(atomic, "_open_unnamed", lambda folder: None)
        with pytest.raises(ZeroDivisionError):
            with atomic_open(target, "w") as f:
                f.write("partial")
                1 / 0
        assert target.read_bytes() == OLD
        _only(tmp_path, ["out.json"])
    write_json(target, {"ok": True})
    assert json.loads(target.read_text()) == {"ok": True}
    assert oct(target.stat().st_mode & 0o777) == oct(0o666 & ~_umask())


def _umask():
    m = os.umask(0)
    os.umask(m)
    return m


@pytest.mark.parametrize("argv,message", [
    (["sample", SCENE, "-r", "5%", "-o", "{d}/is_dir.ply"], "is a directory"),
    (["render", SCENE, "-o", "{d}/is_dir.png"], "is a directory"),
    (["render", SCENE, "-o", "{d}/ok.png", "--depth", "{d}/is_dir.npy"], "is a directory"),
    (["render", SCENE, "-o", "{d}/ok.png", "--stats", "{d}/missing/s.json"], "no such directory"),
])
def test_output_paths_are_checked_before_any_work(tmp_path, argv, message):
    for name in ("is_dir.ply", "is_dir.png", "is_dir.npy"):
        (tmp_path / name).mkdir()
    r = clcsg(*[a.format(d=tmp_path) for a in argv], "--progress", "json")
    assert r.returncode == 2, r.stderr
    events = [json.loads(ln) for ln in r.stderr.splitlines() if ln.strip()]
    assert [e["event"] for e in events] == ["error"], events  # nothing was loaded, sampled or rendered
    assert message in events[0]["message"]


def test_unwritable_folder_is_refused_before_any_work(tmp_path):
    """A folder without write permission; for root (who may write anyway), a read-only mount."""
    ro = tmp_path / "ro"
    ro.mkdir()
    ro.chmod(0o500)
    mounted = False
    try:
        if os.access(ro, os.W_OK):
            m = subprocess.run(["mount", "-t", "tmpfs", "-o", "ro,size=64k", "tmpfs", str(ro)],
                               capture_output=True, text=True)
            if m.returncode != 0:
                pytest.skip(f"root may write anywhere and cannot mount a read-only tmpfs: {m.stderr.strip()}")
            mounted = True
            assert not os.access(ro, os.W_OK)
        r = clcsg("render", SCENE, "-o", str(ro / "x.png"))
        assert r.returncode == 6 and "no permission" in r.stderr, r.stderr
        assert not os.listdir(ro)
    finally:
        if mounted:
            subprocess.run(["umount", "-l", str(ro)], capture_output=True)
        ro.chmod(0o700)
