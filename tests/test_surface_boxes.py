"""The guard's per-quadric facts in one pass (clcsg.compile.bounds.surface_boxes) against the
per-quadric code (term_boxes.literal_box, principal_frame) and against points on the surfaces."""

from __future__ import annotations

import glob
import os

import numpy as np
from hypothesis import given, settings, strategies as st

import clcsg
from clcsg.compile.bounds import estimates as guard
from clcsg.compile.bounds import surface_boxes as sb
from clcsg.compile.bounds.term_boxes import literal_box
from clcsg.compile.quadric_frames import principal_frame, principal_frames
from clcsg.model.quadric import Quadric
from strategies import quadric_cases

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def _surface_points(q: Quadric, rng, n=400):
    """Points of the surface Q = 0: roots of Q along random lines through [-3, 3]^3."""
    p = rng.uniform(-3, 3, (n, 3))
    v = rng.normal(size=(n, 3))
    v /= np.linalg.norm(v, axis=1)[:, None]
    t1, t2 = q.intersect_line(p, v)
    pts = np.concatenate([p + t1[:, None] * v, p + t2[:, None] * v])
    return pts[np.all(np.isfinite(pts), axis=1) & (np.abs(pts).max(axis=1) < 1e6)]


def _scalar_surface_box(q: Quadric):
    lo, hi = np.full(3, -np.inf), np.full(3, np.inf)
    for s in (1, -1):
        b = literal_box(q, s)
        if b is None:
            return None
        lo, hi = np.maximum(lo, b[0]), np.minimum(hi, b[1])
    return lo, hi


@settings(max_examples=150, deadline=None)
@given(st.lists(quadric_cases(), min_size=1, max_size=6), st.integers(0, 2**31 - 1))
def test_surface_boxes_match_the_literal_boxes_and_hold_the_surface(cases, seed):
    mats = np.array([c.quadric.matrix for c in cases])
    lo, hi, empty = sb.surface_boxes(mats)
    rng = np.random.default_rng(seed)
    for k, c in enumerate(cases):
        want = _scalar_surface_box(c.quadric)
        assert empty[k] == (want is None)
        if want is None:
            continue
        np.testing.assert_allclose(lo[k], want[0], rtol=1e-9, atol=1e-9)
        np.testing.assert_allclose(hi[k], want[1], rtol=1e-9, atol=1e-9)
        pts = _surface_points(c.quadric, rng)
        tol = 1e-7 * (1 + np.abs(pts))
        assert np.all((pts >= lo[k] - tol) & (pts <= hi[k] + tol))


@settings(max_examples=100, deadline=None)
@given(st.lists(quadric_cases(), min_size=1, max_size=6), st.integers(0, 2**32 - 1))
def test_principal_frames_reproduce_each_quadric(cases, seed):
    """Per quadric of a stack: U orthonormal and right-handed, lam its eigenvalues (snapped
    ones exactly 0), beta 0 on its non-null axes, a plane's u_3 along its b, and Q(q + U z) =
    sum(lam z^2 + 2 beta z) + gamma at random z; each row equals the frame of its matrix
    alone (the stack's neighbours do not change it)."""
    M = np.array([c.quadric.matrix for c in cases])
    U, lam, center, beta, gamma = principal_frames(M)
    rng = np.random.default_rng(seed)
    for k, c in enumerate(cases):
        q = c.quadric
        scale = 1 + np.abs(q.matrix).max()
        np.testing.assert_allclose(U[k].T @ U[k], np.eye(3), atol=1e-12)
        assert np.linalg.det(U[k]) > 0
        want = np.linalg.eigvalsh(q.A)
        np.testing.assert_allclose(np.sort(lam[k]), want, atol=1e-9 * scale)
        assert np.all(beta[k][lam[k] != 0] == 0)
        if not np.any(lam[k]) and np.linalg.norm(q.b) > 0:
            assert abs(abs(U[k][:, 2] @ q.b) - np.linalg.norm(q.b)) <= 1e-12 * np.linalg.norm(q.b)
        z = rng.uniform(-2, 2, (20, 3))
        x = center[k] + z @ U[k].T
        X = np.c_[x, np.ones(len(x))]
        direct = np.einsum("ni,ij,nj->n", X, q.matrix, X)
        local = (lam[k] * z * z + 2 * beta[k] * z).sum(axis=1) + gamma[k]
        size = scale * (1 + np.abs(x).max()) ** 2
        np.testing.assert_allclose(local, direct, atol=1e-9 * size)
        alone = principal_frame(q)
        for got, one in zip((U[k], lam[k], center[k], beta[k], gamma[k]),
                            (alone.U, alone.lam, alone.center, alone.beta, alone.gamma)):
            np.testing.assert_array_equal(got, one)


def test_kinds_and_surface_meets_on_boxes_around_surface_points():
    """Boxes around points of a surface always meet it; boxes far from every point of it
    (farther than the box's half-diagonal from the sampled points of a sphere) never do."""
    rng = np.random.default_rng(5)
    qs = [Quadric.sphere((0, 0, 0), 1.0), Quadric.cylinder((0, 0, 1), 0.5),
          Quadric(np.diag([1.0, 1.0, -1.0, 0.0])), Quadric(np.array([[0, 0, 0, 0.5], [0, 0, 0, 0], [0, 0, 0, 0],
                                                                       [0.5, 0, 0, -1.0]]))]
    kinds, _ = sb.quadric_kinds(np.array([q.matrix for q in qs]))
    assert kinds.tolist() == [sb.CONVEX, sb.CONVEX, sb.SADDLE, sb.PLANE]
    for k, q in enumerate(qs):
        pts = _surface_points(q, rng, 200)
        h = rng.uniform(0.01, 0.3, (len(pts), 3))
        meets = sb.surface_meets(np.array([m.matrix for m in qs]), np.full(len(pts), k), pts - h, pts + h)
        assert meets.all()
    far = np.array([[5.0, 5.0, 5.0]]) + rng.uniform(0, 1, (50, 3))
    assert not sb.surface_meets(qs[0].matrix[None], np.zeros(50, int), far - 0.1, far + 0.1).any()


def test_estimate_regions_is_the_per_quadric_estimate_on_the_examples():
    """The one-pass estimate against the per-quadric rules written out here (surface box from
    term_boxes.literal_box, the meet test, the area bounds of estimates._area_bounds)."""
    for path in sorted(glob.glob(os.path.join(ROOT, "examples", "*.csg")))[:8]:
        tape = clcsg.load(path).compile()
        regions = guard.quadric_regions(tape.quadrics, tape.instances, tape.bound)
        est = guard.estimate_regions(tape.quadrics, regions, 0.1)
        for u, (m, reg) in enumerate(zip(tape.quadrics, regions)):
            box = _scalar_surface_box(Quadric(m))
            want = 0.0
            if box is not None and len(reg):
                lo, hi = np.maximum(reg[:, 0], box[0]), np.minimum(reg[:, 1], box[1])
                ok = np.all(hi >= lo, axis=1)
                lo, hi = lo[ok], hi[ok]
                d = Quadric(m).distance(0.5 * (lo + hi)) if len(lo) else np.zeros(0)
                plane = np.abs(m[:3, :3]).max() <= 1e-14 * np.abs(m).max()
                if plane:  # the linear function's range over the box holds 0
                    g = 2.0 * m[:3, 3]
                    mid = 0.5 * (lo + hi) @ g + m[3, 3]
                    ok = np.abs(mid) <= 0.5 * (hi - lo) @ np.abs(g) + 1e-12 * (np.abs(m).max() + np.abs(mid))
                else:
                    ok = ~(np.abs(d) > np.linalg.norm(0.5 * (hi - lo), axis=1) * (1 + 1e-9) + 1e-12)
                lo, hi = lo[ok], hi[ok]
                if len(lo):
                    kind = guard._kind(m)
                    sep = guard._area_bounds(kind, lo, hi).sum()
                    tog = guard._area_bounds(kind, lo.min(0, keepdims=True), hi.max(0, keepdims=True))[0]
                    want = min(sep, tog)
            np.testing.assert_allclose(est.quadric_areas[u], want, rtol=1e-9, atol=1e-12, err_msg=f"{path} {u}")
