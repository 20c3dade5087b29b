"""Float64 numpy interpreters of a tape, and tape pruning over a ball: the reference for the
device interpreters in ``cl/include/tape.h`` (same algorithms, instruction for instruction).

Substitution (the quadric-relative view of paper eq. 22, generalized to any tree): for a point
on quadric q, every leaf on q, whatever its place in the tree and its polarity, is replaced by
the constant it has just on q's negative side (K_q < 0) and just on its positive side.  A leaf
(q, s) holds on the negative side iff s = +1.  The point is on the CSG surface, carried by q,
iff the root's membership differs between the two sides, and with f-, f+ the real-valued tapes
(TRUE = -inf, FALSE = +inf for the substituted leaves)

    d_q(p) = min( max(f-(p), -f+(p)),  max(-f-(p), f+(p)) )

is negative iff p is on the surface, and |d_q| is a radius on q within which that
classification holds (first branch: the solid is on the negative side, outward normal
+grad K_q; second: the opposite).
"""

from __future__ import annotations

import numpy as np

from ..cl.constants import ROUNDING_ULPS
from ..model.quadric import Quadric, ray_distance
from ..cl.constants import OP_AND, OP_CONST, OP_COPY, OP_LEAF, OP_OR

#: pruning's rounding margin, relative to the region's size and distance from the origin
#: (the kernels' margin in float64)
PRUNE_SLACK = ROUNDING_ULPS * np.finfo(np.float64).eps


def _values(matrix, points):
    """x^T K x at homogeneous points x = (p, 1) (..., 3): the sum over i then j of
    (x_i K_ij) x_j, accumulated from +0 in that order (einsum's, to the bit).  Zero entries of
    K are skipped when every point is finite: their terms are +-0, and adding +-0 to a sum
    that starts at +0 changes no bit, so a plane costs 7 terms instead of 16."""
    xh = np.concatenate([points, np.ones(points.shape[:-1] + (1,))], axis=-1)
    k = np.asarray(matrix, dtype=np.float64)
    if not np.isfinite(xh).all():
        return np.einsum("...i,ij,...j->...", xh, k, xh)
    cols = [xh[..., i] for i in range(4)]
    acc = np.zeros(xh.shape[:-1])
    tmp = np.empty_like(acc)
    for i, j in zip(*np.nonzero(k)):
        np.multiply(cols[i], k[i, j], out=tmp)
        tmp *= cols[j]
        acc += tmp
    return acc


#: the upper triangle of a symmetric 4x4 matrix, and the factor of each entry in x^T M x
_TRIU = np.triu_indices(4)
_TRIU_FACTOR = np.where(_TRIU[0] == _TRIU[1], 1.0, 2.0)


def _values_many(matrices, points):
    """Q_u(x) = x^T M_u x (x homogeneous) of matrices (U, 4, 4) at points (N, 3) as (U, N):
    one product of the points' ten monomials x_i x_j (i <= j) with the matrices' upper
    triangles (off-diagonal entries twice)."""
    xh = np.concatenate([points, np.ones((len(points), 1))], axis=1)
    mono = xh[:, _TRIU[0]] * xh[:, _TRIU[1]]
    return (matrices[:, _TRIU[0], _TRIU[1]] * _TRIU_FACTOR) @ mono.T


def distances(tape_quadrics, q: int, points) -> np.ndarray:
    """Conservative signed distance d_q (eqs. 10-12) of canonical quadric ``q`` at ``points``."""
    return Quadric(tape_quadrics[q]).distance(points)


def _run(ops, leaf, conj, disj, const):
    """Run a tape over pairs (value with the substituted quadric on its - side, on its + side):
    ``leaf(q, sign)`` gives a leaf's pair, ``conj`` / ``disj`` combine values for AND / OR and
    ``const(a)`` is the pair of a constant row; returns the last row's pair."""
    regs: dict = {}
    for op, out, a, b in np.asarray(ops):
        if op == OP_LEAF:
            regs[out] = leaf(a, b)
        elif op == OP_AND or op == OP_OR:
            f = conj if op == OP_AND else disj
            regs[out] = (f(regs[a][0], regs[b][0]), f(regs[a][1], regs[b][1]))
        elif op == OP_COPY:
            regs[out] = regs[a]
        elif op == OP_CONST:
            regs[out] = const(a)
    return regs[ops[-1][1]]


def _cached(fn):
    cache: dict = {}

    def get(q):
        if q not in cache:
            cache[q] = fn(q)
        return cache[q]

    return get


def evaluate(ops, quadrics, points, self_quadric: int = -1):
    """(f-, f+): the tape over reals at ``points`` (N, 3), AND = max and OR = min of the leaves'
    signed distances (eqs. 10-12), with quadric ``self_quadric`` substituted by -+inf on its two
    sides (both equal f when it is -1)."""
    p = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    inf = np.full(len(p), np.inf)
    dist = _cached(lambda q: distances(quadrics, q, p))

    def leaf(q, sign):
        if q == self_quadric:
            return (-sign * inf, sign * inf)
        v = sign * dist(q)
        return (v, v)

    def const(a):
        v = -inf if a else inf
        return (v, v)

    return _run(ops, leaf, np.maximum, np.minimum, const)


def member(ops, quadrics, points, self_quadric: int = -1):
    """(m-, m+): membership (closed solid: K = 0 counts as inside) with ``self_quadric``
    substituted."""
    p = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    n = len(p)
    value = _cached(lambda q: _values(quadrics[q], p))

    def leaf(q, sign):
        if q == self_quadric:
            return (np.full(n, sign > 0), np.full(n, sign < 0))
        v = sign * value(q) <= 0.0
        return (v, v)

    def const(a):
        v = np.full(n, bool(a))
        return (v, v)

    return _run(ops, leaf, np.logical_and, np.logical_or, const)


def member_per_point(ops, quadrics, points, self_quadrics, chunk_entries: int = None):
    """(m-, m+) as :func:`member`, with a substituted quadric per point (``self_quadrics``
    (N,)): one run of the tape (as the min / max program of :func:`minmax_program`, in chunks
    of at most ``chunk_entries`` program rows x points) for points of many quadrics."""
    p = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    own = np.asarray(self_quadrics).reshape(-1)
    keys, steps, root = minmax_program(ops)
    used, key_q = np.unique(keys[:, 0], return_inverse=True)
    sign = keys[:, 1][:, None]
    k, rows = len(keys), len(keys) + 2 + len(steps)
    steps = steps.tolist()
    minus, plus = np.zeros(len(p), dtype=bool), np.zeros(len(p), dtype=bool)
    for s, e in _chunks(len(p), rows, chunk_entries):
        values = np.empty((rows, 2, e - s), dtype=np.int8)
        values[k], values[k + 1] = _KF, _KT
        if k:
            inside = _values_many(np.asarray(quadrics)[used], p[s:e])[key_q] * sign <= 0.0
            values[:k] = np.where(inside, _KT, _KF)[:, None]
            _substitute_own(values, keys, own[s:e])
        _run_minmax(steps, values)
        minus[s:e], plus[s:e] = values[root] == _KT
    return minus, plus


def contains(ops, quadrics, points) -> np.ndarray:
    return member(ops, quadrics, points)[0]


def contains_around(ops, quadrics, centers, eps: float, directions) -> np.ndarray:
    """Membership (closed solid) at the points c_i + eps d_j round ``centers`` (N, 3) in the
    unit ``directions`` (k, 3), as (N, k) bool.  A leaf's value there comes from its expansion
    about c, exact for a quadric:

        K(c + e d) = K(c) + 2 e (K c)[:3] . d + e^2 d^T K[:3, :3] d

    (the tape's leaf quadrics expanded in one batched product, instead of the form at N k
    points)."""
    c = np.asarray(centers, dtype=np.float64).reshape(-1, 3)
    d = np.asarray(directions, dtype=np.float64)
    ch = np.concatenate([c, np.ones((len(c), 1))], axis=1)
    shape = (len(c), len(d))
    rows = np.asarray(ops).tolist()
    used = sorted({a for op, _, a, _ in rows if op == OP_LEAF})
    slot = {q: i for i, q in enumerate(used)}
    k = quadrics[used]  # (Q, 4, 4): every leaf's expansion at once
    # (K c) per leaf and point, then its slopes along the directions: one small product per
    # leaf each (a single large one would wake BLAS's threads, whose spinning costs more CPU
    # time than the product)
    kc = np.matmul(ch, k)
    vals = np.matmul(np.ascontiguousarray(kc[:, :, :3]), (2.0 * eps) * d.T)
    vals += np.einsum("qnj,nj->qn", kc, ch)[:, :, None]
    vals += (eps * eps) * np.einsum("kj,qji,ki->qk", d, k[:, :3, :3], d)[:, None, :]

    def values(q):
        return vals[slot[q]]

    return run_boolean(rows, lambda q, sign: sign * values(q) <= 0.0, shape)


def run_boolean(rows, leaf, shape):
    """A tape's rows (a list of (op, out, a, b)) over booleans: ``leaf(a, sign)`` a leaf's
    membership array, AND / OR as & / |, constants filled to ``shape``; the last row's value."""
    regs: dict = {}
    for op, out, a, b in rows:
        if op == OP_LEAF:
            regs[out] = leaf(a, b)
        elif op == OP_AND:
            regs[out] = regs[a] & regs[b]
        elif op == OP_OR:
            regs[out] = regs[a] | regs[b]
        elif op == OP_COPY:
            regs[out] = regs[a]
        elif op == OP_CONST:
            regs[out] = np.full(shape, bool(a))
    return regs[rows[-1][1]]


# -- pruning -------------------------------------------------------------------------------------

_F, _T, _LIVE = 0, 1, 2


def leaf_over_region(matrix, sign: int, center, axes, rho: float) -> int:
    """State of the literal (matrix, sign) over the region: the oriented box
    center + sum_m u_m axes[m] (|u_m| <= 1) grown by a ball of radius rho.  Planes are tested
    exactly (a linear function's range over the box), other quadrics by the conservative
    distance at the center against rho plus the box's half-diagonal.  The rounding slack's
    scale takes 1-norms, as the kernels do (``prune_consts_of`` in tape.h)."""
    c = np.asarray(center, dtype=np.float64).reshape(3)
    ax = np.asarray(axes, dtype=np.float64).reshape(3, 3)
    scale = abs(rho) + np.abs(c).sum() + np.abs(ax).sum()
    slack = PRUNE_SLACK * scale
    m = np.asarray(matrix)
    if not np.any(m[:3, :3]):
        g = 2.0 * sign * m[:3, 3]
        v = g @ c + sign * m[3, 3]
        spread = np.abs(ax @ g).sum() + (rho + slack) * np.linalg.norm(g)
        return _F if v > spread else _T if v < -spread else _LIVE
    d = sign * float(Quadric(m).distance(c.reshape(1, 3))[0])
    reach = rho + float(np.sqrt((ax * ax).sum())) + slack
    return _F if d >= reach else _T if d <= -reach else _LIVE


def prune(ops, quadrics, center, radius: float, self_quadric: int = -1, axes=None, leaf_state=None):
    """The tape simplified over a region: (ops, decided, evaluations).

    The region is the ball (center, radius), or with ``axes`` (3, 3) the oriented box
    center + sum_m u_m axes[m] grown by ``radius`` (see :func:`leaf_over_region`).
    Forward pass over the registers: a leaf that keeps one sign over the region becomes TRUE
    or FALSE (leaves on
    ``self_quadric`` stay: they are substituted later); AND with FALSE is FALSE, with TRUE the
    other operand (a COPY unless it already sits in the output register); OR likewise.  The
    same pass tracks, per side of ``self_quadric``, a three-valued state (TRUE, FALSE,
    unknown) of every register.  Backward pass: instructions whose result no later
    instruction reads are dropped.  ``decided``: +1 if both sides are known and equal over the
    whole ball (no surface on the self quadric there), -1 if known and different (all of the
    quadric inside the ball is surface), 0 otherwise.  A constant tape is one CONST row.
    ``leaf_state(quadric, sign)``, if given, is a leaf's state over the region in place of
    :func:`leaf_over_region` (states found for many regions at once).
    """
    axes = np.zeros((3, 3)) if axes is None else axes
    ops = np.asarray(ops)
    state: dict = {}  # register -> (tape state, side-, side+) with side states in {F, T, LIVE}
    emitted = []
    evaluations = 0
    for op, out, a, b in ops:
        if op == OP_LEAF:
            if a == self_quadric:
                state[out] = (_LIVE, _T if b > 0 else _F, _F if b > 0 else _T)
                emitted.append((op, out, a, b))
                continue
            evaluations += 1
            st = leaf_over_region(quadrics[a], b, center, axes, radius) if leaf_state is None else leaf_state(a, b)
            state[out] = (st, st, st)
            if st == _LIVE:
                emitted.append((op, out, a, b))
        elif op in (OP_AND, OP_OR):
            sa, sb = state[a], state[b]
            absorb, neutral = (_F, _T) if op == OP_AND else (_T, _F)
            table = _AND3 if op == OP_AND else _OR3
            sides = (table[sa[1], sb[1]], table[sa[2], sb[2]])
            if sa[0] == absorb or sb[0] == absorb:
                state[out] = (absorb,) + sides
            elif sa[0] == neutral or sb[0] == neutral:
                src = b if sa[0] == neutral else a
                if state[src][0] == _LIVE and src != out:
                    emitted.append((OP_COPY, out, src, 0))
                state[out] = (state[src][0],) + sides
            else:
                emitted.append((op, out, a, b))
                state[out] = (_LIVE,) + sides
        elif op == OP_COPY:
            state[out] = state[a]
            if state[a][0] == _LIVE and a != out:
                emitted.append((op, out, a, b))
        elif op == OP_CONST:
            state[out] = (_T, _T, _T) if a else (_F, _F, _F)
    root = int(ops[-1][1])
    st = state[root]
    known = st[1] != _LIVE and st[2] != _LIVE
    decided = 0 if not known else (1 if st[1] == st[2] else -1)
    if st[0] != _LIVE:
        return np.array([[OP_CONST, root, int(st[0] == _T), 0]], dtype=np.int32), decided, evaluations
    if not emitted or emitted[-1][1] != root:
        emitted.append((OP_COPY, root, root, 0))
    # backward pass: liveness over registers
    needed = {root}
    kept = []
    for ins in reversed(emitted):
        op, out, a, b = ins
        if out not in needed:
            continue
        if not (op == OP_COPY and a == out):
            needed.discard(out)
        if op in (OP_AND, OP_OR):
            needed.update((a, b))
        elif op == OP_COPY:
            needed.add(a)
        kept.append(ins)
    kept.reverse()
    return np.array(kept, dtype=np.int32).reshape(-1, 4), decided, evaluations


#: _combine3 of scalar states, looked up (the pruning pass meets them one register at a time)
_AND3 = {(x, y): _F if _F in (x, y) else _T if x == y == _T else _LIVE for x in (_F, _T, _LIVE) for y in (_F, _T, _LIVE)}
_OR3 = {(x, y): _T if _T in (x, y) else _F if x == y == _F else _LIVE for x in (_F, _T, _LIVE) for y in (_F, _T, _LIVE)}


def _combine3(op, x, y):
    """Three-valued AND / OR of states in {F, T, LIVE} (arrays or scalars)."""
    absorb, neutral = (_F, _T) if op == OP_AND else (_T, _F)
    x, y = np.asarray(x), np.asarray(y)
    out = np.where((x == absorb) | (y == absorb), absorb, np.where((x == neutral) & (y == neutral), neutral, _LIVE))
    return out if out.ndim else int(out)


def leaf_states_over_boxes(matrix, sign: int, lo, hi) -> np.ndarray:
    """:func:`leaf_over_region` for many axis-aligned boxes [lo, hi] (N, 3) at once (rho = 0)."""
    lo, hi = np.asarray(lo, dtype=np.float64), np.asarray(hi, dtype=np.float64)
    c, half = 0.5 * (lo + hi), 0.5 * (hi - lo)
    scale = np.linalg.norm(c, axis=1) + half.sum(axis=1)
    slack = PRUNE_SLACK * scale
    m = np.asarray(matrix, dtype=np.float64)
    if not np.any(m[:3, :3]):
        g = 2.0 * sign * m[:3, 3]
        v = c @ g + sign * m[3, 3]
        spread = half @ np.abs(g) + slack * np.linalg.norm(g)
    else:
        v = sign * Quadric(m).distance(c)
        spread = np.linalg.norm(half, axis=1) + slack
    return np.where(v > spread, _F, np.where(v < -spread, _T, _LIVE))


def _is_plane(matrices) -> np.ndarray:
    """Per 4x4 matrix: True for a plane (no quadratic part)."""
    return ~np.any(matrices[:, :3, :3] != 0, axis=(1, 2))


def _planes_first(quadrics, used, key_q):
    """(used, key_q) with the planes of ``used`` first (their values are then computed in
    place) and ``key_q`` (rows into ``used``) following the new order."""
    perm = np.argsort(~_is_plane(np.asarray(quadrics, dtype=np.float64)[used].reshape(-1, 4, 4)), kind="stable")
    inverse = np.empty_like(perm)
    inverse[perm] = np.arange(len(perm))
    return used[perm], inverse[key_q]


def _signed_leaf_values(quadrics, used, lo, hi):
    """Per quadric of ``used`` and box [lo, hi] (N, 3): (v, spread) with the literal (q, sign)
    FALSE over the box where sign v > spread, TRUE where sign v < -spread (the tests of
    :func:`leaf_states_over_boxes`, for all quadrics at once: a sign only negates v)."""
    c, half = 0.5 * (lo + hi), 0.5 * (hi - lo)
    slack = PRUNE_SLACK * (np.linalg.norm(c, axis=1) + half.sum(axis=1))
    M = np.asarray(quadrics, dtype=np.float64)[np.asarray(used, dtype=np.int64)].reshape(-1, 4, 4)
    v = np.empty((len(M), len(c)))
    spread = np.empty((len(M), len(c)))
    flat = _is_plane(M)
    nf = int(flat.sum())
    if nf and flat[:nf].all():  # planes first (:func:`_planes_first`): written in place
        g = 2.0 * M[:nf, :3, 3]
        np.matmul(g, c.T, out=v[:nf])
        v[:nf] += M[:nf, 3, 3][:, None]
        np.matmul(np.abs(g), half.T, out=spread[:nf])
        spread[:nf] += np.linalg.norm(g, axis=1)[:, None] * slack[None]
    elif nf:
        g = 2.0 * M[flat, :3, 3]
        v[flat] = g @ c.T + M[flat, 3, 3][:, None]
        spread[flat] = np.abs(g) @ half.T + np.linalg.norm(g, axis=1)[:, None] * slack[None]
    k = np.flatnonzero(~flat)
    if len(k):
        A, b = M[k, :3, :3], -M[k, :3, 3]
        lam = np.linalg.eigvalsh(A)
        Ac = np.einsum("kij,nj->kni", A, c)
        f = np.einsum("kni,ni->kn", Ac, c) - 2.0 * (b @ c.T) + M[k, 3, 3][:, None]
        grad = 2.0 * np.linalg.norm(Ac - b[:, None, :], axis=2)
        v[k] = ray_distance(f, grad, lam[:, :1], lam[:, 2:])
        spread[k] = np.linalg.norm(half, axis=1)[None] + slack[None]
    return v, spread


#: the states as ordered values FALSE < LIVE < TRUE: three-valued (Kleene) AND is the min,
#: OR the max, and two-valued logic is the same on FALSE and TRUE alone
_KF, _KL, _KT = 0, 1, 2
#: the most (program rows x boxes or points) a tape run holds at once: the work is split in
#: chunks of columns to keep its arrays to a few tens of MiB
CHUNK_ENTRIES = 1 << 23


def minmax_program(ops):
    """The tape as a straight-line program over rows of values: (keys, steps, root).

    ``keys`` (k, 2): the distinct leaf literals (quadric, sign) in sorted order, rows 0..k-1;
    rows k and k+1 hold the constants FALSE and TRUE; ``steps`` (m, 4) rows [is_or, out, a, b]
    with row out = max (OR) or min (AND) of rows a and b, one new row per AND / OR.  Registers
    are renamed (each instruction's result is a value of its own: an operand is the last
    value written to its register before), COPY is an alias, and the steps and leaves whose
    result does not reach the root are dropped; ``root``: the row of the last instruction's
    register.
    """
    ops = np.asarray(ops, dtype=np.int64).reshape(-1, 4)
    n = len(ops)
    op, out, a, b = ops.T
    index = np.arange(n)
    order = np.lexsort((index, out))
    written = out[order] * (n + 1) + order

    def source(reg):
        """Per instruction, the instruction that last wrote register ``reg`` before it."""
        return order[np.maximum(np.searchsorted(written, reg * (n + 1) + index) - 1, 0)]

    src_a, src_b = source(a), source(b)
    alias = np.where(op == OP_COPY, src_a, index)
    while True:  # copies of copies: at most log2(n) rounds
        deeper = alias[alias]
        if np.array_equal(deeper, alias):
            break
        alias = deeper
    binary = (op == OP_AND) | (op == OP_OR)
    child_a, child_b = alias[src_a], alias[src_b]
    root = int(alias[n - 1])
    live = bytearray(n)
    live[root] = 1
    is_step, ca, cb = binary.tolist(), child_a.tolist(), child_b.tolist()
    for i in range(root, -1, -1):
        if live[i] and is_step[i]:
            live[ca[i]] = live[cb[i]] = 1
    live = np.frombuffer(bytes(live), dtype=np.uint8).astype(bool)
    leaf = live & (op == OP_LEAF)
    keys, key_of = np.unique(np.stack([a[leaf], b[leaf]], axis=1), axis=0, return_inverse=True)
    k = len(keys)
    step = np.flatnonzero(live & binary)
    row = np.zeros(n, dtype=np.int64)
    row[leaf] = key_of.reshape(-1)
    row[op == OP_CONST] = k + (a[op == OP_CONST] != 0)
    row[step] = k + 2 + np.arange(len(step))
    steps = np.stack([op[step] == OP_OR, row[step], row[child_a[step]], row[child_b[step]]], axis=1)
    return keys.reshape(-1, 2), steps.astype(np.int64).reshape(-1, 4), int(row[root])


def _run_minmax(steps, values) -> None:
    """Run ``steps`` of :func:`minmax_program` in place over ``values`` (rows, ...)."""
    lo, hi = np.minimum, np.maximum
    for is_or, out, a, b in steps:
        (hi if is_or else lo)(values[a], values[b], out=values[out])


def _substitute_own(values, keys, own) -> None:
    """Put the substituted constants in the leaf rows of ``values`` (rows, 2, n): where column j
    belongs to quadric own[j], its literal (own[j], s) is TRUE on the negative side (index 0)
    and FALSE on the positive side when s = +1, the opposite when s = -1."""
    order = np.argsort(keys[:, 0], kind="stable")
    kq = keys[order, 0]
    first = np.searchsorted(kq, own, side="left")
    count = np.searchsorted(kq, own, side="right") - first
    col = np.repeat(np.arange(len(own)), count)
    step = np.arange(len(col)) - np.repeat(np.cumsum(count) - count, count)
    key = order[np.repeat(first, count) + step]
    positive = keys[key, 1] > 0
    values[key, 0, col] = np.where(positive, _KT, _KF)
    values[key, 1, col] = np.where(positive, _KF, _KT)


def _leaf_states(states, keys, key_q, v, spread) -> None:
    """The states (k, n) of the literals ``keys`` (quadric row ``key_q``, sign) over n boxes
    from :func:`_signed_leaf_values`: (q, s) is FALSE where s v > spread, else TRUE where
    s v < -spread, else LIVE.  Negating v is exact, so for s = -1 the two tests are v < -spread
    and v > spread: both signs come from the same two comparisons."""
    above = v > spread
    below = np.less(v, np.negative(spread, out=spread))
    positive = keys[:, 1] > 0
    for side, false, true in ((positive, above, below), (~positive, below, above)):
        if side.all():
            rows = key_q
        elif side.any():
            rows = key_q[side]
        else:
            continue
        st = true[rows].view(np.int8) + np.int8(_KL)  # TRUE or LIVE ...
        st *= ~false[rows]  # ... or FALSE
        if side.all():
            states[:] = st
        else:
            states[side] = st


def _chunks(n: int, rows: int, entries: int = None):
    """Column ranges of at most ``entries`` (default :data:`CHUNK_ENTRIES`) / ``rows`` columns
    covering range(n)."""
    size = max(1, (entries or CHUNK_ENTRIES) // max(rows, 1))
    return [(s, min(n, s + size)) for s in range(0, n, size)]


def surface_in_boxes(ops, quadrics, lo, hi, box_quadric, chunk_entries: int = None, program=None) -> np.ndarray:
    """Mask of the boxes [lo, hi] (N, 3) in which quadric ``box_quadric[i]`` may carry CSG
    surface: False where pruning over the box decides that the two substituted sides of the
    tape are the same constant (:func:`prune`'s ``decided`` = +1), for all boxes at once.

    The leaves' states over each box (:func:`leaf_states_over_boxes`) go through the tape
    as a program of min / max (:func:`minmax_program`: three-valued AND / OR) on the two
    sides at once, in chunks of at most ``chunk_entries`` program rows x boxes.  ``program``:
    the :func:`minmax_program` of ``ops`` if already made (the same tape over many calls)."""
    lo, hi = np.asarray(lo, dtype=np.float64), np.asarray(hi, dtype=np.float64)
    own = np.asarray(box_quadric).reshape(-1)
    keys, steps, root = minmax_program(ops) if program is None else program
    used, key_q = _planes_first(quadrics, *np.unique(keys[:, 0], return_inverse=True))
    rows = len(keys) + 2 + len(steps)
    steps = steps.tolist()
    mask = np.ones(len(lo), dtype=bool)
    for s, e in _chunks(len(lo), rows, chunk_entries):
        values = np.empty((rows, 2, e - s), dtype=np.int8)
        values[len(keys)] = _KF
        values[len(keys) + 1] = _KT
        if len(keys):
            _leaf_states(values[:len(keys), 0], keys, key_q, *_signed_leaf_values(quadrics, used, lo[s:e], hi[s:e]))
            values[:len(keys), 1] = values[:len(keys), 0]
            _substitute_own(values, keys, own[s:e])
        _run_minmax(steps, values)
        neg, pos = values[root]
        mask[s:e] = ~((neg != _KL) & (neg == pos))
    return mask
