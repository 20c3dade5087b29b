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

Many splats at once (:meth:`ClipPrograms.clip_many`): the state of every leaf over every
splat's ball (TRUE, FALSE or live) is found in one vectorized pass with the bounds of
:func:`~clcsg.compile.interpret.leaf_over_region`; splats with the same own quadric and the
same leaf states prune to the same program up to the marker planes, so the tape is pruned
once per such group and the marker rows are filled in per splat.
"""

from __future__ import annotations

import numpy as np

from ..cl.constants import OP_LEAF
from ..compile.interpret import PRUNE_SLACK, prune
from ..compile.tape import QuadricTable
from ..model.quadric import Quadric

_F, _T, _LIVE = 0, 1, 2  # leaf states, as in clcsg.compile.interpret
_OWN = 3  # a leaf on the splat's own quadric: no state (prune keeps it)


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

    def clip_many(self, centers, radii, own, planes):
        """:meth:`clip` of m splats: ``centers`` (m, 3), ``radii`` (m,), ``own`` (m,) quadric
        indices of the marker tape, ``planes[j]`` = (c, n) of (m, 3) each: operand j's
        half-space per splat.  (first, count, kept) arrays; ``kept`` is False where the
        splat is nowhere on the surface (:meth:`clip` returned None)."""
        t = self.tape
        centers, radii = np.asarray(centers, dtype=np.float64).reshape(-1, 3), np.asarray(radii, dtype=np.float64)
        own = np.asarray(own, dtype=np.int64)
        m = len(centers)
        first, count, kept = np.zeros(m, np.int32), np.zeros(m, np.int32), np.ones(m, bool)
        if not m:
            return first, count, kept
        marker = {int(mq): (j, int(ms)) for j, (mq, ms) in enumerate(t.markers)}
        target = {}
        for mq, (j, ms) in marker.items():
            c, n = planes[j]
            uniq, inv = np.unique(np.concatenate([c, n], axis=1), axis=0, return_inverse=True)
            idx, sg = self.planes(uniq[:, :3], uniq[:, 3:])
            inv = inv.reshape(-1)
            target[mq] = (idx[inv], ms * sg[inv])
        leaves = sorted({(int(a), int(b)) for op, _, a, b in t.ops if op == OP_LEAF})
        states = np.empty((m, len(leaves)), dtype=np.int8)
        slack = PRUNE_SLACK * (radii + np.linalg.norm(centers, axis=1))
        for k, (a, b) in enumerate(leaves):
            if a in marker:
                j, ms = marker[a]
                c, n = planes[j]
                g = b * ms * n  # the gradient of b * ms * (x - c) . n
                v = np.einsum("ij,ij->i", centers - c, g)
                spread = (radii + slack) * np.linalg.norm(g, axis=1)
            else:
                q = t.quadrics[a]
                if not np.any(q[:3, :3]):
                    g = 2.0 * b * q[:3, 3]
                    v = centers @ g + b * q[3, 3]
                    spread = (radii + slack) * np.linalg.norm(g)
                else:
                    v = b * Quadric(q).distance(centers)
                    spread = radii + slack
            states[:, k] = np.where(v > spread, _F, np.where(v < -spread, _T, _LIVE))
            states[own == a, k] = _OWN
        groups, inv = np.unique(np.column_stack([own, states]), axis=0, return_inverse=True)
        inv = inv.reshape(-1)
        order = np.argsort(inv, kind="stable")
        bounds = np.searchsorted(inv[order], np.arange(len(groups) + 1))
        for g, key in enumerate(groups):
            sel = order[bounds[g]:bounds[g + 1]]
            state = dict(zip(leaves, key[1:].tolist()))
            i0 = int(sel[0])
            rows, decided, _ = prune(t.ops, t.quadrics, centers[i0], float(radii[i0]), int(key[0]),
                                     leaf_state=lambda a, b: state[(int(a), int(b))])
            if decided == 1:
                kept[sel] = False
                continue
            if decided == -1:
                continue
            block = np.repeat(np.asarray(rows, dtype=np.int32)[None], len(sel), axis=0)
            for r, row in enumerate(rows):
                if row[0] == OP_LEAF and int(row[2]) in target:
                    idx, sg = target[int(row[2])]
                    block[:, r, 2] = idx[sel]
                    block[:, r, 3] = int(row[3]) * sg[sel]
            first[sel] = self.used + len(rows) * np.arange(len(sel), dtype=np.int32)
            count[sel] = len(rows)
            self.add_rows(block.reshape(-1, 4))
        return first, count, kept
