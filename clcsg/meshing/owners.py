"""Per triangle: the quadric it lies on, the primitive instance that carries it there, its colour.

A triangle's quadric is the one its three vertices share (for a triangle whose vertices all
lie on a curve, the shared quadric nearest to its centroid).  Its primitive is the first
instance (tree order) that has that quadric as a literal and whose other literals hold at the
triangle's centroid, within the mesh tolerance (to first order, |K| <= tol |grad K|), else
the one whose literals the centroid misses by the least (a large triangle along a curved
sharp edge: its centroid lies off the curve by the chord's sag); the colour is that
instance's colour (the default grey if no instance has the quadric).
"""

from __future__ import annotations

import numpy as np

from ..model.csg import DEFAULT_COLOR
from .project import first_order_distance, residuals
from .refine import _compact, common


def triangle_owners(tape, m, tol: float = 0.0):
    """(quadric (T,), primitive (T,), colours (T, 4)) of the triangles of ``m``."""
    s = m.sets[m.triangles]
    shared = common(common(s[:, 0], s[:, 1]), s[:, 2])
    centroid = m.vertices[m.triangles].mean(axis=1)
    dist = np.full(shared.shape, np.inf)
    for k in range(shared.shape[1]):  # several shared (a triangle along a curve): the nearest
        sel = shared[:, k] >= 0
        dist[sel, k] = first_order_distance(tape.quadrics[shared[sel, k]][:, None], centroid[sel])
    best = np.take_along_axis(shared, np.argmin(dist, axis=1)[:, None], axis=1)[:, 0]
    quad = np.where(np.isfinite(dist.min(axis=1)), best, _compact(s[:, 0])[:, 0])
    prim = np.full(len(quad), -1, dtype=np.int64)
    owners = tape.owners()
    slack = max(tol, 1e-9 * max(1.0, float(np.abs(tape.bound).max())))
    for q in np.unique(quad):
        sel = np.flatnonzero(quad == q)
        best = np.full(len(sel), np.inf)
        for inst in (tape.instances[i] for i in owners[q]):
            viol = np.zeros(len(sel))  # the largest first-order distance outside a literal
            for lq, sign in inst.literals:
                if lq == q:
                    continue
                f, j = residuals(tape.quadrics[[lq]][None].repeat(len(sel), 0), centroid[sel])
                with np.errstate(divide="ignore", invalid="ignore"):
                    d = np.nan_to_num(sign * f[:, 0] / np.linalg.norm(j[:, 0], axis=1), nan=0.0, posinf=np.inf)
                viol = np.maximum(viol, d)
            viol = np.where(viol <= slack, 0.0, viol)  # within the slack: holds (the first such)
            take = viol < best
            prim[sel[take]] = inst.index
            best[take] = viol[take]
    palette = np.array([inst.color for inst in tape.instances] + [DEFAULT_COLOR], dtype=np.float64)
    colors = palette[np.where(prim >= 0, prim, len(tape.instances))]
    return quad, prim, colors
