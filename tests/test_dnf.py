"""DNF normalization (clcsg/compile/dnf.py, paper section 5): the normal form holds exactly the
points of the CSG graph, pruning loses nothing, identical quadrics are stored once, term bounds
hold their terms, runaway distribution and unbounded terms are reported.

``CLCSG_HYPOTHESIS_EXAMPLES=500 pytest tests/test_dnf.py`` runs a longer search.
"""

from __future__ import annotations

import os
import time
from unittest import mock

import numpy as np
import pytest
from hypothesis import HealthCheck, given, reject, settings
from hypothesis import strategies as st

import clcsg
from clcsg.model import csg, solids
from clcsg.errors import DnfLimitError, SceneError, UnboundedError
from clcsg.compile.bounds import term_boxes as bounds_module
from clcsg.compile import dnf as dnf_module
from clcsg.compile.dnf import normalize
from clcsg.model.quadric import Quadric
from strategies import any_primitives, shapes

EXAMPLES = int(os.environ.get("CLCSG_HYPOTHESIS_EXAMPLES", 30))
SETTINGS = settings(
    max_examples=EXAMPLES,
    deadline=None,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.filter_too_much, HealthCheck.data_too_large],
)

UB = np.array([[-3.5, -3.5, -3.5], [3.5, 3.5, 3.5]])
TERM_LIMIT = 3000  # random graphs past this are skipped: they test the limit, not membership


def random_points(rng, bound, n):
    lo, hi = np.asarray(bound, dtype=np.float64)
    return rng.uniform(lo, hi, (n, 3))


def away_from_surfaces(dnf, x, eps=1e-9):
    """Mask of points farther than eps (relative) from every quadric surface of the DNF; the
    conservative distance never over-estimates, so the mask is safe."""
    keep = np.ones(len(x), dtype=bool)
    for m in dnf.quadrics:
        keep &= np.abs(Quadric(m).distance(x)) > eps * (1.0 + np.abs(x).max(axis=1))
    return keep


def normalize_or_skip(shape, **kw):
    try:
        return normalize(shape, term_limit=TERM_LIMIT, **kw)
    except DnfLimitError:
        reject()


def unpruned(shape, user_bound):
    """The DNF with pruning switched off: no disjoint-box pruning or redundant-literal dropping
    while distributing and no
    empty-polytope pruning afterwards (contradictions K & ~K are still dropped: they hold no
    point at all).  Same quadric table as the pruned normalization."""
    lo, hi = np.asarray(user_bound, dtype=np.float64)
    real_term_box = bounds_module.term_box

    def term_box(literals, ub=None):
        box = real_term_box(literals, ub)
        return (lo.copy(), hi.copy()) if box is None else box

    with mock.patch.object(dnf_module._Normalizer, "_simplify", lambda self, term: term), mock.patch.object(
        bounds_module, "term_box", term_box
    ):
        return normalize(shape, term_limit=50 * TERM_LIMIT, user_bound=user_bound)


def check_term_bounds(dnf, x, rel=1e-9):
    """Every point of a term lies in that term's bound."""
    inside = dnf.term_contains(x)
    for t in range(dnf.n_terms):
        pts = x[inside[:, t]]
        if not len(pts):
            continue
        lo, hi = dnf.term_bounds[t]
        tol = rel * (1.0 + np.abs(dnf.term_bounds[t]).max())
        assert np.all(pts >= lo - tol) and np.all(pts <= hi + tol), (
            f"term {t} {dnf.terms[t]}: bound {lo.tolist()} .. {hi.tolist()} misses "
            f"{pts[np.any((pts < lo - tol) | (pts > hi + tol), axis=1)][:3].tolist()}"
        )


# -- membership -----------------------------------------------------------------------------------
@SETTINGS
@given(shape=shapes(), clip=st.booleans(), seed=st.integers(0, 2**32 - 1))
def test_dnf_holds_the_points_of_the_graph(shape, clip, seed):
    """normalize(shape).contains(x) == csg.contains(shape, x) away from surfaces: either the
    graph is clipped by a box (bounded, no user bound needed) or a user bound is given."""
    rng = np.random.default_rng(seed)
    if clip:
        shape = csg.Intersection([shape, solids.box(6.0)])
        dnf = normalize_or_skip(shape)
        region = np.array([[-3.2, -3.2, -3.2], [3.2, 3.2, 3.2]])
    else:
        dnf = normalize_or_skip(shape, user_bound=UB)
        region = UB
    x = random_points(rng, region, 1500)
    x = x[away_from_surfaces(dnf, x)]
    expected = clcsg.contains(shape, x)
    got = dnf.contains(x)
    bad = np.flatnonzero(got != expected)
    assert not len(bad), f"{len(bad)} points differ, e.g. {x[bad[:3]].tolist()} (graph says {expected[bad[:3]]})"
    assert dnf.n_terms == dnf.stats["terms"] == len(dnf.term_bounds)
    check_term_bounds(dnf, x)


@SETTINGS
@given(shape=shapes(leaves=any_primitives()), seed=st.integers(0, 2**32 - 1))
def test_dnf_of_every_primitive_kind(shape, seed):
    """The same with leaves of every solids kind (unbounded ones too), within a user bound."""
    dnf = normalize_or_skip(shape, user_bound=UB)
    x = random_points(np.random.default_rng(seed), UB, 1000)
    x = x[away_from_surfaces(dnf, x)]
    np.testing.assert_array_equal(dnf.contains(x), clcsg.contains(shape, x))


@SETTINGS
@given(shape=shapes(), seed=st.integers(0, 2**32 - 1))
def test_pruning_never_drops_a_point(shape, seed):
    """Pruned and unpruned DNFs hold exactly the same points (everywhere, surfaces included:
    both use the same quadric table), every point of the solid is in a kept term, and the
    bound of every kept term holds every sampled point of the term."""
    pruned = normalize_or_skip(shape, user_bound=UB)
    full = unpruned(shape, UB)
    np.testing.assert_array_equal(pruned.quadrics, full.quadrics)
    # pruning drops terms and redundant literals: each kept term is a subset of a full one
    assert all(any(set(p) <= set(f) for f in full.terms) for p in pruned.terms)
    assert pruned.stats["terms_before_pruning"] >= pruned.n_terms
    rng = np.random.default_rng(seed)
    x = random_points(rng, UB, 1500)
    # add points on the surfaces: the quadrics' roots along random lines
    for m in pruned.quadrics[:8]:
        p = random_points(rng, UB, 50)
        v = rng.normal(size=(50, 3))
        t = Quadric(m).intersect_line(p, v)[0]
        ok = np.isfinite(t)
        x = np.vstack([x, p[ok] + t[ok, None] * v[ok]])
    x = x[np.all((x >= UB[0]) & (x <= UB[1]), axis=1)]
    a = pruned.contains(x)
    b = full.contains(x)
    lost = np.flatnonzero(b & ~a)
    assert not len(lost), f"pruning lost {len(lost)} points, e.g. {x[lost[:3]].tolist()}"
    np.testing.assert_array_equal(a, b)
    check_term_bounds(pruned, x)


# -- identical quadrics ---------------------------------------------------------------------------
def literal_map(dnf):
    return [dict(t) for t in dnf.terms]


@pytest.mark.parametrize(
    "moved",
    [
        solids.box(1.0).translate((0.0, 0.5, 0.0)),
        solids.box(1.0, center=(0.0, 0.5, 0.0)),
        solids.box(1.0).rotate((0, 0, 1), 90).translate((0.0, 0.5, 0.0)),
    ],
    ids=["translated", "centered", "rotated+translated"],
)
def test_shared_faces_are_one_quadric(moved):
    """box(1) | box(1) moved by 0.5 along y: the x and z faces coincide (same orientation),
    the y faces do not: 6 + 2 unique quadrics, and the shared ones with the same polarity."""
    dnf = normalize(solids.box(1.0) | moved)
    assert dnf.n_quadrics == 8
    assert dnf.n_terms == 2
    a, b = literal_map(dnf)
    common = set(a) & set(b)
    assert len(common) == 4
    assert all(a[q] == b[q] for q in common)


@pytest.mark.parametrize(
    "neighbour",
    [solids.box(1.0, center=(1.0, 0.0, 0.0)), solids.box(1.0).translate((1.0, 0.0, 0.0))],
    ids=["centered", "translated"],
)
def test_touching_faces_have_opposite_polarity(neighbour):
    """Two boxes touching face to face: the touching face is one quadric, with opposite signs
    (the side faces coincide too: 6 + 1 unique quadrics)."""
    dnf = normalize(solids.box(1.0) | neighbour)
    assert dnf.n_quadrics == 7
    a, b = literal_map(dnf)
    common = set(a) & set(b)
    assert len(common) == 5
    opposite = [q for q in common if a[q] == -b[q]]
    assert len(opposite) == 1
    k = Quadric(dnf.quadrics[opposite[0]])
    np.testing.assert_allclose(k.value([[0.5, 0.3, -0.2], [0.5, -7.0, 3.0]]), 0.0, atol=1e-12)


def test_identical_solids_built_differently_share_quadrics():
    shapes_ = [
        solids.sphere(1.0, center=(1.0, 2.0, 3.0)),
        solids.sphere(1.0).translate((1.0, 2.0, 3.0)),
        solids.sphere(0.5).scale(2.0).translate((1.0, 2.0, 3.0)),
        solids.box(1.0).rotate((0, 0, 1), 90),
        solids.box(1.0).rotate((1, 1, 1), 120),  # maps the axes onto each other
        solids.box(1.0),
    ]
    dnf = normalize(csg.Union(shapes_))
    assert dnf.n_quadrics == 1 + 6
    assert dnf.n_terms == 2  # duplicate terms are merged


def test_contradictions_and_disjoint_terms_are_pruned():
    assert normalize(solids.sphere(1.0) - solids.sphere(1.0)).n_terms == 0
    assert normalize(solids.box(1.0) & ~solids.box(1.0)).n_terms == 0
    far = normalize(solids.box(1.0) & solids.box(1.0, center=(5.0, 0, 0)))
    assert far.n_terms == 0
    assert normalize(csg.Union([])).n_terms == 0


# -- term limit -----------------------------------------------------------------------------------
def test_term_limit_stops_runaway_distribution():
    rng = np.random.default_rng(7)
    small = [solids.box(float(rng.uniform(0.5, 2.0)), center=rng.uniform(-45, 45, 3)) for _ in range(300)]
    shape = solids.box(100.0) - clcsg.union(*small)
    start = time.process_time()  # CPU time: other processes on the machine do not count
    with pytest.raises(DnfLimitError) as info:
        normalize(shape, source="many.json")
    elapsed = time.process_time() - start
    assert elapsed < 10.0, f"the limit took {elapsed:.1f} s (CPU) to trigger"
    msg = str(info.value)
    assert "\n" not in msg
    assert msg.startswith("many.json: ")
    assert "union" in msg  # the operation (a complement of a union here)
    assert str(dnf_module.DEFAULT_TERM_LIMIT) in msg  # the limit ...
    assert any(ch.isdigit() for ch in msg.replace(str(dnf_module.DEFAULT_TERM_LIMIT), ""))  # ... and the counts
    assert info.value.exit_code == 5


def test_term_limit_is_configurable():
    shape = solids.box(4.0) - solids.box(1.0) - solids.box(1.0, center=(0.5, 0.5, 0.5))
    assert normalize(shape).n_terms > 3
    with pytest.raises(DnfLimitError, match=r"\b3\b"):
        normalize(shape, term_limit=3)
    big_union = csg.Union([solids.sphere(0.1, center=(i, 0, 0)) for i in range(20)])
    with pytest.raises(DnfLimitError, match="union"):
        normalize(big_union, term_limit=10)


# -- unbounded terms ------------------------------------------------------------------------------

UNBOUNDED = [
    solids.Primitive("double_cone", {}),
    solids.halfspace((0, 0, 1), 0.0),
    ~solids.sphere(1.0),
    solids.Primitive("elliptic_paraboloid", {}),
    pytest.param(solids.Primitive("infinite_cylinder", {"axis": (1, 1, 0)}), id="tilted infinite_cylinder"),
    solids.Primitive("hyperboloid_one_sheet", {}),
    solids.slab((0, 0, 1), -1, 1) & solids.halfspace((1, 0, 0), 0.0),
]


@pytest.mark.parametrize("shape", UNBOUNDED, ids=lambda s: repr(s)[:40])
def test_unbounded_terms_need_a_user_bound(shape):
    with pytest.raises(UnboundedError) as info:
        normalize(shape, source="open.json")
    msg = str(info.value)
    assert isinstance(info.value, SceneError)
    assert msg.startswith("open.json: ") and "unbounded" in msg and "\n" not in msg
    ub = np.array([[-2.0, -2.5, -3.0], [2.0, 2.5, 3.0]])
    dnf = normalize(shape, user_bound=ub)
    assert dnf.n_terms >= 1
    assert np.all(dnf.term_bounds[:, 0] >= ub[0] - 1e-9) and np.all(dnf.term_bounds[:, 1] <= ub[1] + 1e-9)
    x = random_points(np.random.default_rng(3), ub, 3000)
    np.testing.assert_array_equal(dnf.contains(x), clcsg.contains(shape, x))
    check_term_bounds(dnf, x)


@pytest.mark.parametrize("bad", [[[0, 0, 0], [0, 1, 1]], [[0, 0, 0]], [[0, 0, np.nan], [1, 1, 1]]])
def test_bad_user_bound(bad):
    with pytest.raises(SceneError, match="bound"):
        normalize(solids.sphere(), user_bound=bad)


# -- term bounds ----------------------------------------------------------------------------------
def tilted(shape, axis=(1.0, 2.0, 0.5), degrees=37.0):
    return shape.rotate(axis, degrees).translate((0.3, -0.2, 0.1))


BOUNDED_SHAPES = {
    "tilted cylinder": solids.cylinder(2.0, 0.5, center=(0.2, 0.1, 0.0), axis=(1, 1, 1)),
    "transformed cylinder": tilted(solids.cylinder(1.5, 0.3)),
    "cone frustum": solids.cone(1.5, 0.8, 0.2, axis=(0.3, -1.0, 0.4)),
    "cone to apex": tilted(solids.cone(1.2, 0.0, 0.6)),
    "ellipsoid": tilted(solids.ellipsoid((1.2, 0.4, 0.7))),
    "sheared ellipsoid": solids.ellipsoid((1.0, 0.5, 0.3)).transform(
        [[1, 0.8, 0, 0.1], [0, 1, 0.3, 0], [0, 0, 1, -0.2], [0, 0, 0, 1]]
    ),
    "paraboloid & box": csg.Intersection(
        [tilted(solids.Primitive("elliptic_paraboloid", {"radii": (0.5, 0.3)})), solids.box(2.0)]
    ),
    "saddle & box": solids.Primitive("hyperbolic_paraboloid", {"axis": (0, 1, 1)}) & solids.box(1.5),
    "hyperboloid & slab & cylinder": csg.Intersection(
        [
            tilted(solids.Primitive("hyperboloid_one_sheet", {"radii": (0.5, 0.6, 0.8)})),
            tilted(solids.slab((0, 0, 1), -0.7, 0.9)),
        ]
    ),
    "double cone & sphere": solids.Primitive("double_cone", {"axis": (1, 0, 1), "slope": 0.5})
    & solids.sphere(1.3),
    "two-sheet hyperboloid & box": solids.Primitive("hyperboloid_two_sheets", {"radii": (0.3, 0.3, 0.4)})
    & solids.box(2.0),
    "box minus tilted cylinder": solids.box(1.6) - solids.cylinder(3.0, 0.4, axis=(1, 1, 0)),
}


@pytest.mark.parametrize("name", BOUNDED_SHAPES)
def test_term_bounds_hold_monte_carlo_points(name):
    shape = BOUNDED_SHAPES[name]
    dnf = normalize(shape)
    assert dnf.n_terms >= 1
    assert np.all(np.isfinite(dnf.term_bounds))
    rng = np.random.default_rng(11)
    for t in range(dnf.n_terms):
        lo, hi = dnf.term_bounds[t]
        c, e = (lo + hi) / 2, (hi - lo) / 2
        # sample well beyond the bound: a bound that is too small shows up as term points outside
        x = random_points(rng, [c - 2.0 * e - 0.5, c + 2.0 * e + 0.5], 40_000)
        pts = x[dnf.term_contains(x)[:, t]]
        tol = 1e-9 * (1.0 + np.abs(dnf.term_bounds[t]).max())
        assert np.all(pts >= lo - tol) and np.all(pts <= hi + tol), (name, t, lo, hi)
    # the union of the term bounds is the scene bound
    np.testing.assert_array_equal(dnf.bound[0], dnf.term_bounds[:, 0].min(0))
    np.testing.assert_array_equal(dnf.bound[1], dnf.term_bounds[:, 1].max(0))
    x = random_points(rng, [dnf.bound[0] - 0.5, dnf.bound[1] + 0.5], 20_000)
    np.testing.assert_array_equal(dnf.contains(x), clcsg.contains(shape, x))


def test_bounds_of_axis_aligned_solids_are_exact():
    cases = [
        (solids.box((1.0, 2.0, 3.0), center=(0.5, -1.0, 2.0)), [[0.0, -2.0, 0.5], [1.0, 0.0, 3.5]]),
        (solids.sphere(0.7, center=(1.0, 2.0, 3.0)), [[0.3, 1.3, 2.3], [1.7, 2.7, 3.7]]),
        (solids.ellipsoid((0.5, 1.0, 2.0)), None),  # extents along x, y, z: some order of 0.5, 1, 2
        (solids.cylinder(2.0, 0.5, axis=(0, 1, 0)), [[-0.5, -1.0, -0.5], [0.5, 1.0, 0.5]]),
    ]
    for shape, expected in cases:
        dnf = normalize(shape)
        if expected is None:
            np.testing.assert_allclose(sorted(dnf.bound[1]), [0.5, 1.0, 2.0], atol=1e-9)
            np.testing.assert_allclose(dnf.bound[0], -dnf.bound[1], atol=1e-9)
        else:
            np.testing.assert_allclose(dnf.bound, expected, atol=1e-9)


@pytest.mark.parametrize("scale", [1.0, 0.01])
def test_empty_tilted_term_is_pruned(scale):
    """A box and the half-space x + y >= 1.5 (the box reaches x + y = 1 only) share no point."""
    shape = solids.box(scale) & solids.halfspace((-1, -1, 0), -1.5 * scale)
    assert normalize(shape).n_terms == 0


def test_normalize_rejects_non_shapes():
    with pytest.raises(SceneError, match="expected a CSG shape"):
        normalize("box", source="x")


def test_complement_of_empty_union_is_everything():
    from clcsg.model.csg import Difference, Union, contains

    s = Difference([solids.box(1), Union([])])
    d = normalize(s)
    x = np.random.default_rng(0).uniform(-1, 1, (500, 3))
    assert d.n_terms == 1
    np.testing.assert_array_equal(d.contains(x), contains(s, x))


def test_redundant_literals_are_dropped_without_changing_the_solid():
    """A hole far from the part and a subtracted box beside it cut nothing: their literals go."""
    part = solids.box(2)
    far_hole = solids.cylinder(5, 0.3, center=(5, 5, 0))
    beside = solids.box(1).translate((0.5, 0.5, 1.2))  # overlaps the top only
    shape = part - far_hole - beside
    d = normalize(shape)
    assert d.stats["redundant_literals_dropped"] > 0
    used = {qi for t in d.terms for qi, _ in t}
    x = np.random.default_rng(3).uniform(-3, 6, (20000, 3))
    np.testing.assert_array_equal(d.contains(x), csg.contains(shape, x))
    # the far cylinder's side surface is in no term
    cyl = clcsg.Scene(far_hole).normalize()
    side = [q for q in cyl.quadrics if np.abs(q[:3, :3]).max() > 0][0]
    assert not any(np.allclose(d.quadrics[qi], side) for qi in used)


@pytest.mark.parametrize("axis", [(1, 1, 0), (1, 2, 3), (0, 0, 1)])
def test_tilted_cone_frustum_bound_holds_the_solid(axis):
    """Regression: far-box vertices of the caps' slab were lost to a too tight tolerance, so
    the cone's cross-section bound used a wrong height and cut the wide end off."""
    shape = solids.cone(2, 1, 0.3, axis=axis)
    d = normalize(shape)
    x = np.random.default_rng(5).uniform(-2, 2, (400000, 3))
    p = x[csg.contains(shape, x)]
    assert len(p) > 1000
    lo, hi = d.term_bounds[0]
    assert np.all(p >= lo - 1e-9) and np.all(p <= hi + 1e-9)
