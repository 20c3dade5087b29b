"""The tree oracle (tests/tree_oracle.py) against hand-computed facts: shared and flush faces,
bores, cavities seen from inside, a 1,000-deep difference chain, DAG sharing, sphere coverage."""

from __future__ import annotations

import numpy as np
import pytest

import clcsg
from clcsg.model.csg import Difference, Transformed, Union
from clcsg.model.quadric import Quadric
import tree_oracle as T


def plane(normal, offset):
    return Quadric.half_space(normal, offset).matrix


def rng_dirs(rng, n):
    d = rng.normal(size=(n, 3))
    return d / np.linalg.norm(d, axis=1, keepdims=True)


def face_points(rng, n, axis, value, lo=-0.45, hi=0.45):
    p = rng.uniform(lo, hi, (n, 3))
    p[:, axis] = value
    return p


# -- canonical forms and the table ---------------------------------------------------------------


def test_canonical_and_table():
    q = Quadric.sphere((1, 2, 3), 0.5).matrix
    key, s = T.canonical(q)
    assert s == 1 and key[0] > 0
    assert np.linalg.norm(T._matrix(key)) == pytest.approx(1.0, abs=1e-15)
    k2, s2 = T.canonical(-3.0 * q)
    assert s2 == -1 and np.abs(k2 - key).max() < 1e-15
    table = T.QuadricTable([q, plane((1, 0, 0), 0.5)])
    assert table.id_of(-7.0 * q) == (0, -1)
    assert table.id_of(plane((-1, 0, 0), -0.5)) == (1, -1)  # the same plane, facing the other way
    assert table.id_of(q * (1 + 1e-12)) == (0, 1)
    assert table.match([2 * q, plane((0, 1, 0), 0.5), -plane((1, 0, 0), 0.5)]).tolist() == [0, -1, 1]
    # a plane rotated by 90 degrees: the 6e-17 x coefficient does not decide the sign
    rot = clcsg.box(1).rotate((0, 0, 1), 90)
    y_top = T.instances(rot)[0].quadrics[0]  # x <= 0.5 mapped to y <= 0.5
    assert T.quadric_table(rot).id_of(y_top)[0] == T.quadric_table(rot).id_of(plane((0, 1, 0), 0.5))[0]


# -- two boxes touching face to face -------------------------------------------------------------


def test_touching_boxes_have_no_shared_face():
    rng = np.random.default_rng(1)
    shape = clcsg.box(1) | clcsg.box(1, center=(1, 0, 0))
    table = T.quadric_table(shape)
    assert len(table) == 7  # 12 planes: x = 0.5 and the y, z side planes are shared
    ia, sa = table.id_of(plane((1, 0, 0), 0.5))
    ib, sb = table.id_of(T.instances(shape)[1].quadrics[1])  # -x <= -0.5 of the second box
    assert ia == ib and sa == -sb
    shared = face_points(rng, 200, 0, 0.5)
    assert not T.on_surface(shape, shared, plane((1, 0, 0), 0.5)).any()
    neg, pos = T.membership_sides(shape, shared, plane((1, 0, 0), 0.5))
    assert neg.all() and pos.all()
    assert T.contains(shape, shared).all()
    for axis, value, n in ((0, -0.5, (-1, 0, 0)), (0, 1.5, (1, 0, 0))):
        p = face_points(rng, 200, axis, value)
        assert T.on_surface(shape, p, plane(n, value * n[0])).all()
    side = face_points(rng, 200, 1, 0.5, -0.45, 1.45)
    side[:, 2] = rng.uniform(-0.45, 0.45, 200)
    assert T.on_surface(shape, side, plane((0, 1, 0), 0.5)).all()
    assert T.primitive_at(shape, side, plane((0, 1, 0), 0.5)).tolist() == (side[:, 0] > 0.5).astype(int).tolist()
    sp = T.surface_points(shape, [[-0.5, -0.5, -0.5], [1.5, 0.5, 0.5]], n_lines=5000)
    assert len(sp) > 5000 and not (sp.quadrics == ia).any()
    # every point is on the boundary of the 2 x 1 x 1 union and its normal is the face's axis
    c = sp.points - [0.5, 0, 0]
    half = np.array([1.0, 0.5, 0.5])
    gap = np.abs(np.abs(c) - half).min(axis=1)
    assert gap.max() < 1e-12 and (np.abs(c) <= half + 1e-12).all()
    assert np.allclose(np.abs(sp.normals).max(axis=1), 1.0, atol=1e-12)
    axis = np.abs(sp.normals).argmax(axis=1)
    assert np.allclose(sp.normals[np.arange(len(sp)), axis], np.sign(c[np.arange(len(sp)), axis]))


def test_flush_tops_are_one_surface():
    rng = np.random.default_rng(2)
    a = clcsg.box((2, 1, 1))
    b = clcsg.box((2, 1, 1)).translate((1.5, 0, 0))
    shape = a | b
    top = plane((0, 0, 1), 0.5)
    ids = [T.quadric_table(shape).id_of(i.quadrics[4]) for i in T.instances(shape)]
    assert ids[0] == ids[1]
    x = np.concatenate([rng.uniform(-0.99, 0.99, 300), rng.uniform(1.01, 2.49, 300)])
    p = np.column_stack([x, rng.uniform(-0.49, 0.49, 600), np.full(600, 0.5)])
    assert T.on_surface(shape, p, top).all()
    assert T.primitive_at(shape, p, top).tolist() == [0] * 300 + [1] * 300
    # the overlap's inner walls are not surface: a's x = 1 inside b, b's x = 0.5 inside a
    for wall in (1.0, 0.5):
        q = face_points(rng, 100, 0, wall)
        assert not T.on_surface(shape, q, plane((1, 0, 0), wall)).any()
        assert T.primitive_at(shape, q, plane((1, 0, 0), wall)).tolist() == [0 if wall == 1.0 else 1] * 100
    # rays from above hit the top at depth 1.5 everywhere, with the first box where both overlap
    hits = T.cast(shape, p + [0, 0, 1.5], [0, 0, -1])
    assert np.abs(hits.depth - 1.5).max() < 1e-12 and (hits.primitive == (x > 1)).all()
    assert (hits.quadric == ids[0][0]).all() and np.allclose(hits.normal, [0, 0, 1])


# -- sphere minus cylinder -----------------------------------------------------------------------


def test_sphere_minus_cylinder_bore():
    rng = np.random.default_rng(3)
    shape = clcsg.sphere(1) - clcsg.cylinder(4, 0.3)
    bore = Quadric.cylinder((0, 0, 1), 0.3).matrix
    th = rng.uniform(0, 2 * np.pi, 400)
    z = np.concatenate([rng.uniform(-0.9, 0.9, 200), rng.choice([-1, 1], 200) * rng.uniform(0.97, 1.9, 200)])
    p = np.column_stack([0.3 * np.cos(th), 0.3 * np.sin(th), z])
    assert T.on_surface(shape, p, bore).tolist() == [True] * 200 + [False] * 200
    assert (T.primitive_at(shape, p[:200], bore) == 1).all()
    sphere = Quadric.sphere((0, 0, 0), 1).matrix
    assert T.on_surface(shape, [[1, 0, 0], [0, 0, 1], [0, 0, -1]], sphere).tolist() == [True, False, False]
    # eye on the axis (outside the solid): sideways rays hit the bore at 0.3, the axial ray misses
    d = np.array([[1, 0, 0], [0, -1, 0], [0.6, 0.8, 0], [0, 0, 1]])
    hits = T.cast(shape, [0, 0, 0.2], d)
    assert np.abs(hits.depth[:3] - 0.3).max() < 1e-12 and np.isinf(hits.depth[3])
    assert np.allclose(hits.normal[:3], -d[:3], atol=1e-12) and hits.primitive[:3].tolist() == [1, 1, 1]
    sp = T.surface_points(shape, [[-1, -1, -1], [1, 1, 1]], n_lines=4000)
    r, rxy = np.linalg.norm(sp.points, axis=1), np.linalg.norm(sp.points[:, :2], axis=1)
    on_sphere = np.abs(r - 1) < 1e-12
    on_bore = np.abs(rxy - 0.3) < 1e-12
    assert (on_sphere | on_bore).all() and on_bore.sum() > 200 and on_sphere.sum() > 2000
    assert (rxy[on_sphere] >= 0.3 - 1e-12).all() and (r[on_bore] <= 1 + 1e-12).all()
    on_q, on_csg = T.sample_residuals(shape, p, np.broadcast_to(bore, (400, 4, 4)))
    assert on_q.max() < 1e-15 and on_csg.tolist() == [True] * 200 + [False] * 200
    on_q, _ = T.sample_residuals(shape, p * [1.01, 1.01, 1], np.broadcast_to(bore, (400, 4, 4)))
    assert np.allclose(on_q, 0.003, rtol=1e-2)


# -- a cavity seen from inside -------------------------------------------------------------------


def test_cast_from_inside_hollow_box():
    rng = np.random.default_rng(4)
    shape = clcsg.box(4) - clcsg.box(2)
    d = rng_dirs(rng, 500)
    hits = T.cast(shape, [0, 0, 0], d)
    ax = np.abs(d).argmax(axis=1)
    assert np.abs(hits.depth * np.abs(d).max(axis=1) - 1.0).max() < 1e-12
    expected = np.zeros_like(d)
    expected[np.arange(500), ax] = -np.sign(d[np.arange(500), ax])
    assert np.allclose(hits.normal, expected) and (hits.primitive == 1).all()
    assert not T.fragile(shape, [0, 0, 0], d).any()
    # eye inside the wall: the outer face one way, the inner face the other, both at 0.5
    hits = T.cast(shape, [1.5, 0, 0], [[1, 0, 0], [-1, 0, 0]])
    assert np.abs(hits.depth - 0.5).max() < 1e-15
    assert np.allclose(hits.normal, [[1, 0, 0], [-1, 0, 0]]) and hits.primitive.tolist() == [0, 1]
    # closed operands, literal Booleans: the subtracted box's closed face is removed
    probe = [[0, 0, 0], [1.5, 0, 0], [1, 0, 0], [2, 0, 0]]
    assert T.contains(shape, probe).tolist() == [False, True, False, True]
    sp = T.surface_points(shape, [[-2, -2, -2], [2, 2, 2]], n_lines=6000)
    m = np.abs(sp.points).max(axis=1)
    inner, outer = np.abs(m - 1) < 1e-12, np.abs(m - 2) < 1e-12
    # each line through a point of the box crosses its boundary twice; lines through random
    # points are chord-length weighted, so the inner box gets more than its area ratio 1/4
    assert (inner | outer).all() and outer.sum() == 2 * 6000 and inner.sum() % 2 == 0
    assert 0.3 < inner.sum() / outer.sum() < 0.55
    assert (np.einsum("ij,ij->i", sp.normals, sp.points)[inner] < 0).all()


def test_grazing_and_shared_face_rays_are_fragile():
    shape = clcsg.box(1) | clcsg.box(1, center=(1, 0, 0))
    o = [[-3, 0, 0], [-3, 0.5 + 1e-13, 0], [0.5, 0, -3], [-3, 0.2, 0.1]]
    d = [[1, 0, 0], [1, 0, 0], [0, 0, 1], [1, 0, 0]]
    hits = T.cast(shape, o, d)
    assert hits.mask.tolist() == [True, False, True, True]
    assert T.fragile(shape, o, d).tolist() == [False, True, True, False]


# -- a 1,000-deep chain of differences -----------------------------------------------------------


def test_deep_difference_chain():
    g = np.arange(10) * 8.0 - 36.0
    centers = np.stack(np.meshgrid(g, g, g, indexing="ij"), -1).reshape(-1, 3)
    shape = clcsg.box(100)
    for c in centers:
        shape = shape - clcsg.sphere(0.4, center=c)
    assert isinstance(shape, Difference) and len(shape.operands) == 2
    assert len(T.instances(shape)) == 1001 and len(T.quadric_table(shape)) == 1006
    assert T.contains(shape, centers).sum() == 0
    assert T.contains(shape, centers + 2.0).all()
    assert not T.contains(shape, [[0, 0, 50.5]]).any()
    rng = np.random.default_rng(5)
    u = rng_dirs(rng, 1000)
    spheres = np.array([Quadric.sphere(c, 0.4).matrix for c in centers])
    assert T.on_surface(shape, centers + 0.4 * u, spheres).all()
    top = np.column_stack([rng.uniform(-49, 49, 200), rng.uniform(51, 60, 200), np.full(200, 50.0)])
    assert T.on_surface(shape, top[:, [0, 0, 2]], plane((0, 0, 1), 50)).all()
    assert not T.on_surface(shape, top, plane((0, 0, 1), 50)).any()
    assert (T.primitive_at(shape, centers + 0.4 * u, spheres) == np.arange(1, 1001)).all()
    pick = rng.choice(1000, 50, replace=False)
    hits = T.cast(shape, centers[pick], u[pick])
    assert np.abs(hits.depth - 0.4).max() < 1e-12 and (hits.primitive == pick + 1).all()
    assert np.allclose(hits.normal, -u[pick])
    hits = T.cast(shape, [[0.5, 0.5, -60], [4, 4, 60]], [[0, 0, 1], [0, 0, -1]])
    assert np.abs(hits.depth - 10).max() < 1e-12 and hits.primitive.tolist() == [0, 0]


# -- DAGs ----------------------------------------------------------------------------------------


def _expanded(node):
    """The DAG as a tree (fresh operation nodes, the same leaves); test-only recursion."""
    if isinstance(node, Union):
        return Union([_expanded(c) for c in node.operands])
    if isinstance(node, Transformed):
        return Transformed(_expanded(node.operand), node.matrix)
    return node


def test_dag_equals_expanded_tree():
    leaf = clcsg.box(1)
    for step in ((1.0, 0, 0), None):
        dag = leaf
        for i in range(6):
            off = step if step else (2.0**i * 1.25, 0, 0)
            dag = Union([dag, dag.translate(off)])
        tree = _expanded(dag)
        a, b = T.instances(dag), T.instances(tree)
        assert len(a) == (7 if step else 64) and len(b) == len(a)
        assert all(x.node is y.node and np.array_equal(x.matrix, y.matrix) for x, y in zip(a, b))
        assert [x.matrix[0, 3] for x in a] == [y.matrix[0, 3] for y in b]
        p = np.random.default_rng(6).uniform([-1, -1, -1], [80, 1, 1], (3000, 3))
        assert np.array_equal(T.contains(dag, p), T.contains(tree, p))
    # 40 levels: 2^40 leaves expanded, 41 distinct instances
    dag = leaf
    for i in range(40):
        dag = Union([dag, dag.translate((1.0, 0, 0))])
    assert [i.matrix[0, 3] for i in T.instances(dag)] == [float(k) for k in range(41)]
    x = np.arange(-4, 170) * 0.25
    inside = T.contains(dag, np.column_stack([x, np.zeros_like(x), np.zeros_like(x)]))
    assert np.array_equal(inside, (x >= -0.5) & (x <= 40.5))


# -- surface coverage ----------------------------------------------------------------------------


def test_unit_sphere_points_cover_it():
    sp = T.surface_points(clcsg.sphere(1), [[-1, -1, -1], [1, 1, 1]], n_lines=20000)
    assert len(sp) > 20000
    assert np.abs(np.linalg.norm(sp.points, axis=1) - 1).max() < 1e-14
    assert (sp.signs == 1).all() and np.abs(sp.normals - sp.points).max() < 1e-14 and (sp.primitives == 0).all()
    probes = rng_dirs(np.random.default_rng(7), 2000)
    best = np.concatenate([(probes[k : k + 200] @ sp.points.T).max(axis=1) for k in range(0, 2000, 200)])
    assert np.arccos(np.minimum(best, 1)).max() < 0.05  # mean spacing ~ sqrt(4 pi / n) ~ 0.018


def test_rays_agree_with_marching():
    """No membership change before the hit (marched at 4,000 steps) and one across it."""
    rng = np.random.default_rng(8)
    parts = [clcsg.box(rng.uniform(0.5, 2, 3), center=rng.uniform(-1.5, 1.5, 3)) for _ in range(6)]
    parts += [clcsg.sphere(rng.uniform(0.3, 1), center=rng.uniform(-1.5, 1.5, 3)) for _ in range(6)]
    parts += [clcsg.cylinder(2, 0.4, axis=rng.normal(size=3)).translate(rng.uniform(-1.5, 1.5, 3)) for _ in "abcd"]
    shape = parts[0]
    for i, p in enumerate(parts[1:]):
        shape = [shape | p, shape - p, shape | p, shape & ~p][i % 4]
    o = rng.uniform(-2.5, 2.5, (400, 3))
    d = rng_dirs(rng, 400)
    hits = T.cast(shape, o, d)
    ok = hits.mask & ~T.fragile(shape, o, d)
    assert ok.sum() > 100 and T.contains(shape, o).any()
    t = hits.depth[ok, None] * np.linspace(0, 1 - 1e-6, 4000)
    inside = T.contains(shape, o[ok, None] + t[..., None] * d[ok, None])
    assert (inside == inside[:, :1]).all()
    after = T.contains(shape, hits.point[ok] + 1e-7 * d[ok])
    assert (after != inside[:, 0]).all()
    assert (np.einsum("ij,ij->i", hits.normal[ok], d[ok]) * np.where(inside[:, 0], 1, -1) > 0).all()
