"""The vectorized tape runs of clcsg.compile.interpret (surface_in_boxes, member_per_point: the
tape as a min / max program over all boxes or points at once, in chunks) against plain
per-box and per-point evaluations of the tape, written here op by op with the three-valued
logic spelled out.

The random tapes reuse registers, copy and hold constants; the planes and boxes have
coefficients on a grid of quarters, so the leaves' sums are exact in any order and the
reference's arithmetic cannot round differently from the numpy one."""

from __future__ import annotations

import math

import numpy as np
from hypothesis import given, settings, strategies as st

from clcsg.cl.constants import OP_AND, OP_CONST, OP_COPY, OP_LEAF, OP_OR
from clcsg.compile.interpret import PRUNE_SLACK, member, member_per_point, surface_in_boxes

N_REGS = 5
QUARTERS = st.integers(-12, 12).map(lambda k: k / 4)


def _plane(n, d):
    """The plane quadric n . x + d (value of the homogeneous form)."""
    m = np.zeros((4, 4))
    m[:3, 3] = m[3, :3] = 0.5 * np.asarray(n, dtype=np.float64)
    m[3, 3] = d
    return m


@st.composite
def tapes(draw, n_quadrics):
    """A valid tape: every read register was written before; the last row is the root."""
    ops, written = [], set()
    for _ in range(draw(st.integers(1, 30))):
        kinds = [OP_LEAF, OP_CONST] + ([OP_AND, OP_OR, OP_COPY] if written else [])
        op = draw(st.sampled_from(kinds))
        out = draw(st.integers(0, N_REGS - 1))
        regs = sorted(written)
        if op == OP_LEAF:
            row = (op, out, draw(st.integers(0, n_quadrics - 1)), draw(st.sampled_from([-1, 1])))
        elif op == OP_CONST:
            row = (op, out, draw(st.integers(0, 1)), 0)
        elif op == OP_COPY:
            row = (op, out, draw(st.sampled_from(regs)), 0)
        else:
            row = (op, out, draw(st.sampled_from(regs)), draw(st.sampled_from(regs)))
        ops.append(row)
        written.add(out)
    return np.array(ops, dtype=np.int32)


@st.composite
def scenes(draw, n_columns=st.integers(1, 12)):
    """(planes (k, 4, 4), tape, columns' lo (n, 3), hi (n, 3), own quadric per column)."""
    k = draw(st.integers(1, 4))
    planes = np.array([_plane([draw(QUARTERS) for _ in range(3)], draw(QUARTERS)) for _ in range(k)])
    ops = draw(tapes(k))
    n = draw(n_columns)
    lo = np.array([[draw(QUARTERS) for _ in range(3)] for _ in range(n)])
    hi = lo + np.array([[draw(st.integers(0, 8)) / 4 for _ in range(3)] for _ in range(n)])
    own = np.array([draw(st.integers(0, k)) for _ in range(n)])  # k: a quadric not in the tape
    return planes, ops, lo, hi, own


def _and3(x, y):
    if x == "F" or y == "F":
        return "F"
    return "T" if x == y == "T" else "?"


def _or3(x, y):
    if x == "T" or y == "T":
        return "T"
    return "F" if x == y == "F" else "?"


def _plane_state(m, sign, lo, hi):
    """The literal's state over the box: FALSE where sign (n . x + d) > 0 on all of it, TRUE
    where < 0, with pruning's rounding margin (PRUNE_SLACK times the box's size and distance
    from the origin)."""
    c = [(a + b) / 2 for a, b in zip(lo, hi)]
    half = [(b - a) / 2 for a, b in zip(lo, hi)]
    g = [2 * m[i][3] for i in range(3)]
    v = sign * (sum(gi * ci for gi, ci in zip(g, c)) + m[3][3])
    slack = PRUNE_SLACK * (math.sqrt(sum(ci * ci for ci in c)) + sum(half))
    spread = sum(abs(gi) * hi_ for gi, hi_ in zip(g, half)) + math.sqrt(sum(gi * gi for gi in g)) * slack
    return "F" if v > spread else "T" if v < -spread else "?"


def _run_plainly(ops, leaf, both, const):
    """The tape's root pair (minus side, plus side): ``leaf(q, s)`` a leaf's pair, ``both`` the
    pair logic of AND / OR, ``const(a)`` a constant's pair."""
    regs = {}
    for op, out, a, b in ops.tolist():
        if op == OP_LEAF:
            regs[out] = leaf(a, b)
        elif op in (OP_AND, OP_OR):
            f = both[op]
            regs[out] = (f(regs[a][0], regs[b][0]), f(regs[a][1], regs[b][1]))
        elif op == OP_COPY:
            regs[out] = regs[a]
        else:
            regs[out] = const(a)
    return regs[int(ops[-1][1])]


def _surface_in_box(planes, ops, lo, hi, own):
    """False iff the tape over the box, with quadric ``own`` substituted, is the same known
    constant on its two sides."""
    def leaf(q, s):
        if q == own:
            return ("T", "F") if s > 0 else ("F", "T")
        st_ = _plane_state(planes[q], s, lo, hi)
        return (st_, st_)

    neg, pos = _run_plainly(ops, leaf, {OP_AND: _and3, OP_OR: _or3}, lambda a: ("T", "T") if a else ("F", "F"))
    return not (neg != "?" and neg == pos)


def _member_at(planes, ops, x, own):
    """(m-, m+) at point x with quadric ``own`` substituted, in plain booleans."""
    def leaf(q, s):
        if q == own:
            return (s > 0, s < 0)
        inside = s * (float(np.dot(2 * planes[q][:3, 3], x)) + planes[q][3, 3]) <= 0.0
        return (inside, inside)

    both = {OP_AND: lambda x_, y: x_ and y, OP_OR: lambda x_, y: x_ or y}
    return _run_plainly(ops, leaf, both, lambda a: (bool(a), bool(a)))


@settings(max_examples=300, deadline=None)
@given(scenes(), st.sampled_from([None, 1, 7, 50]))
def test_surface_in_boxes_is_the_plain_per_box_run(scene, chunk):
    planes, ops, lo, hi, own = scene
    got = surface_in_boxes(ops, planes, lo, hi, own, chunk_entries=chunk)
    want = [_surface_in_box(planes, ops, lo[i], hi[i], own[i]) for i in range(len(lo))]
    assert got.dtype == bool
    np.testing.assert_array_equal(got, want)


@settings(max_examples=300, deadline=None)
@given(scenes(), st.sampled_from([None, 1, 7, 50]))
def test_member_per_point_is_the_plain_per_point_run(scene, chunk):
    planes, ops, lo, hi, own = scene
    x = np.concatenate([lo, hi, 0.5 * (lo + hi)])  # grid points: many on the planes exactly
    own = np.tile(own, 3)
    minus, plus = member_per_point(ops, planes, x, own, chunk_entries=chunk)
    want = np.array([_member_at(planes, ops, x[i], own[i]) for i in range(len(x))], dtype=bool).reshape(-1, 2)
    np.testing.assert_array_equal(minus, want[:, 0])
    np.testing.assert_array_equal(plus, want[:, 1])


@settings(max_examples=100, deadline=None)
@given(scenes(st.just(6)))
def test_member_per_point_with_one_quadric_is_member(scene):
    planes, ops, lo, hi, _ = scene
    for q in range(len(planes) + 1):
        want = member(ops, planes, lo, q)
        got = member_per_point(ops, planes, lo, np.full(len(lo), q))
        np.testing.assert_array_equal(got[0], want[0])
        np.testing.assert_array_equal(got[1], want[1])
