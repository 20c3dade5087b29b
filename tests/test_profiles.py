"""Random simple polygons with holes (hypothesis), extruded and revolved, against the polygon's
own exact inside test (even-odd crossing numbers, written here independently of
clcsg.model.profile): membership of random points, and the device's samples (on the surface:
the inside test flips across each sample along its normal; every surface point on random lines
has a sample within r).  Also offsets, 2-D hulls and refusals of bad polygons.

More examples: CLCSG_PROFILE_EXAMPLES=200 (host) and CLCSG_PROFILE_DEVICE_EXAMPLES=20."""

from __future__ import annotations

import math
import os
import types

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import clcsg
from clcsg.errors import SceneError
from clcsg.model.profile import circle, polygon, square
from clcsg.model.profile_ops import hull_disks, offset_delta, offset_r

import tree_oracle as T
from coverage import uncovered

HOST_EXAMPLES = int(os.environ.get("CLCSG_PROFILE_EXAMPLES", "25"))
DEVICE_EXAMPLES = int(os.environ.get("CLCSG_PROFILE_DEVICE_EXAMPLES", "3"))


def crossing_inside(loops, pts):
    """Even-odd rule over all loops, vectorized over points."""
    x, y = pts[:, 0], pts[:, 1]
    inside = np.zeros(len(pts), bool)
    for lp in loops:
        a, b = lp, np.roll(lp, -1, axis=0)
        for (x1, y1), (x2, y2) in zip(a, b):
            cond = (y1 > y) != (y2 > y)
            with np.errstate(all="ignore"):
                xc = x1 + (y - y1) * (x2 - x1) / (y2 - y1)
            inside ^= cond & (x < xc)
    return inside


@st.composite
def star(draw, n_min, n_max, r_lo, r_hi, center_max):
    n = draw(st.integers(n_min, n_max))
    jit = draw(st.lists(st.floats(-0.3, 0.3), min_size=n, max_size=n))
    rad = draw(st.lists(st.floats(r_lo, r_hi), min_size=n, max_size=n))
    cx, cy = draw(st.floats(-center_max, center_max)), draw(st.floats(-center_max, center_max))
    t = (np.arange(n) + np.array(jit)) * 2 * math.pi / n
    return np.c_[cx + np.array(rad) * np.cos(t), cy + np.array(rad) * np.sin(t)]


@st.composite
def polygons_with_holes(draw):
    """A star-shaped outer loop (vertex radii 2..4, 5..10 vertices: its edges stay more than
    1.07 from the origin) and 0 or 1 star-shaped hole inside radius 0.95."""
    loops = [draw(star(5, 10, 2.0, 4.0, 0.0))]
    if draw(st.booleans()):
        hole = draw(star(3, 6, 0.2, 0.7, 0.25))
        loops.append(hole if draw(st.booleans()) else hole[::-1])
    return loops


def profile_of(loops):
    pts = np.vstack(loops)
    paths, k = [], 0
    for lp in loops:
        paths.append(list(range(k, k + len(lp))))
        k += len(lp)
    return polygon(pts, paths)


def extrude_reference(loops, h, s, pts):
    k = 1 + (s - 1) * pts[:, 2] / h
    return crossing_inside(loops, pts[:, :2] / k[:, None]) & (pts[:, 2] >= 0) & (pts[:, 2] <= h)


def revolve_reference(loops, angle, pts):
    r = np.hypot(pts[:, 0], pts[:, 1])
    phi = np.degrees(np.arctan2(pts[:, 1], pts[:, 0])) % 360
    return crossing_inside(loops, np.c_[r, pts[:, 2]]) & (phi <= angle)


SHIFT = 4.5  # revolved profiles are moved to x >= 0.5


@settings(max_examples=HOST_EXAMPLES)
@given(polygons_with_holes(), st.sampled_from([1.0, 0.6, 0.0]))
def test_random_polygons_extruded(loops, s):
    solid = clcsg.extrude(profile_of(loops), 1.5, scale=s)
    pts = np.random.default_rng(0).uniform((-4.5, -4.5, -0.2), (4.5, 4.5, 1.7), (6000, 3))
    np.testing.assert_array_equal(T.contains(solid, pts), extrude_reference(loops, 1.5, s, pts))


@settings(max_examples=HOST_EXAMPLES)
@given(polygons_with_holes(), st.sampled_from([360.0, 250.0, 90.0]))
def test_random_polygons_revolved(loops, angle):
    moved = [lp + (SHIFT, 0) for lp in loops]
    solid = clcsg.revolve(profile_of(moved), angle)
    pts = np.random.default_rng(1).uniform((-9, -9, -4.5), (9, 9, 4.5), (6000, 3))
    np.testing.assert_array_equal(T.contains(solid, pts), revolve_reference(moved, angle, pts))


def _device_check(solid, reference_inside, cl_context):
    tape = clcsg.Scene(solid).compile()
    lo, hi = tape.bound
    size = float(np.linalg.norm(hi - lo))
    r = size / 30
    s = clcsg.sample(solid, r, device=cl_context)
    assert len(s) > 100
    eps = 1e-7 * size
    out = reference_inside(s.positions + eps * s.normals)
    inn = reference_inside(s.positions - eps * s.normals)
    flips = inn & ~out
    # along an edge both offsets may land on one side: only samples near a second surface
    Q = s.tape.quadrics[s.quadrics]
    on_q, on_csg = T.sample_residuals(solid, s.positions, Q, tol=1e-9 * size)
    assert on_csg.all() and on_q.max() <= 1e-6 * size
    assert flips.mean() >= 0.995, f"{(~flips).sum()} of {len(s)} samples are not on the polygon's boundary"
    pad = 1e-3 * size
    ref = T.surface_points(solid, tape.bound + [[-pad], [pad]], n_lines=3000)
    ids = T.quadric_table(solid).match(s.tape.quadrics)
    missing = uncovered(ref.points, ref.quadrics, types.SimpleNamespace(positions=s.positions, quadrics=ids[s.quadrics]), r)
    assert len(missing) == 0, f"{len(missing)} of {len(ref)} surface points uncovered"


@settings(max_examples=DEVICE_EXAMPLES)
@given(loops=polygons_with_holes())
def test_random_polygons_sampled(loops, cl_context):
    solid = clcsg.extrude(profile_of(loops), 1.5, scale=0.6)
    _device_check(solid, lambda p: extrude_reference(loops, 1.5, 0.6, p), cl_context)
    moved = [lp + (SHIFT, 0) for lp in loops]
    solid = clcsg.revolve(profile_of(moved), 250)
    _device_check(solid, lambda p: revolve_reference(moved, 250, p), cl_context)


# -- offsets and 2-D hulls -----------------------------------------------------------------------
def _dist_to_segments(loop, pts):
    a, b = loop, np.roll(loop, -1, axis=0)
    d = np.full(len(pts), np.inf)
    for p, q in zip(a, b):
        t = np.clip(((pts - p) @ (q - p)) / ((q - p) @ (q - p)), 0, 1)
        d = np.minimum(d, np.linalg.norm(pts - (p + t[:, None] * (q - p)), axis=1))
    return d


@settings(max_examples=HOST_EXAMPLES)
@given(polygons_with_holes(), st.floats(-0.25, 0.6).filter(lambda v: abs(v) > 1e-3))
def test_offset_r_is_the_distance_band(loops, r):
    pts = np.random.default_rng(2).uniform(-5, 5, (6000, 2))
    inside = crossing_inside(loops, pts)
    dist = np.min([_dist_to_segments(lp, pts) for lp in loops], axis=0)
    expect = (inside | (dist <= r)) if r > 0 else (inside & (dist >= -r))
    got = offset_r(profile_of(loops), r).contains(pts)
    np.testing.assert_array_equal(got, expect)


def test_offset_delta_square_and_chamfer():
    sq = square(2, center=True)
    pts = np.random.default_rng(3).uniform(-2, 2, (20000, 2))
    np.testing.assert_array_equal(offset_delta(sq, 0.5).contains(pts), np.all(np.abs(pts) <= 1.5, axis=1))
    cham = offset_delta(sq, 0.5, chamfer=True).contains(pts)
    # square joins: each corner cut by the line at distance 0.5 from the corner along the diagonal
    expect = np.all(np.abs(pts) <= 1.5, axis=1) & (np.abs(pts).sum(axis=1) <= 2 + 0.5 * math.sqrt(2))
    np.testing.assert_array_equal(cham, expect)
    with pytest.raises(SceneError, match="collapses an edge"):
        offset_delta(polygon([(0, 0), (4, 0), (4, 0.2), (0, 0.2)]), -0.2)


def test_hull_of_disks_any_radii():
    c, r = np.array([[0, 0], [3, 1], [1, 3], [1.2, 1.0]]), np.array([1.0, 0.4, 0.7, 0.3])
    prof = hull_disks(c, r)
    pts = np.random.default_rng(4).uniform(-2, 4.5, (20000, 2))
    n = np.c_[np.cos(np.linspace(0, 2 * np.pi, 4096, endpoint=False)), np.sin(np.linspace(0, 2 * np.pi, 4096, endpoint=False))]
    support = (n @ c.T + r).max(axis=1)
    margin = (pts @ n.T - support).max(axis=1)  # > 0: outside; near 0: too close to call
    clear = np.abs(margin) > 1e-3
    np.testing.assert_array_equal(prof.contains(pts)[clear], (margin <= 0)[clear])


@pytest.mark.parametrize("points, paths, message", [
    ([(0, 0), (2, 2), (2, 0), (0, 2)], None, "path 0 crosses itself"),
    ([(0, 0), (4, 0), (4, 4), (0, 4), (1, 1), (5, 1), (5, 2)], [[0, 1, 2, 3], [4, 5, 6]], "paths 0 and 1 cross or touch"),
    ([(0, 0), (1, 1), (2, 2)], None, "has no area"),
])
def test_bad_polygons_are_refused(points, paths, message):
    with pytest.raises(SceneError, match=message):
        polygon(points, paths)


def test_circle_extrusion_is_a_cylinder_and_revolution_is_refused():
    c = clcsg.extrude(circle(1, (2, 0)), 2)
    assert c.describe() == "linear_extrude of a circle (height 2): 2 planes, 1 cylinder"
    with pytest.raises(SceneError, match="torus, a quartic"):
        clcsg.revolve(circle(1, (2, 0)))
    with pytest.raises(SceneError, match="both sides of the axis"):
        clcsg.revolve(square(2, center=True))
