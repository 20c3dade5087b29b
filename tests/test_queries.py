"""clcsg.inside / clcsg.distance (clcsg/queries, query.cl) against the numpy reference of the
tape and the independent tree oracle: membership, the sign of the distance, and the
conservative bound (the open ball of radius |d| holds no surface point)."""

from __future__ import annotations

import warnings

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import clcsg
from clcsg.cl.device import real_dtype
from clcsg.compile import interpret
from clcsg.errors import UsageError

import tree_oracle as T
from strategies import bounded_primitives, csg_programs, shapes

SCENES = {
    "drilled block": clcsg.box(2) - clcsg.cylinder(3, 0.5) - clcsg.cylinder(3, 0.5, axis=(1, 0, 0)),
    "rounded cube": clcsg.box(2) & clcsg.sphere(1.3),
    "complement": clcsg.sphere(1.5) & ~clcsg.box((0.5, 3, 3)).rotate((0, 0, 1), 30),
}


def _points(shape, n, seed, pad=0.5):
    b = clcsg.Scene(shape).compile().bound
    return np.random.default_rng(seed).uniform(b[0] - pad, b[1] + pad, (n, 3))


def _check(shape, pts, ctx):
    """Device results against the numpy tape reference and the tree oracle."""
    # the tree tape does not depend on the bound: one around the points compiles unbounded solids
    tape = clcsg.Scene(shape, np.array([pts.min(0) - 1, pts.max(0) + 1])).compile()
    d = clcsg.distance(shape, pts, device=ctx)
    ins = clcsg.inside(shape, pts, device=ctx)
    assert d.shape == ins.shape == (len(pts),) and ins.dtype == bool
    real = real_dtype(ctx)
    ref = interpret.evaluate(tape.ops, tape.quadrics, pts)[0]  # world coordinates
    fin = np.isfinite(ref)
    assert np.array_equal(np.isfinite(d), fin)
    rtol = 1e-9 if real == np.float64 else 1e-3
    np.testing.assert_allclose(d[fin], ref[fin], rtol=rtol, atol=rtol * 10)
    # inside is exactly the sign of the distance (closed solid: 0 counts as inside)
    assert np.array_equal(ins, d <= 0)
    # the oracle's membership, away from the rounding band of the surface
    size = float(np.abs(pts).max()) + 1.0
    clear = np.abs(d) > (1e-9 if real == np.float64 else 1e-4) * size
    oracle = T.contains(shape, pts)
    assert np.array_equal(ins[clear], oracle[clear]), np.flatnonzero(ins[clear] != oracle[clear])[:5]
    return d, ins, oracle, clear


def _ball_holds_no_surface(shape, pts, d, oracle, clear, seed=0, k=24):
    """Points inside the ball of radius |d| around p have p's membership (oracle)."""
    rng = np.random.default_rng(seed)
    sel = np.flatnonzero(clear & np.isfinite(d))
    u = rng.normal(size=(len(sel), k, 3))
    u /= np.linalg.norm(u, axis=2, keepdims=True)
    s = rng.uniform(0.0, 0.999, (len(sel), k, 1))
    s[:, 0] = 0.999  # one point near the ball's boundary in each direction set
    q = pts[sel, None, :] + s * np.abs(d[sel])[:, None, None] * u
    inside_q = T.contains(shape, q.reshape(-1, 3)).reshape(len(sel), k)
    assert np.array_equal(inside_q, np.repeat(oracle[sel, None], k, axis=1))


@pytest.mark.parametrize("name", sorted(SCENES))
def test_queries_match_reference_and_oracle(name, cl_context):
    shape = SCENES[name]
    pts = _points(shape, 4000, 1)
    d, ins, oracle, clear = _check(shape, pts, cl_context)
    assert 0.05 < ins.mean() < 0.95  # both sides are exercised
    _ball_holds_no_surface(shape, pts, d, oracle, clear)


def test_distance_is_a_lower_bound_of_the_distance_to_samples(cl_context):
    """The surface is no farther than the nearest sample, so |d| <= that distance; and |d| is
    not trivially small (a sphere: the distance is exact up to rounding)."""
    shape = SCENES["drilled block"]
    warnings.simplefilter("ignore")
    s = clcsg.sample(shape, 0.05, device=cl_context, progress=False)
    pts = _points(shape, 400, 2)
    d = clcsg.distance(shape, pts, device=cl_context)
    nearest = np.sqrt(((pts[:, None, :] - s.positions[None, :, :]) ** 2).sum(-1)).min(1)
    assert np.all(np.abs(d) <= nearest + 1e-9)
    assert np.mean(np.abs(d) >= 0.2 * nearest) > 0.5
    sphere = clcsg.sphere(1.0, center=(0.3, -0.2, 0.1))
    q = _points(sphere, 1000, 3)
    exact = np.linalg.norm(q - (0.3, -0.2, 0.1), axis=1) - 1.0
    np.testing.assert_allclose(clcsg.distance(sphere, q, device=cl_context), exact, rtol=1e-6, atol=1e-9)


@settings(max_examples=12)
@given(prog=csg_programs(max_depth=2), seed=st.integers(0, 2**16))
def test_random_programs(prog, seed, cl_context):
    pts = _points(prog.shape, 600, seed, pad=1.0)
    d, ins, oracle, clear = _check(prog.shape, pts, cl_context)
    _ball_holds_no_surface(prog.shape, pts[:150], d[:150], oracle[:150], clear[:150], seed, k=8)


@settings(max_examples=12)
@given(shape=shapes(bounded_primitives(), max_depth=3), seed=st.integers(0, 2**16))
def test_random_graphs_with_complements_and_sharing(shape, seed, cl_context):
    pts = np.random.default_rng(seed).uniform(-3, 3, (600, 3))
    d, ins, oracle, clear = _check(shape, pts, cl_context)
    _ball_holds_no_surface(shape, pts[:150], d[:150], oracle[:150], clear[:150], seed, k=8)


def test_inputs_shapes_and_errors(cl_context, tmp_scene):
    shape = SCENES["rounded cube"]
    grid = np.stack(np.meshgrid(*[np.linspace(-1.2, 1.2, 5)] * 3, indexing="ij"), axis=-1)
    from_shape = clcsg.inside(shape, grid, device=cl_context)
    assert from_shape.shape == (5, 5, 5)
    path = tmp_scene(shape)
    tape = clcsg.Scene(shape).compile()
    for other in (path, clcsg.load(path), tape):
        assert np.array_equal(clcsg.inside(other, grid, device=cl_context), from_shape)
    assert clcsg.distance(shape, np.zeros((0, 3)), device=cl_context).shape == (0,)
    assert clcsg.inside(shape, [0.0, 0.0, 0.0], device=cl_context).shape == ()
    for bad in (np.zeros((4, 2)), [[0.0, np.nan, 0.0]], "abc"):
        with pytest.raises(UsageError):
            clcsg.distance(shape, bad, device=cl_context)
    empty = clcsg.sphere(1) & clcsg.sphere(1, center=(5, 0, 0))
    assert not clcsg.inside(empty, grid, device=cl_context).any()
