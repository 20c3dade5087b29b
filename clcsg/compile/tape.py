"""Compiling a CSG graph into a tape: a straight-line program over unique canonical quadrics.

The graph (a tree or a DAG of :mod:`clcsg.model.csg` nodes) becomes, in one iterative pass:

* transforms pushed into the leaves (Q' = M^-T Q M^-1, paper eq. 17);
* complements pushed to the leaves (negation normal form: ~(a | b) = ~a & ~b, ~(a - b) =
  ~a | b), so that every leaf is a *literal* (q, s): canonical quadric q, polarity s, solid
  ``s K_q(x) <= 0``;
* every quadric stored once in canonical form (unit norm, first non-zero coefficient positive,
  the sign moved into s), so coincident faces of different solids are one quadric;
* an expression DAG of AND / OR nodes, hash-consed (equal sub-expressions are one node, a
  shared sub-graph is computed once), with constants folded (x & false = false, x | true =
  true) and x & ~x = false for literals;
* a tape: SSA instructions in an order that keeps few values alive (the operand needing more
  registers first, Sethi-Ullman), then registers assigned by a linear scan.

Instructions are int32 rows ``(op, out, a, b)``:

=========  ===================================================================================
LEAF       reg[out] = the literal (quadric a, sign b)
AND        reg[out] = reg[a] AND reg[b]      (max of distances, & of memberships)
OR         reg[out] = reg[a] OR reg[b]       (min of distances, | of memberships)
COPY       reg[out] = reg[a]                 (written only by pruning)
CONST      reg[out] = a ? TRUE : FALSE       (a whole tape that pruning made constant)
=========  ===================================================================================

The result is ``reg[ops[-1].out]``.  Over reals a literal is ``s d_q(x)``, the conservative
signed distance (eqs. 10-12), TRUE is -inf and FALSE +inf: then min / max compose to a
conservative signed distance of the whole solid (the maximizing operand of an AND that is > 0
stays > 0 within its value; all operands of an AND that is < 0 stay < 0 within |value|).

The disjunctive normal form of the paper (section 5, eq. 18) is one shape of tape: an OR of
ANDs (:func:`dnf_tape`), run by the same kernels.
"""

from __future__ import annotations

import heapq
import math
from dataclasses import dataclass, field

import numpy as np

from ..cl.constants import OP_AND, OP_CONST, OP_COPY, OP_LEAF, OP_NAMES, OP_OR
from ..errors import ParameterError, SceneError, UnboundedError
from ..model.csg import Complement, Difference, Intersection, Primitive, Shape, Transformed, Union
from ..model.quadric import COEFFICIENT_INDEX, Quadric
from ..model.surfels import with_surfaces
from .bounds.exact_boxes import kind_boxes, kind_face_boxes
from .bounds.term_boxes import term_box
from .bounds import tree as bounds
from ..errors import UsageError
from .dnf import DEFAULT_TERM_LIMIT, normalize


#: canonical coefficients closer than this are the same quadric
SAME_QUADRIC = 1e-9
#: coefficients smaller than this (relative to the unit-norm matrix) are rounding noise
_ZERO = 1e-13

_TRUE, _FALSE = 0, 1  # expression ids of the constants
_LEAF, _AND, _OR, _CONST = "leaf", "and", "or", "const"


#: batches of at least this many quadrics are first checked for rows with no near neighbour
_BATCH = 256
#: irregular weights of unit 1-norm: the projection that finds those rows
_PROJECTION = np.array([0.131, -0.097, 0.113, 0.089, -0.071, 0.103, 0.083, -0.119, 0.107, 0.087])
_PROJECTION = _PROJECTION / np.abs(_PROJECTION).sum()
_ROWS = np.array([i for i, _ in COEFFICIENT_INDEX])
_COLS = np.array([j for _, j in COEFFICIENT_INDEX])


class QuadricTable:
    """Unique canonical quadrics, found with a tolerance (a dict on rounded coefficients,
    checked against the neighbours of the rounding grid)."""

    def __init__(self):
        self.coefs: list[np.ndarray] = []
        self._grid: dict = {}

    def __len__(self) -> int:
        return len(self.coefs)

    def add(self, matrix: np.ndarray) -> tuple[int, int]:
        """(index, sign) of the canonical form K of ``matrix``: matrix = sign * |matrix| * K."""
        return self.add_many(np.asarray(matrix, dtype=np.float64).reshape(1, 4, 4))[0]

    def add_many(self, matrices: np.ndarray) -> list[tuple[int, int]]:
        """:meth:`add` of every matrix of ``matrices`` (n, 4, 4), canonicalized in one batch."""
        m = np.asarray(matrices, dtype=np.float64).reshape(-1, 4, 4)
        with np.errstate(all="ignore"):
            norm = np.sqrt((m * m).sum(axis=(1, 2)))
        if not np.all(np.isfinite(norm) & (norm > 0.0)):
            raise ParameterError("not a finite non-zero quadric")
        coef = m[:, _ROWS, _COLS] / norm[:, None]
        coef[np.abs(coef) < _ZERO] = 0.0
        nz = np.argmax(coef != 0.0, axis=1)
        sign = np.where(coef[np.arange(len(coef)), nz] > 0, 1, -1)
        coef *= sign[:, None]
        scaled = coef / (4 * SAME_QUADRIC)
        keys = np.round(scaled)
        # a coefficient within SAME_QUADRIC of another may round the other way only near a
        # rounding boundary: those axes need the neighbouring keys too
        near = np.abs(scaled - keys) > 0.25
        keys = keys.astype(np.int64)
        if len(coef) < _BATCH:
            return [(self._find(c, tuple(k), np.flatnonzero(nr)), int(sg))
                    for c, k, nr, sg in zip(coef, keys.tolist(), near, sign)]
        out = []
        for c, k, nr, sg, alone in zip(coef, keys.tolist(), near, sign.tolist(), self._isolated(coef).tolist()):
            if alone:  # no quadric of the table or the batch within the tolerance: a new entry
                self.coefs.append(c)
                self._grid.setdefault(tuple(k), []).append(len(self.coefs) - 1)
                out.append((len(self.coefs) - 1, sg))
            else:
                out.append((self._find(c, tuple(k), np.flatnonzero(nr)), sg))
        return out

    def _isolated(self, coef) -> np.ndarray:
        """Per row of ``coef``: is no other row and no table entry within SAME_QUADRIC of it?
        Two such quadrics are within SAME_QUADRIC of each other on the projection onto
        ``_PROJECTION`` (unit 1-norm), so a row alone on it (with twice that margin) is alone."""
        proj = coef @ _PROJECTION
        old = np.array(self.coefs, dtype=np.float64).reshape(-1, 10) @ _PROJECTION
        allp = np.concatenate([old, proj])
        order = np.argsort(allp, kind="stable")
        gaps = np.diff(allp[order])
        close = np.zeros(len(allp), dtype=bool)
        tight = gaps <= 2 * SAME_QUADRIC
        close[order[:-1][tight]] = True
        close[order[1:][tight]] = True
        return ~close[len(old):]

    def _find(self, coef, key, near=range(10)) -> int:
        for k in self._neighbours(key, near):
            for idx in self._grid.get(k, ()):
                if np.abs(self.coefs[idx] - coef).max() < SAME_QUADRIC:
                    return idx
        self.coefs.append(coef)
        self._grid.setdefault(key, []).append(len(self.coefs) - 1)
        return len(self.coefs) - 1

    @staticmethod
    def _neighbours(key, axes):
        yield key
        for i in axes:
            for d in (-1, 1):
                yield key[:i] + (key[i] + d,) + key[i + 1:]

    def matrices(self) -> np.ndarray:
        c = np.array(self.coefs, dtype=np.float64).reshape(-1, 10)
        m = np.zeros((len(c), 4, 4))
        m[:, _ROWS, _COLS] = c
        m[:, _COLS, _ROWS] = c
        return m


@dataclass
class Instance:
    """A primitive instance: a Primitive node under one accumulated world transform, in tree
    order (the first occurrence in a depth-first walk).  ``literals`` are (quadric, sign) of
    its own (un-complemented) solid."""

    index: int
    node: Primitive
    matrix: np.ndarray
    literals: list
    color: tuple
    box: tuple | None  # (lo, hi), None if provably empty
    #: (n, 2, 3) per literal, the box of the primitive's face on it (closed-form kinds)
    face_boxes: np.ndarray | None = None


@dataclass
class Tape:
    """A compiled scene: the instructions, the quadric table, the primitive instances, the bound."""

    ops: np.ndarray  # (N, 4) int32
    n_regs: int
    quadrics: np.ndarray  # (U, 4, 4) canonical world matrices
    instances: list
    bound: np.ndarray  # (2, 3)
    shape: str = "tree"  # or "dnf"
    stats: dict = field(default_factory=dict)
    empty: bool = False
    #: the CSG over the instances (:mod:`clcsg.compile.instance_program`): (ops, registers)
    instance_program: tuple | None = None
    #: (builder, root, {expression: [(instance, negated)]}) of a tree tape: the expression DAG
    #: the tape was emitted from, for pruning it per region (:mod:`clcsg.compile.root_tapes`)
    dag: tuple | None = field(default=None, repr=False, compare=False)

    @property
    def n_quadrics(self) -> int:
        return len(self.quadrics)

    @property
    def leaves(self) -> np.ndarray:
        return self.ops[self.ops[:, 0] == OP_LEAF]

    def owners(self) -> list[list[int]]:
        """Per quadric, the instances (tree order) that have it as a literal."""
        out = [[] for _ in range(self.n_quadrics)]
        for inst in self.instances:
            for q, _ in inst.literals:
                if not out[q] or out[q][-1] != inst.index:
                    out[q].append(inst.index)
        return out

    def exact(self) -> "Tape":
        """The tape of the solid itself, which the exact ray tracer traces: this tape (a
        sampler's tape with point operands overrides it)."""
        return self

    def describe(self, limit: int = 40) -> str:
        lines = []
        for k, (op, out, a, b) in enumerate(self.ops[:limit]):
            if op == OP_LEAF:
                arg = f"{'+' if b > 0 else '-'}q{a}"
            elif op == OP_CONST:
                arg = "TRUE" if a else "FALSE"
            elif op == OP_COPY:
                arg = f"r{a}"
            else:
                arg = f"r{a} r{b}"
            lines.append(f"{k:5d}  r{out} = {OP_NAMES[op]} {arg}")
        if len(self.ops) > limit:
            lines.append(f"  ... {len(self.ops) - limit} more")
        return "\n".join(lines)


class _Builder:
    """The expression DAG: hash-consed nodes ``(kind, args)``."""

    def __init__(self):
        self.kind = [_CONST, _CONST]
        self.args: list = [(1,), (0,)]
        self._ids = {(_CONST, (1,)): _TRUE, (_CONST, (0,)): _FALSE}
        self.complement = {_TRUE: _FALSE, _FALSE: _TRUE}  # node -> its complement, where both exist

    def node(self, kind, args) -> int:
        key = (kind, args)
        i = self._ids.get(key)
        if i is None:
            i = self._ids[key] = len(self.kind)
            self.kind.append(kind)
            self.args.append(args)
        return i

    def leaf(self, q: int, s: int) -> int:
        return self.node(_LEAF, (q, s))

    def combine(self, kind, ids) -> int:
        absorbing, neutral = (_FALSE, _TRUE) if kind == _AND else (_TRUE, _FALSE)
        seen = []
        members = set()
        lits = set()
        for i in ids:
            if i == absorbing:
                return absorbing
            if i == neutral or i in members:
                continue
            if self.kind[i] == _LEAF:
                q, s = self.args[i]
                if (q, -s) in lits:  # K & ~K is the surface (no volume); K | ~K everything
                    return absorbing
                lits.add((q, s))
            seen.append(i)
            members.add(i)
        if any(self.complement.get(i, -1) in members for i in seen):  # x & ~x is empty, x | ~x everything
            return absorbing
        if not seen:
            return neutral
        if len(seen) == 1:
            return seen[0]
        return self.node(kind, tuple(sorted(seen)))


def _inverse_cache():
    cache: dict = {}

    def inv(m: np.ndarray) -> np.ndarray:
        k = m.tobytes()
        r = cache.get(k)
        if r is None:
            r = cache[k] = np.linalg.inv(m)
        return r

    return inv


def _children(node, m, neg):
    """(kind, [(child, matrix, negated)]) of an inner node; kind None for pass-through."""
    if isinstance(node, Transformed):
        return None, [(node.operand, m @ node.matrix, neg)]
    if isinstance(node, Complement):
        return None, [(node.operand, m, not neg)]
    if isinstance(node, Union):
        return (_AND if neg else _OR), [(c, m, neg) for c in node.operands]
    if isinstance(node, Intersection):
        return (_OR if neg else _AND), [(c, m, neg) for c in node.operands]
    if isinstance(node, Difference):
        ops = [(node.operands[0], m, neg)] + [(c, m, not neg) for c in node.operands[1:]]
        return (_OR if neg else _AND), ops
    if hasattr(node, "normals") and hasattr(node, "radii"):
        raise SceneError("a point operand (surfels) is compiled as the mesh of its surface (compile_scene), "
                         "or replaced by the sampler's substitutions")
    raise SceneError(f"not a CSG node: {type(node).__name__}")


class _WorldLiterals:
    """The world literals (quadric index, sign) of each primitive under each accumulated
    transform, computed once (Q' = M^-T Q M^-1 for all of a primitive's quadrics at once) and
    shared by the walks of the compiler."""

    def __init__(self, table: QuadricTable, source: str):
        self.table, self.source = table, source
        self._inv = _inverse_cache()
        self._memo: dict = {}

    def __call__(self, node: Primitive, m: np.ndarray) -> list:
        out = self._memo.get((id(node), m.tobytes()))
        if out is None:
            self.prepare([(node, m)])
            out = self._memo[(id(node), m.tobytes())]
        return out[1]

    def prepare(self, pairs) -> None:
        """Compute the literals of many (primitive, transform) pairs in one batch, in order
        (the quadric table's indices follow it)."""
        pairs = [(n, m) for n, m in pairs if (id(n), m.tobytes()) not in self._memo]
        if not pairs:
            return
        im = np.array([self._inv(m) for _, m in pairs])
        counts = [len(n.quadrics()) for n, _ in pairs]
        owner = np.repeat(np.arange(len(pairs)), counts)
        q = np.array([q.matrix for n, _ in pairs for q in n.quadrics()]).reshape(-1, 4, 4)
        with np.errstate(all="ignore"):
            w = np.einsum("nji,njk,nkl->nil", im[owner], q, im[owner])
            norm = np.sqrt((w * w).sum(axis=(1, 2)))  # the quadric table divides by it
            bad = ~np.all(np.isfinite(w), axis=(1, 2)) | ~(np.abs(w).max(axis=(1, 2)) > 0) | ~np.isfinite(norm)
        if bad.any():
            node = pairs[owner[np.flatnonzero(bad)[0]]][0]
            raise SceneError(f"{self.source}: {node!r}: its quadric overflows float64 after the transforms "
                             "(sizes or offsets far too large)")
        lits = self.table.add_many(w)
        start = 0
        for (node, m), c in zip(pairs, counts):
            self._memo[(id(node), m.tobytes())] = (node, lits[start:start + c])  # the node keeps its id unique
            start += c


def instance_matrices(shape: Shape) -> list[tuple]:
    """(primitive, accumulated transform) of ``shape``'s primitive instances in tree order
    (iterative depth-first walk; a shared sub-graph under the same transform is walked once)."""
    out: list = []
    seen = set()
    stack = [(shape, np.eye(4))]
    while stack:
        node, m = stack.pop()
        key = (id(node), m.tobytes())
        if key in seen:
            continue
        seen.add(key)
        if isinstance(node, Primitive):
            out.append((node, m))
            continue
        _, kids = _children(node, m, False)
        for child, cm, _ in reversed(kids):
            stack.append((child, cm))
    return out


def instances_of(shape: Shape, table: QuadricTable, source: str = "scene", world=None) -> list[Instance]:
    """The primitive instances of ``shape`` in tree order (:func:`instance_matrices`).  Their
    boxes are the primitives' exact boxes (:func:`~clcsg.compile.bounds.exact_boxes.kind_boxes`,
    in one batch; the polytope box of :func:`~clcsg.compile.bounds.term_boxes.term_box` for
    kinds without a closed form)."""
    world = _WorldLiterals(table, source) if world is None else world
    out = [Instance(k, node, m, None, node.color, None) for k, (node, m) in enumerate(instance_matrices(shape))]
    world.prepare([(i.node, i.matrix) for i in out])
    for inst in out:
        inst.literals = world(inst.node, inst.matrix)
    _instance_boxes(out, table)
    return out


def _instance_boxes(instances: list, table: QuadricTable) -> None:
    """Set every instance's box (None if provably empty)."""
    if not instances:
        return
    nodes, mats = [i.node for i in instances], np.array([i.matrix for i in instances])
    lo, hi, done = kind_boxes(nodes, mats)
    faces = kind_face_boxes(nodes, mats, lo, hi, done)
    for inst, l, h, ok, f in zip(instances, lo, hi, done, faces):
        if ok:
            inst.box = None if np.any(l > h) else (l, h)
            inst.face_boxes = None if inst.box is None else f
        else:
            quads = [(Quadric.from_coefficients(table.coefs[q]), s) for q, s in inst.literals]
            inst.box = term_box(quads)


def fold_shape(shape: Shape, b: _Builder, leaf) -> int:
    """The root expression id of ``shape`` in builder ``b``: an iterative post-order walk of
    the CSG graph, memoized on (node, transform, negated), complements pushed to the leaves
    (:func:`_children`); ``leaf(node, m, neg)`` gives a primitive's expression.  The
    expressions of (node, m, neg) and (node, m, not neg) are recorded as complements."""
    memo: dict = {}
    stack = [(shape, np.eye(4), False, False)]
    while stack:
        node, m, neg, expanded = stack.pop()
        key = (id(node), m.tobytes(), neg)
        if key in memo:
            continue
        if isinstance(node, Primitive):
            memo[key] = leaf(node, m, neg)
            _pair(b, memo, key)
            continue
        kind, kids = _children(node, m, neg)
        keys = [(id(c), cm.tobytes(), cn) for c, cm, cn in kids]
        if not expanded:
            stack.append((node, m, neg, True))
            for (c, cm, cn), k in zip(reversed(kids), reversed(keys)):
                if k not in memo:
                    stack.append((c, cm, cn, False))
            continue
        ids = [memo[k] for k in keys]
        if kind is None:
            memo[key] = ids[0]
        elif not ids:  # an empty union is nothing; its complement everything
            memo[key] = _FALSE if kind == _OR else _TRUE
        else:
            memo[key] = b.combine(kind, ids)
        _pair(b, memo, key)
    return memo[(id(shape), np.eye(4).tobytes(), False)]


def _expression(shape: Shape, world: _WorldLiterals, b: _Builder, prims: list | None = None) -> int:
    """The root expression id of ``shape`` over quadric literals; ``prims`` collects (node id,
    transform bytes, negated, expression) of every primitive."""

    def leaf(node, m, neg):
        lits = world(node, m)
        if neg:
            e = b.combine(_OR, [b.leaf(q, -s) for q, s in lits])
        else:
            e = b.combine(_AND, [b.leaf(q, s) for q, s in lits])
        if prims is not None:
            prims.append((id(node), m.tobytes(), neg, e))
        return e

    return fold_shape(shape, b, leaf)


def _pair(b: _Builder, memo: dict, key) -> None:
    """Record that the expressions of (node, m, neg) and (node, m, not neg) are complements."""
    other = memo.get((key[0], key[1], not key[2]))
    if other is not None:
        b.complement[memo[key]] = other
        b.complement[other] = memo[key]


def _postorder(b: _Builder, root: int, known=()) -> list[int]:
    """Every node reachable from ``root`` once, each after its operands (iterative); nodes in
    ``known`` are left out, and their operands not visited."""
    order: list[int] = []
    seen: set = set()
    stack = [(root, False)]
    while stack:
        i, done = stack.pop()
        if done:
            order.append(i)
        elif i not in seen and i not in known:
            seen.add(i)
            stack.append((i, True))
            if b.kind[i] not in (_LEAF, _CONST):
                stack.extend((c, False) for c in b.args[i] if c not in seen)
    return order


def _needs(b: _Builder, root: int, need: dict | None = None) -> dict:
    """Sethi-Ullman register estimates of every node reachable from ``root``, added to
    ``need`` (a node's estimate depends on its sub-DAG only: nodes already in it are kept, and
    their operands not visited)."""
    need = {} if need is None else need
    for i in _postorder(b, root, need):
        if b.kind[i] in (_LEAF, _CONST):
            need[i] = 1
            continue
        ns = sorted((need[c] for c in b.args[i]), reverse=True)
        need[i] = max(ns[0], 1 + max(ns[1:], default=0))
    return need


#: a tape that needs more than REMATERIALIZE_PAST registers is emitted again with every leaf
#: used more than REMATERIALIZE instructions after its last evaluation evaluated again,
#: instead of holding a register all the way (a large mesh's face plane is a leaf in each k-d
#: cell it spans: held, such planes took 295 registers, evaluated again 22)
REMATERIALIZE_PAST = 32
REMATERIALIZE = 64


def _emit(b: _Builder, root: int, registers: int | None = None, need: dict | None = None) -> tuple[np.ndarray, int]:
    """SSA instructions in evaluation order, then linear-scan register allocation (see
    :data:`REMATERIALIZE_PAST`; ``registers``: a lower count past which to try, the budget of
    a tape that must fit another's registers; ``need``: register estimates known already,
    kept and added to, for a builder that emits many tapes)."""
    need = _needs(b, root, need)
    ops, n_regs = _emit_once(b, root, None, need)
    if n_regs > min(REMATERIALIZE_PAST, registers if registers is not None else REMATERIALIZE_PAST):
        again, regs = _emit_once(b, root, REMATERIALIZE, need)
        if regs < n_regs:
            return again, regs
    return ops, n_regs


def _emit_once(b: _Builder, root: int, remat: int | None, need: dict) -> tuple[np.ndarray, int]:
    """:func:`_emit` with leaves evaluated again past ``remat`` instructions (None: never);
    ``need``: the register estimates of the nodes (:func:`_needs`).  (Names bound locally and
    rows kept in lists: the host prunes hundreds of root tapes per scene with it.)"""
    remat = float("inf") if remat is None else remat
    kinds, args = b.kind, b.args
    value: dict = {}  # expression id -> SSA value
    ssa: list = []  # (op, a, b) with SSA operands for AND/OR
    append = ssa.append
    # frames: [node, sorted children, next index, accumulated value]
    stack = [[root, None, 0, None]]
    while stack:
        fr = stack[-1]
        i = fr[0]
        kind = kinds[i]
        if i in value and not (kind == _LEAF and len(ssa) - value[i] > remat):
            stack.pop()
            continue
        if kind == _LEAF:
            q, sign = args[i]
            value[i] = len(ssa)
            append((OP_LEAF, q, sign))
            stack.pop()
            continue
        if kind == _CONST:
            value[i] = len(ssa)
            append((OP_CONST, args[i][0], 0))
            stack.pop()
            continue
        kids = fr[1]
        if kids is None:
            kids = fr[1] = sorted(args[i], key=lambda c: -need[c])
        if fr[2] < len(kids):
            c = kids[fr[2]]
            if c not in value or (kinds[c] == _LEAF and len(ssa) - value[c] > remat):
                stack.append([c, None, 0, None])
                continue
            v = value[c]
            if fr[3] is None:
                fr[3] = v
            else:
                append((OP_AND if kind == _AND else OP_OR, fr[3], v))
                fr[3] = len(ssa) - 1
            fr[2] += 1
            continue
        value[i] = fr[3]
        stack.pop()
    result = value[root]
    # linear scan: a value dies at its last use; its register is free for the next write
    binary = (OP_AND, OP_OR)
    last = {}
    for k, (op, x, y) in enumerate(ssa):
        if op in binary:
            last[x] = k
            last[y] = k
    last[result] = len(ssa)
    free: list = []
    n_regs = 0
    reg: list = []
    rows: list = []
    push, pop = heapq.heappush, heapq.heappop
    for k, (op, x, y) in enumerate(ssa):
        if op in binary:
            if last[x] == k:
                push(free, reg[x])
            if y != x and last[y] == k:
                push(free, reg[y])
            x, y = reg[x], reg[y]
        if free:
            r = pop(free)
        else:
            r = n_regs
            n_regs += 1
        reg.append(r)
        rows.append((op, r, x, y))
    ops = np.array(rows, dtype=np.int32).reshape(-1, 4)
    assert result == len(ssa) - 1  # the root's value is the last one computed
    return ops, max(n_regs, 1)


def _depth_and_terms(b: _Builder, root: int) -> tuple[int, float]:
    """Depth of the expression DAG and the number of DNF terms distributing it would give
    (float; inf past 1e300), both without building anything."""
    depth: dict = {}
    terms: dict = {}
    for i in _postorder(b, root):
        kind = b.kind[i]
        if kind in (_LEAF, _CONST):
            depth[i] = 1
            terms[i] = 0.0 if i == _FALSE else 1.0
            continue
        kids = b.args[i]
        depth[i] = 1 + max(depth[c] for c in kids)
        if kind == _OR:
            t = math.fsum(terms[c] for c in kids)
        else:
            t = 1.0
            for c in kids:
                t *= terms[c]
        terms[i] = t if t < 1e300 else math.inf
    return depth[root], terms[root]


def compile_shape(shape: Shape, user_bound=None, source: str = "scene", table: QuadricTable | None = None) -> Tape:
    """Compile ``shape`` into a :class:`Tape` (the tree shape).  ``user_bound``: (lo, hi)."""
    if not isinstance(shape, Shape):
        raise SceneError(f"{source}: expected a CSG shape, got {type(shape).__name__}")
    table = QuadricTable() if table is None else table
    world = _WorldLiterals(table, source)
    instances = instances_of(shape, table, source, world)
    b = _Builder()
    prim_keys: list = []
    root = _expression(shape, world, b, prim_keys)
    ops, n_regs = _emit(b, root)
    depth, dnf_terms = _depth_and_terms(b, root)
    bound, empty = scene_bound(shape, instances, root, user_bound, source)
    tape = Tape(ops, n_regs, table.matrices(), instances, bound, "tree", empty=empty or root == _FALSE,
                dag=(b, root, _primitive_expressions(instances, prim_keys)))
    from .instance_program import instance_program

    tape.instance_program = instance_program(shape, instances)
    tape.stats = _tape_stats(tape, depth=depth, dnf_terms=dnf_terms)
    return tape


def _primitive_expressions(instances, prim_keys) -> dict:
    """expression id -> [(instance index, negated)] of the primitives' expressions."""
    index = {(id(i.node), i.matrix.tobytes()): i.index for i in instances}
    out: dict = {}
    for node_id, m, neg, e in prim_keys:
        if e not in (_TRUE, _FALSE):
            out.setdefault(e, []).append((index[(node_id, m)], neg))
    return out


def leaf_quadrics(ops) -> np.ndarray:
    """The quadrics the LEAF rows of ``ops`` (N, 4) use, sorted, each once (by a sort, not
    ``np.unique``, whose import of numpy.ma costs a short run 7 ms)."""
    ops = np.asarray(ops).reshape(-1, 4)
    used = np.sort(ops[ops[:, 0] == OP_LEAF, 2]).astype(np.int64)
    return used[np.r_[True, used[1:] != used[:-1]]] if len(used) else used


def _tape_stats(tape: Tape, **extra) -> dict:
    leaves = tape.ops[tape.ops[:, 0] == OP_LEAF]
    return {
        "shape": tape.shape,
        "instructions": int(len(tape.ops)),
        "leaves": int(len(leaves)),
        "quadrics": len(leaf_quadrics(tape.ops)),
        "registers": int(tape.n_regs),
        "primitives": len(tape.instances),
        **extra,
    }


def scene_bound(shape, instances, root, user_bound, source):
    """(bound (2, 3), empty) of the solid."""
    if root == _FALSE:
        return np.zeros((2, 3)), True

    if hasattr(bounds, "shape_bound"):
        return bounds.shape_bound(shape, user_bound=user_bound, source=source)
    boxes = [i.box for i in instances if i.box is not None]
    lo = np.min([b[0] for b in boxes], axis=0) if boxes else np.zeros(3)
    hi = np.max([b[1] for b in boxes], axis=0) if boxes else np.zeros(3)
    if user_bound is not None:
        ub = np.asarray(user_bound, dtype=np.float64)
        lo, hi = np.maximum(lo, ub[0]), np.minimum(hi, ub[1])
    if not (np.all(np.isfinite(lo)) and np.all(np.isfinite(hi))):
        raise UnboundedError(f"{source}: the solid is unbounded; intersect it with a box or give a bound")
    return np.array([lo, hi]), not boxes


def dnf_tape(dnf, instances, bound, table_matrices) -> Tape:
    """The DNF (an OR of ANDs of literals over ``table_matrices``) as a tape."""
    b = _Builder()
    terms = [b.combine(_AND, [b.leaf(q, s) for q, s in term]) for term in dnf.terms]
    root = b.combine(_OR, terms) if terms else _FALSE
    ops, n_regs = _emit(b, root)
    depth, dnf_terms = _depth_and_terms(b, root)
    tape = Tape(ops, n_regs, table_matrices, instances, bound, "dnf", empty=root == _FALSE)
    tape.stats = _tape_stats(tape, depth=depth, dnf_terms=dnf_terms, terms=dnf.n_terms)
    return tape


NORMAL_FORMS = ("tree", "dnf")


def compile_scene(scene, normal_form: str = "tree", term_limit: int | None = None) -> Tape:
    """The tape of a :class:`~clcsg.model.scene.Scene` in the given normal form.  A point
    operand is compiled as the mesh of its surface (:func:`~clcsg.model.surfels.with_surfaces`);
    the sampler compiles its own tapes of such scenes (:mod:`clcsg.sampling.surfel_csg`)."""
    if normal_form not in NORMAL_FORMS:
        raise UsageError(f"normal form must be one of {', '.join(NORMAL_FORMS)}, got {normal_form!r}")
    table = QuadricTable()
    shape = with_surfaces(scene.shape)
    tree = compile_shape(shape, scene.bound, scene.source, table)
    if normal_form == "tree":
        return tree

    dnf = normalize(shape, DEFAULT_TERM_LIMIT if term_limit is None else term_limit, scene.bound,
                    scene.source, table=table)
    tape = dnf_tape(dnf, tree.instances, tree.bound, table.matrices())
    tape.stats.update({f"dnf_{k}": v for k, v in dnf.stats.items()})
    tape.empty = tape.empty or tree.empty
    tape.instance_program = tree.instance_program
    return tape
