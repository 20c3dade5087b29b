"""Random CSG programs end to end, the way a dataset pipeline feeds them: boxes, spheres,
cylinders and cone frusta, rotated and scaled, in unions, differences and intersections nested
up to three deep within [-6, 6]^3 (:mod:`clcsg.model.random_programs`, drawn by hypothesis so a
failure shrinks), sampled and rendered through the public API and through the CLI (from the
programs' OpenSCAD ``.csg`` text), against the float64 tree oracle:

* no refusal at a radius of 1-5% of the bound's diagonal, no internal error;
* every sample on the CSG surface;
* coverage of the whole surface, hidden and inner (cavity) surfaces included: every crossing
  of random lines with every leaf where the membership changes has a sample on its quadric
  within the radius;
* splat images equal to the oracle's ray cast: mask, depth, quadric and primitive per pixel.

``CLCSG_RANDOM_PROGRAMS=N`` sets the number of API examples (default 160; CI runs the
default; ``CLCSG_RANDOM_PROGRAMS=2000`` is the long run), the CLI test a quarter as many.
"""

from __future__ import annotations

import contextlib
import io
import os

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import clcsg
from clcsg.cli import main

import tree_oracle as T
from image_check import compare
from strategies import csg_programs
from test_tree_pipeline import check_samples

#: random programs per run (the CI run: 80; CLCSG_RANDOM_PROGRAMS=160 or more for a longer sweep)
EXAMPLES = int(os.environ.get("CLCSG_RANDOM_PROGRAMS", "80"))
W, H = 48, 36
SETTINGS = dict(deadline=None, suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])


def _diagonal(bound) -> float:
    return float(np.linalg.norm(np.asarray(bound[1]) - np.asarray(bound[0])))


def _assert_no_interior(shape, bound):
    """A solid without samples (one the compiler cannot prove empty, such as the touching
    sliver of two solids) holds no point of a dense random cloud in its bound."""
    rng = np.random.default_rng(0)
    lo, hi = np.asarray(bound[0], dtype=float), np.asarray(bound[1], dtype=float)
    assert not T.contains(shape, lo + rng.random((200_000, 3)) * (hi - lo)).any()


def _assert_empty(shape, bound):
    """A solid the compiler calls empty holds no point of a dense random cloud."""
    rng = np.random.default_rng(0)
    lo, hi = np.full(3, -6.5), np.full(3, 6.5)
    assert not T.contains(shape, lo + rng.random((20_000, 3)) * (hi - lo)).any()


@settings(max_examples=EXAMPLES, **SETTINGS)
@given(prog=csg_programs(max_depth=3), rel=st.floats(0.01, 0.05), view=st.integers(0, 3))
def test_random_programs_through_the_api(prog, rel, view, cl_context):
    shape = prog.shape
    tape = clcsg.Scene(shape).compile()
    if tape.empty:
        _assert_empty(shape, tape.bound)
        return
    radius = rel * _diagonal(tape.bound)
    s = clcsg.sample(shape, radius, device=cl_context)
    if not len(s):  # no surface above the sampler's floor: then the solid has no interior
        _assert_no_interior(shape, tape.bound)
        return
    check_samples(shape, s, radius, n_lines=3000)
    cams = [clcsg.Camera.fit(s.bound, W, H)] + list(clcsg.orbit(s.bound, 4, width=W, height=H))[1:]
    cam = cams[view % len(cams)]
    compare(clcsg.render(s, cam, device=cl_context), shape, s.tape, cam)


def _cli(argv) -> int:
    """``clcsg ARGV`` in this process; its stderr must hold no internal error or traceback."""
    err = io.StringIO()
    with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
        rc = main(argv)
    assert "internal error" not in err.getvalue() and "Traceback" not in err.getvalue(), err.getvalue()
    return rc


@settings(max_examples=max(EXAMPLES // 4, 10), **SETTINGS)
@given(prog=csg_programs(max_depth=3), rel=st.sampled_from(["0.01", "0.03", "0.05"]))
def test_random_programs_through_the_cli(prog, rel, cl_context, tmp_path_factory):
    """The OpenSCAD text of the program through ``clcsg info``, ``sample`` and ``render``:
    exit code 0, no internal error, and the PLY's samples on the surface of the program as
    clcsg reads it back."""
    from plyfile import PlyData

    d = tmp_path_factory.mktemp("prog")
    path = d / "prog.csg"
    path.write_text(prog.csg)
    scene = clcsg.load(path)
    tape = scene.compile()
    if tape.empty:
        _assert_empty(scene.shape, tape.bound)
        assert _cli(["info", str(path)]) == 0
        return
    radius = float(rel) * _diagonal(tape.bound)
    ply, png = d / "s.ply", d / "s.png"
    dev = cl_context.info.spec
    assert _cli(["info", str(path)]) == 0
    assert _cli(["sample", str(path), "-r", repr(radius), "-o", str(ply), "--quiet", "--device", dev]) == 0
    assert _cli(["render", str(path), "-r", repr(radius), "-o", str(png), "--size", f"{W}x{H}", "--quiet",
                 "--device", dev]) == 0
    v = PlyData.read(str(ply))["vertex"]
    pos = np.column_stack([v["x"], v["y"], v["z"]]).astype(np.float64)
    assert len(pos) > 0 and png.stat().st_size > 0
    on_q, on_csg = T.sample_residuals(scene.shape, pos, tape.quadrics[np.asarray(v["quadric"])],
                                      tol=1e-9 * _diagonal(tape.bound))
    assert on_q.max() <= 1e-6 * _diagonal(tape.bound) and on_csg.all()


@pytest.mark.parametrize("seed", range(3))
def test_random_programs_are_deterministic_across_runs(seed, cl_context):
    """The same program and radius give the same samples twice (no state leaks between runs)."""
    from clcsg.model.random_programs import random_program

    prog = random_program(np.random.default_rng(1000 + seed))
    tape = clcsg.Scene(prog.shape).compile()
    if tape.empty:
        pytest.fail(f"seed {seed}: expected a non-empty program")
    r = 0.03 * _diagonal(tape.bound)
    a = clcsg.sample(prog.shape, r, device=cl_context)
    b = clcsg.sample(prog.shape, r, device=cl_context)
    order = lambda s: np.lexsort(s.positions.T)  # noqa: E731
    assert np.array_equal(a.positions[order(a)], b.positions[order(b)])
