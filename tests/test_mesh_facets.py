"""The facets method of ``clcsg.mesh`` (:mod:`clcsg.meshing.exact_facets`): faceted primitives,
manifold3d's Booleans, vertices solved onto the exact surface.  The primitives' facets against
their own quadrics (float64), the segment counts against the chord sag (hypothesis), the
visible primitive of every triangle against the float64 oracle's colour rule, and the
method's choice and errors."""

from __future__ import annotations

import math

import manifold3d
import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

import clcsg
import tree_oracle as oracle
from clcsg.model.csg import Primitive
from clcsg.errors import UsageError
from clcsg.meshing.facets import CLOSING, KINDS, SAG_SHARE, circle_segments, instance_facets, sphere_segments, _unit_sphere
from test_mesh import check_closed_manifold, check_vertices_on_surface, point_mesh_distance
from test_raytrace import COLOUR_SCENES


@settings(max_examples=200, deadline=None)
@given(radius=st.floats(1e-3, 1e3), rel=st.floats(1e-5, 0.5))
def test_circle_segments_are_the_fewest_within_the_sag(radius, rel):
    """R (1 - cos(pi / n)) <= SAG_SHARE tol, and n - 1 segments would exceed it."""
    tol = rel * radius
    n = circle_segments(radius, tol)
    sag = lambda k: radius * (1.0 - math.cos(math.pi / k))
    assert sag(n) <= SAG_SHARE * tol * (1 + 1e-12)
    assert n == 3 or sag(n - 1) > SAG_SHARE * tol


@pytest.mark.parametrize("sag", [0.3, 0.05, 0.01, 0.002, 0.0004])
def test_sphere_segments_meet_the_sag(sag):
    """The geodesic unit sphere of the chosen frequency has its triangles' planes within the sag
    of the sphere, one of lower frequency does not; it is a closed outward 2-manifold with its
    vertices on the sphere, and its measured sag is what a scan of each triangle's plane
    distance gives."""
    f = sphere_segments(sag)
    v, t, got = _unit_sphere(f)
    assert got <= sag
    assert f == 1 or _unit_sphere(f - 1)[2] > sag
    assert np.allclose(np.linalg.norm(v, axis=1), 1.0, atol=1e-15)
    mesh = manifold3d.Manifold(manifold3d.Mesh64(np.ascontiguousarray(v), np.ascontiguousarray(t, dtype=np.uint64)))
    assert mesh.status() == manifold3d.Error.NoError and mesh.volume() > 0 and mesh.num_tri() == len(t) == 20 * f * f
    a, b, c = v[t[:, 0]], v[t[:, 1]], v[t[:, 2]]
    dips = [1.0 - abs(np.dot(np.cross(b[k] - a[k], c[k] - a[k]), a[k])) / np.linalg.norm(np.cross(b[k] - a[k], c[k] - a[k]))
            for k in range(len(t))]
    assert max(dips) == pytest.approx(got, rel=1e-12)


def _affine(rng):
    m = np.eye(4)
    m[:3, :3] = rng.normal(size=(3, 3)) + 2 * np.eye(3)
    m[:3, 3] = rng.normal(size=3)
    return m


PRIMITIVES = {
    "box": clcsg.box((1.0, 2.0, 0.5), center=(0.1, 0.2, 0.3)),
    "cylinder": clcsg.cylinder(height=2.0, radius=0.7, axis=(1, 1, 0)),
    "cone": clcsg.cone(height=1.5, r1=0.8, r2=0.2),
    "apex_cone": clcsg.cone(height=1.5, r1=0.0, r2=0.6, axis=(0, 1, 1)),
    "sphere": clcsg.sphere(0.9, center=(0.3, 0, 0)),
    "ellipsoid": clcsg.ellipsoid((1.0, 0.4, 0.7)),
    "halfspace": clcsg.halfspace((0.3, 1.0, 0.2), 0.4),
    "slab": clcsg.slab((1, 0, 1), -0.3, 0.5),
    "infinite_cylinder": Primitive("infinite_cylinder", {"axis": (0, 1, 0), "radius": 0.5}),
    "elliptic_cylinder": Primitive("elliptic_cylinder", {"axis": (1, 0, 1), "radii": (0.6, 0.3)}),
}


@pytest.mark.parametrize("name", sorted(PRIMITIVES))
@pytest.mark.parametrize("seed", [0, 1])
def test_facets_closed_on_their_literals_within_the_sag(name, seed):
    """Each kind's facets under a random affine map: a closed 2-manifold of positive volume;
    every vertex of a triangle tagged with literal k lies on that literal's quadric (float64
    residual), and the triangle's centroid and edge midpoints stay within the tolerance."""
    assert PRIMITIVES[name].kind in KINDS
    shape = PRIMITIVES[name].transform(_affine(np.random.default_rng(seed)))
    tape = clcsg.Scene(shape, bound=((-4, -4, -4), (4, 4, 4))).compile()
    inst = tape.instances[0]
    tol = 0.01
    f = instance_facets(inst, tol, (np.zeros(3), 4.0 * math.sqrt(3)))
    mesh = manifold3d.Manifold(manifold3d.Mesh64(vert_properties=f.vertices, tri_verts=f.triangles.astype(np.uint64)))
    assert mesh.status() == manifold3d.Error.NoError
    assert mesh.volume() > 0
    assert set(np.unique(f.tags)) <= set(range(len(inst.literals))) | {CLOSING}
    for k, (q, _) in enumerate(inst.literals):
        on = f.tags == k
        if not on.any():
            continue
        Q = tape.quadrics[q]
        v = f.vertices[f.triangles[on]]
        pts = np.concatenate([v.reshape(-1, 3), v.mean(axis=1), 0.5 * (v + np.roll(v, 1, axis=1)).reshape(-1, 3)])
        xh = np.c_[pts, np.ones(len(pts))]
        val = np.einsum("ni,ij,nj->n", xh, Q, xh)
        grad = np.linalg.norm(2 * (xh @ Q)[:, :3], axis=1)
        at_vertex = np.abs(val[:v.size // 3])
        assert at_vertex.max() <= 1e-12 * max(1.0, np.abs(Q).max()) * max(1.0, np.abs(pts).max()) ** 2
        dist = np.abs(val[v.size // 3:]) / np.maximum(grad[v.size // 3:], 1e-300)
        assert dist.max() <= tol


@pytest.mark.parametrize("name", sorted(COLOUR_SCENES))
def test_visible_primitive_per_triangle(name):
    """Each triangle names the primitive the colour rule gives its centroid (the oracle's
    ``primitive_at``): flush inlays show the inlay, coincident faces the first that bounds the
    solid, a coloured cutter its own colour, two cubes side by side keep theirs; the colours
    are those primitives'."""
    shape = COLOUR_SCENES[name]
    sc = clcsg.Scene(shape)
    tape = sc.compile()
    m = clcsg.mesh(sc, method="facets")
    check_closed_manifold(m)
    ref = oracle.primitive_at(shape, m.vertices[m.triangles].mean(axis=1), tape.quadrics[m.quadric], tol=m.tolerance)
    assert np.array_equal(m.primitive, ref)
    colors = np.array([inst.color for inst in tape.instances])
    assert np.allclose(m.colors, colors[m.primitive])


def test_unbounded_kinds_clipped_to_the_bound():
    """A half-space, a slab and an infinite cylinder, clipped by the scene's bound: closed,
    every vertex on the surface of the clipped solid, the bound's faces where it is cut."""
    shape = clcsg.intersection(clcsg.halfspace((0, 0, 1), 0.3), clcsg.slab((1, 0, 0), -0.5, 0.5),
                               ~Primitive("infinite_cylinder", {"axis": (0, 1, 0), "radius": 0.3}))
    sc = clcsg.Scene(shape, bound=((-1, -1, -1), (1, 1, 1)))
    m = clcsg.mesh(sc, method="facets")
    check_closed_manifold(m)
    lo, hi = m.vertices.min(axis=0), m.vertices.max(axis=0)
    assert np.allclose(lo, (-0.5, -1, -1)) and np.allclose(hi, (0.5, 1, 0.3))
    exact = 1.0 * 2.0 * 1.3 - math.pi * 0.09 * 2.0
    import trimesh

    vol = trimesh.Trimesh(m.vertices, m.triangles, process=False).volume
    assert abs(vol - exact) <= 30 * m.tolerance
    on_bound = (m.quadric < 0)
    assert on_bound.any()  # the cut faces of the bound
    real = m.vertex_quadrics[:, 0] >= 0
    q = sc.compile().quadrics[m.vertex_quadrics[real, 0]]
    on_q, _ = oracle.sample_residuals(shape, m.vertices[real], q)
    assert on_q.max() <= 1e-12


@pytest.mark.parametrize("tolerance", ["0.1%", "0.03%"])
def test_grazing_cylinders(tolerance):
    """The tricylinder's cylinders touch tangentially at six points, where facets may meet the
    wrong way round (then the instances are faceted again): every triangle within the
    tolerance of its quadric and on it at its vertices (a triangle may cross where two
    cylinders touch tangentially, within the tolerance, as no sharp edge), closed, and exact
    surface points within the tolerance of the mesh."""
    sc = clcsg.load(oracle_path("examples/zoo/steinmetz.json"))
    m = clcsg.mesh(sc, method="facets", tolerance=tolerance)
    assert m.stats["far_triangles"] == 0 and m.stats["spanning_wide_triangles"] == 0
    _check_smooth_spans(sc.compile(), m)
    check_closed_manifold(m)
    check_vertices_on_surface(sc, m)
    sp = oracle.surface_points(sc.shape, sc.compile().bound, n_lines=200, seed=2)
    assert point_mesh_distance(sp.points, m.vertices, m.triangles).max() <= m.tolerance


def _check_smooth_spans(tape, m):
    """Every triangle whose vertices share no quadric with it has each vertex within the
    tolerance of its quadric, and where one is more than SPAN_SLACK tolerances off it, the
    vertex's own quadrics meet the triangle's at less than SHARP_DEGREES there."""
    from clcsg.meshing.exact_facets import SHARP_DEGREES, SPAN_SLACK
    from clcsg.meshing.project import residuals

    span = np.flatnonzero(~(m.vertex_quadrics[m.triangles] == m.quadric[:, None, None]).any(axis=2).all(axis=1))
    for t in span:
        q = tape.quadrics[m.quadric[t]]
        for v in m.triangles[t]:
            f, g = residuals(q[None, None], m.vertices[v][None])
            miss = abs(f[0, 0]) / np.linalg.norm(g[0, 0])
            assert miss <= m.tolerance
            if miss > SPAN_SLACK * m.tolerance:
                for own in m.vertex_quadrics[v][m.vertex_quadrics[v] >= 0]:
                    _, h = residuals(tape.quadrics[own][None, None], m.vertices[v][None])
                    cos = abs(g[0, 0] @ h[0, 0]) / (np.linalg.norm(g[0, 0]) * np.linalg.norm(h[0, 0]))
                    assert cos >= np.cos(np.radians(SHARP_DEGREES))


def oracle_path(rel):
    import os

    return os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), rel)


def test_methods_chosen_and_checked():
    """auto: facets where every kind has a faceting, contour for a hyperboloid; facets asked
    for a hyperboloid is a usage error naming the kind; an unknown method too."""
    box = clcsg.Scene(clcsg.box(1.0) - clcsg.cylinder(2.0, 0.3))
    assert clcsg.mesh(box).stats["method"] == "facets"
    assert clcsg.mesh(box, method="contour").stats["method"] == "contour"
    tower = clcsg.Scene(Primitive("hyperboloid_one_sheet", {"radii": (0.6, 0.6, 0.9)}) & clcsg.box(1.0))
    with pytest.raises(UsageError, match="hyperboloid_one_sheet"):
        clcsg.mesh(tower, method="facets")
    with pytest.raises(UsageError, match="method"):
        clcsg.mesh(box, method="marching")


def test_chamfered_holes_narrower_than_the_tolerance():
    """A plate with an 8 x 8 grid of holes, each chamfered by a cone whose narrow end lies
    0.01 inside its bore (a sliver far under the tolerance): one faceting round; closed; every
    vertex on the CSG surface; the triangles across the sliver within a quarter of the
    tolerance of their quadric; points on the mesh within the tolerance of the CSG surface."""
    from bench import zoo
    from test_mesh import check_near_csg_surface

    shape = zoo.plate(8, size=40.0)
    sc = clcsg.Scene(shape)
    m = clcsg.mesh(sc)
    assert m.stats["method"] == "facets" and m.stats["facet_rounds"] == 1
    check_closed_manifold(m)
    check_vertices_on_surface(sc, m)
    assert m.stats["spanning_wide_triangles"] == 0 and m.stats["far_triangles"] == 0
    check_near_csg_surface(shape, m)


def check_triangles_near_the_solid(shape, m):
    """The centroid and edge midpoints of every triangle lie within the tolerance of the CSG
    surface by the float64 oracle: of the points at that distance round each, some inside and
    some outside (128 directions, then 20,000 round the points those miss)."""
    from clcsg.meshing.snap import fibonacci_directions

    v = m.vertices[m.triangles]
    pts = np.concatenate([v.mean(axis=1), 0.5 * (v + np.roll(v, -1, axis=1)).reshape(-1, 3)])
    for n in (128, 20000):
        if not len(pts):
            break
        probes = pts[:, None] + m.tolerance * fibonacci_directions(n)[None]
        ins = oracle.contains(shape, probes.reshape(-1, 3)).reshape(len(pts), -1)
        pts = pts[~(ins.any(axis=1) & ~ins.all(axis=1))]
    assert not len(pts), f"{len(pts)} points farther than the tolerance from the CSG surface, e.g. {pts[:3]}"


@pytest.mark.parametrize("name", ["drilled_die", "flange", "steinmetz"])
def test_every_triangle_near_the_solid(name):
    """Every triangle near the CSG surface (:func:`check_triangles_near_the_solid`).  On the
    drilled die the oblique holes' rims meet the sphere's at a shallow angle, where the
    corner's solve moves a vertex by several tolerances; its triangles were dragged across the
    rim until they were checked."""
    from bench import zoo

    shape = zoo.model(name).build()
    check_triangles_near_the_solid(shape, clcsg.mesh(clcsg.Scene(shape)))


def test_hole_rims_on_a_slope_split_locally():
    """A plate tilted by 20 degrees with three holes: the rims' chords sag off the tilted face
    and the bore at once, beyond the tolerance.  The far chords are split at points solved
    onto the rim curves (no second faceting round); the mesh is closed, every vertex on the
    CSG surface, and every triangle's centroid and edge midpoints within the tolerance of the
    CSG surface (:func:`check_triangles_near_the_solid`)."""
    plate = clcsg.box((4.0, 4.0, 0.5)).rotate([0, 1, 0], 20)
    holes = clcsg.union(*[clcsg.cylinder(height=6.0, radius=r, center=(x, y, 0.0))
                          for x, y, r in ((-1, -1, 0.3), (1, -1, 0.5), (0, 1, 0.4))])
    shape = clcsg.difference(plate, holes)
    sc = clcsg.Scene(shape)
    m = clcsg.mesh(sc)
    assert m.stats["facet_rounds"] == 1 and m.stats["chord_splits"] > 0
    assert m.stats["far_triangles"] == 0 and m.stats["spanning_wide_triangles"] == 0
    check_closed_manifold(m)
    check_vertices_on_surface(sc, m)
    check_triangles_near_the_solid(shape, m)


@settings(max_examples=100, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), k=st.integers(1, 3))
def test_min_norm_step_is_the_least_squares_step(seed, k):
    """The closed-form Newton step J^T (J J^T)^-1 F equals numpy's minimum-norm least-squares
    solution of J dx = F for well-conditioned random J (k rows of 3)."""
    from clcsg.meshing.project import min_norm_step

    rng = np.random.default_rng(seed)
    j = rng.normal(size=(8, k, 3))
    j = j[np.linalg.svd(j, compute_uv=False).min(axis=1) > 0.1]
    f = rng.normal(size=(len(j), k))
    got = min_norm_step(f, j)
    want = np.stack([np.linalg.lstsq(jj, ff, rcond=None)[0] for jj, ff in zip(j, f)]) if len(j) else got
    assert np.allclose(got, want, rtol=1e-9, atol=1e-9)


def test_newton_stops_points_that_leave_their_reach():
    """Three planes with no common point (two parallel): Newton leaves with 'not converged'
    once the point passes the reach; three planes through a corner converge onto it."""
    from clcsg.meshing.project import newton

    def plane(n, d):
        m = np.zeros((4, 4))
        m[:3, 3] = m[3, :3] = 0.5 * np.asarray(n, dtype=np.float64)
        m[3, 3] = -d
        return m

    corner = np.array([[plane((1, 0, 0), 1.0), plane((0, 1, 0), 2.0), plane((0, 0, 1), 3.0)]])
    x, ok = newton(corner, np.zeros((1, 3)), reach=10.0)
    assert ok[0] and np.allclose(x[0], [1.0, 2.0, 3.0])
    apart = np.array([[plane((1, 0, 0), 1.0), plane((1, 0, 0), 2.0), plane((0, 0, 1), 3.0)]])
    assert not newton(apart, np.zeros((1, 3)), reach=10.0)[1][0]


@pytest.mark.parametrize("name", ["flange", "gear"])
def test_membership_around_points_equals_the_interpreter(name):
    """The membership at c + e d from each leaf's expansion about c equals the tape run at
    those points (random centres in the bound, e = 1% of the diagonal)."""
    from bench import zoo
    from clcsg.compile.interpret import contains, contains_around
    from clcsg.meshing.exact_facets import contains_near
    from clcsg.meshing.snap import fibonacci_directions

    tape = clcsg.Scene(zoo.model(name).build()).compile()
    lo, hi = (np.asarray(b) for b in tape.bound)
    rng = np.random.default_rng(3)
    c = lo + (hi - lo) * rng.random((300, 3))
    eps = 0.01 * float(np.linalg.norm(hi - lo))
    d = fibonacci_directions(16)
    want = contains(tape.ops, tape.quadrics, (c[:, None] + eps * d[None]).reshape(-1, 3)).reshape(len(c), -1)
    assert np.array_equal(contains_around(tape.ops, tape.quadrics, c, eps, d), want)
    assert np.array_equal(contains_near(tape, c, eps, d), want)


def test_circles_shared_by_coaxial_primitives_get_one_segment_count():
    """A bore (r = 1) with a countersink cone standing on it (r 1 -> 2, 45 degrees: its chords'
    points lie the sag times cos 45 from it) and a coaxial pin far below it (r = 0.3): the bore
    and the cone share the circle r = 1 and take the larger count
    (their polygons' vertices coincide there); the pin keeps the fewest its tolerance needs; a
    cylinder on a parallel axis is not grouped.  The plate they cut meshes closed with the cone's
    rim vertices on the bore's."""
    from clcsg.meshing.facets import circle_segments, shared_segments

    bore = clcsg.cylinder(height=2.0, radius=1.0, center=(0, 0, 0))
    cone = clcsg.cone(height=1.0, r1=1.0, r2=2.0, center=(0, 0, 0.5))
    pin = clcsg.cylinder(height=1.0, radius=0.3, center=(0, 0, -5))
    beside = clcsg.cylinder(height=2.0, radius=1.0, center=(3, 0, 0))
    tape = clcsg.Scene(clcsg.union(bore, cone, pin, beside)).compile()
    tol = 0.01
    got = shared_segments(tape.instances, np.full(len(tape.instances), tol), [i.matrix for i in tape.instances])
    by_kind = {(i.node.kind, i.node.params.get("radius"), tuple(i.node.params.get("center", ()))): got[i.index]
               for i in tape.instances}
    want_cone = circle_segments(2.0 / math.sqrt(2.0), tol)  # a 45-degree cone: the sag times cos 45
    assert want_cone > circle_segments(1.0, tol)
    assert by_kind[("cone", None, (0, 0, 0.5))] == want_cone == by_kind[("cylinder", 1.0, (0, 0, 0))]
    assert by_kind[("cylinder", 0.3, (0, 0, -5))] == circle_segments(0.3, tol)
    assert by_kind[("cylinder", 1.0, (3, 0, 0))] == circle_segments(1.0, tol)
    plate = clcsg.box((6.0, 6.0, 1.0), center=(0, 0, 0.5))
    sc = clcsg.Scene(clcsg.difference(plate, clcsg.union(bore, cone)))
    m = clcsg.mesh(sc, tolerance=tol)
    check_closed_manifold(m)
    check_vertices_on_surface(sc, m)
    assert m.stats["far_triangles"] == 0 and m.stats["spanning_triangles"] == 0


def test_a_hidden_side_does_not_raise_its_circles_count():
    """A countersunk hole (bore r = 1, 45-degree cone r 1 -> 2 up to the top face and a little
    above it, a clearance cylinder r = 2 standing on the cone's top ring, all in the air above
    the plate): the clearance cylinder's side bounds nothing, so its count (that of r = 2, more
    than the cone's r = 2 cos 45) does not raise the group, which takes the cone's.  Without
    the visibility test it does.  The plate meshes closed in one round, within the tolerance
    of the CSG surface, with fewer triangles."""
    from functools import partial

    from clcsg.meshing import instance_booleans as ib
    from clcsg.meshing.exact_facets import _on_surface
    from clcsg.meshing.facets import circle_segments
    from test_mesh import check_near_csg_surface

    tol, lift = 0.004, 0.01
    bore = clcsg.cylinder(height=3.0, radius=1.0, center=(0, 0, -0.5))
    cone = clcsg.cone(height=1.0 + lift, r1=1.0, r2=2.0 + lift, center=(0, 0, 0.5 + lift / 2))
    clear = clcsg.cylinder(height=1.0, radius=2.0 + lift, center=(0, 0, 1.0 + lift + 0.5))
    plate = clcsg.box((8.0, 8.0, 1.0), center=(0, 0, 0.5))
    shape = clcsg.difference(plate, clcsg.union(bore, cone, clear))
    sc = clcsg.Scene(shape)
    tape = sc.compile()
    frame = ib.common_frame(sc.shape, tape.instances)
    tols = np.full(len(tape.instances), tol)
    counts = {}
    for test in (None, partial(_on_surface, tape, tol)):
        facets = ib.facets_of(tape, tols, frame, test)
        counts[test is None] = {i.node.kind: len(f.vertices) for i, f in zip(tape.instances, facets) if i.node.kind == "cone"}
    n_cone, n_clear = circle_segments((2.0 + lift) / math.sqrt(2.0), tol), circle_segments(2.0 + lift, tol)
    assert n_cone < n_clear
    assert counts[True]["cone"] == 2 * n_clear and counts[False]["cone"] == 2 * n_cone
    m = clcsg.mesh(sc, tolerance=tol)
    check_closed_manifold(m)
    check_vertices_on_surface(sc, m)
    check_near_csg_surface(shape, m)
    assert m.stats["facet_rounds"] == 1 and m.stats["far_triangles"] == 0


def test_a_rim_chord_within_the_tolerance_of_a_cone_is_accepted():
    """The chord of a cone's rim on a plane (45 degrees) sags s from the rim circle but
    s cos 45 from the cone: with s cos 45 < tol < s the foot test accepts its midpoint (the
    foot on the cone is on the solid's surface), and rejects it with tol < s cos 45; a point
    whose foot on the cone is out of the solid (the cone's extension above the plate) is not
    accepted either."""
    from clcsg.meshing.exact_facets import _foot_on_solid
    from clcsg.meshing.project import line_steps

    cone = clcsg.cone(height=1.0, r1=1.0, r2=2.0, center=(0, 0, -0.5))  # 45 degrees, rim r = 2 at z = 0
    sc = clcsg.Scene(clcsg.difference(clcsg.box((8.0, 8.0, 1.0), center=(0, 0, -0.5)), cone))
    tape = sc.compile()
    side = next(i for i in tape.instances if i.node.kind == "cone").literals[0][0]
    top = int(np.argmin(np.abs(tape.quadrics[:, 2, 3] * 2 - 1) + np.abs(tape.quadrics[:, 3, 3])))
    n = 12
    a, b = 2.0 * np.array([[1.0, 0, 0], [math.cos(2 * math.pi / n), math.sin(2 * math.pi / n), 0]])
    mid = 0.5 * (a + b)[None]
    s = 2.0 - float(np.linalg.norm(mid))
    quads = np.array([[side, top]])
    t, nrm = line_steps(tape.quadrics[quads], mid)
    assert abs(abs(t[0, 0]) - s / math.sqrt(2.0)) < 1e-3 * s and abs(t[0, 1]) < 1e-15  # the gradient line: near the normal
    assert _foot_on_solid(tape, mid, quads, 0.5 * (s + s / math.sqrt(2.0)))[0]
    assert not _foot_on_solid(tape, mid, quads, 0.9 * s / math.sqrt(2.0))[0]
    above = np.array([[1.8, 0.0, 0.5]])  # nearest the cone's extension above the plate, in the air
    assert not _foot_on_solid(tape, above, np.array([[side, side]]), 1.0)[0]


@settings(max_examples=60, deadline=None)
@given(st.floats(0.2, 3.0), st.floats(-2.0, 2.0), st.floats(-2.0, 2.0), st.floats(-2.0, 2.0))
def test_a_line_step_lands_on_its_quadric(r, x, y, z):
    """line_steps: x + t n lies on the quadric (a sphere of radius r, a cylinder and a plane
    through the origin) in double precision, and |t| is line_distance."""
    from clcsg.meshing.project import line_distance, line_steps
    from clcsg.model.quadric import Quadric

    qs = np.stack([q.matrix for q in (Quadric.sphere(radius=r), Quadric.cylinder(axis=(1, 1, 0), radius=r),
                                      Quadric.half_space((1.0, 2.0, 2.0), 0.0))])
    p = np.array([[x, y, z]])
    t, n = line_steps(qs[None], p)
    for k in range(3):
        if not np.isfinite(t[0, k]):
            continue
        foot = p[0] + t[0, k] * n[0, k]
        f = np.append(foot, 1.0) @ qs[k] @ np.append(foot, 1.0)
        assert abs(f) <= 1e-12 * (1.0 + np.abs(qs[k]).max() * (1 + foot @ foot))
    assert line_distance(qs[None], p)[0] == np.abs(t[0]).max()


@pytest.mark.parametrize("r1, r2, height", [(1.0, 0.2, 0.3), (1.0, 0.0, 2.0), (0.5, 1.5, 0.2)])
def test_cones_faceted_by_their_slant_within_the_tolerance(r1, r2, height):
    """A cone's chords lie the sag times cos(alpha) from it, so a flat cone gets fewer segments
    than a cylinder of its largest radius; turned and scaled uniformly, alone and cut from a
    plate, its mesh still lies within the tolerance: every triangle's centroid and edge
    midpoints of the exact distance (Newton onto the cone) and points on the mesh of the CSG
    surface (float64 oracle)."""
    from clcsg.meshing.facets import circle_segments, round_segments
    from clcsg.meshing.project import newton
    from test_mesh import check_near_csg_surface

    tol = 0.004
    cone = clcsg.cone(height=height, r1=r1, r2=r2).rotate([1, 2, 3], 40).scale(1.5)
    tape = clcsg.Scene(cone).compile()
    inst = tape.instances[0]
    from clcsg.meshing.facets import _round_shape

    assert round_segments(*_round_shape(inst.node.params, inst.matrix, "cone"), tol) < circle_segments(1.5 * max(r1, r2), tol)
    for shape in (cone, clcsg.difference(clcsg.box(4.0), cone)):
        sc = clcsg.Scene(shape)
        m = clcsg.mesh(sc, tolerance=tol)
        check_closed_manifold(m)
        check_near_csg_surface(shape, m)
        side = next(i for i in sc.compile().instances if i.node.kind == "cone").literals[0][0]
        on = np.flatnonzero(m.quadric == side)
        v = m.vertices[m.triangles[on]]
        pts = np.concatenate([v.mean(axis=1), 0.5 * (v + np.roll(v, -1, axis=1)).reshape(-1, 3)])
        foot, ok = newton(np.repeat(sc.compile().quadrics[[side]][None], len(pts), 0), pts)
        assert ok.all() and np.linalg.norm(foot - pts, axis=1).max() <= tol


@pytest.mark.parametrize("name", ["flange", "lens", "bracket"])
def test_placed_unit_primitives_keep_their_literals(name):
    """Cylinders, cones and spheres built once as unit manifolds and placed by a transform
    give the Booleans' triangles the same instances and literals as the same facets read in
    one by one with their face IDs: per (instance, literal) the same count of triangles, and
    the same triangles (their centroids) on each."""
    from bench import zoo
    from clcsg.meshing import instance_booleans as ib

    sc = clcsg.Scene(zoo.model(name).build())
    tape = sc.compile()
    frame = ib.common_frame(sc.shape, tape.instances)
    tol = 1e-3 * float(np.linalg.norm(np.subtract(*tape.bound)))
    facets = ib.facets_of(tape, np.full(len(tape.instances), tol), frame)
    assert any(f.unit is not None for f in facets)
    placed = ib.boolean_mesh(tape, facets, frame[0])
    for f in facets:
        f.unit = None
    read = ib.boolean_mesh(tape, facets, frame[0])

    def labelled(got):
        c = np.round(got.vertices[got.triangles].mean(axis=1) / tol, 3)
        return sorted(zip(got.instance.tolist(), got.tag.tolist(), map(tuple, c.tolist())))

    assert labelled(placed) == labelled(read)
