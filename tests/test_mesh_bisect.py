"""Newest-vertex bisection of the Kuhn tetrahedra (clcsg.meshing.bisect): random local
refinement stays a conforming tetrahedral mesh of the same cells (every inner triangle shared
by exactly two tetrahedra, the volume unchanged), and three bisections make Kuhn tetrahedra of
half the size."""

import numpy as np
import pytest

from clcsg.meshing.bisect import SCALE, bisect, kuhn_tets, refine_tets
from clcsg.meshing.octree import Cells


def _cells(ijk, size=8):
    ijk = np.asarray(ijk, dtype=np.int64)
    return Cells(ijk, np.ones((len(ijk), 2), dtype=bool), np.zeros(3), 1.0, size, 0)


def _volumes(tets):
    x = tets.xyz.astype(np.float64)
    return np.abs(np.linalg.det(x[:, 1:] - x[:, :1])) / 6.0


def _faces(tets):
    keys = tets.keys()
    f = np.concatenate([keys[:, [1, 2, 3]], keys[:, [0, 2, 3]], keys[:, [0, 1, 3]], keys[:, [0, 1, 2]]])
    f = np.sort(f, axis=1)
    _, counts = np.unique(f, axis=0, return_counts=True)
    return counts


def test_three_bisections_halve_the_kuhn_tetrahedra():
    t = kuhn_tets(_cells([[1, 1, 1]]))
    for _ in range(3):
        t, _parent, _cuts = bisect(t, np.arange(len(t)))
    assert len(t) == 48
    assert np.allclose(_volumes(t), (SCALE / 2) ** 3 / 6.0)
    assert set(np.unique(t.tag)) == {3}
    # each child is a Kuhn tetrahedron of a half-size cube: its edge vectors are axis steps
    steps = np.diff(t.xyz, axis=1)  # (48, 3, 3)
    assert np.all(np.sort(np.abs(steps), axis=2) == np.array([0, 0, SCALE // 2]))


@pytest.mark.parametrize("seed", range(4))
def test_random_refinement_conforms(seed):
    rng = np.random.default_rng(seed)
    ijk = np.array([[i, j, k] for i in range(1, 4) for j in range(1, 4) for k in range(1, 3)])
    t = kuhn_tets(_cells(ijk))
    total = _volumes(t).sum()
    boundary_faces = (_faces(t) == 1).sum()
    for _ in range(6):
        sel = rng.choice(len(t), size=max(1, len(t) // 10), replace=False)
        t = refine_tets(t, sel)
        counts = _faces(t)
        assert counts.max() == 2  # no face shared by three: no overlap
        assert np.isclose(_volumes(t).sum(), total)
    # a conforming mesh: a face on the outside is split into faces on the outside only, and no
    # inner face is seen from one side (a hanging vertex would leave such faces)
    outer = (counts == 1).sum()
    assert outer >= boundary_faces
    x = t.xyz.astype(np.float64)
    keys = t.keys()
    f = np.concatenate([keys[:, [1, 2, 3]], keys[:, [0, 2, 3]], keys[:, [0, 1, 3]], keys[:, [0, 1, 2]]])
    fx = np.concatenate([x[:, [1, 2, 3]], x[:, [0, 2, 3]], x[:, [0, 1, 3]], x[:, [0, 1, 2]]])
    u, inv, c = np.unique(np.sort(f, axis=1), axis=0, return_inverse=True, return_counts=True)
    single = c[inv.ravel()] == 1
    lo = ijk.min(axis=0) * SCALE
    hi = (ijk.max(axis=0) + 1) * SCALE
    on_outside = np.any(np.all((fx[single] == lo) | (fx[single] == hi), axis=1), axis=1)
    assert on_outside.all()
