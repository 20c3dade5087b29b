"""Properties of the float64 quadric reference (clcsg/quadric.py), checked against brute-force
oracles: conservative distance (eqs. 8-12), line intersection (eqs. 5, 6) including degenerate
directions and far origins, transforms (eq. 17), canonical form, gradient and normal (eq. 4).

Every quadric type is covered: each named constructor of Quadric plus raw random matrices,
with and without a random well-conditioned affine map (tests/strategies.py).
``CLCSG_HYPOTHESIS_EXAMPLES=2000 pytest tests/test_quadric.py`` runs a longer search.
"""

from __future__ import annotations

import os

import numpy as np
import pytest
from hypothesis import HealthCheck, assume, given, settings
from hypothesis import strategies as st

from clcsg.errors import TransformError
from clcsg.model.quadric import Quadric, affine, check_affine
from strategies import (
    QUADRIC_KINDS,
    affine_maps,
    fibonacci_sphere,
    floats,
    quadric_cases,
    unit_vectors,
    vec3,
)

SETTINGS = settings(max_examples=int(os.environ.get("CLCSG_HYPOTHESIS_EXAMPLES", 60)), deadline=None, suppress_health_check=[HealthCheck.too_slow])
DIRS = fibonacci_sphere(3000)


def abs_terms(q: Quadric, x) -> np.ndarray:
    """Sum of the absolute values of the terms of Q(x): the scale of its rounding error."""
    x = np.asarray(x, dtype=np.float64)
    ax = np.abs(x)
    return np.einsum("...i,ij,...j->...", ax, np.abs(q.A), ax) + 2.0 * ax @ np.abs(q.b) + abs(q.c)


def residual_ok(q: Quadric, x, reach) -> np.ndarray:
    """|Q(x)| <= 1e-9 relative to the sum of absolute terms and to |grad Q| times ``reach``
    (how far the point was carried from the line origin: its absolute rounding)."""
    x = np.asarray(x, dtype=np.float64)
    g = np.linalg.norm(q.gradient(x), axis=-1)
    tol = 1e-9 * (abs_terms(q, x) + g * reach) + 1e-300
    return np.abs(q.value(x)) <= tol


def surface_along_rays(q: Quadric, origin, dirs) -> np.ndarray:
    """|t| of every verified root of the rays origin + t dirs (flattened, may be empty)."""
    t1, t2 = q.intersect_line(np.broadcast_to(origin, dirs.shape), dirs)
    t = np.concatenate([t1, t2])
    d = np.concatenate([dirs, dirs])
    ok = np.isfinite(t)
    t, d = t[ok], d[ok]
    pts = origin + t[:, None] * d
    good = residual_ok(q, pts, np.linalg.norm(origin) + np.abs(t))
    return np.abs(t[good])


def surface_uncertainty(q: Quadric, x) -> float:
    """How far the surface may be from where float64 puts it, seen from x: the conservative
    distance formula applied to Q's rounding error eps_Q.  ~eps_Q / |grad Q| at regular
    points, ~sqrt(eps_Q / lambda) at singular ones (a cone's apex: there the brute force
    accepts x itself as a surface point while d is ~1e-8)."""
    eps_q = 1e-14 * float(abs_terms(q, x))
    g = 2.0 * float(np.linalg.norm(q.A @ x - q.b))
    lam = float(np.abs(np.linalg.eigvalsh(q.A)).max())
    den = g + np.sqrt(g * g + 4.0 * lam * eps_q)
    return (2.0 * eps_q / den if den > 0 else 0.0) + 1e-12 * (1.0 + float(np.linalg.norm(x)))


def brute_distance_rays(q: Quadric, x) -> float:
    """Upper bound on the true distance: nearest root over a dense sphere of directions."""
    t = surface_along_rays(q, x, DIRS)
    return float(t.min()) if len(t) else np.inf


def brute_distance_samples(q: Quadric, x, rng, n=2000) -> float:
    """Upper bound on the true distance: nearest of many surface points found by casting
    random rays from random origins around x."""
    origins = x + rng.uniform(-2.0, 2.0, (n, 3))
    dirs = rng.normal(size=(n, 3))
    dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
    t1, t2 = q.intersect_line(origins, dirs)
    pts = np.concatenate([origins + t1[:, None] * dirs, origins + t2[:, None] * dirs])
    reach = np.concatenate([np.abs(t1), np.abs(t2)]) + np.linalg.norm(np.concatenate([origins, origins]), axis=1)
    ok = np.all(np.isfinite(pts), axis=1)
    pts, reach = pts[ok], reach[ok]
    pts = pts[residual_ok(q, pts, reach)]
    if not len(pts):
        return np.inf
    return float(np.linalg.norm(pts - x, axis=1).min())


@st.composite
def query_points(draw, case):
    """Uniform points around the quadric, or points just off its surface."""
    if case.surface_point is not None and draw(st.booleans()):
        p = case.surface_point
        g = case.quadric.gradient(p)
        if np.linalg.norm(g) > 0:
            n = g / np.linalg.norm(g)
            off = draw(st.sampled_from([1e-7, 1e-5, 1e-3, 0.05, 0.3])) * draw(st.sampled_from([1.0, -1.0]))
            return p + off * n
    return draw(vec3(-3.0, 3.0))


# -- (a) conservative distance ------------------------------------------------------------------
@SETTINGS
@given(data=st.data(), case=quadric_cases(), seed=st.integers(0, 2**32 - 1))
def test_distance_is_conservative_and_signed(data, case, seed):
    q = case.quadric
    x = data.draw(query_points(case), label="x")
    d = float(q.distance(x))
    f = float(q.value(x))
    # sign of Q(x)
    if f < 0:
        assert d < 0
    elif f > 0:
        assert d > 0
    else:
        assert d == 0
    tiny = surface_uncertainty(q, x)
    rays = brute_distance_rays(q, x)
    assert abs(d) <= rays * (1 + 1e-9) + tiny, (d, rays)
    samples = brute_distance_samples(q, x, np.random.default_rng(seed))
    assert abs(d) <= samples * (1 + 1e-9) + tiny, (d, samples)


@SETTINGS
@given(
    case=quadric_cases(kinds=tuple(k for k in QUADRIC_KINDS if k != "raw")),
    off=st.sampled_from([1e-7, 1e-6, 1e-5]),
    side=st.sampled_from([1.0, -1.0]),
)
def test_distance_is_tight_near_the_surface(case, off, side):
    """The paper's relative-error property: close to a regular surface point |d| ~ distance
    (so a d that is conservative only by being ~0 fails here)."""
    q = case.quadric
    p = case.surface_point
    g = q.gradient(p)
    assume(np.linalg.norm(g) > 1e-2 * np.abs(q.matrix).max())  # not at a cone apex
    x = p + side * off * g / np.linalg.norm(g)
    d = float(q.distance(x))
    assert np.sign(d) == side
    assert 0.5 * off <= abs(d) <= off * (1 + 1e-6)


def test_distance_of_sphere_and_plane_is_exact():
    s = Quadric.sphere((1.0, 2.0, 3.0), 2.0)
    x = np.array([[1.0, 2.0, 3.0], [5.0, 2.0, 3.0], [1.0, 2.0, 4.5]])
    np.testing.assert_allclose(s.distance(x), [-2.0, 2.0, -0.5], rtol=1e-12)
    h = Quadric.half_space((0.0, 0.0, 2.0), 1.0)  # z <= 0.5
    np.testing.assert_allclose(h.distance([[0, 0, 3.0], [7, -1, 0.0]]), [2.5, -0.5], rtol=1e-12)


def test_distance_without_surface_is_infinite():
    empty = Quadric(np.diag([1.0, 1.0, 1.0, 1.0]))  # x^2 + y^2 + z^2 + 1 <= 0: no point, no surface
    assert q_inf(empty.distance([0.0, 0.0, 0.0])) == np.inf
    full = Quadric(np.diag([-1.0, -1.0, -1.0, -1.0]))  # everything inside, no surface
    assert q_inf(full.distance([3.0, 0.0, 0.0])) == -np.inf


def q_inf(d):
    return float(d)


# -- (b) line intersection ----------------------------------------------------------------------
@st.composite
def lines(draw, case):
    """(p, v): a random line, a line along a degenerate direction, or a far-away origin."""
    mode = draw(st.sampled_from(["random", "degenerate", "far"]))
    p = draw(vec3(-2.0, 2.0))
    v = draw(unit_vectors())
    if mode == "degenerate" and case.degenerate_dirs:
        v = case.degenerate_dirs[draw(st.integers(0, len(case.degenerate_dirs) - 1))]
        if case.surface_point is not None and draw(st.booleans()):
            # a line close to the surface in the degenerate direction (e.g. near a generator)
            p = case.surface_point + draw(floats(-0.1, 0.1)) * draw(unit_vectors())
    elif mode == "far":
        k = draw(st.integers(2, 6))
        p = draw(unit_vectors()) * 10.0**k
        target = draw(vec3(-1.0, 1.0)) if case.surface_point is None else case.surface_point
        v = (target - p) / np.linalg.norm(target - p)
    return np.asarray(p, dtype=np.float64), np.asarray(v, dtype=np.float64), mode


@SETTINGS
@given(data=st.data(), case=quadric_cases())
def test_intersect_line_roots_are_on_the_surface(data, case):
    q = case.quadric
    p, v, mode = data.draw(lines(case), label="line")
    t1, t2 = (float(t) for t in q.intersect_line(p, v))
    # ordering and NaN convention: t2 is NaN whenever t1 is
    assert not (np.isnan(t1) and not np.isnan(t2))
    if not np.isnan(t2):
        assert t1 <= t2
    for t in (t1, t2):
        if np.isnan(t):
            continue
        x = p + t * v
        # the roots are solved from the line's point nearest the quadric's center, so they
        # carry the rounding of that shift too
        reach = np.linalg.norm(p) + abs(t) + np.linalg.norm(q.center - p)
        assert residual_ok(q, x, reach), (mode, t, q.value(x))


@SETTINGS
@given(data=st.data(), case=quadric_cases())
def test_intersect_line_misses_no_sign_change(data, case):
    """Where Q clearly changes sign between two samples of the line a root lies between them."""
    q = case.quadric
    p, v, mode = data.draw(lines(case), label="line")
    if mode == "far":
        ts = np.linalg.norm(p) + np.linspace(-4.0, 4.0, 401)
    else:
        ts = np.linspace(-5.0, 5.0, 401)
    x = p + ts[:, None] * v
    val = q.value(x)
    tol = 1e-9 * (abs_terms(q, x) + np.linalg.norm(q.gradient(x), axis=1) * (np.linalg.norm(p) + np.abs(ts)))
    sgn = np.where(val > tol, 1, np.where(val < -tol, -1, 0))
    roots = np.array([float(t) for t in q.intersect_line(p, v)])
    roots = roots[np.isfinite(roots)]
    step = ts[1] - ts[0]
    for i in np.flatnonzero(sgn[:-1] * sgn[1:] < 0):
        lo, hi = ts[i], ts[i + 1]
        slack = 1e-9 * (abs(lo) + abs(hi)) + 1e-12
        assert np.any((roots >= lo - slack) & (roots <= hi + slack)), (mode, lo, hi, roots, step)


DEGENERATE_LINES = [
    # (quadric, p, v, expected sorted roots; nan = none)
    (Quadric.cylinder((0, 0, 1), 1.0), (0.5, 0, -3), (0, 0, 1), (np.nan, np.nan)),  # along the axis
    (Quadric.elliptic_paraboloid((0, 0, 0), (0, 0, 1), (1, 1)), (0.5, 0, -3), (0, 0, 1), (0.25 + 3, np.nan)),
    (Quadric.half_space((0, 0, 1), 1.0), (0, 0, 0), (1, 0, 0), (np.nan, np.nan)),  # parallel to the plane
    (Quadric.half_space((0, 0, 1), 1.0), (0, 0, 0), (0, 0, 1), (1.0, np.nan)),
    (Quadric.cone((0, 0, 0), (0, 0, 1), 1.0), (0, 0, -1), (1 / np.sqrt(2), 0, 1 / np.sqrt(2)), (np.sqrt(2) / 2, np.nan)),
    (Quadric.slab((0, 0, 1), -1, 1), (5, 5, 0), (0, 0, 1), (-1.0, 1.0)),
    (Quadric.sphere((0, 0, 0), 1.0), (0, 0, 1e6), (0, 0, -1), (1e6 - 1, 1e6 + 1)),  # far origin
]


@pytest.mark.parametrize("q, p, v, expected", DEGENERATE_LINES)
def test_intersect_line_degenerate_cases(q, p, v, expected):
    t1, t2 = (float(t) for t in q.intersect_line(np.array(p, float), np.array(v, float)))
    np.testing.assert_allclose([t1, t2], expected, rtol=1e-12, atol=1e-12, equal_nan=True)


def test_intersect_line_is_vectorized():
    q = Quadric.sphere((0, 0, 0), 1.0)
    p = np.zeros((4, 5, 3))
    v = np.broadcast_to(np.array([1.0, 0.0, 0.0]), (4, 5, 3))
    t1, t2 = q.intersect_line(p, v)
    assert t1.shape == t2.shape == (4, 5)
    np.testing.assert_allclose(t1, -1.0)
    np.testing.assert_allclose(t2, 1.0)


# -- (c) transforms -----------------------------------------------------------------------------
@SETTINGS
@given(case=quadric_cases(), m=affine_maps(), x=vec3(-3.0, 3.0))
def test_transform_moves_the_quadric(case, m, x):
    q = case.quadric
    qt = q.transform(m)
    y = m[:3, :3] @ x + m[:3, 3]
    tol = 1e-9 * (abs_terms(q, x) + abs_terms(qt, y))
    assert abs(float(qt.value(y)) - float(q.value(x))) <= tol


@pytest.mark.filterwarnings("ignore:divide by zero encountered in det:RuntimeWarning")
@SETTINGS
@given(case=quadric_cases(), u=unit_vectors(), w=unit_vectors(), kind=st.sampled_from(["zero_column", "rank1", "rank2", "zero"]))
def test_transform_rejects_singular_maps(case, u, w, kind):
    lin = np.outer(u, w)
    if kind == "zero_column":
        lin = np.eye(3)
        lin[:, 1] = 0.0
    elif kind == "rank2":
        lin = np.column_stack([u, w, 2.0 * u - 0.5 * w])
    elif kind == "zero":
        lin = np.zeros((3, 3))
    with pytest.raises(TransformError, match="singular"):
        case.quadric.transform(affine(lin, (1.0, 2.0, 3.0)))


@pytest.mark.parametrize(
    "last_row",
    [(0, 0, 0, 2.0), (0, 0, 1e-3, 1.0), (1.0, 0, 0, 1.0), (0, 0, 0, 0.0), (0, 0, 0, -1.0)],
)
def test_transform_rejects_non_affine_maps(last_row):
    m = np.eye(4)
    m[3] = last_row
    with pytest.raises(TransformError, match="not affine"):
        Quadric.sphere().transform(m)


@pytest.mark.parametrize("bad", [np.full((4, 4), np.nan), np.eye(3), np.zeros((2, 4))])
def test_transform_rejects_malformed_maps(bad):
    with pytest.raises(TransformError):
        Quadric.sphere().transform(bad)


def test_check_affine_accepts_3x4():
    m = check_affine(np.eye(4)[:3])
    np.testing.assert_array_equal(m, np.eye(4))


# -- (d) canonical form -------------------------------------------------------------------------
def _no_coefficient_near_snap(q):
    k = np.abs(q.matrix / np.linalg.norm(q.matrix))
    return not np.any((k > 1e-15) & (k < 1e-11))


@SETTINGS
@given(case=quadric_cases(), alpha=floats(1e-3, 1e3), k=st.integers(-20, 20))
def test_canonical_is_invariant_under_positive_rescaling(case, alpha, k):
    q = case.quadric
    K, s = q.canonical()
    assert s in (1, -1)
    assert abs(np.linalg.norm(K.matrix) - 1.0) <= 1e-12
    first = next(c for c in K.coefficients() if c != 0.0)
    assert first > 0
    np.testing.assert_allclose(s * np.linalg.norm(q.matrix) * K.matrix, q.matrix, rtol=0,
                               atol=1e-12 * np.abs(q.matrix).max())
    # exact rescaling (a power of two): bit-identical canonical form
    K2, s2 = Quadric(q.matrix * 2.0**k).canonical()
    assert s2 == s and np.array_equal(K2.matrix, K.matrix)
    # any positive factor: the same up to rounding
    assume(_no_coefficient_near_snap(q))
    K3, s3 = Quadric(q.matrix * alpha).canonical()
    assert s3 == s
    np.testing.assert_allclose(K3.matrix, K.matrix, rtol=0, atol=1e-13)


@SETTINGS
@given(case=quadric_cases())
def test_canonical_moves_the_sign_into_the_polarity(case):
    q = case.quadric
    K, s = q.canonical()
    Kc, sc = q.complement().canonical()
    assert sc == -s
    assert np.array_equal(Kc.matrix, K.matrix)


@SETTINGS
@given(case=quadric_cases(kinds=tuple(k for k in QUADRIC_KINDS if k != "raw")), m=affine_maps())
def test_canonical_of_the_same_surface_built_two_ways(case, m):
    """Moving a quadric forth and back, or building it directly: canonical forms agree within
    the DNF's identity tolerance (compile/dnf.py SAME_QUADRIC = 1e-9)."""
    q = case.quadric
    back = q.transform(m).transform(np.linalg.inv(m))
    K, s = q.canonical()
    Kb, sb = back.canonical()
    assume(_no_coefficient_near_snap(q))
    assert sb == s
    np.testing.assert_allclose(Kb.matrix, K.matrix, rtol=0, atol=1e-10)


def test_canonical_identifies_coincident_named_surfaces():
    pairs = [
        (Quadric.half_space((0, 0, 1), 0.5), Quadric.half_space((0, 0, -3), -1.5), -1),
        (Quadric.sphere((1, 2, 3), 2.0), Quadric.sphere().transform(affine(2 * np.eye(3), (1, 2, 3))), 1),
        (Quadric.cylinder((0, 0, 1), 1.0), Quadric.cylinder((0, 0, -1), 1.0, (0, 0, 5.0)), 1),
        (Quadric.cone((0, 0, 0), (1, 0, 0), 0.5), Quadric.cone((0, 0, 0), (-1, 0, 0), 0.5), 1),
        (Quadric.slab((1, 0, 0), -1, 2), Quadric.slab((-1, 0, 0), -2, 1), 1),
    ]
    for a, b, rel in pairs:
        Ka, sa = a.canonical()
        Kb, sb = b.canonical()
        np.testing.assert_allclose(Ka.matrix, Kb.matrix, atol=1e-12)
        assert sa * sb == rel


def test_canonical_rejects_zero():
    with pytest.raises(ValueError):
        Quadric(np.zeros((4, 4))).canonical()


# -- (e) gradient and normal --------------------------------------------------------------------
@SETTINGS
@given(case=quadric_cases(), x=vec3(-3.0, 3.0))
def test_gradient_matches_finite_differences(case, x):
    q = case.quadric
    h = 1e-4 * (1.0 + np.linalg.norm(x))
    e = np.eye(3) * h
    fd = (q.value(x + e) - q.value(x - e)) / (2.0 * h)
    g = q.gradient(x)
    rounding = np.abs(abs_terms(q, x + e)) + np.abs(abs_terms(q, x - e))  # Q is quadratic: no truncation
    tol = 1e-13 * rounding.max() / h + 1e-9 * np.linalg.norm(g)
    np.testing.assert_allclose(g, fd, rtol=0, atol=tol)


@SETTINGS
@given(case=quadric_cases(), x=vec3(-3.0, 3.0))
def test_normal_is_unit_and_outward(case, x):
    q = case.quadric
    g = q.gradient(x)
    assume(np.linalg.norm(g) > 1e-6 * abs_terms(q, x))
    n = q.normal(x)
    assert abs(np.linalg.norm(n) - 1.0) <= 1e-12
    np.testing.assert_allclose(n, g / np.linalg.norm(g), atol=1e-14)
    eps = 1e-6
    assert q.value(x + eps * n) > q.value(x - eps * n)  # towards the outside Q grows


def test_vectorized_shapes():
    q = Quadric.ellipsoid((0, 0, 0), (1, 2, 3))
    x = np.random.default_rng(1).normal(size=(5, 7, 3))
    assert q.value(x).shape == (5, 7)
    assert q.gradient(x).shape == (5, 7, 3)
    assert q.normal(x).shape == (5, 7, 3)
    assert q.distance(x).shape == (5, 7)
    with pytest.raises(ValueError):
        q.value(np.zeros((4, 2)))


def test_every_constructor_has_a_strategy():
    ctors = {
        name
        for name, f in vars(Quadric).items()
        if isinstance(f, classmethod) and name not in ("from_coefficients", "_local")
    }
    assert ctors <= set(QUADRIC_KINDS), ctors - set(QUADRIC_KINDS)


def test_coefficients_round_trip():
    q = Quadric.hyperboloid_one_sheet((1, 2, 3), (1, 1, 0), (1, 2, 0.5))
    assert Quadric.from_coefficients(q.coefficients()) == q


def test_ellipsoid_radii_follow_the_rotation_columns():
    q = Quadric.ellipsoid((0, 0, 0), (2.0, 1.0, 0.5))
    np.testing.assert_allclose(q.value([[2.0, 0, 0], [0, 1.0, 0], [0, 0, 0.5]]), 0.0, atol=1e-12)
