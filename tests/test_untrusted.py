"""Sample files are untrusted input: a crafted ``.npz`` never crashes ``clcsg render``.

Hypothesis mutates one array of a valid sample file at a time (a value, the shape, the
dtype, or drops it; or damages the file itself) and runs ``clcsg render`` on it in a
subprocess.  The outcome is exit 0 with an image, or exit 3 with one line on stderr; never
a signal (the kernels reading outside a buffer), never exit 1 (an internal error).  Where
the right answer is known it is checked exactly: a mutation that keeps every value (an int32
array stored as int64, a dropped ``instance_kinds``) renders the reference image pixel for
pixel; an index or count far outside its range, a missing array, a wrong dtype kind and a
damaged file exit 3.

``CLCSG_FUZZ_EXAMPLES`` sets the number of examples (default 60).
"""

from __future__ import annotations

import os
import subprocess
import sys
import tempfile

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from PIL import Image

from clcsg.errors import SceneError
from clcsg.writers.ply import read_samples, write_samples

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
EXAMPLES = int(os.environ.get("CLCSG_FUZZ_EXAMPLES", "60"))
VIEW = ["--size", "40x30", "--eye", "4,-5,3", "--target", "0,0,0"]
#: arrays holding indices or counts into other arrays
INDEX_ARRAYS = ("quadrics", "primitives", "clip_first", "clip_count", "clip_ops", "tape_ops", "tape_n_regs",
                "instance_literals", "instance_literal_counts", "signs")
#: values outside every valid range of the small reference file
HOSTILE_INTS = (2**30, 2**20, 10**6, 2**28, -2, -(2**31), 2**31 - 1, 2**40)
ODD_FLOATS = (np.nan, np.inf, -np.inf, 0.0, -1.0, 1e300, 2.0**30)


def clcsg(*argv, timeout=300):
    env = {**os.environ, "PYTHONPATH": ROOT + os.pathsep + os.environ.get("PYTHONPATH", "")}
    return subprocess.run([sys.executable, "-m", "clcsg", *argv], capture_output=True, text=True, timeout=timeout,
                          env=env)


@pytest.fixture(scope="module")
def reference(tmp_path_factory, cl_context):
    """(arrays of a valid sample file, the RGBA pixels clcsg render draws from it)."""
    d = tmp_path_factory.mktemp("untrusted")
    npz, png = str(d / "ref.npz"), str(d / "ref.png")
    r = clcsg("sample", os.path.join(ROOT, "examples", "drilled_block.json"), "-r", "8%", "-o", npz, "-q")
    assert r.returncode == 0, r.stderr
    r = clcsg("render", npz, "-o", png, "-q", *VIEW)
    assert r.returncode == 0, r.stderr
    with np.load(npz) as z:
        arrays = {k: z[k] for k in z.files}
    return arrays, np.asarray(Image.open(png))


def _one_line_error(r) -> None:
    lines = [ln for ln in r.stderr.splitlines() if ln.strip()]
    assert len(lines) == 1 and lines[0].startswith("clcsg: error: "), r.stderr


def _render(path: str, out: str):
    r = clcsg("render", path, "-o", out, "-q", *VIEW)
    assert r.returncode >= 0, f"killed by signal {-r.returncode}: {r.stderr}"
    assert r.returncode in (0, 3), f"exit {r.returncode}: {r.stderr}"
    if r.returncode == 3:
        _one_line_error(r)
        assert not os.path.exists(out)
    else:
        assert np.asarray(Image.open(out)).shape == (30, 40, 4)
    return r


@st.composite
def mutations(draw, keys):
    """(key, kind, parameters) of one mutation."""
    key = draw(st.sampled_from(sorted(keys)))
    kind = draw(st.sampled_from(("value", "value", "value", "shape", "dtype", "widen", "drop", "file")))
    return key, kind, draw(st.integers(0, 2**32 - 1))


def _value(a: np.ndarray, rng) -> tuple[np.ndarray, bool]:
    """``a`` with one element replaced by an odd value; True if it is surely out of range."""
    a = np.array(a, copy=True)
    if a.size == 0:
        return a, False
    flat = a.reshape(-1) if a.ndim else a.reshape(1)
    k = int(rng.integers(flat.size))
    if a.dtype.kind in "iu":
        v = HOSTILE_INTS[int(rng.integers(len(HOSTILE_INTS)))]
        info = np.iinfo(a.dtype)
        if not info.min <= v <= info.max:
            a = a.astype(np.int64)
            flat = a.reshape(-1) if a.ndim else a.reshape(1)
        flat[k] = v
        return a, True
    if a.dtype.kind == "f":
        flat[k] = ODD_FLOATS[int(rng.integers(len(ODD_FLOATS)))]
    elif a.dtype.kind == "b":
        flat[k] = not flat[k]
    elif a.dtype.kind == "U":
        a = np.array(["", "tree", "dnf", "{}", "[1]", "<f4", "clcsg-samples", "\x00"][int(rng.integers(8))])
    return a, False


def _shape(a: np.ndarray, rng) -> np.ndarray:
    choice = int(rng.integers(4))
    if a.ndim == 0 or choice == 0:
        return a.reshape(-1)[..., None] if a.ndim else a.reshape(1)
    if choice == 1:
        return a[:-1]
    if choice == 2:
        return np.concatenate([a, a[-1:]]) if len(a) else np.zeros((1, *a.shape[1:]), a.dtype)
    return a.reshape(len(a), -1) if a.ndim > 2 else a[..., None]


def _dtype(a: np.ndarray, rng) -> np.ndarray:
    """Another dtype kind (never valid)."""
    if a.dtype.kind in "iu":
        return a.astype(np.float64)
    if a.dtype.kind == "f":
        return np.round(a).astype(np.int64) if np.isfinite(a).all() else a.astype(str)
    if a.dtype.kind == "b":
        return a.astype(np.int8)
    return np.zeros(a.shape, np.int64)


def _widen(a: np.ndarray) -> np.ndarray:
    """The same values in a wider dtype of the same kind."""
    if a.dtype.kind in "iu":
        return a.astype(np.int64)
    if a.dtype.kind == "f":
        return a.astype(np.longdouble)
    return a


def _damaged(data: bytes, rng) -> bytes:
    if rng.integers(2):
        return data[: int(rng.integers(len(data)))]
    b = bytearray(data)
    for k in rng.integers(0, len(b), 16):
        b[int(k)] = int(rng.integers(256))
    return bytes(b)


def _expect_same_image(r, out, ref_rgba) -> None:
    assert r.returncode == 0, r.stderr
    assert np.array_equal(np.asarray(Image.open(out)), ref_rgba)


def _check(arrays, ref_rgba, key, kind, seed) -> None:
    rng = np.random.default_rng(seed)
    with tempfile.TemporaryDirectory() as tmp:
        path, out = os.path.join(tmp, "m.npz"), os.path.join(tmp, "m.png")
        mutated = dict(arrays)
        if kind == "drop":
            del mutated[key]
        elif kind == "value":
            mutated[key], out_of_range = _value(arrays[key], rng)
        elif kind == "shape":
            mutated[key] = _shape(arrays[key], rng)
        elif kind == "dtype":
            mutated[key] = _dtype(arrays[key], rng)
        elif kind == "widen":
            mutated[key] = _widen(arrays[key])
        np.savez(path, **mutated)
        if kind == "file":
            with open(path, "rb") as f:
                data = _damaged(f.read(), rng)
            with open(path, "wb") as f:
                f.write(data)
        r = _render(path, out)
        if key == "instance_kinds" and kind != "file":  # informational: never read
            _expect_same_image(r, out, ref_rgba)
        elif kind == "widen":
            _expect_same_image(r, out, ref_rgba)
        elif kind in ("drop", "dtype") or (kind == "value" and key in INDEX_ARRAYS and out_of_range):
            assert r.returncode == 3, f"{kind} of {key}: exit {r.returncode}"


def test_mutated_sample_files_render_or_fail_with_one_line(reference):
    arrays, ref_rgba = reference

    @settings(max_examples=EXAMPLES, deadline=None, suppress_health_check=list(HealthCheck))
    @given(mutations(arrays.keys()))
    def run(m):
        _check(arrays, ref_rgba, *m)

    run()


@pytest.mark.parametrize("key,value,reason", [
    ("clip_first", 2**30, "clip programs"), ("clip_count", 2**20, "clip programs"), ("quadrics", 10**6, "quadrics"),
    ("tape_ops", 2**28, "tape_ops"), ("tape_n_regs", 0, "tape_n_regs"), ("instance_literal_counts", -3, "literal"),
    ("instance_ops", 2**20, "instance_ops"), ("instance_n_regs", 0, "instance_n_regs"),
])
def test_the_reported_crashes_are_one_line_errors(reference, tmp_path, key, value, reason):
    """The crafted files of the bug report: each exits 3 and names the array."""
    arrays, _ = reference
    a = np.array(arrays[key], dtype=np.int64, copy=True)
    a.reshape(-1)[-1 if key == "tape_ops" else 0] = value
    if key == "tape_ops":
        a[-1, 0] = 1  # an AND reading register 2**28
    np.savez(tmp_path / "bad.npz", **{**arrays, key: a})
    r = _render(str(tmp_path / "bad.npz"), str(tmp_path / "bad.png"))
    assert r.returncode == 3 and reason in r.stderr, r.stderr


def test_undefined_register_read_is_refused(reference, tmp_path):
    """A tape row reading a register no earlier row wrote: refused, not rendered with garbage."""
    arrays, _ = reference
    ops = np.array(arrays["tape_ops"], copy=True)
    ops[0] = (1, ops[0, 1], ops[0, 1], ops[0, 1])  # the first row ANDs its own, unwritten, register
    np.savez(tmp_path / "bad.npz", **{**arrays, "tape_ops": ops})
    r = _render(str(tmp_path / "bad.npz"), str(tmp_path / "bad.png"))
    assert r.returncode == 3 and "no earlier row" in r.stderr, r.stderr


def test_ply_reader_refuses_damaged_files(tmp_path, reference):
    from clcsg import load_samples

    arrays, _ = reference
    np.savez(tmp_path / "ok.npz", **arrays)
    s = load_samples(tmp_path / "ok.npz")
    write_samples(s, tmp_path / "ok.ply")
    back = read_samples(tmp_path / "ok.ply")
    assert np.array_equal(back["positions"], s.positions)
    data = (tmp_path / "ok.ply").read_bytes()
    for bad, why in ((data[:-5], "truncated"), (b"ply\nformat ascii 1.0\nend_header\n", "unsupported"),
                     (b"nonsense", "not a PLY"), (data.replace(b"property double x", b"property float x"), "properties")):
        (tmp_path / "bad.ply").write_bytes(bad)
        with pytest.raises(SceneError, match=why):
            read_samples(tmp_path / "bad.ply")


# -- huge scene files ---------------------------------------------------------------------------

_MEASURE = """
import os, resource, sys
from clcsg.readers.scenes import load
base = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
load(sys.argv[1])
print((resource.getrusage(resource.RUSAGE_SELF).ru_maxrss - base) * 1024 / os.path.getsize(sys.argv[1]))
"""


def _holes_csg(path, n: int) -> None:
    """An OpenSCAD export of a plate with ``n`` holes and pins (about 190 bytes per item)."""
    rng = np.random.default_rng(5)
    with open(path, "w") as f:
        f.write("group() {\n\tdifference() {\n\t\tcube(size = [100, 100, 10], center = false);\n")
        for k, (x, y) in enumerate(rng.uniform(0, 100, (n, 2))):
            r = 0.3 + 0.001 * (k % 50)
            f.write(f"\t\tmultmatrix([[1, 0, 0, {x:.6g}], [0, 1, 0, {y:.6g}], [0, 0, 1, -1], [0, 0, 0, 1]]) {{\n"
                    f"\t\t\tcylinder($fn = 0, $fa = 12, $fs = 2, h = 12, r1 = {r:g}, r2 = {r:g}, center = false);\n"
                    "\t\t}\n")
        f.write("\t}\n}\n")


def _holes_json(path, n: int) -> None:
    rng = np.random.default_rng(5)
    items = ['{"box": {"size": [100, 100, 10]}}'] + [
        '{"cylinder": {"height": 12, "radius": %g}, "transform": [{"translate": [%.6g, %.6g, 0]}]}'
        % (0.3 + 0.001 * (k % 50), x, y) for k, (x, y) in enumerate(rng.uniform(0, 100, (n, 2)))]
    with open(path, "w") as f:
        f.write('{"clcsg": 1, "root": {"difference": [\n' + ",\n".join(items) + "\n]}}\n")


@pytest.mark.parametrize("ext,make,factor", [(".csg", _holes_csg, "CSG_FACTOR"), (".json", _holes_json, "JSON_FACTOR")])
def test_scene_readers_stay_within_the_memory_the_guard_assumes(tmp_path, ext, make, factor):
    """Peak RSS growth while loading a ~1 MB file, per byte of the file, is within the factor
    the up-front memory guard uses (so the guard's estimate is an upper bound)."""
    from clcsg.readers import budget

    path = str(tmp_path / f"big{ext}")
    make(path, 5000)
    env = {**os.environ, "PYTHONPATH": ROOT + os.pathsep + os.environ.get("PYTHONPATH", "")}
    r = subprocess.run([sys.executable, "-c", _MEASURE, path], capture_output=True, text=True, timeout=600, env=env)
    assert r.returncode == 0, r.stderr
    assert float(r.stdout) <= getattr(budget, factor), f"{float(r.stdout):.1f} bytes of memory per byte of {ext}"


def test_a_scene_larger_than_memory_is_refused_up_front(tmp_path, monkeypatch):
    from clcsg.errors import LimitError
    from clcsg.readers import budget
    from clcsg.readers.scenes import load

    path = tmp_path / "big.csg"
    _holes_csg(path, 200)
    monkeypatch.setattr(budget, "available_memory", lambda: 1e5)
    with pytest.raises(LimitError, match=r"big\.csg: reading this .* needs about .* of memory, more than") as e:
        load(path)
    assert e.value.exit_code == 5
    (tmp_path / "big.json").write_text('{"clcsg": 1, "root": {"sphere": {"radius": 1}}}' + " " * 100_000)
    with pytest.raises(LimitError, match="big.json"):
        load(tmp_path / "big.json")
