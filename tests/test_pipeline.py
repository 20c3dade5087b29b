"""The pipeline's one rule per step: the radius (scene units or a fraction of the compiled
bound's diagonal, 1% by default), and the same samples as :func:`clcsg.sample`."""

from __future__ import annotations

import math

import numpy as np
import pytest

import clcsg
from clcsg.errors import UsageError
from clcsg.pipeline import DEFAULT_RADIUS, Pipeline, bound_diagonal, resolve_radius
from clcsg.sampling.radius import Radius

BOUND = np.array([[0.0, 0.0, 0.0], [3.0, 4.0, 12.0]])  # diagonal 13


def test_diagonal_and_its_empty_cases():
    assert bound_diagonal(BOUND) == 13.0
    assert bound_diagonal(None) == 1.0
    assert bound_diagonal([[1, 1, 1], [1, 1, 1]]) == 1.0  # degenerate
    assert bound_diagonal([[0, 0, 0], [math.inf, 1, 1]]) == 1.0


@pytest.mark.parametrize("radius, expected", [
    (None, 0.13), ("1%", 0.13), ("10%", 1.3), (0.5, 0.5), ("0.5", 0.5), (Radius(0.02, relative=True), 0.26),
])
def test_one_radius_rule(radius, expected):
    assert resolve_radius(radius, BOUND) == pytest.approx(expected, rel=1e-12)


def test_default_radius_is_one_percent():
    assert DEFAULT_RADIUS == Radius(0.01, relative=True)


def test_bad_radius_is_a_usage_error():
    with pytest.raises(UsageError, match="radius"):
        resolve_radius("-1%", BOUND)


def _rows(samples):
    table = np.column_stack([samples.positions, samples.normals, samples.radii,
                             samples.quadrics, samples.signs, samples.primitives])
    return table[np.lexsort(table.T[::-1])]


def test_pipeline_samples_are_the_sampler_s(cl_context):
    shape = clcsg.box(2.0) - clcsg.sphere(1.2)
    pipe = Pipeline(clcsg.as_scene(shape), cl_context)
    tape = pipe.tape
    r = pipe.radius("5%")
    assert r == pytest.approx(0.05 * bound_diagonal(tape.bound))
    assert pipe.radius(0.2) == 0.2
    got = pipe.samples("5%", progress=False)
    ref = clcsg.sample(shape, r, device=cl_context, progress=False)
    assert got.radius == ref.radius and len(got) == len(ref) > 100
    # the sampler appends with atomics, so two runs list the same samples in different orders
    np.testing.assert_array_equal(_rows(got), _rows(ref))
    assert pipe.tape is tape  # compiled once, shared with the sampler
