"""The CSG over primitive *instances*: a tape whose leaves are instance memberships.

The quadric tape (:mod:`clcsg.compile.tape`) shares literals between instances, so it cannot
say which instance a surface point owes its existence to.  This program can: leaf
``(instance i, sign s)`` is instance i's solid (s = +1) or its complement (s = -1), AND / OR
rows as in the quadric tape (the same instruction set, complements pushed to the leaves,
equal sub-expressions shared).  Evaluated at a point with one instance's membership switched,
it tells whether that instance bounds the solid there (the colour rule of
``cl/include/primitives.h``).
"""

from __future__ import annotations

import numpy as np

from ..model.csg import Primitive, Shape
from .tape import _FALSE, _OR, _TRUE, _Builder, _children, _emit


def instance_program(shape: Shape, instances) -> tuple[np.ndarray, int]:
    """(ops (N, 4) int32, registers) of ``shape`` over ``instances`` (the tree-order instances
    of :func:`clcsg.compile.tape.instances_of`, matched on (node, world matrix))."""
    index = {(id(i.node), i.matrix.tobytes()): i.index for i in instances}
    b = _Builder()
    memo: dict = {}
    stack = [(shape, np.eye(4), False, False)]
    while stack:
        node, m, neg, expanded = stack.pop()
        key = (id(node), m.tobytes(), neg)
        if key in memo:
            continue
        if isinstance(node, Primitive):
            memo[key] = b.leaf(index[(id(node), m.tobytes())], -1 if neg else 1)
            continue
        kind, kids = _children(node, m, neg)
        keys = [(id(c), cm.tobytes(), cn) for c, cm, cn in kids]
        if not expanded:
            stack.append((node, m, neg, True))
            stack.extend((c, cm, cn, False) for (c, cm, cn), k in zip(reversed(kids), reversed(keys))
                         if k not in memo)
            continue
        ids = [memo[k] for k in keys]
        if kind is None:
            memo[key] = ids[0]
        elif not ids:
            memo[key] = _FALSE if kind == _OR else _TRUE
        else:
            memo[key] = b.combine(kind, ids)
    return _emit(b, memo[(id(shape), np.eye(4).tobytes(), False)])
