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
from ..cl.constants import OP_AND, OP_CONST, OP_COPY, OP_LEAF, OP_OR
from .project import first_order_distance, newton, residuals
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
    prim = primitives_of(tape, quad, centroid, tol)
    palette = np.array([inst.color for inst in tape.instances] + [DEFAULT_COLOR], dtype=np.float64)
    colors = palette[np.where(prim >= 0, prim, len(tape.instances))]
    return quad, prim, colors


def shared_nearest(tape, vertices, triangles, sets, quad):
    """Per triangle the quadric, among those all three of its vertices lie on, nearest to it
    (the largest first-order distance over its centroid and edge midpoints; ``quad`` where the
    vertices share one quadric or none): a triangle of a faceted Boolean whose vertices all
    lie on one curve may carry either surface, and the faceted surfaces may have met the wrong
    way round where they graze (two cylinders tangent along a line)."""
    s = sets[triangles]  # (T, 3, W)
    cand = np.where((s[:, 0, :, None] == s[:, 1, None, :]).any(axis=2)
                    & (s[:, 0, :, None] == s[:, 2, None, :]).any(axis=2) & (s[:, 0] >= 0), s[:, 0], -1)
    many = np.flatnonzero((cand >= 0).sum(axis=1) > 1)
    out = quad.copy()
    if not len(many):
        return out
    v = vertices[triangles[many]]
    pts = np.stack([v.mean(axis=1), 0.5 * (v[:, 0] + v[:, 1]), 0.5 * (v[:, 1] + v[:, 2]), 0.5 * (v[:, 2] + v[:, 0])], 1)
    dist = np.full(cand[many].shape, np.inf)
    for k in range(cand.shape[1]):
        sel = cand[many, k] >= 0
        if sel.any():
            q = tape.quadrics[cand[many[sel], k]]
            d = [first_order_distance(q[:, None], pts[sel, j]) for j in range(4)]
            dist[sel, k] = np.max(d, axis=0)
    out[many] = cand[many, np.argmin(dist, axis=1)]
    return out


def primitives_of(tape, quad, centroid, tol: float = 0.0):
    """Per triangle (its quadric ``quad``, its ``centroid``) the primitive the colour rule
    gives it: among the instances (tree order) that have the quadric as a literal and whose
    other literals hold at the centroid within the tolerance, the only one; of several, the
    first that bounds the solid there (:func:`bounding_first`), else the first; of none, the
    one whose literals the centroid misses by the least; -1 if no instance has the quadric."""
    prim = np.full(len(quad), -1, dtype=np.int64)
    owners = tape.owners()
    slack = max(tol, 1e-9 * max(1.0, float(np.abs(tape.bound).max())))
    for q in np.unique(quad[quad >= 0]):
        sel = np.flatnonzero(quad == q)
        best = np.full(len(sel), np.inf)
        holding = []
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
            holding.append(viol == 0.0)
            take = viol < best
            prim[sel[take]] = inst.index
            best[take] = viol[take]
        if len(holding) > 1 and tape.instance_program is not None:
            held = np.array(holding)  # (owners, triangles)
            several = np.flatnonzero(held.sum(axis=0) > 1)
            if len(several):
                got = bounding_first(tape, int(q), [owners[q][k] for k in range(len(holding))],
                                     held[:, several], centroid[sel[several]])
                prim[sel[several]] = np.where(got >= 0, got, prim[sel[several]])
    return prim


def _memberships(tape, q: int, points):
    """(on q's negative side, on its positive side): per instance (rows) and point (columns)
    its membership, literal q substituted by the side."""
    n_inst = len(tape.instances)
    values = {}
    out = np.ones((2, n_inst, len(points)), dtype=bool)
    for inst in tape.instances:
        for lq, sign in inst.literals:
            if lq == q:
                out[0, inst.index] &= sign > 0
                out[1, inst.index] &= sign < 0
                continue
            if lq not in values:
                f, _ = residuals(tape.quadrics[[lq]][None].repeat(len(points), 0), points)
                values[lq] = f[:, 0]
            out[:, inst.index] &= (sign * values[lq] <= 0.0)[None]
    return out


def _solid(ops, member):
    """The instance program over memberships ``member`` (instances, points) -> (points,)."""
    regs: dict = {}
    for op, out, a, b in np.asarray(ops).tolist():
        if op == OP_LEAF:
            regs[out] = member[a] if b > 0 else ~member[a]
        elif op == OP_AND:
            regs[out] = regs[a] & regs[b]
        elif op == OP_OR:
            regs[out] = regs[a] | regs[b]
        elif op == OP_COPY:
            regs[out] = regs[a]
        elif op == OP_CONST:
            regs[out] = np.full(member.shape[1], bool(a))
    return regs[ops[-1][1]]


def bounding_first(tape, q: int, carriers, held, points):
    """Per point (on or near quadric ``q``, held by several of its ``carriers``: ``held``
    (carriers, points)) the first carrier that holds it and bounds the solid there: switching
    its membership on one side of q changes the solid's on that side (the instance program
    :mod:`clcsg.compile.instance_program`); -1 where none does.  The point is first moved onto
    q (Newton)."""
    x, ok = newton(tape.quadrics[[q]][None].repeat(len(points), 0), points)
    x = np.where(ok[:, None], x, points)
    ops = tape.instance_program[0]
    sides = _memberships(tape, q, x)
    plain = [_solid(ops, member) for member in sides]
    out = np.full(len(points), -1, dtype=np.int64)
    for i, h in zip(carriers, held):
        todo = h & (out < 0)
        if not todo.any():
            continue
        changed = np.zeros(len(points), dtype=bool)
        for member, base in zip(sides, plain):
            flipped = member[:, todo].copy()
            flipped[i] = ~flipped[i]
            changed[todo] |= _solid(ops, flipped) != base[todo]
        out[todo & changed] = i
    return out
