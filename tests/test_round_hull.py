"""Hulls of balls of any radii and of parallel cylinders and cones, and Minkowski sums with
cylinders and cones, against an independent float64 oracle built from the operands alone:

* inside: the point is in the Qhull polytope of dense points on the operands' surfaces
  (the sphere, or the two cap circles of a cylinder or cone; for a sum, the pairwise sums of
  the dense point sets), which lies inside the true hull or sum;
* outside: some direction n of 20,000 has n . x above the support value h(n), computed from
  the operands' support functions (n . c + r |n| for a ball, max over its caps of
  n . p + r |n - (n . w) w| for a cylinder or cone, the max over vertices for a polytope;
  the support of a sum is the sum of the supports).

Points in neither set lie within the dense sets' spacing of the surface; they are few (the
test asserts it) and left out.  The construction's membership (the tree oracle's
``contains``) must agree on every other point."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial import ConvexHull

import clcsg
from clcsg.errors import SceneError
from clcsg.model.construction import Construction
from clcsg.model.csg import Primitive, rotation_matrix, walk
from clcsg.model.profile_ops import hull2d_of

import tree_oracle as T

DIRS = np.random.default_rng(0).normal(size=(20000, 3))
DIRS /= np.linalg.norm(DIRS, axis=1, keepdims=True)


def fibonacci(n):
    i = np.arange(n) + 0.5
    phi = np.arccos(1 - 2 * i / n)
    theta = np.pi * (1 + 5 ** 0.5) * i
    return np.c_[np.cos(theta) * np.sin(phi), np.sin(theta) * np.sin(phi), np.cos(phi)]


def circle_points(center, radius, axis, n=720):
    w = np.asarray(axis, float) / np.linalg.norm(axis)
    u = np.cross(w, [1.0, 0, 0] if abs(w[0]) < 0.9 else [0, 1.0, 0])
    u /= np.linalg.norm(u)
    v = np.cross(w, u)
    t = np.linspace(0, 2 * np.pi, n, endpoint=False)
    return center + radius * (np.cos(t)[:, None] * u + np.sin(t)[:, None] * v)


class Frustum:
    """A cylinder or cone between cap centers p0 (radius r0) and p1 (radius r1)."""

    def __init__(self, p0, r0, p1, r1, w=None):
        self.p0, self.p1, self.r0, self.r1 = np.asarray(p0, float), np.asarray(p1, float), r0, r1
        self.w = (self.p1 - self.p0) / np.linalg.norm(self.p1 - self.p0) if w is None else np.asarray(w, float)

    def shape(self):
        h = float(np.linalg.norm(self.p1 - self.p0))
        c = (self.p0 + self.p1) / 2
        if self.r0 == self.r1:
            return clcsg.cylinder(h, self.r0, center=c, axis=self.w)
        return clcsg.cone(h, self.r0, self.r1, center=c, axis=self.w)

    def points(self):
        return np.vstack([circle_points(p, r, self.w) if r > 0 else p[None] for p, r in ((self.p0, self.r0), (self.p1, self.r1))])

    def support(self, n):
        perp = np.linalg.norm(n - np.outer(n @ self.w, self.w), axis=1)
        return np.maximum(n @ self.p0 + self.r0 * perp, n @ self.p1 + self.r1 * perp)


class Ball:
    def __init__(self, c, r):
        self.c, self.r = np.asarray(c, float), float(r)

    def shape(self):
        return clcsg.sphere(self.r, self.c)

    def points(self):
        return self.c + self.r * fibonacci(3000)

    def support(self, n):
        return n @ self.c + self.r


def box_points(lo, hi):
    return np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])], float)


def oracle(dense, support, pts, scale):
    """(inside, outside) certificates for ``pts``."""
    hull = ConvexHull(dense)
    inside = (pts @ hull.equations[:, :3].T + hull.equations[:, 3]).max(axis=1) < -1e-9 * scale
    outside = (pts @ DIRS.T - support(DIRS)).max(axis=1) > 1e-9 * scale
    return inside, outside


def agree(solid, dense, support, rng, n=6000):
    lo, hi = dense.min(axis=0), dense.max(axis=0)
    size = float(np.linalg.norm(hi - lo))
    pts = rng.uniform(lo - 0.1 * size, hi + 0.1 * size, (n, 3))
    inside, outside = oracle(dense, support, pts, size)
    assert not np.any(inside & outside)
    assert (~inside & ~outside).mean() < 0.03, "the oracle's band is too wide"
    assert inside.sum() > 100 and outside.sum() > 300
    got = T.contains(solid, pts)
    bad_in, bad_out = inside & ~got, outside & got
    assert not bad_in.any(), f"{bad_in.sum()} points inside the hull are outside the construction, e.g. {pts[bad_in][:3].tolist()}"
    assert not bad_out.any(), f"{bad_out.sum()} points outside the hull are inside the construction, e.g. {pts[bad_out][:3].tolist()}"


def hull_check(ops, rng):
    solid = clcsg.hull(*[o.shape() for o in ops])
    assert isinstance(solid, Construction)
    agree(solid, np.vstack([o.points() for o in ops]), lambda n: np.max([o.support(n) for o in ops], axis=0), rng)
    return solid


@pytest.mark.parametrize("seed", range(6))
def test_hull_of_balls_of_different_radii(seed):
    rng = np.random.default_rng(seed)
    n = 3 + seed
    ops = [Ball(rng.uniform(-3, 3, 3), rng.uniform(0.2, 1.5)) for _ in range(n)]
    hull_check(ops, rng)


def test_hull_of_balls_and_a_cube():
    rng = np.random.default_rng(7)
    ops = [Ball((4, 0, 0), 1.0), Ball((0, 3, 1), 0.5)]
    solid = clcsg.hull(clcsg.box(2), *[o.shape() for o in ops])
    cube = box_points((-1, -1, -1), (1, 1, 1))
    dense = np.vstack([cube] + [o.points() for o in ops])
    agree(solid, dense, lambda n: np.max([(n @ cube.T).max(axis=1)] + [o.support(n) for o in ops], axis=0), rng)


def test_hull_of_four_balls_has_only_its_own_surfaces():
    """Four balls at a regular tetrahedron's corners, radii 1 to 1.3, edge 10: the hull has 4
    faces, 6 tangent cones and the 4 sphere patches.  The construction is one polytope, 6
    frustums and 4 balls; its planes are the 4 faces, the 2 x 6 tangent-circle planes of the
    frustums and the 6 + 4 facets that close the polytope inside (one per edge, one per ball)."""
    c = 10 * np.array([[0, 0, 0], [1, 0, 0], [0.5, 3 ** 0.5 / 2, 0], [0.5, 3 ** 0.5 / 6, (2 / 3) ** 0.5]])
    r = [1.0, 1.1, 1.2, 1.3]
    solid = hull_check([Ball(c[i], r[i]) for i in range(4)], np.random.default_rng(1))
    assert solid.describe() == "hull of 4 spheres: 26 planes, 6 cones, 4 spheres"
    body = solid.operands[0].operands[0]
    assert len(body.operands) == 1 + 6 + 4


def test_hull_of_many_balls_is_smaller_than_a_star():
    """Every primitive of the hull of 8 balls is a face, a cone, a ball, a frustum cap or a
    facet of the one inner polytope: at most faces + 3 edges + balls + facets primitives."""
    rng = np.random.default_rng(3)
    ops = [Ball(rng.uniform(-3, 3, 3), rng.uniform(0.3, 1.2)) for _ in range(8)]
    solid = hull_check(ops, rng)
    prims = [p for p in walk(solid) if isinstance(p, Primitive)]
    kinds = {p.kind for p in prims}
    assert kinds <= {"halfspace", "double_cone", "infinite_cylinder", "sphere", "box"}
    assert sum(p.kind == "sphere" for p in prims) <= 8


@pytest.mark.parametrize("axis", [(0, 0, 1), (1, 2, 3)])
def test_hull_of_parallel_cylinders_and_cones(axis):
    rng = np.random.default_rng(4)
    w = np.asarray(axis, float) / np.linalg.norm(axis)
    ops = [Frustum((0, 0, 0), 2.0, 1.0 * w, 2.0),                        # cylinder
           Frustum(3.0 * w, 1.0, 4.0 * w, 1.0),                          # coaxial, smaller
           Frustum(np.array([4.0, 1, 0]) + w, 0.5, np.array([4.0, 1, 0]) + 2.5 * w, 1.5),  # a cone, off axis
           Frustum(np.array([-1.0, 3, 1]), 0.0, np.array([-1.0, 3, 1]) + 2 * w, 1.0)]     # a cone to its apex
    hull_check(ops, rng)
    hull_check(ops[:2], rng)


def test_hull_of_coaxial_cylinders_is_a_cylinder_and_a_cone():
    """hull(cylinder r 2 on 0..1, cylinder r 1 on 3..4): the profile (2, 0) (2, 1) (1, 4): the
    corner (1, 3) is inside, so one cylinder and one cone (and their cap planes)."""
    solid = clcsg.hull(clcsg.cylinder(1, 2, center=(0, 0, 0.5)), clcsg.cylinder(1, 1, center=(0, 0, 3.5)))
    assert solid.describe() == "hull of 2 cylinders: 3 planes, 1 cylinder, 1 cone"
    ref = clcsg.cylinder(1, 2, center=(0, 0, 0.5)) | clcsg.cone(3, 2, 1, center=(0, 0, 2.5))
    pts = np.random.default_rng(2).uniform(-3, 5, (20000, 3))
    np.testing.assert_array_equal(T.contains(solid, pts), T.contains(ref, pts))


def test_hull_of_a_cube_and_cylinders():
    rng = np.random.default_rng(5)
    ops = [Frustum((4, 1, 0), 1.0, (4, 1, 1), 1.0), Frustum((1, 5, -1), 0.5, (1, 5, 2), 0.5)]
    solid = clcsg.hull(clcsg.box((2, 2, 1), center=(1, 1, 0.5)), *[o.shape() for o in ops])
    cube = box_points((0, 0, 0), (2, 2, 1))
    agree(solid, np.vstack([cube] + [o.points() for o in ops]),
          lambda n: np.max([(n @ cube.T).max(axis=1)] + [o.support(n) for o in ops], axis=0), rng)


def _sum_check(poly_pts, solid_of_poly, frustum, rng):
    solid = clcsg.minkowski(solid_of_poly, frustum.shape())
    dense = (poly_pts[:, None, :] + frustum.points()[None]).reshape(-1, 3)
    agree(solid, dense, lambda n: (n @ poly_pts.T).max(axis=1) + frustum.support(n), rng)
    return solid


@pytest.mark.parametrize("axis", [(1, 0, 0), (0, 1, 1), (0.3, -0.5, 1)])
def test_minkowski_of_a_turned_cube_and_a_cylinder(axis):
    rng = np.random.default_rng(6)
    turn = rotation_matrix((1, 1, 0), 30.0)
    pts = box_points((0, 0, 0), (4, 3, 2)) @ turn.T
    cube = clcsg.box((4, 3, 2), center=(2, 1.5, 1)).rotate((1, 1, 0), 30.0)
    w = np.asarray(axis, float) / np.linalg.norm(axis)
    _sum_check(pts, cube, Frustum(-0.5 * w, 0.5, 0.5 * w, 0.5), rng)


def test_minkowski_of_a_polytope_and_a_cone():
    rng = np.random.default_rng(8)
    pts = np.array([[0, 0, 0], [3, 0, 0], [0, 2, 0], [0.5, 0.5, 2.0]])
    tet = clcsg.hull(*[clcsg.box(1e-9, center=p) for p in pts])  # corners of tiny cubes: the tetrahedron
    pts = np.array([q for p in pts for q in box_points(p - 5e-10, p + 5e-10)])
    _sum_check(pts, tet, Frustum((0, 0, 0), 1.0, (0.2, 0.3, 1.0), 0.0), rng)


def test_minkowski_of_a_prism_and_a_cylinder_along_its_axis_is_an_extrusion():
    m = clcsg.minkowski(clcsg.box((4, 3, 2), center=(2, 1.5, 1)), clcsg.cylinder(1, 0.5, axis=(1, 0, 0)))
    assert m.describe() == "minkowski of 1 cube and 1 cylinder: 14 planes, 4 cylinders"
    ref = clcsg.union(clcsg.box((5, 4, 2), center=(2, 1.5, 1)), clcsg.box((5, 3, 3), center=(2, 1.5, 1)),
                      *[clcsg.cylinder(5, 0.5, center=(2, y, z), axis=(1, 0, 0)) for y in (0, 3) for z in (0, 2)])
    pts = np.random.default_rng(9).uniform(-1, 5, (20000, 3))
    np.testing.assert_array_equal(T.contains(m, pts), T.contains(ref, pts))


@pytest.mark.parametrize("shapes, message", [
    (lambda: (clcsg.sphere(1), clcsg.cylinder(1, 1, center=(3, 0, 0))), "hull() of 1 sphere and 1 cylinder is not covered exactly"),
    (lambda: (clcsg.cylinder(1, 1), clcsg.cylinder(1, 1, axis=(1, 0, 0))), "cylinders and cones whose axes are not parallel"),
])
def test_hull_refusals(shapes, message):
    with pytest.raises(SceneError, match=message.replace("(", r"\(").replace(")", r"\)")):
        clcsg.hull(*shapes())


def test_minkowski_of_skew_cylinders_is_refused():
    with pytest.raises(SceneError, match="cylinders and cones whose axes are not parallel"):
        clcsg.minkowski(clcsg.box(1), clcsg.cylinder(1, 1), clcsg.cylinder(1, 1, axis=(1, 0, 0)))


def test_minkowski_of_a_hull_of_balls_and_a_sphere():
    """A hull() operand is one convex item: hull(B_i) + B(s) = hull(B(c_i, r_i + s))."""
    rng = np.random.default_rng(12)
    balls = [Ball((0, 0, 0), 1.0), Ball((3, 0, 0), 0.5), Ball((1, 2, 1), 0.3)]
    solid = clcsg.minkowski(clcsg.hull(*[b.shape() for b in balls]), clcsg.sphere(0.2))
    grown = [Ball(b.c, b.r + 0.2) for b in balls]
    agree(solid, np.vstack([b.points() for b in grown]), lambda n: np.max([b.support(n) for b in grown], axis=0), rng)


def test_minkowski_of_a_cube_and_a_hull_of_cylinders():
    rng = np.random.default_rng(13)
    slot = [Frustum((0, 0, -0.5), 0.4, (0, 0, 0.5), 0.4), Frustum((1.5, 0, -0.5), 0.2, (1.5, 0, 0.5), 0.2)]
    solid = clcsg.minkowski(clcsg.box(1), clcsg.hull(*[f.shape() for f in slot]))
    cube = box_points((-0.5, -0.5, -0.5), (0.5, 0.5, 0.5))
    dense = (cube[:, None, :] + np.vstack([f.points() for f in slot])[None]).reshape(-1, 3)
    agree(solid, dense, lambda n: (n @ cube.T).max(axis=1) + np.max([f.support(n) for f in slot], axis=0), rng)


def test_hull_of_a_hull_is_the_hull_of_all_parts():
    balls = [Ball((0, 0, 0), 1.0), Ball((3, 0, 0), 0.5), Ball((1, 2, 1), 0.3)]
    inner = clcsg.hull(*[b.shape() for b in balls[:2]])
    solid = clcsg.hull(inner, balls[2].shape())
    flat = clcsg.hull(*[b.shape() for b in balls])
    pts = np.random.default_rng(14).uniform(-2, 4, (20000, 3))
    np.testing.assert_array_equal(T.contains(solid, pts), T.contains(flat, pts))


@pytest.mark.parametrize("axis", [(0, 0, 1), (2, -1, 1)])
def test_hull_of_spheres_and_cylinders_on_one_axis(axis):
    """Spheres centered on the cylinders' and cones' common axis: a solid of revolution."""
    rng = np.random.default_rng(15)
    w = np.asarray(axis, float) / np.linalg.norm(axis)
    o = np.array([0.5, -0.2, 0.1])
    ops = [Frustum(o, 2.0, o + w, 2.0), Ball(o + 3 * w, 1.5), Frustum(o + 4 * w, 0.5, o + 5 * w, 0.0), Ball(o - 1.5 * w, 0.7)]
    solid = hull_check(ops, rng)
    assert {p.kind for p in walk(solid) if isinstance(p, Primitive)} == {"cylinder", "cone", "sphere", "box"}  # box: the bound


def test_bullet_is_a_cylinder_and_a_sphere():
    """hull(cylinder r 1 on 0..3, sphere r 1 at the top cap's center) is their union."""
    solid = clcsg.hull(clcsg.cylinder(3, 1, center=(0, 0, 1.5)), clcsg.sphere(1, (0, 0, 3)))
    ref = clcsg.cylinder(3, 1, center=(0, 0, 1.5)) | clcsg.sphere(1, (0, 0, 3))
    pts = np.random.default_rng(16).uniform(-2, 5, (20000, 3))
    np.testing.assert_array_equal(T.contains(solid, pts), T.contains(ref, pts))


@pytest.mark.parametrize("seed", range(12))
def test_hulls_on_a_grid(seed):
    """Integer centers and radii 0.5 or 1: four or more items on one face, equal and unequal
    radii mixed, cubes among balls or among parallel cylinders and cones."""
    rng = np.random.default_rng(100 + seed)
    w = np.array([0, 0, 1.0]) if seed % 4 < 2 else np.array([1.0, 1, 0]) / 2 ** 0.5
    ops, cubes = [], []
    for _ in range(int(rng.integers(2, 6))):
        c = rng.integers(-2, 3, 3).astype(float)
        r = float(rng.choice([0.5, 1.0]))
        if rng.random() < 0.25:
            cubes.append(box_points(c - 0.5, c + 0.5))
        elif seed % 2 == 0:
            ops.append(Ball(c, r))
        else:
            ops.append(Frustum(c, r, c + float(rng.choice([1, 2])) * w, float(rng.choice([0, 0.5, r]))))
    if not ops:
        ops.append(Ball((0, 0, 0), 1.0))
    corners = np.vstack(cubes) if cubes else np.zeros((0, 3))
    solid = clcsg.hull(*[o.shape() for o in ops], *[clcsg.box(1, center=q.mean(axis=0)) for q in cubes])
    agree(solid, np.vstack([o.points() for o in ops] + [corners]),
          lambda n: np.max([o.support(n) for o in ops] + ([(n @ corners.T).max(axis=1)] if cubes else []), axis=0), rng)


def test_hull_of_an_extruded_circle_and_a_cylinder():
    """linear_extrude(2, scale = 0.5) of a circle off the origin is an oblique cone (caps
    perpendicular to z, the top center scaled too): one item of hull()."""
    rng = np.random.default_rng(17)
    cone = Frustum((1, 0, 0), 1.0, (0.5, 0, 2), 0.5, w=(0, 0, 1))
    cyl = Frustum((5, 0, 0), 0.5, (5, 0, 2), 0.5)
    solid = clcsg.hull(clcsg.extrude(clcsg.circle(1).translate((1, 0)), 2, scale=0.5), cyl.shape())
    agree(solid, np.vstack([cone.points(), cyl.points()]), lambda n: np.maximum(cone.support(n), cyl.support(n)), rng)


def test_constructions_that_are_no_item_are_named():
    with pytest.raises(SceneError, match=r"a minkowski of 1 cube and 1 sphere inside is not covered"):
        clcsg.hull(clcsg.minkowski(clcsg.box(1), clcsg.sphere(0.1)), clcsg.sphere(1, (3, 0, 0)))


def test_extruded_2d_hull_of_a_square_and_circles_is_the_3d_hull():
    """2-D hull() of polygons and circles (vertices as disks of radius 0: tangent lines and
    arcs) extruded, against the oracle of the 3-D hull of the cube and the cylinders."""
    rng = np.random.default_rng(18)
    prof = hull2d_of(clcsg.square((2, 2)), clcsg.circle(1).translate((5, 1)), clcsg.circle(0.5).translate((1, 4)))
    solid = clcsg.extrude(prof, 1)
    ops = [Frustum((5, 1, 0), 1.0, (5, 1, 1), 1.0), Frustum((1, 4, 0), 0.5, (1, 4, 1), 0.5)]
    cube = box_points((0, 0, 0), (2, 2, 1))
    agree(solid, np.vstack([cube] + [o.points() for o in ops]),
          lambda n: np.max([(n @ cube.T).max(axis=1)] + [o.support(n) for o in ops], axis=0), rng)


def _dist_to_polygon(pts, poly):
    """Distance from each point to the filled simple polygon (0 inside): even-odd crossing
    test and the nearest edge, in float64."""
    a, b = poly, np.roll(poly, -1, axis=0)
    x, y = pts[:, :1], pts[:, 1:2]
    cross = ((a[:, 1] > y) != (b[:, 1] > y)) & (x < (b[:, 0] - a[:, 0]) * (y - a[:, 1]) / (b[:, 1] - a[:, 1] + 1e-300) + a[:, 0])
    inside = cross.sum(axis=1) % 2 == 1
    e = b - a
    t = np.clip(((pts[:, None, :] - a) * e).sum(-1) / (e * e).sum(-1), 0, 1)
    d = np.linalg.norm(pts[:, None, :] - (a + t[..., None] * e), axis=-1).min(axis=1)
    return np.where(inside, 0.0, d)


def test_2d_minkowski_of_a_polygon_and_a_circle():
    """P + D(c, r) = {x : dist(x - c, P) <= r}, for a non-convex polygon (an L)."""
    from clcsg.model.profile_ops import minkowski2d

    ell = np.array([[0, 0], [4, 0], [4, 1], [1, 1], [1, 3], [0, 3]], float)
    c, r = np.array([0.5, -0.25]), 0.6
    solid = clcsg.extrude(minkowski2d(clcsg.polygon(ell), clcsg.circle(r).translate(c)), 1.0)
    rng = np.random.default_rng(19)
    pts = np.c_[rng.uniform(-1.5, 6, (20000, 2)), np.full(20000, 0.5)]
    d = _dist_to_polygon(pts[:, :2] - c, ell)
    sure = np.abs(d - r) > 1e-9
    np.testing.assert_array_equal(T.contains(solid, pts)[sure], (d <= r)[sure])
    with pytest.raises(SceneError, match="2-D minkowski.. of two polygons is covered for convex ones only"):
        minkowski2d(clcsg.polygon(ell), clcsg.square(1))
