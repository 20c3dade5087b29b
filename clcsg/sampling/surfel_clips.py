"""Clip programs of splats near point operands (paper section 3.3, on the splat renderer's
clip programs): the tape with one marker plane per point operand, each marker swapped per
splat for a surfel's half-space, pruned over the splat's ball with its own quadric
substituted (:func:`clcsg.compile.interpret.prune`); and the quadric table that grows by the
surfels' tangent planes.

A marker literal (m, s) holds where the operand does.  For a splat, marker m becomes the plane
P(x) = (x - c) . n of surfel (c, n) (negative behind it) with the literal's sign folded in:
the table entry is s_m P, with s_m the sign of the operand's own (positive) literal, so a
literal (m, s) holds iff s s_m P <= 0.  In the combined table the plane is stored canonically,
P = sigma |P| K, so the literal becomes (K, s s_m sigma).
"""

from __future__ import annotations

import numpy as np

from ..cl.constants import OP_LEAF
from ..compile.interpret import prune
from ..compile.tape import QuadricTable


def plane_matrix(c, n) -> np.ndarray:
    """The plane quadrics (x - c) . n as 4x4 matrices (negative behind the surfel): (4, 4) for
    one center and normal, (m, 4, 4) for (m, 3) of each."""
    c, n = np.asarray(c, dtype=np.float64), np.asarray(n, dtype=np.float64)
    m = np.zeros(n.shape[:-1] + (4, 4))
    m[..., :3, 3] = m[..., 3, :3] = 0.5 * n
    m[..., 3, 3] = -np.einsum("...j,...j->...", n, c)
    return m


class ClipPrograms:
    """The combined quadric table (the marker tape's quadrics first, in their order, then
    the planes added) and the clip rows being built, for a marker tape (a
    :class:`~clcsg.sampling.surfel_csg.SurfelTape`: ``ops``, ``quadrics``, ``markers``)."""

    def __init__(self, marker_tape):
        self.tape = marker_tape
        self.table = QuadricTable()
        for m in marker_tape.quadrics:
            self.table.add(m)
        assert len(self.table) == marker_tape.n_quadrics
        self.rows: list = []
        self.used = 0

    def plane(self, c, n) -> tuple[int, int]:
        """(index, sign) of the surfel plane (x - c) . n in the table: P = sign |P| K."""
        return self.table.add(plane_matrix(c, n))

    def planes(self, c, n) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`plane` of many: (indices, signs)."""
        got = self.table.add_many(plane_matrix(c, n))
        return np.array([i for i, _ in got], dtype=np.int32), np.array([s for _, s in got], dtype=np.int32)

    def add_rows(self, rows) -> tuple[int, int]:
        rows = np.asarray(rows, dtype=np.int32).reshape(-1, 4)
        self.rows.append(rows)
        first = self.used
        self.used += len(rows)
        return first, len(rows)

    def clip(self, center, radius, own, planes) -> tuple[int, int] | None:
        """The clip program (first, count) of a splat at ``center`` with ``radius`` on quadric
        ``own`` of the marker tape (a scene quadric, or operand j's marker for its own surfels),
        each point operand j replaced by the half-space ``planes[j]`` = (c, n); None when its
        splat is nowhere on the surface."""
        t = self.tape
        q = t.quadrics.copy()
        target = {}
        for (mq, ms), (c, n) in zip(t.markers, planes):
            q[mq] = ms * plane_matrix(c, n)
            idx, sg = self.plane(c, n)
            target[mq] = (idx, ms * sg)
        rows, decided, _ = prune(t.ops, q, center, radius, own)
        if decided == 1:
            return None
        if decided == -1:
            return (0, 0)
        rows = rows.copy()
        for r in rows:
            if r[0] == OP_LEAF and int(r[2]) in target:
                idx, sg = target[int(r[2])]
                r[2], r[3] = idx, int(r[3]) * sg
        return self.add_rows(rows)
