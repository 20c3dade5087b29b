"""Many face planes in the bounds code (a mesh operand is an expression of its face planes):
the dense plane groups of :mod:`clcsg.compile.bounds.sparse_distance` against the planes read
one by one, :func:`~clcsg.compile.bounds.exact_boxes.halfspace_boxes` and the half-space rows of
:func:`~clcsg.compile.bounds.exact_boxes.kind_boxes` against :func:`primitive_box`, all float64;
and a tessellated sphere minus a cylinder sampled, every sample on the surface of an independent
oracle (the sphere mesh is convex: inside is every face plane's signed distance <= 0)."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import clcsg
from clcsg.compile.bounds.exact_boxes import halfspace_boxes, kind_boxes, primitive_box
from clcsg.compile.bounds.tree import _Graph, _Leaves
from clcsg.model.construction import plane
from clcsg.model.csg import Intersection, Union

from strategies import affine_maps, unit_vectors, vec3


@st.composite
def plane_graphs(draw):
    """ANDs and ORs mixing many half-spaces (some negated, some shared) with spheres, nested."""
    pool = [plane(draw(unit_vectors()), draw(st.floats(-0.5, 0.8))) for _ in range(draw(st.integers(4, 14)))]
    balls = [clcsg.sphere(draw(st.floats(0.2, 1.0)), tuple(draw(vec3(-0.8, 0.8)))) for _ in range(draw(st.integers(0, 3)))]

    def operand():
        k = draw(st.integers(0, len(pool) + len(balls) - 1))
        s = (pool + balls)[k]
        return ~s if draw(st.booleans()) else s

    def node(depth):
        kids = [operand() for _ in range(draw(st.integers(1, 9)))]
        if depth:
            kids += [node(depth - 1) for _ in range(draw(st.integers(0, 2)))]
        return Intersection(kids) if draw(st.booleans()) else Union(kids)

    return Intersection([clcsg.box((3, 3, 3)), node(draw(st.integers(0, 2)))])


@settings(max_examples=40, deadline=None)
@given(plane_graphs(), st.integers(0, 2 ** 31 - 1))
def test_grouped_planes_equal_the_planes_one_by_one(shape, seed):
    g = _Graph(shape, "test")
    leaves = _Leaves(g, "test")
    grouped, single = leaves.sparse_distance(), leaves.sparse_distance(min_group=0)
    rng = np.random.default_rng(seed)
    c = rng.uniform(-2, 2, (300, 3))
    h = rng.uniform(0.0, 0.6, (300, 3))
    a, b = grouped(c, h), single(c, h)
    same_inf = np.isinf(a) & (a == b)
    fin = np.isfinite(a) & np.isfinite(b)
    assert np.all(same_inf | fin), np.flatnonzero(~(same_inf | fin))[:5]
    np.testing.assert_allclose(a[fin], b[fin], rtol=1e-12, atol=1e-12)


def test_a_convex_mesh_is_one_group():
    import trimesh

    m = trimesh.creation.icosphere(2)
    shape = clcsg.polyhedron(m.vertices, m.faces) - clcsg.cylinder(3, 0.3)
    d = _Leaves(_Graph(shape, "test"), "test").sparse_distance()
    assert len(d.group_planes) == 1 and len(d.group_planes[0][1]) == len(m.faces)
    assert len(d.tree_leaves) < 10  # the planes are not in the box tree


@settings(max_examples=200, deadline=None)
@given(unit_vectors(), st.floats(-2, 2), vec3(-1.5, 1.5), vec3(0.01, 1.5))
def test_halfspace_boxes_equal_primitive_box(n, d, c, h):
    q = plane(n, d).quadrics()
    lo, hi = halfspace_boxes(n[None], np.array([d]), (c - h)[None], (c + h)[None])
    ref = primitive_box(q, (c - h, c + h))
    if ref is None or np.any(ref[0] > ref[1]):
        assert np.all(lo == np.inf) and np.all(hi == -np.inf)
    else:
        tol = 1e-9 * (1 + np.abs(c).max() + h.max())
        np.testing.assert_allclose(lo[0], ref[0], atol=tol)
        np.testing.assert_allclose(hi[0], ref[1], atol=tol)


@settings(max_examples=100, deadline=None)
@given(st.sampled_from([(1, 0, 0), (0, -1, 0), (0, 0, 2), (1, 2, 3), (0, 1, 1)]), st.floats(-2, 2), affine_maps(),
       st.booleans())
def test_halfspace_own_boxes_equal_primitive_box(n, d, m, moved):
    node = plane(n, d)
    mat = m if moved else np.eye(4)
    lo, hi, done = kind_boxes([node], mat[None])
    assert done[0]
    world = [q.transform(mat) for q in node.quadrics()]
    ref = primitive_box(world)
    b_w = np.abs(world[0].matrix[:3, 3]) / np.linalg.norm(world[0].matrix[:3, 3])
    # not exactly along an axis: the half-space is unbounded on every side, where primitive_box
    # clips it at |x| ~ 1e9 (finite after a tilt of 1e-7: 119 for x >= 1.2e-7 z)
    tilted = np.count_nonzero(b_w) > 1
    if tilted:
        assert np.all(np.isinf(lo[0])) and np.all(np.isinf(hi[0])), (lo, hi)
    # primitive_box clips an unbounded side far out (|x| ~ 1e8 or more): that side is infinite
    for a, b, sign in ((lo[0], ref[0], -1), (hi[0], ref[1], 1)):
        far = ~(np.abs(b) < 1e6) | (tilted & np.isinf(a))
        assert np.all(a[far] == sign * np.inf), (a, b)
        np.testing.assert_allclose(a[~far], b[~far], atol=1e-9 * (1 + np.abs(b[~far]).max(initial=0)))


def test_a_1280_face_sphere_minus_a_cylinder_samples_on_its_surface(cl_context):
    """Every sample on the surface: by the float64 tree oracle, and by an independent one
    (the icosphere is convex: its solid is max_f (n_f . x - d_f) <= 0; minus the cylinder)."""
    import trimesh

    import tree_oracle as T

    m = trimesh.creation.icosphere(3)
    v, f = np.asarray(m.vertices), np.asarray(m.faces)
    assert len(f) == 1280
    shape = clcsg.polyhedron(v, f) - clcsg.cylinder(3, 0.3, center=(0.2, 0.1, 0.0))
    s = clcsg.sample(shape, 0.05, device=cl_context, progress=False)
    assert len(s) > 1000
    Q = s.tape.quadrics[s.quadrics]
    on_q, on_csg = T.sample_residuals(shape, s.positions, Q, tol=1e-9)
    assert on_q.max() <= 1e-6 and on_csg.all()
    tri = v[f]
    n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    off = np.einsum("ij,ij->i", n, tri[:, 0])
    p = np.asarray(s.positions, dtype=np.float64)
    mesh = (p @ n.T - off).max(axis=1)  # signed distance to the convex mesh (a lower bound outside)
    cyl = np.hypot(p[:, 0] - 0.2, p[:, 1] - 0.1) - 0.3
    top = np.abs(p[:, 2]) - 1.5
    solid_cyl = np.maximum(cyl, top)
    tol = 1e-6
    on_mesh_part = (np.abs(mesh) <= tol) & (solid_cyl >= -tol)
    on_cyl_part = (np.abs(solid_cyl) <= tol) & (mesh <= tol)
    assert np.all(on_mesh_part | on_cyl_part), p[~(on_mesh_part | on_cyl_part)][:3].tolist()
    assert on_mesh_part.sum() > 100 and on_cyl_part.sum() > 100


if __name__ == "__main__":
    pytest.main([__file__])
