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
from ..compile.interpret import run_boolean
from ..model.bvh import morton_order
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
    table = _literal_table(tape)
    boxes = _instance_boxes(tape)
    rank = np.empty(len(centroid), dtype=np.int64)
    rank[morton_order(centroid) if len(centroid) else rank] = np.arange(len(centroid))
    order = np.lexsort((rank, quad))  # by quadric, then along a Morton curve
    starts = np.searchsorted(quad[order], np.arange(tape.n_quadrics + 1))
    for q in np.unique(quad[quad >= 0]):
        every = np.asarray(owners[q], dtype=np.int64)
        if len(every) == 1:  # one carrier: the only one, or the least missed
            prim[order[starts[q]:starts[q + 1]]] = every[0]
            continue
        for a in range(starts[q], starts[q + 1], CHUNK):  # neighbouring points together
            sel = order[a:min(a + CHUNK, starts[q + 1])]
            carriers = _near(boxes, every, centroid[sel], slack)
            viol = _violations(tape, table, carriers, int(q), centroid[sel], slack)  # (carriers, points)
            held = viol == 0.0
            prim[sel] = carriers[np.argmin(viol, axis=0)]  # the first that holds, else the least missed
            several = np.flatnonzero(held.sum(axis=0) > 1)
            if len(several) and tape.instance_program is not None:
                got = bounding_first(tape, int(q), carriers, held[:, several], centroid[sel[several]], table, boxes)
                prim[sel[several]] = np.where(got >= 0, got, prim[sel[several]])
    return prim


#: points whose primitive is decided together (neighbours along a Morton curve)
CHUNK = 256


def _instance_boxes(tape):
    """(lo, hi) (instances, 3): each instance's box, all of space where it has none listed."""
    lo = np.array([i.box[0] if i.box is not None else np.full(3, -np.inf) for i in tape.instances]).reshape(-1, 3)
    hi = np.array([i.box[1] if i.box is not None else np.full(3, np.inf) for i in tape.instances]).reshape(-1, 3)
    return lo, hi


def _near(boxes, instances, points, slack):
    """The ``instances`` (tree order kept) whose box, grown by ``slack``, meets the points'
    bounding box; the first of them if none does (a point off every box: the least missed)."""
    lo, hi = boxes[0][instances], boxes[1][instances]
    plo, phi = points.min(axis=0), points.max(axis=0)
    meet = np.all((lo - slack <= phi) & (hi + slack >= plo), axis=1)
    return instances[meet] if meet.any() else instances[:1]


def _violations(tape, table, carriers, q: int, points, slack: float) -> np.ndarray:
    """(carriers, points): the largest first-order distance of each point outside a literal of
    each carrier other than ``q`` (0 within ``slack``: the literal holds)."""
    qs, signs = table[0][carriers], table[1][carriers]
    live = (qs >= 0) & (qs != q)
    out = np.zeros((len(carriers), len(points)))
    if not live.any() or not len(points):
        return out
    used, index = np.unique(qs[live], return_inverse=True)
    f, j = residuals(np.broadcast_to(tape.quadrics[used][None], (len(points), len(used), 4, 4)), points)
    with np.errstate(divide="ignore", invalid="ignore"):
        d = np.nan_to_num(f / np.linalg.norm(j, axis=2), nan=0.0, posinf=np.inf, neginf=-np.inf).T  # (used, points)
    per = np.full(qs.shape + (len(points),), -np.inf)
    per[live] = signs[live][:, None] * d[index]
    out = np.maximum(per.max(axis=1), 0.0)
    return np.where(out <= slack, 0.0, out)


def _literal_table(tape):
    """(quadric, sign) per instance and literal slot, (instances, width); quadric -1 pads."""
    width = max((len(i.literals) for i in tape.instances), default=1)
    qs = np.full((len(tape.instances), width), -1, dtype=np.int64)
    signs = np.ones((len(tape.instances), width))
    for inst in tape.instances:
        for k, (lq, sign) in enumerate(inst.literals):
            qs[inst.index, k], signs[inst.index, k] = lq, sign
    return qs, signs


def _memberships(tape, q: int, points, table, boxes):
    """(on q's negative side, on its positive side): per instance (rows) and point (columns)
    its membership, literal q substituted by the side; an instance whose box misses the points'
    bounding box is out (its solid lies in its box)."""
    qs, signs = table
    near = _near(boxes, np.arange(len(qs)), points, 0.0)
    out = []
    for side in _near_memberships(tape, q, points, (qs[near], signs[near])):
        full = np.zeros((len(qs), len(points)), dtype=bool)
        full[near] = side
        out.append(full)
    return out


def _near_memberships(tape, q: int, points, table):
    qs, signs = table
    used, index = np.unique(qs[qs >= 0], return_inverse=True)
    f, _ = residuals(np.broadcast_to(tape.quadrics[used][None], (len(points), len(used), 4, 4)), points)
    holds = np.ones(qs.shape + (len(points),), dtype=bool)  # (instances, slots, points)
    lit = np.flatnonzero((qs >= 0).ravel())
    holds.reshape(-1, len(points))[lit] = (signs.ravel()[lit][:, None] * f.T[index]) <= 0.0
    own = qs == q
    out = []
    for side_holds in (signs > 0, signs < 0):  # on q's negative side a literal (q, +1) holds
        h = holds.copy()
        h[own] = side_holds[own][:, None]
        out.append(h.all(axis=1))
    return out


def _solid(ops, member):
    """The instance program over memberships ``member`` (instances, points) -> (points,)."""
    return run_boolean(np.asarray(ops).tolist(), lambda a, sign: member[a] if sign > 0 else ~member[a],
                       member.shape[1])


def bounding_first(tape, q: int, carriers, held, points, table, boxes):
    """Per point (on or near quadric ``q``, held by several of its ``carriers``: ``held``
    (carriers, points)) the first carrier that holds it and bounds the solid there: switching
    its membership on one side of q changes the solid's on that side (the instance program
    :mod:`clcsg.compile.instance_program`); -1 where none does.  The point is first moved onto
    q (Newton)."""
    x, ok = newton(tape.quadrics[[q]][None].repeat(len(points), 0), points)
    x = np.where(ok[:, None], x, points)
    ops = tape.instance_program[0]
    n, c = len(points), len(carriers)
    changed = np.zeros((c, n), dtype=bool)
    for member in _memberships(tape, q, x, table, boxes):
        # one run of the program over (plain, each carrier switched) x points
        wide = np.repeat(member[:, None, :], c + 1, axis=1)
        wide[carriers, np.arange(1, c + 1)] = ~wide[carriers, np.arange(1, c + 1)]
        solid = _solid(ops, wide.reshape(len(member), -1)).reshape(c + 1, n)
        changed |= solid[1:] != solid[0]
    bounding = changed & held
    return np.where(bounding.any(axis=0), carriers[np.argmax(bounding, axis=0)], -1)
