"""Root tapes per sampled quadric: the tape pruned, primitive by primitive, to what can matter
over a region (the patches of the quadric's sampling tasks).

A primitive's solid misses a region its exact box misses: over that region the primitive is
FALSE and its complement TRUE, whatever the point.  So in the compiled expression DAG (the
negation normal form the tape is emitted from) the node of such a primitive is a constant, and
constants fold (FALSE absorbs AND, TRUE absorbs OR, the neutral element drops out).  The
nodes of the primitives holding the sampled quadric are never replaced: the sampler substitutes
that quadric's leaves by constants on its two sides, and a primitive with a substituted leaf is
no longer its own solid.  The result is exact over the region: the same membership and the same
conservative distances (eq. 22 on the tree) at every point of it as the full tape.

The pruned expression is built from the near primitives upwards, so the work per quadric is the
size of its pruned tape (and of the ancestors of its near primitives), not of the whole tape:
each inner node knows how many of its operands are FALSE or TRUE when all their primitives are
at their defaults (``default``), and only operands holding a near or fixed primitive are
visited.  A primitive's default is far, except for a half-space's, which is to hold the region:
a half-space has no box, and a convex solid of many planes (a hull, a convex mesh) lies in
nearly all of them, so a region lists only the few half-spaces crossing it or missing it, and
the work stays with the planes near it, not with all of them.
"""

from __future__ import annotations

import numpy as np

from ..model.bvh import BoxTree, morton_order
from .tape import _AND, _CONST, _FALSE, _LEAF, _OR, _TRUE, _Builder, _emit, _postorder


class PrimitiveDag:
    """The expression DAG of a tree tape and where its primitives are in it.

    ``builder``/``root``: the compiler's hash-consed DAG; ``prims``: expression id -> the
    (instance index, negated) pairs whose expression it is."""

    def __init__(self, builder: _Builder, root: int, prims: dict, held=frozenset()):
        self.b, self.root = builder, root
        self.order = _postorder(builder, root)
        self.pos = {e: k for k, e in enumerate(self.order)}
        self.by_instance: dict = {}
        #: expression -> negated, for the expressions whose instances all have one polarity
        #: (they are one solid: equal expressions are one node)
        self.negated: dict = {}
        for e, owners in prims.items():
            if e in self.pos:
                for inst, _ in owners:
                    self.by_instance.setdefault(inst, []).append(e)
                polarity = {bool(neg) for _, neg in owners}
                if len(polarity) == 1:
                    self.negated[e] = polarity.pop()
        self.parents: dict = {}
        self.default: dict = {_TRUE: True, _FALSE: False}
        self.n_false: dict = {}
        self.n_true: dict = {}
        self.none_args: dict = {}
        for e in self.order:
            kind = builder.kind[e]
            if kind == _CONST:
                continue
            if kind in (_AND, _OR):
                args = builder.args[e]
                for a in args:
                    self.parents.setdefault(a, []).append(e)
                d = [self.default.get(a) for a in args]
                self.n_false[e] = sum(x is False for x in d)
                self.n_true[e] = sum(x is True for x in d)
                self.none_args[e] = [a for a, x in zip(args, d) if x is None]
            owners = prims.get(e, ())
            polarities = {neg for _, neg in owners}
            if len(polarities) == 1:  # a primitive: FALSE where it is far, its complement TRUE
                neg = polarities.pop()
                # or, for the held ones, TRUE where it is not listed (its complement FALSE)
                self.default[e] = (not neg) if all(i in held for i, _ in owners) else neg
            elif kind == _AND:
                self.default[e] = False if self.n_false[e] else (True if self.n_true[e] == len(args) else None)
            elif kind == _OR:
                self.default[e] = True if self.n_true[e] else (False if self.n_false[e] == len(args) else None)
            else:
                self.default[e] = None

    def pruned(self, near_instances, outside_instances=(), registers=None) -> tuple[np.ndarray, int]:
        """(ops, registers) of the tape with the primitives of ``near_instances`` kept, those of
        ``outside_instances`` FALSE (the region misses their solid: their complements TRUE) and
        every other one at its default: far (FALSE, its complement TRUE), or for a held
        instance (given when the DAG was built: a half-space, whose solid holds most regions)
        TRUE, its complement FALSE.  ``registers``: the count it should fit (the full tape's)."""
        near = {e for i in near_instances for e in self.by_instance.get(int(i), ())}
        fixed = {}
        for i in outside_instances:
            for e in self.by_instance.get(int(i), ()):
                if e in near:
                    continue
                if e not in self.negated:  # of both polarities: kept as it is
                    near.add(e)
                elif self.default[e] != self.negated[e]:  # held: the region misses it here
                    fixed[e] = _TRUE if self.negated[e] else _FALSE
        live: dict = {self.root: set()}
        stack = list(near) + list(fixed)
        seen = set(stack)
        while stack:
            e = stack.pop()
            for p in self.parents.get(e, ()):
                live.setdefault(p, set()).add(e)
                if p not in seen:
                    seen.add(p)
                    stack.append(p)
        nb, full, need = self._target()
        built: dict = {}
        for e in sorted(seen | {self.root}, key=self.pos.__getitem__):
            if e in fixed:
                built[e] = fixed[e]
                continue
            if e in near or self.b.kind[e] in (_LEAF, _CONST):
                built[e] = self._copy(e, nb, full)
                continue
            kind = self.b.kind[e]
            args = live.get(e, set())
            n_false = self.n_false[e] - sum(self.default.get(a) is False for a in args)
            n_true = self.n_true[e] - sum(self.default.get(a) is True for a in args)
            if (kind == _AND and n_false) or (kind == _OR and n_true):
                built[e] = _FALSE if kind == _AND else _TRUE
                continue
            ids = [built[a] for a in args] + [self._copy(a, nb, full) for a in self.none_args[e] if a not in args]
            built[e] = nb.combine(kind, ids)
        return _emit(nb, built[self.root], registers, need)

    def _target(self) -> tuple:
        """(builder, copies, register estimates) shared by the tapes pruned from this DAG: a
        primitive's sub-DAG is copied into the builder once, however many regions keep it (a
        hole of the 2,500-hole plate is near 20 of its 599 root tapes), and its estimates are
        found once.  Started again past TARGET_NODES times the DAG's nodes."""
        if getattr(self, "_nb", None) is None or len(self._nb.kind) > TARGET_NODES * max(len(self.order), 64):
            self._nb, self._full, self._need = _Builder(), {}, {}
        return self._nb, self._full, self._need

    def _copy(self, e, nb: _Builder, full: dict) -> int:
        """The whole sub-DAG of ``e`` in ``nb`` (iterative post-order, memoized in ``full``)."""
        stack = [(e, False)]
        while stack:
            x, done = stack.pop()
            if x in full:
                continue
            kind = self.b.kind[x]
            if kind == _CONST:
                full[x] = x
            elif kind == _LEAF:
                full[x] = nb.leaf(*self.b.args[x])
            elif done:
                full[x] = nb.combine(kind, [full[a] for a in self.b.args[x]])
            else:
                stack.append((x, True))
                stack.extend((a, False) for a in self.b.args[x] if a not in full)
        return full[e]


def primitive_dag(tape) -> PrimitiveDag | None:
    """The :class:`PrimitiveDag` of a tree tape (built once and kept on the tape), None for a
    tape without one (the DNF shape).  Its half-spaces (:func:`half_spaces`) are held: TRUE
    unless a region lists them as crossing or outside, since a convex solid of many planes (a
    hull, a convex mesh, a mesh's BSP cell) lies in nearly all of them, so the lists a region
    gives stay as short as the planes that cross it."""
    if getattr(tape, "dag", None) is None:
        return None
    cached = getattr(tape, "_primitive_dag", None)
    if cached is None:
        cached = tape._primitive_dag = PrimitiveDag(*tape.dag, held=frozenset(half_spaces(tape)))
    return cached


def half_spaces(tape) -> list:
    """The instances of ``tape`` that are one plane's half-space (their box is all of space, so
    a box test keeps every one near; :func:`_half_space_sides` decides them exactly)."""
    Q = np.asarray(tape.quadrics)
    return [k for k, i in enumerate(tape.instances) if i.box is not None and i.node.kind == "halfspace"
            and getattr(i.node, "support", None) is None
            and len(i.literals) == 1 and not np.any(Q[i.literals[0][0], :3, :3])]


#: a quadric whose region holds more than this fraction of the primitives keeps the full tape
#: (pruning would save little), and past a budget of (quadric, near primitive) pairs in all,
#: the remaining quadrics keep it too: MAX_NEAR, or where more, 1/NEAR_SHARE of the rows the
#: full tape would give their root cells (the host's pruning then costs a small share of the
#: level-0 work it saves; a mesh of 20,000 face planes has about 1.3M pairs)
DENSE_FRACTION = 0.5
#: the tapes pruned from a DAG share a builder until it has this many times the DAG's nodes
TARGET_NODES = 16
MAX_NEAR = 400_000
NEAR_SHARE = 64
#: quadrics whose regions are neighbours along a Morton curve share one root tape, pruned to
#: the union of their near primitives (fewer, slightly longer tapes: less host work): GROUP
#: of them, or more where that would make more than ROOT_TAPES tapes (the host's pruning costs
#: about 10 ms per tape; a mesh of 20,000 face planes samples in 21 s instead of 26 s so)
GROUP = 8
ROOT_TAPES = 1024


def prune_root_tapes(tape, regions: dict, oriented: dict | None = None) -> tuple[dict, np.ndarray]:
    """Per quadric of ``regions`` ({quadric: (lo, hi) world box}) its root tape: ({quadric:
    (first, count)} into the returned rows (N, 4) int32, which start with the full tape).
    ``oriented`` ({quadric: (o, U, lo, hi)}, optional): a second box of each region, the points
    o + U z with lo <= z <= hi; the tapes are then exact over the part of each world box in it.

    A primitive is near a quadric's region if its box meets it (a
    :class:`~clcsg.model.bvh.BoxTree` query for all regions at once); the primitives holding
    the quadric are always near.  A tape pruned to a set of near primitives is exact over every
    region whose near primitives it holds, so :data:`GROUP` neighbouring quadrics (more past
    :data:`ROOT_TAPES` tapes) share one, and equal near sets one tape."""
    full = np.asarray(tape.ops, dtype=np.int32)
    out = {q: (0, len(full)) for q in regions}
    dag = primitive_dag(tape)
    if dag is None or not regions:
        return out, full
    qs = list(regions)
    near, outside = _near_sets(tape, qs, regions, oriented)
    n_inst = len(tape.instances)
    sparse = [k for k, nr in enumerate(near) if len(nr) <= DENSE_FRACTION * n_inst]
    centers = np.array([0.5 * (regions[qs[k]][0] + regions[qs[k]][1]) for k in sparse]).reshape(-1, 3)
    sparse = [sparse[k] for k in morton_order(centers)]
    rows, used, shared = [full], len(full), {}
    budget = max(MAX_NEAR, len(sparse) * len(full) // NEAR_SHARE)
    group = max(GROUP, -(-len(sparse) // ROOT_TAPES))
    for g in range(0, len(sparse), group):
        members = sparse[g:g + group]
        # a half-space outside some members' regions and not others' is near for the group
        outs = [frozenset(outside[k]) for k in members]
        missed = frozenset.intersection(*outs)
        key = frozenset().union(*(near[k] for k in members), *outs) - missed
        if len(key) > budget:
            break
        budget -= len(key)
        if (key, missed) not in shared:
            ops, regs = dag.pruned(key, outside_instances=missed, registers=tape.n_regs)
            if regs > tape.n_regs or len(ops) >= len(full):
                shared[key, missed] = (0, len(full))
            else:
                shared[key, missed] = (used, len(ops))
                rows.append(ops)
                used += len(ops)
        for k in members:
            out[qs[k]] = shared[key, missed]
    return out, np.concatenate(rows).astype(np.int32)


def _near_sets(tape, qs, regions, oriented=None) -> tuple[list, list]:
    """Per quadric of ``qs``, (near, outside): the instances whose boxes meet its region, its
    owners and the half-spaces whose plane may cross the region; and the half-spaces whose
    solid misses the whole region (:func:`_half_space_sides`, then :func:`_oriented_sides` on
    the crossing ones where the region has an ``oriented`` box).  The other half-spaces hold
    it, their default in the :class:`PrimitiveDag` (:func:`primitive_dag`)."""
    halves, lo, hi = _boxes_but_half_spaces(tape)
    rlo = np.array([regions[q][0] for q in qs]).reshape(-1, 3)
    rhi = np.array([regions[q][1] for q in qs]).reshape(-1, 3)
    region_of, inst = BoxTree(lo, hi).query(rlo, rhi)
    order = np.argsort(region_of, kind="stable")
    region_of, inst = region_of[order], inst[order]
    bounds = np.searchsorted(region_of, np.arange(len(qs) + 1))
    owners = tape.owners()
    near = [set(inst[bounds[k]:bounds[k + 1]].tolist()) | set(owners[q]) for k, q in enumerate(qs)]
    outside: list = [set() for _ in qs]
    if halves:
        crossing, missed = _half_space_sides(tape, halves, rlo, rhi)
        if oriented:
            _oriented_sides(tape, halves, [oriented.get(q) for q in qs], rlo, rhi, crossing, missed)
        for k in range(len(qs)):
            near[k].update(crossing[k])
            outside[k].update(missed[k])
    return near, outside


def _boxes_but_half_spaces(tape):
    """(the half-space instances, per instance the box lo and hi (n, 3)): empty (+inf, -inf)
    for a half-space or an instance without a box, so that a box query never lists them."""
    halves = half_spaces(tape)
    is_half = np.zeros(len(tape.instances), dtype=bool)
    is_half[halves] = True
    lo = np.array([i.box[0] if i.box is not None and not h else np.full(3, np.inf)
                   for i, h in zip(tape.instances, is_half)]).reshape(-1, 3)
    hi = np.array([i.box[1] if i.box is not None and not h else np.full(3, -np.inf)
                   for i, h in zip(tape.instances, is_half)]).reshape(-1, 3)
    return halves, lo, hi


def local_instances(tape, lo, hi) -> tuple[list, list]:
    """Per box [lo, hi] (R, 3): (near, outside) for :meth:`PrimitiveDag.pruned`, the
    instances whose boxes meet it and the half-spaces whose plane may cross it, and the
    half-spaces whose solid misses it; over the box the pruned tape is the solid."""
    halves, ilo, ihi = _boxes_but_half_spaces(tape)
    box_of, inst = BoxTree(ilo, ihi).query(lo, hi)
    near = [set() for _ in range(len(lo))]
    for b, i in zip(box_of.tolist(), inst.tolist()):
        near[b].add(i)
    outside: list = [set() for _ in range(len(lo))]
    if halves:
        crossing, missed = _half_space_sides(tape, halves, lo, hi)
        for k in range(len(lo)):
            near[k].update(crossing[k])
            outside[k].update(missed[k])
    return near, outside


#: (node, half-space) pairs held at once by :func:`_half_space_sides` (the half-spaces are
#: taken in chunks so that even a plane crossing every region keeps to it)
_SIDE_CHUNK = 1 << 22


def _half_space_sides(tape, halves, rlo, rhi) -> tuple[list, list]:
    """Per region box [rlo, rhi] (R, 3), the half-space instances ``halves`` whose plane may
    cross it and those whose solid misses all of it (the rest hold it).  The solid s Q(x) <= 0
    of a plane is linear, g . x + c <= 0, so its range over a box is exact: g . m +- sum |g_i|
    h_i at the box's center m and half-sizes h; a relative slack keeps the cases that rounding
    could decide wrongly crossing (near).

    The regions are the leaves of a :class:`~clcsg.model.bvh.BoxTree`, walked from the root:
    a half-space that holds or misses a node's box does so for every region below it, so only
    the pairs whose plane crosses a node go down to its children.  A face plane of a convex
    mesh crosses the few boxes near its face at each level, so the work is about the planes
    times the depth, not the planes times the regions."""
    g, c = _half_space_planes(tape, halves)
    ids = np.asarray(halves)
    R = len(rlo)
    crossing: list = [[] for _ in range(R)]
    missed: list = [[] for _ in range(R)]
    if R == 0 or len(ids) == 0:
        return crossing, missed
    tree = BoxTree(rlo, rhi)
    assert len(tree.unbounded) == 0, "task regions are bounded"
    height = len(tree.levels) - 1
    with np.errstate(invalid="ignore"):  # the empty nodes padding the tree: nan, never decided
        boxes = [(0.5 * (lo + hi), 0.5 * (hi - lo), _side_scale(lo, hi)) for lo, hi in tree.levels]
    gabs, gnorm = np.abs(g), np.linalg.norm(g, axis=1)
    found = {"cross": [], "miss": []}  # (level, node, plane) per decided pair
    step = max(1, _SIDE_CHUNK // R)
    for p0 in range(0, len(ids), step):
        plane = np.arange(p0, min(p0 + step, len(ids)))
        node = np.zeros(len(plane), dtype=np.int64)
        for depth, (m, h, scale) in enumerate(boxes):
            with np.errstate(invalid="ignore"):
                v = np.einsum("pi,pi->p", m[node], g[plane]) + c[plane]
                spread = np.einsum("pi,pi->p", h[node], gabs[plane])
                slack = 1e-9 * scale[node] * gnorm[plane]
                hi_v, lo_v = v + spread + slack, v - spread - slack
                miss = lo_v > 0
                cross = (hi_v >= 0) & (lo_v <= 0)
            found["miss"].append((height - depth, node[miss], plane[miss]))
            node, plane = node[cross], plane[cross]
            if depth == height:
                found["cross"].append((0, node, plane))
                break
            node, plane = np.concatenate([2 * node, 2 * node + 1]), np.concatenate([plane, plane])
    for key, out in (("cross", crossing), ("miss", missed)):
        leaves, planes = [], []
        for up, node, plane in found[key]:  # a node `up` levels above the leaves covers 2^up
            span = 1 << up
            leaves.append((node[:, None] * span + np.arange(span)[None]).reshape(-1))
            planes.append(np.repeat(plane, span))
        region = tree.leaf_id[np.concatenate(leaves)]
        inst = ids[np.concatenate(planes)]
        real = region >= 0
        region, inst = region[real], inst[real]
        by = np.argsort(region, kind="stable")
        region, inst = region[by], inst[by]
        cuts = np.searchsorted(region, np.arange(R + 1))
        for k in range(R):
            out[k] = inst[cuts[k]:cuts[k + 1]].tolist()
    return crossing, missed


def _half_space_planes(tape, halves) -> tuple[np.ndarray, np.ndarray]:
    """(g (H, 3), c (H,)): the solid of each half-space instance as g . x + c <= 0."""
    Q = np.asarray(tape.quadrics, dtype=np.float64)
    qi = np.array([tape.instances[k].literals[0][0] for k in halves])
    sg = np.array([tape.instances[k].literals[0][1] for k in halves], dtype=np.float64)
    return 2.0 * sg[:, None] * Q[qi, :3, 3], sg * Q[qi, 3, 3]


def _side_scale(rlo, rhi) -> np.ndarray:
    """The coordinate scale of each region box, for the slack of the side tests."""
    return 1.0 + np.abs(np.concatenate([rlo, rhi], axis=1)).max(axis=1)


#: (region, crossing half-space) pairs tested at once in :func:`_oriented_sides`
_PAIR_CHUNK = 1 << 20


def _oriented_sides(tape, halves, oriented, rlo, rhi, crossing, missed) -> None:
    """The half-spaces in ``crossing`` (per region, from its world box) tested again on the
    region's oriented box (o, U, lo, hi) where it has one: over o + U z, lo <= z <= hi, the
    solid's g . x + c is g . (o + U m) + c +- sum |(U^T g)_i| h_i (m, h: the box's center and
    half-sizes), exact as for the world box, with the same slack.  Those that miss it move to
    ``missed``; those that hold it leave ``crossing`` (a half-space holds by default).  In
    place."""
    g, c = _half_space_planes(tape, halves)
    row_of = {int(i): k for k, i in enumerate(halves)}
    regions = [k for k, box in enumerate(oriented) if box is not None and crossing[k]]
    if not regions:
        return
    scale = _side_scale(rlo, rhi)
    gnorm = np.linalg.norm(g, axis=1)
    for s in range(0, len(regions), max(1, _PAIR_CHUNK // max(len(halves), 1))):
        chunk = regions[s:s + max(1, _PAIR_CHUNK // max(len(halves), 1))]
        r = np.concatenate([np.full(len(crossing[k]), j) for j, k in enumerate(chunk)])
        inst = np.concatenate([crossing[k] for k in chunk]).astype(np.int64)
        rows = np.array([row_of[i] for i in inst.tolist()], dtype=np.int64)
        o = np.array([oriented[k][0] for k in chunk], dtype=np.float64)
        U = np.array([oriented[k][1] for k in chunk], dtype=np.float64)
        lo = np.array([oriented[k][2] for k in chunk], dtype=np.float64)
        hi = np.array([oriented[k][3] for k in chunk], dtype=np.float64)
        mid = o + np.einsum("rij,rj->ri", U, 0.5 * (lo + hi))
        gp = g[rows]
        v = np.einsum("pi,pi->p", gp, mid[r]) + c[rows]
        spread = np.einsum("pj,pj->p", np.abs(np.einsum("pi,pij->pj", gp, U[r])), 0.5 * (hi - lo)[r])
        slack = 1e-9 * scale[np.asarray(chunk)][r] * gnorm[rows]
        hi_v, lo_v = v + spread + slack, v - spread - slack
        keep, miss = (hi_v >= 0) & (lo_v <= 0), lo_v > 0
        cuts = np.searchsorted(r, np.arange(len(chunk) + 1))
        for j, k in enumerate(chunk):
            a, b = cuts[j], cuts[j + 1]
            missed[k] = list(missed[k]) + inst[a:b][miss[a:b]].tolist()
            crossing[k] = inst[a:b][keep[a:b]].tolist()


#: boxes per shared tape of :func:`box_tapes` (a few dozen: the tape interpreter's cost per
#: row is mostly fixed, so fewer, longer tapes cost less than one per box)
CLUSTER = 64


def box_tapes(tape, lo, hi, box_quadric, size: int = CLUSTER) -> tuple[np.ndarray, list]:
    """(group per box, [ops per group]): the boxes [lo, hi] (N, 3), each of a quadric
    ``box_quadric``, in groups of ``size`` neighbours along a Morton curve of their centers
    (among boxes of the same size to within 2x),
    each group with the tape pruned to the primitives whose boxes meet the group's bounding
    box G.  The others are FALSE on a neighbourhood of G (their solids miss it), so the pruned
    tape is the solid near G, and its sides with a quadric substituted decide the surface on
    that quadric in G at least as tightly as the full tape's.  A primitive that holds a
    quadric but misses G is pruned too (the full tape would switch its leaf of the quadric,
    though the primitive is nowhere near): that is what keeps the tapes short when one plane
    is shared by thousands of primitives.  A region box of a quadric lies in the box of a
    primitive holding it (:func:`clcsg.compile.bounds.regions.quadric_regions`), so that
    primitive meets G and stays.  The full tape where there is no DAG or pruning saves
    nothing."""
    full = np.asarray(tape.ops, dtype=np.int32)
    lo, hi = np.asarray(lo, dtype=np.float64).reshape(-1, 3), np.asarray(hi, dtype=np.float64).reshape(-1, 3)
    q = np.asarray(box_quadric, dtype=np.int64)
    dag = primitive_dag(tape)
    if dag is None or len(q) <= size:
        return np.zeros(len(q), dtype=np.int64), ([full] if len(q) else [])
    # boxes of one size class together (a face of the whole scene next to a small hole's
    # would give the hole's group the full tape), then along the Morton curve
    rank = np.empty(len(q), dtype=np.int64)
    rank[morton_order(0.5 * (lo + hi))] = np.arange(len(q))
    size_class = np.floor(np.log2(np.maximum((hi - lo).max(axis=1), 1e-300)))
    order = np.lexsort((rank, size_class))
    group = np.empty(len(q), dtype=np.int64)
    group[order] = np.arange(len(q)) // size
    starts = np.arange(0, len(q), size)
    glo = np.minimum.reduceat(lo[order], starts, axis=0)
    ghi = np.maximum.reduceat(hi[order], starts, axis=0)
    ilo = np.array([i.box[0] if i.box is not None else np.full(3, np.inf) for i in tape.instances]).reshape(-1, 3)
    ihi = np.array([i.box[1] if i.box is not None else np.full(3, -np.inf) for i in tape.instances]).reshape(-1, 3)
    g_of, inst = BoxTree(ilo, ihi).query(glo, ghi)
    near = [set() for _ in starts]
    for g, k in zip(g_of.tolist(), inst.tolist()):
        near[g].add(k)
    tapes = []
    for nr in near:
        ops, regs = dag.pruned(frozenset(nr), registers=tape.n_regs)
        tapes.append(full if regs > tape.n_regs or len(ops) >= len(full) else ops)
    return group, tapes
