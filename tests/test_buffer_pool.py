"""The sampler's buffer pool: size classes hold what is asked and are their own class; buffers
come back and are handed out again; and samples are the same, bit for bit (in any order),
whether the buffers are fresh or hold what another scene's run left in them, also when tiny
forced capacities make every level overflow, grow and run again."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import clcsg
from clcsg.cl.buffer_pool import MIN_CLASS, BufferPool, pool_of, size_class


@settings(max_examples=300)
@given(st.integers(min_value=0, max_value=1 << 40))
def test_size_classes_hold_the_size_and_are_their_own_class(n):
    c = size_class(n)
    assert c >= n and size_class(c) == c
    assert c <= 1.25 * max(n, MIN_CLASS)


def test_a_buffer_given_back_is_taken_again_within_the_limit(cl_context):
    pool = BufferPool(cl_context)
    a = pool.take(10_000, "test")
    assert a.size == size_class(10_000)
    pool.give(a, None)
    assert pool.take(9_000, "test") is a  # the same class
    assert pool.take(9_000, "test") is not a
    pool.limit = a.size - 1
    pool.give(a)
    assert pool.held == 0 and not any(pool.free.values())


def _canonical(s):
    """The samples' fields in one order (by position, then quadric) with each clip program as its
    rows: the order of a run's samples depends on how its two threads met the atomics."""
    order = np.lexsort((s.quadrics, s.positions[:, 2], s.positions[:, 1], s.positions[:, 0]))
    clips = [s.clip_ops[f:f + c].tobytes() for f, c in zip(s.clip_first[order], s.clip_count[order])]
    return [s.positions[order], s.normals[order], s.radii[order], s.quadrics[order], s.signs[order],
            s.primitives[order], clips]


@pytest.mark.parametrize("capacity", [None, (8, 8, 8, 8)])
def test_samples_do_not_depend_on_what_a_pooled_buffer_held(cl_context, capacity):
    pooled = "oclgrind" not in cl_context.info.platform.lower()  # Oclgrind takes host-zeroed buffers
    lens = clcsg.sphere(1.0, center=(0, 0, 0.6)) & clcsg.sphere(1.0, center=(0, 0, -0.6))
    other = clcsg.box(2.0) - clcsg.cylinder(3.0, 0.5) - clcsg.sphere(0.4, center=(1, 1, 1))
    pool_of(cl_context).clear()
    first = clcsg.sample(lens, 0.05, device=cl_context, capacity=capacity, progress=False)
    clcsg.sample(other, 0.03, device=cl_context, capacity=capacity, progress=False)
    pool = pool_of(cl_context)
    assert (pool.held > 0) == pooled, "the runs gave their buffers back (not on Oclgrind)"
    reused = pool.reused
    again = clcsg.sample(lens, 0.05, device=cl_context, capacity=capacity, progress=False)
    assert (pool.reused > reused) == pooled, "the second run of the lens took buffers the other scene used"
    for a, b in zip(_canonical(first), _canonical(again)):
        np.testing.assert_array_equal(a, b)
