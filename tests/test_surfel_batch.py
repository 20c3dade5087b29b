"""The batched host paths of point-operand sampling against their one-at-a-time forms: the
clip programs of many splats (:meth:`ClipPrograms.clip_many` against :meth:`ClipPrograms.clip`
per splat) and large quadric batches of the quadric table (against :meth:`QuadricTable.add`
one by one)."""

from __future__ import annotations

import numpy as np
import pytest

import clcsg
from clcsg.cl.constants import OP_LEAF
from clcsg.compile.tape import QuadricTable
from clcsg.sampling.surfel_clips import ClipPrograms
from clcsg.sampling.surfel_csg import marker_tape


def sphere_cloud(n):
    i = np.arange(n) + 0.5
    phi = np.arccos(1 - 2 * i / n)
    th = np.pi * (1 + 5 ** 0.5) * i
    u = np.stack([np.cos(th) * np.sin(phi), np.sin(th) * np.sin(phi), np.cos(phi)], 1)
    return u, u.copy()


def program(prog, first, count):
    """A clip program with every leaf's quadric replaced by its matrix (table order free)."""
    rows = np.concatenate(prog.rows)[first:first + count] if count else np.zeros((0, 4), np.int32)
    m = prog.table.matrices()
    return [(tuple(r), m[r[2]]) if r[0] == OP_LEAF else (tuple(r), None) for r in rows]


def same_program(a, b):
    assert len(a) == len(b)
    for (ra, ma), (rb, mb) in zip(a, b):
        assert ra[0] == rb[0] and ra[1] == rb[1]
        if ma is None:
            assert ra[2:] == rb[2:]
        else:
            assert ra[3] == rb[3] and np.allclose(ma, mb, atol=1e-12)


@pytest.mark.parametrize("scene", ["cloud minus cylinder", "box minus two clouds"])
def test_clip_many_matches_clip_per_splat(scene):
    """Splats of every kind near the operands (quadric splats, a cloud's own surfels, with
    partners from each cloud): the batch gives the same kept flags and the same programs
    (leaf by leaf, quadrics compared as matrices) as one call per splat."""
    p, n = sphere_cloud(3000)
    a = clcsg.surfels(p, n, 0.07)
    b = clcsg.surfels(0.5 * p + 0.4, n, 0.05)
    shape = a - clcsg.cylinder(3, 0.4) if scene == "cloud minus cylinder" else clcsg.box(1.6) - a - b
    tape, _ = marker_tape(clcsg.Scene(shape), 0.05)
    rng = np.random.default_rng(7)
    m = 400
    centers = rng.uniform(-1.2, 1.2, (m, 3))
    centers[:200] = p[rng.integers(0, len(p), 200)] * rng.uniform(0.97, 1.03, (200, 1))
    radii = rng.uniform(0.02, 0.12, m)
    scene_q = [q for q in range(tape.n_quadrics) if q not in {mq for mq, _ in tape.markers}]
    own = np.where(rng.random(m) < 0.5, rng.choice(scene_q, m), tape.markers[0][0])
    planes = []
    for s in tape.operands:
        _, idx = s.nearest(centers, 1)
        planes.append((s.points[idx[:, 0]], s.normals[idx[:, 0]]))
    own_surfel = own == tape.markers[0][0]  # a cloud's own splat: its own plane for its cloud
    planes[0][0][own_surfel], planes[0][1][own_surfel] = centers[own_surfel], planes[0][1][own_surfel]
    one, many = ClipPrograms(tape), ClipPrograms(tape)
    first, count, kept = many.clip_many(centers, radii, own, planes)
    outcomes = set()
    for i in range(m):
        got = one.clip(centers[i], radii[i], int(own[i]), [(c[i], nn[i]) for c, nn in planes])
        assert kept[i] == (got is not None)
        if got is None:
            outcomes.add("dropped")
            continue
        assert count[i] == got[1]
        outcomes.add("clipped" if got[1] else "unclipped")
        same_program(program(one, *got), program(many, int(first[i]), int(count[i])))
    assert outcomes == {"dropped", "clipped", "unclipped"}


def test_large_batches_match_one_by_one():
    """A batch above the fast path's size with exact repeats, near repeats (1e-12 apart),
    sign flips, scaled copies and entries already in the table gives the same indices, signs
    and table as adding the matrices one at a time."""
    rng = np.random.default_rng(11)
    base = rng.normal(size=(300, 4, 4))
    base = base + base.transpose(0, 2, 1)
    base[:100, :3, :3] = 0.0  # planes
    batch = np.concatenate([base, base[:50], base[200:250] + 1e-12, -base[100:150], 3.0 * base[150:200]])
    batch = batch[rng.permutation(len(batch))]
    one, many = QuadricTable(), QuadricTable()
    for t in (one, many):
        for q in base[:20]:
            t.add(q)
    expect = [one.add(q) for q in batch]
    assert many.add_many(batch) == expect
    assert len(many) == len(one) == 300
    assert np.array_equal(many.matrices(), one.matrices())
