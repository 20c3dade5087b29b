"""Per splat, the primitive the colour rule gives every point of it, decided once on the host
so that the splat renderer's resolve pass runs the rule (``cl/include/primitives.h``,
``primitive_at``) only for splats over which the answer may change."""

from __future__ import annotations

import numpy as np

from ..cl.records import PackedScene

#: the ball B(s, r) is grown by this relative amount (fragments are accepted within r in the
#: device's precision; the rounding of that precision is added on top)
GROW = 1e-3
#: rounding margin, in units of the device precision's epsilon
ULPS = 64


def splat_primitives(packed: PackedScene, pos: np.ndarray, radii: np.ndarray, quadrics: np.ndarray) -> np.ndarray:
    """Per sample the primitive that ``primitive_at`` gives every point of its splat on its
    quadric q, or -1 where it may vary over the splat (the resolve pass then decides per
    pixel).  ``pos``: device coordinates.

    ``primitive_at`` at p considers the owners of q whose boundary holds p (p in the padded box,
    every other literal of the instance holding at p) and takes the first owner of q where none
    does.  Over the ball B = B(s, r) an owner is *possible* unless its box misses B or one of
    its other literals fails everywhere in B, and *sure* if each of those literals holds
    everywhere in B (bounds of Q over B below): a point on q (within rounding) where they all
    hold is in the instance, so in its box, which is padded by the rounding margin.  The answer is constant over B
    if no owner is possible (the first owner), if only the first owner is (the first owner,
    held or not), or if only one owner is possible and it is sure (that one); a quadric with
    one owner always gives it.  Over B, Q(s + w) = Q(s) + g.w + w^T A w (g = grad Q(s),
    |w| <= r) lies in [Q(s) - |g| r + min(lam_min, 0) r^2, Q(s) + |g| r + max(lam_max, 0) r^2]."""
    n = len(pos)
    out = np.full(n, -1, dtype=np.int32)
    if not n or not len(packed.owners):
        return out
    q = np.asarray(quadrics, dtype=np.int64)
    first, count = packed.owners["first"][q].astype(np.int64), packed.owners["count"][q].astype(np.int64)
    owned = count > 0
    out[owned] = packed.owner_list[first[owned]]
    multi = np.flatnonzero(count > 1)
    if not len(multi):
        return out
    rows, k = _expand(multi, count[multi])  # one row per (sample, owner) pair
    inst = packed.owner_list[first[rows] + k].astype(np.int64)
    p = np.asarray(pos, dtype=np.float64)[rows]
    r = np.asarray(radii, dtype=np.float64)[rows]
    R = r * (1 + GROW) + ULPS * float(np.finfo(packed.real).eps) * (np.linalg.norm(p, axis=1) + r)
    meets = _ball_meets_box(packed.prim_boxes.astype(np.float64)[inst], p, R)
    never, sure = _literals_over_balls(packed, inst, q[rows], p, R)
    possible = meets & ~never
    n_possible = np.bincount(rows[possible], minlength=n)[multi]
    first_possible = np.bincount(rows[possible & (k == 0)], minlength=n)[multi] > 0
    only = np.zeros(n, dtype=np.int64)
    only[rows[possible]] = inst[possible]
    only_sure = np.zeros(n, dtype=bool)
    only_sure[rows[possible & sure]] = True
    single = n_possible == 1
    take_only = single & ~first_possible & only_sure[multi]
    fixed = (n_possible == 0) | (single & first_possible) | take_only
    out[multi] = np.where(fixed, np.where(take_only, only[multi], out[multi]), -1)
    return out


def _expand(items: np.ndarray, reps: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(items repeated reps times, the position 0 .. reps - 1 of each copy)."""
    rows = np.repeat(items, reps)
    k = np.arange(len(rows)) - np.repeat(np.cumsum(reps) - reps, reps)
    return rows, k


def _ball_meets_box(box: np.ndarray, p: np.ndarray, R: np.ndarray) -> np.ndarray:
    """Per row: does the ball B(p, R) meet the box (lo = box[0, :3], hi = box[1, :3])?  An
    empty box (lo = +inf) meets none."""
    with np.errstate(invalid="ignore"):
        gap = np.maximum(np.maximum(box[:, 0, :3] - p, p - box[:, 1, :3]), 0.0)
    return ~((gap * gap).sum(axis=1) > R * R)


def _literals_over_balls(packed: PackedScene, inst: np.ndarray, q: np.ndarray, p: np.ndarray,
                         R: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per row (instance inst on quadric q, ball B(p, R)): does one of the instance's literals
    other than q fail everywhere in the ball, and do all of them hold everywhere in it (with q
    itself taken with one sign only)?  A literal (j, s) holds where s Q_j <= 0 (primitives.h)."""
    lit_first = packed.prims["lit_first"][inst].astype(np.int64)
    rows, k = _expand(np.arange(len(inst)), packed.prims["lit_count"][inst].astype(np.int64))
    lits = packed.prim_literals[lit_first[rows] + k].astype(np.int64)
    j, sign = lits[:, 0], lits[:, 1]
    own = j == q[rows]
    M = packed.local_matrices[j]
    x, rad = p[rows], R[rows]
    g = 2 * (np.einsum("nij,nj->ni", M[:, :3, :3], x) + M[:, :3, 3])
    value = np.einsum("ni,ni->n", x, 0.5 * g + M[:, :3, 3]) + M[:, 3, 3]
    lam = np.linalg.eigvalsh(packed.local_matrices[:, :3, :3])[j]
    gl = np.linalg.norm(g, axis=1)
    lo = value - gl * rad + np.minimum(lam[:, 0], 0) * rad * rad
    hi = value + gl * rad + np.maximum(lam[:, 2], 0) * rad * rad
    tol = ULPS * float(np.finfo(packed.real).eps) * np.abs(M).sum(axis=(1, 2)) * (1 + np.abs(x).sum(axis=1) + rad) ** 2
    fails = np.where(sign > 0, lo > tol, hi < -tol) & ~own
    holds = np.where(sign > 0, hi < -tol, lo > tol) | own
    n = len(inst)
    both_sides = (np.bincount(rows[own & (sign > 0)], minlength=n) > 0) & (np.bincount(rows[own & (sign < 0)], minlength=n) > 0)
    never = np.bincount(rows[fails], minlength=n) > 0
    always = (np.bincount(rows[~holds], minlength=n) == 0) & ~both_sides
    return never, always
