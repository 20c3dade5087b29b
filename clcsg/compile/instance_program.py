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

from ..model.csg import Shape
from .tape import _Builder, _emit, fold_shape


def instance_program(shape: Shape, instances) -> tuple[np.ndarray, int]:
    """(ops (N, 4) int32, registers) of ``shape`` over ``instances`` (the tree-order instances
    of :func:`clcsg.compile.tape.instances_of`, matched on (node, world matrix))."""
    index = {(id(i.node), i.matrix.tobytes()): i.index for i in instances}
    b = _Builder()
    root = fold_shape(shape, b, lambda node, m, neg: b.leaf(index[(id(node), m.tobytes())], -1 if neg else 1))
    return _emit(b, root)
