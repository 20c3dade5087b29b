"""Compiling scenes of thousands of primitives: the tape is right, the bound is right, and the
root tapes pruned per quadric are exact over their regions.

Checked against the independent float64 tree oracle (tests/tree_oracle.py).  No timing here:
``python -m bench compile`` measures the compile time against the number of primitives.
"""

from __future__ import annotations

import math
import os

import numpy as np
import pytest

import clcsg
import tree_oracle
from clcsg.cl.records import pack
from clcsg.compile.bounds.tree import tree_bounds
from clcsg.compile.quadric_frames import principal_frame
from clcsg.compile.interpret import contains, member
from clcsg.compile.root_tapes import prune_root_tapes
from clcsg.model.csg import Difference, Union
from clcsg.model.quadric import Quadric
from clcsg.model.scene import Scene
from clcsg.sampling.sampler import quadric_boxes, root_tasks

SIZE, THICK = 200.0, 5.0
EXAMPLES = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "examples")


def perforated_plate(n: int):
    """A SIZE x SIZE x THICK plate minus an n x n grid of holes (a cylinder and a cone chamfer
    each): 2 n^2 + 1 primitives."""
    pitch = SIZE / n
    r = 0.3 * pitch
    parts = [clcsg.box((SIZE, SIZE, THICK))]
    for i in range(n):
        for j in range(n):
            x, y = -SIZE / 2 + (i + 0.5) * pitch, -SIZE / 2 + (j + 0.5) * pitch
            parts.append(clcsg.cylinder(THICK + 2, r, (x, y, 0)))
            parts.append(clcsg.cone(0.6 * r + 0.01, 1.5 * r, r - 0.01, (x, y, THICK / 2 - 0.3 * r)))
    return Difference(parts)


def sphere_union(n: int, radius: float = 0.6):
    k = math.ceil(n ** (1 / 3))
    return Union([clcsg.sphere(radius, (i % k, (i // k) % k, i // (k * k))) for i in range(n)])


@pytest.fixture(scope="module")
def union_5000():
    shape = sphere_union(5000)
    return shape, Scene(shape).compile()


@pytest.fixture(scope="module")
def plate_2500():
    shape = perforated_plate(50)
    return shape, Scene(shape).compile()


def test_5000_leaf_union_compiles_to_the_oracle_membership(union_5000):
    shape, tape = union_5000
    assert tape.stats["leaves"] == 5000 and len(tape.instances) == 5000
    rng = np.random.default_rng(1)
    lo, hi = tape.bound
    # points everywhere in the bound, and points near the spheres' surfaces (where a wrong
    # leaf or a wrong sign shows)
    centers = np.array([[i % 18, (i // 18) % 18, i // 324] for i in range(5000)], dtype=float)
    d = rng.normal(size=(800, 3))
    near = centers[rng.integers(0, 5000, 800)] + 0.6 * (1 + rng.uniform(-0.02, 0.02, (800, 1))) * (
        d / np.linalg.norm(d, axis=1)[:, None])
    x = np.vstack([rng.uniform(lo, hi, (800, 3)), near])
    got = contains(tape.ops, tape.quadrics, x)
    want = tree_oracle.contains(shape, x)
    assert got.any() and not got.all()
    np.testing.assert_array_equal(got, want)


def test_5000_leaf_union_bound(union_5000):
    _, tape = union_5000
    np.testing.assert_allclose(tape.bound, [[-0.6, -0.6, -0.6], [17.6, 17.6, 15.6]], atol=1e-6)


def test_2500_hole_plate_compiles_with_the_right_bound(plate_2500):
    shape, tape = plate_2500
    assert len(tape.instances) == 5001
    half = np.array([SIZE / 2, SIZE / 2, THICK / 2])
    np.testing.assert_allclose(tape.bound, [-half, half], atol=1e-6)
    tb = tree_bounds(shape)
    np.testing.assert_allclose(tb.bound, tape.bound, atol=1e-12)
    rng = np.random.default_rng(2)
    x = rng.uniform(-half * 1.05, half * 1.05, (1000, 3))
    np.testing.assert_array_equal(contains(tape.ops, tape.quadrics, x), tree_oracle.contains(shape, x))


def _region_points(lo, hi, rng, n):
    return rng.uniform(lo, hi, (n, 3))


def _faceted_sphere_minus_bore(partitioned=False):
    """A convex mesh of 1,280 faces minus a bore: one intersection of its face planes (held
    half-spaces, what these tests are about), or with ``partitioned`` a k-d tree of local BSPs
    (its face planes bounded by their cells, tests/test_mesh_partition.py)."""
    from test_operands import faceted_sphere
    import clcsg.model.polyhedron as P

    v, f = faceted_sphere(3)
    limit = P.PARTITION_PLANES
    P.PARTITION_PLANES = limit if partitioned else len(f)
    try:
        return clcsg.polyhedron(v, f) - clcsg.cylinder(3, 0.3)
    finally:
        P.PARTITION_PLANES = limit


def _random_mesh_minus_bore():
    from test_operands import _random_mesh

    v, f = _random_mesh(2)
    return clcsg.polyhedron(v, f) - clcsg.cylinder(4, 0.3)


@pytest.mark.parametrize("scene", ["plate", "union", "mesh", "kd_mesh", "concave_mesh", "pen_stand"])
def test_root_tapes_are_exact_over_their_regions(scene):
    """Per quadric, the pruned root tape gives the full tape's membership on both sides of the
    quadric (the substitution of eq. 22 on the tree) at random points of its region.  The mesh
    (512 face planes, each a half-space whose box is most of space) is pruned by the half-spaces'
    sides of each region: those holding it are TRUE there (their default), those missing it
    FALSE.  The concave mesh (rotated boxes cut from and added to a cube: a BSP of many convex
    cells) has regions that many half-spaces miss."""
    shape = {"plate": lambda: perforated_plate(8), "union": lambda: sphere_union(216),
             "mesh": _faceted_sphere_minus_bore, "kd_mesh": lambda: _faceted_sphere_minus_bore(True),
             "concave_mesh": _random_mesh_minus_bore,
             # hulls and a Minkowski sum: half-spaces of one plane in several instances, and
             # neighbouring regions (one root tape) that one half-space holds and another misses
             "pen_stand": lambda: clcsg.load(os.path.join(EXAMPLES, "pen_stand.csg")).shape}[scene]()
    tape = Scene(shape).compile()
    rng = np.random.default_rng(3)
    boxes = quadric_boxes(tape)
    grow = 0.01 if scene == "mesh" else 0.05  # a far face plane of a convex mesh still passes near
    regions = {q: (lo - grow, hi + grow) for q, (lo, hi) in boxes.items()}
    spans, rows = prune_root_tapes(tape, regions)
    pruned = [q for q, (first, _) in spans.items() if first > 0]
    if scene in ("pen_stand", "concave_mesh"):  # most of their quadrics' regions hold most of their few primitives
        assert len(pruned) >= 10
    elif scene == "kd_mesh":  # regions grown this much meet several of its few cells
        assert len(pruned) > 0.6 * len(spans)
    else:
        assert len(pruned) > 0.8 * len(spans)
    for q in (pruned if len(pruned) <= 40 else rng.choice(pruned, 25, replace=False)):
        first, count = spans[q]
        ops = rows[first:first + count]
        assert count < len(tape.ops) * {"mesh": 0.6, "kd_mesh": 0.6, "pen_stand": 1.0, "concave_mesh": 1.0}.get(scene, 1 / 3)
        x = _region_points(*regions[q], rng, 400)
        full = member(tape.ops, tape.quadrics, x, int(q))
        part = member(ops, tape.quadrics, x, int(q))
        np.testing.assert_array_equal(part[0], full[0])
        np.testing.assert_array_equal(part[1], full[1])


@pytest.mark.parametrize("scene", ["mesh", "kd_mesh", "concave_mesh", "pen_stand"])
def test_root_tapes_are_exact_where_the_world_and_frame_boxes_meet(scene):
    """The sampler's regions as it makes them (its tasks' patches grown by the radius, as a
    world box and as a box in each quadric's principal frame, which for a tilted face plane is
    much thinner): the root tapes decided on both are exact at random points of the frame box
    inside the world box, on both sides of the quadric, and shorter than from the world boxes
    alone on the faceted sphere."""
    from clcsg.sampling.sampler import _task_regions

    shape = {"mesh": _faceted_sphere_minus_bore, "kd_mesh": lambda: _faceted_sphere_minus_bore(True),
             "concave_mesh": _random_mesh_minus_bore,
             "pen_stand": lambda: clcsg.load(os.path.join(EXAMPLES, "pen_stand.csg")).shape}[scene]()
    tape = Scene(shape).compile()
    packed = pack(tape, np.float64)
    frames = [principal_frame(Quadric(m)) for m in packed.local_matrices]
    radius = 0.01 * float(np.linalg.norm(tape.bound[1] - tape.bound[0]))
    tasks = root_tasks(tape, packed, frames, radius)[0]
    regions, oriented = _task_regions(tasks, frames, packed.origin, 1.01 * radius)
    spans, rows = prune_root_tapes(tape, regions, oriented)
    plain, _ = prune_root_tapes(tape, regions)
    if scene == "mesh":
        assert sum(c for _, c in spans.values()) < 0.8 * sum(c for _, c in plain.values())
    rng = np.random.default_rng(4)
    pruned = [q for q, (first, _) in spans.items() if first > 0]
    assert len(pruned) >= 10
    for q in (pruned if len(pruned) <= 40 else rng.choice(pruned, 40, replace=False)):
        first, count = spans[q]
        o, U, lo, hi = oriented[q]
        x = o + rng.uniform(lo, hi, (1500, 3)) @ U.T
        wlo, whi = regions[q]
        x = x[np.all((x >= wlo) & (x <= whi), axis=1)][:400]
        assert len(x) >= 50
        full = member(tape.ops, tape.quadrics, x, int(q))
        part = member(rows[first:first + count], tape.quadrics, x, int(q))
        np.testing.assert_array_equal(part[0], full[0])
        np.testing.assert_array_equal(part[1], full[1])


def test_root_tasks_point_at_pruned_tapes_that_start_the_arena():
    shape = sphere_union(125)
    tape = Scene(shape).compile()
    packed = pack(tape, np.float64)
    frames = [principal_frame(Quadric(m)) for m in packed.local_matrices]
    tasks, cells, rows = root_tasks(tape, packed, frames, radius=0.05)
    full = tape.ops.astype(np.int32)
    as_ops = rows.view(np.int32).reshape(-1, 4)
    np.testing.assert_array_equal(as_ops[:len(full)], full)
    assert np.all(cells["tape_first"] + cells["tape_count"] <= len(rows))
    assert cells["tape_count"].mean() < len(full) / 2
    for c in cells[:50]:
        ops = as_ops[c["tape_first"]:c["tape_first"] + c["tape_count"]]
        # every leaf of a task's own quadric survives the pruning
        assert tasks["quadric"][c["task"]] in ops[ops[:, 0] == 0, 2]


@pytest.mark.parametrize("scene", ["plate", "union"])
def test_refined_regions_on_pruned_group_tapes_are_those_of_the_full_tape(scene, monkeypatch):
    """refine_regions tests each group of neighbouring boxes on a tape pruned to the
    primitives near the group (root_tapes.box_tapes); with one group (the full tape) the
    regions are the same, and points of the quadrics' CSG surface (the full tape's two
    substituted sides differ) lie in the refined regions."""
    from clcsg.compile import root_tapes
    from clcsg.compile.bounds import estimates as guard
    from clcsg.compile.bounds.regions import quadric_regions

    shape = perforated_plate(12) if scene == "plate" else sphere_union(343)
    tape = Scene(shape).compile()
    regions = quadric_regions(tape.quadrics, tape.instances, tape.bound)
    got = guard.refine_regions(tape, regions)
    full = root_tapes.box_tapes
    monkeypatch.setattr(guard, "box_tapes", lambda t, lo, hi, q: full(t, lo, hi, q, size=len(q) + 1))
    want = guard.refine_regions(tape, regions)
    for g, w in zip(got, want):
        np.testing.assert_array_equal(g, w)
    rng = np.random.default_rng(4)
    checked = 0
    for u in rng.choice(len(regions), 20, replace=False):
        q = Quadric(tape.quadrics[u])
        p = rng.uniform(tape.bound[0], tape.bound[1], (3000, 3))
        v = rng.normal(size=(3000, 3))
        t1, _ = q.intersect_line(p, v)
        x = (p + t1[:, None] * v)[np.isfinite(t1)]
        x = x[np.all((x >= tape.bound[0]) & (x <= tape.bound[1]), axis=1)]
        minus, plus = member(tape.ops, tape.quadrics, x, int(u))
        on = x[minus != plus]
        r = got[u]
        inside = np.any(np.all((on[:, None] >= r[None, :, 0] - 1e-9) & (on[:, None] <= r[None, :, 1] + 1e-9), axis=2), axis=1)
        assert inside.all()
        checked += len(on)
    assert checked > 100
