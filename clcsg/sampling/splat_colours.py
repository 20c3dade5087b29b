"""Per splat, the primitive the colour rule gives every point of it, decided once on the host
so that the splat renderer's resolve pass runs the rule (``cl/include/primitives.h``,
``primitive_at``) only for splats over which the answer may change.

Over a sample's ball B = B(s, r) each instance's membership at the points of B on the sample's
quadric q is classified by bounds of its literals over B: *none* (its box misses B, or one of
its literals fails everywhere in B), *known* (every literal other than q holds everywhere in B:
then the membership on q's two sides is fixed by the sign of its literal on q, both sides for
an instance without one) or *unknown*.  ``primitive_at`` is then replayed in three-valued
logic; where every step it takes is known, its answer holds over all of B."""

from __future__ import annotations

import numpy as np

from ..cl.constants import OP_AND, OP_COPY, OP_LEAF, OP_OR
from ..cl.records import PackedScene

#: the ball B(s, r) is grown by this relative amount (fragments are accepted within r in the
#: device's precision; the rounding of that precision is added on top)
GROW = 1e-3
#: rounding margin, in units of the device precision's epsilon
ULPS = 64
#: scenes with more instances replay only the owners' part of the rule
MAX_INSTANCES = 64
#: (instance, ball) rows classified at once (each expands to its literals: bounded memory)
CHUNK = 16384


def splat_primitives(packed: PackedScene, pos: np.ndarray, radii: np.ndarray, quadrics: np.ndarray) -> np.ndarray:
    """Per sample the primitive that ``primitive_at`` gives every point of its splat on its
    quadric q, or -1 where it may vary over the splat (the resolve pass then decides per
    pixel).  ``pos``: device coordinates.

    ``primitive_at`` takes, among the owners of q that hold p in tree order (the holding set H),
    the only one, or the first whose switching changes the instance program, else the first of
    H; the first owner of q if H is empty.  So the answer is constant over B if no owner can
    hold a point of B (the first owner), if only the first owner can (the first owner, held or
    not), if exactly one owner can and surely does (that one), or if every owner's state is
    known and the instance program's lanes are known over B (module docstring).  Over B,
    Q(s + w) = Q(s) + g.w + w^T A w (g = grad Q(s), |w| <= r) lies in
    [Q(s) - |g| r + min(lam_min, 0) r^2,  Q(s) + |g| r + max(lam_max, 0) r^2]."""
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
    rows, k = _expand(multi, count[multi])  # one row per (sample, owner) pair, in owner order
    inst = packed.owner_list[first[rows] + k].astype(np.int64)
    p = np.asarray(pos, dtype=np.float64)[multi]
    R = _reach(packed, p, np.asarray(radii, dtype=np.float64)[multi])
    local = np.repeat(np.arange(len(multi)), count[multi])
    tables = _quadric_tables(packed)
    bits, known = _states(packed, tables, inst, q[rows], p[local], R[local])
    holds = known & (bits != 0)
    possible = ~known | holds
    n_possible = np.bincount(local[possible], minlength=len(multi))
    first_possible = np.bincount(local[possible & (k == 0)], minlength=len(multi)) > 0
    only = np.zeros(len(multi), dtype=np.int64)
    only[local[possible]] = inst[possible]
    only_sure = np.zeros(len(multi), dtype=bool)
    only_sure[local[possible & holds]] = True
    take_only = (n_possible == 1) & ~first_possible & only_sure
    fixed = (n_possible == 0) | ((n_possible == 1) & first_possible) | take_only
    res = np.where(fixed, np.where(take_only, only, out[multi]), -1)
    rest = ~fixed & (np.bincount(local[~known], minlength=len(multi)) == 0)  # |H| >= 2, every owner known
    if rest.any():
        sel = rest[local] & holds
        res[rest] = _replay_program(packed, tables, np.flatnonzero(rest), local[sel], inst[sel], q[multi], p, R)
    out[multi] = res
    return out


def _expand(items: np.ndarray, reps: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(items repeated reps times, the position 0 .. reps - 1 of each copy)."""
    rows = np.repeat(items, reps)
    k = np.arange(len(rows)) - np.repeat(np.cumsum(reps) - reps, reps)
    return rows, k


def _reach(packed: PackedScene, p: np.ndarray, r: np.ndarray) -> np.ndarray:
    return r * (1 + GROW) + ULPS * float(np.finfo(packed.real).eps) * (np.linalg.norm(p, axis=1) + r)


def _states(packed: PackedScene, tables: tuple, inst: np.ndarray, q: np.ndarray, p: np.ndarray,
            R: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per row (instance inst, points of the ball B(p, R) on quadric q): its membership bits as
    ``instance_sides`` (bit 0: q's negative side, bit 1: its positive side) and whether they
    are the same over all of B."""
    if len(inst) > CHUNK:
        parts = [_states(packed, tables, inst[i:i + CHUNK], q[i:i + CHUNK], p[i:i + CHUNK], R[i:i + CHUNK])
                 for i in range(0, len(inst), CHUNK)]
        return np.concatenate([a for a, _ in parts]), np.concatenate([b for _, b in parts])
    box = packed.prim_boxes.astype(np.float64)[inst]
    with np.errstate(invalid="ignore"):
        gap = np.maximum(np.maximum(box[:, 0, :3] - p, p - box[:, 1, :3]), 0.0)
    meets = np.flatnonzero(~((gap * gap).sum(axis=1) > R * R))  # an empty box (lo = +inf) meets none
    bits, known = np.zeros(len(inst), np.uint8), np.ones(len(inst), bool)
    never, always, sides = _literals_over_balls(packed, tables, inst[meets], q[meets], p[meets], R[meets])
    bits[meets] = np.where(never, 0, sides)
    known[meets] = never | always
    return bits, known


def _literals_over_balls(packed: PackedScene, tables: tuple, inst: np.ndarray, q: np.ndarray, p: np.ndarray,
                         R: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per row (instance inst on quadric q, ball B(p, R)): does one of its literals other than q
    fail everywhere in B, do all of them hold everywhere in B, and the two side bits its
    literals on q leave (3 without one).  A literal (j, s) holds where s Q_j <= 0."""
    lit_first = packed.prims["lit_first"][inst].astype(np.int64)
    rows, k = _expand(np.arange(len(inst)), packed.prims["lit_count"][inst].astype(np.int64))
    lits = packed.prim_literals[lit_first[rows] + k].astype(np.int64)
    j, sign = lits[:, 0], lits[:, 1]
    own = j == q[rows]
    A, b, c, lam, scale = (t[j] for t in tables)
    x, rad = p[rows], R[rows]
    g = 2 * (np.einsum("nij,nj->ni", A, x) + b)
    value = np.einsum("ni,ni->n", x, 0.5 * g + b) + c
    gl = np.sqrt(np.einsum("ni,ni->n", g, g))
    lo = value - gl * rad + lam[:, 0] * rad * rad
    hi = value + gl * rad + lam[:, 1] * rad * rad
    tol = scale * (1 + np.abs(x).sum(axis=1) + rad) ** 2
    fails = np.where(sign > 0, lo > tol, hi < -tol) & ~own
    holds = np.where(sign > 0, hi < -tol, lo > tol) | own
    n = len(inst)
    neg_side = np.bincount(rows[own & (sign > 0)], minlength=n) > 0  # Q <= 0: only the negative side
    pos_side = np.bincount(rows[own & (sign < 0)], minlength=n) > 0
    sides = np.where(neg_side, 1, 3) & np.where(pos_side, 2, 3)
    return np.bincount(rows[fails], minlength=n) > 0, np.bincount(rows[~holds], minlength=n) == 0, sides


def _quadric_tables(packed: PackedScene) -> tuple:
    """Per quadric (device coordinates) A, b, c of Q(x) = x^T A x + 2 b.x + c, (min(lam_min, 0),
    max(lam_max, 0)) of A, and the rounding margin per unit of (1 + |x|_1 + r)^2."""
    M = packed.local_matrices
    lam = np.linalg.eigvalsh(M[:, :3, :3]) if len(M) else np.zeros((0, 3))
    return (M[:, :3, :3], M[:, :3, 3], M[:, 3, 3], np.stack([np.minimum(lam[:, 0], 0), np.maximum(lam[:, -1], 0)], axis=1),
            ULPS * float(np.finfo(packed.real).eps) * np.abs(M).sum(axis=(1, 2)))


def _replay_program(packed: PackedScene, tables: tuple, splats: np.ndarray, cand_splat: np.ndarray, cand_inst: np.ndarray,
                    q: np.ndarray, p: np.ndarray, R: np.ndarray) -> np.ndarray:
    """For splats (indices into q, p, R) whose owners' states are all known and of which two or
    more hold (cand_splat / cand_inst: the holding ones, in owner order): the first candidate
    whose switching changes the instance program (lane 0 plain, lane 1 + i with instance i
    switched), else the first candidate; -1 where a lane it needs is unknown over the ball."""
    n_inst = len(packed.prims)
    pos_of = np.full(len(q), -1, dtype=np.int64)
    pos_of[splats] = np.arange(len(splats))
    cs = pos_of[cand_splat]
    firsts = np.full(len(splats), -1, dtype=np.int64)
    firsts[cs[::-1]] = cand_inst[::-1]  # the first candidate of each splat
    if packed.instance_rows == 0:
        return firsts
    if n_inst > MAX_INSTANCES:
        return np.full(len(splats), -1, dtype=np.int64)
    rows, inst = _expand(np.arange(len(splats)), np.full(len(splats), n_inst))
    bits, known = _states(packed, tables, inst, q[splats][rows], p[splats][rows], R[splats][rows])
    val, kn = _lanes(packed, bits.reshape(-1, n_inst), np.where(known, 3, 0).astype(np.uint8).reshape(-1, n_inst))
    lane0_known = kn[:, 0] == 3
    c_known = kn[cs, 1 + cand_inst] == 3
    differs = c_known & (val[cs, 1 + cand_inst] != val[cs, 0])
    stop = differs | ~c_known  # the first candidate that decides (or cannot be decided)
    order = np.arange(len(cs))
    first_stop = np.full(len(splats), len(cs), dtype=np.int64)
    np.minimum.at(first_stop, cs[stop], order[stop])
    res = firsts.copy()
    hit = first_stop < len(cs)
    res[hit] = np.where(differs[first_stop[hit]], cand_inst[first_stop[hit]], -1)
    res[~lane0_known] = -1
    return res


def _lanes(packed: PackedScene, bits: np.ndarray, known: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The instance program in three-valued logic, per splat (rows of bits / known, one column
    per instance) and lane (0 plain, 1 + i: instance i's two bits complemented): the output's
    two bits and which of them are known (3: both)."""
    n, n_inst = bits.shape
    lanes = n_inst + 1
    regs: dict[int, tuple[np.ndarray, np.ndarray]] = {}
    ops = packed.instance_tape[: packed.instance_rows]
    for op, o, a, b in zip(*(ops[f].tolist() for f in ("op", "out", "a", "b"))):
        if op == OP_LEAF:
            v = np.repeat(bits[:, a:a + 1], lanes, axis=1)
            v[:, 1 + a] ^= 3
            if b < 0:
                v = ~v & 3
            regs[o] = (v, np.repeat(known[:, a:a + 1], lanes, axis=1))
        elif op in (OP_AND, OP_OR):
            (va, ka), (vb, kb) = regs[a], regs[b]
            if op == OP_AND:
                regs[o] = (va & vb, (ka & kb) | (ka & ~va & 3) | (kb & ~vb & 3))
            else:
                regs[o] = (va | vb, (ka & kb) | (ka & va) | (kb & vb))
        elif op == OP_COPY:
            regs[o] = regs[a]
        else:
            regs[o] = (np.full((n, lanes), 3 if a else 0, np.uint8), np.full((n, lanes), 3, np.uint8))
    v, k = regs[int(ops["out"][-1])]
    return v & k, k
