"""The resource guard (clcsg/compile/bounds/estimates.py) and the device's allocation limits: the
estimate against real sample counts, a tiny radius on a big scene fails before any kernel
runs, normal runs pass, and every device buffer is checked before it is created."""

from __future__ import annotations

import math
import os
import time
import warnings

import numpy as np
import pytest

import clcsg
from clcsg.cli import app as cli
from clcsg.errors import LimitError, UsageError
from clcsg.writers.ply import read_samples as read_ply
from clcsg.compile.bounds import estimates as guard
from clcsg.sampling.sampler import sample

from test_robustness import EXAMPLES, NAN, _info, _tape
from test_sampler import SCENES as SAMPLER_SCENES

# -- the resource guard -------------------------------------------------------------------------


def test_area_bounds_are_upper_bounds():
    # planes: the hexagonal section x + y + z = 0 of [-1, 1]^3 has area 3 sqrt(3)
    plane = clcsg.halfspace((1, 1, 1), 0.0).quadrics()[0].matrix
    assert guard.quadric_area_bound(plane, [-1] * 3, [1] * 3) >= 3 * math.sqrt(3) - 1e-12
    zplane = clcsg.halfspace((0, 0, 1), 0.3).quadrics()[0].matrix
    assert guard.quadric_area_bound(zplane, [-1] * 3, [1] * 3) == pytest.approx(4.0)
    # exact areas of whole surfaces against the bound the tape gives
    cases = [
        (clcsg.sphere(1.0), 4 * math.pi),
        (clcsg.box(2.0), 24.0),
        (clcsg.cylinder(2.0, 0.5), 2 * math.pi * 0.5 * 2 + 2 * math.pi * 0.25),
        (clcsg.cone(1.0, 1.0, 0.0), math.pi * 1.0 * (1.0 + math.sqrt(2.0))),
        (clcsg.ellipsoid((1.0, 0.5, 0.25)).rotate((1, 1, 0), 30), 3.0),  # area > 3 (> pi a b)
        (clcsg.box(2) - clcsg.sphere(0.3), 24 + 4 * math.pi * 0.09),
    ]
    for shape, area in cases:
        est = guard.estimate_tape(_tape(shape), 0.1)
        assert est.area >= area * (1 - 1e-12), (shape, est.area, area)
        assert est.area <= 6 * area, (shape, est.area, area)  # not absurd either
    # a small hole in a big block counts with its own box, not the block's
    block = guard.estimate_tape(_tape(clcsg.box(20)), 0.1).area
    holed = guard.estimate_tape(_tape(clcsg.box(20) - clcsg.sphere(0.5)), 0.1).area
    assert holed - block < 10


GUARD_SCENES = ["sphere", "drilled_block", "sharp_tips", "thin_walls", "hyperboloid_paraboloid", "cone_frustum",
                "touching_boxes", "shared_surface", "tangent_spheres"]
GUARD_EXAMPLES = ["saddle.json", "bracket.json", "flange.csg", "spheres.json"]


@pytest.mark.parametrize("name", GUARD_SCENES + GUARD_EXAMPLES)
def test_estimate_is_never_far_below_the_real_count(cl_context, name):
    if name in SAMPLER_SCENES:
        shape, r = SAMPLER_SCENES[name]
        sc = clcsg.as_scene(shape)
    else:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            sc = clcsg.load(os.path.join(EXAMPLES, name))
        b = sc.compile().bound
        r = float(np.linalg.norm(b[1] - b[0])) / 50
    tape = sc.compile()
    for radius in (r, r / 2):
        est = guard.estimate_tape(tape, radius)
        n = len(sample(sc, radius, device=cl_context, progress=False))
        assert n <= 4 * est.samples, f"{name} r={radius:g}: {n} samples, estimate {est.samples:.0f}"
        assert est.samples <= 8 * n, f"{name} r={radius:g}: {n} samples, estimate {est.samples:.0f}"


def test_tiny_radius_fails_fast_before_any_kernel(cl_context, monkeypatch):
    from clcsg.sampling import sampler

    def forbidden(*a, **k):
        raise AssertionError("the guard must stop before packing, building or launching")

    patched = [name for name in ("pack", "build", "_Subdivision", "_finish") if hasattr(sampler, name)]
    assert len(patched) >= 3, patched
    for name in patched:
        monkeypatch.setattr(sampler, name, forbidden)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        big = clcsg.load(os.path.join(EXAMPLES, "bracket.json"))
    t = time.perf_counter()
    with pytest.raises(LimitError) as e:
        sample(big, 1e-4, device=cl_context)
    assert time.perf_counter() - t < 10
    msg = str(e.value)
    assert e.value.exit_code == 5 and "\n" not in msg
    assert "bracket.json" in msg and "samples" in msg and "--radius" in msg and "--max-samples" in msg
    # the suggested radius passes the guard
    fit = float(msg.split("about ")[-1].split()[0])
    guard.check_tape(big.compile(), fit, cl_context.info)


def test_guard_limits_and_messages(cl_context):
    tape = _tape(clcsg.sphere(1.0))
    est = guard.check_tape(tape, 0.1, cl_context.info)  # a normal case passes
    assert 100 < est.samples < 10_000 and est.device_bytes > 0
    with pytest.raises(LimitError, match="limit of 1,000 samples"):
        guard.check_tape(tape, 0.01, max_samples=1000)
    guard.check_tape(tape, 0.01, max_samples=10**6)
    # the memory cap comes from the device: a synthetic device with 64 MiB
    small = _info(global_mem=64 << 20, max_mem_alloc=16 << 20)
    with pytest.raises(LimitError, match="global memory"):
        guard.check_tape(tape, 0.002, small)
    with pytest.raises(LimitError, match="largest allocation"):
        guard.check_tape(tape, 0.002, _info(global_mem=64 << 30, max_mem_alloc=16 << 20))
    # no limit short of the 32-bit indices of the kernels
    with pytest.raises(LimitError, match="32-bit"):
        guard.check_tape(tape, 1e-5, max_samples=math.inf)
    for bad in (0, -1, NAN, "x"):
        with pytest.raises(UsageError):
            guard.check_tape(tape, 0.1, max_samples=bad)
    assert guard.check_tape(_tape(clcsg.sphere(1) - clcsg.sphere(2)), 1e-9).samples == 0


def test_normal_runs_pass_the_guard(cl_context, tmp_path, capsys):
    path = os.path.join(EXAMPLES, "drilled_block.json")
    rc = cli.main(["sample", path, "-r", "0.05", "-o", str(tmp_path / "b.ply"), "--max-samples", "100000"])
    assert rc == 0, capsys.readouterr().err
    assert len(read_ply(tmp_path / "b.ply")["positions"]) > 1000


def test_a_buffer_past_the_device_limit_is_a_limit_error(cl_context):
    """Every device buffer is checked against the device's max_mem_alloc_size and global memory
    before it is created: a cell buffer past them (forced through ``capacity``) is refused with
    a LimitError naming it, not a driver error."""
    from clcsg.cl.memory import check_allocation, device_buffer

    info = cl_context.info
    too_many = info.max_mem_alloc // 8 + 1
    with pytest.raises(LimitError, match="cell buffer"):
        clcsg.sample(clcsg.sphere(1.0), 0.1, device=cl_context, capacity=(too_many, 64))
    with pytest.raises(LimitError, match="framebuffer"):
        device_buffer(cl_context, info.max_mem_alloc + 1, "framebuffer")
    check_allocation(cl_context, info.max_mem_alloc, "largest")  # the limit itself is allowed
    s = clcsg.sample(clcsg.sphere(1.0), 0.1, device=cl_context, capacity=(64, 64))
    assert len(s) > 0


def test_a_probed_estimate_expects_the_probe_count_without_the_margin():
    """After a probe run, the guard's estimate is the probe's count scaled as 1 / r^2 times
    PROBE_MARGIN (a limit must not pass on a lucky probe); the expected count (the progress
    bar's total work) is the same scaling without the margin."""
    tape = clcsg.Scene(clcsg.box(2) - clcsg.sphere(1.2)).compile()
    est = guard.estimate_tape(tape, 0.01)
    probe = guard.measured(est, probe_samples=4000, probe_radius=0.05)
    assert probe.measured_at == 0.05
    want = 4000 * (0.05 / 0.01) ** 2
    assert probe.samples == pytest.approx(guard.PROBE_MARGIN * want, rel=1e-9)
    assert guard.expected_samples(tape, probe) == pytest.approx(want, rel=1e-9)
