"""The tape over many axis-aligned boxes at once: which boxes the surface may cross, and which
quadrics may carry it there.

Every literal (q, s) gets a three-valued state per box from
:func:`~clcsg.compile.interpret.leaf_states_over_boxes` (planes exactly, other quadrics by the
conservative distance at the box's center against its half-diagonal, both with the pruning
slack).  A forward pass over the tape combines them (AND / OR over {FALSE, TRUE, LIVE}); a box
whose root is not LIVE holds no surface (the solid is constant over the closed box: that is a
pruned tape reduced to one CONST row).  A backward pass keeps a leaf *needed* in a box if a
path of LIVE instructions leads from it to the root there: the leaves of the box's pruned tape.
Their quadrics are the only ones the surface may lie on within the box.
"""

from __future__ import annotations

import numpy as np

from ..compile.interpret import _F, _LIVE, _T, _combine3, leaf_states_over_boxes
from ..compile.tape import OP_AND, OP_CONST, OP_COPY, OP_LEAF, OP_OR


def _ssa_operands(ops) -> list:
    """Per instruction, the instruction indices that wrote its register operands (the tape
    reuses registers; this undoes that)."""
    writer: dict = {}
    out = []
    for k, (op, reg, a, b) in enumerate(ops):
        if op in (OP_AND, OP_OR):
            out.append((writer[a], writer[b]))
        elif op == OP_COPY:
            out.append((writer[a],))
        else:
            out.append(())
        writer[reg] = k
    return out


def box_states(tape, lo, hi, with_quadrics: bool = True):
    """(root state (N,) in {FALSE, TRUE, LIVE}, needed quadrics (N, U) bool or None) of the
    tape over the boxes [lo, hi] (N, 3)."""
    ops = np.asarray(tape.ops)
    n = len(lo)
    args = _ssa_operands(ops)
    state = [None] * len(ops)
    cache: dict = {}
    for k, (op, _reg, a, b) in enumerate(ops):
        if op == OP_LEAF:
            if (a, b) not in cache:
                cache[(a, b)] = leaf_states_over_boxes(tape.quadrics[a], int(b), lo, hi)
            state[k] = cache[(a, b)]
        elif op in (OP_AND, OP_OR):
            state[k] = _combine3(op, state[args[k][0]], state[args[k][1]])
        elif op == OP_COPY:
            state[k] = state[args[k][0]]
        elif op == OP_CONST:
            state[k] = np.full(n, _T if a else _F)
    root = np.asarray(state[-1]).reshape(-1) if n else np.zeros(0, dtype=int)
    root = np.broadcast_to(root, (n,)).copy()
    if not with_quadrics:
        return root, None
    needed_q = np.zeros((n, max(tape.n_quadrics, 1)), dtype=bool)
    need = [None] * len(ops)
    need[-1] = root == _LIVE
    for k in range(len(ops) - 1, -1, -1):
        nk = need[k]
        if nk is None or not nk.any():
            continue
        op = ops[k, 0]
        if op == OP_LEAF:
            needed_q[:, ops[k, 2]] |= nk
            continue
        for j in args[k]:
            add = nk & (state[j] == _LIVE)
            need[j] = add if need[j] is None else (need[j] | add)
    return root, needed_q


__all__ = ["box_states", "_LIVE", "_T", "_F"]
