"""Per-quadric culling boxes of the exact ray tracer (``raytrace.cl``).

A primitive instance is the AND of its literals ``s K_q <= 0`` and is FALSE outside its box.
Replacing its literal on q by FALSE (K_q taken with the sign s) keeps it FALSE there, and a
negated instance (the OR of the complements) TRUE.  So for quadric q let B_q be the hull of the
boxes of the instances that have q as a literal: if all those literals have one sign s_q,
then at every point outside B_q each instance has the value it has with K_q's sign taken as
s_q, and so has the tape (a Boolean function of the instances' values, pruned or not).  A ray
whose stretch misses B_q needs no solve of q: its sign is s_q all along it.  Quadrics whose
literals disagree in sign (a face shared by two touching solids) are always solved, and so are
planes (their solve costs what a box test does).

The instance boxes are :func:`~clcsg.cl.records.instance_boxes` (device coordinates, padded by
the rounding margin; an empty instance has lo > hi and adds nothing to the hull).
"""

from __future__ import annotations

import numpy as np


def cull_boxes(packed, enabled: bool = True) -> np.ndarray:
    """(U, 8) ``real`` rows per quadric: lo.xyz, s_q, hi.xyz, 0, with s_q in {-1, +1} (0: the
    quadric is always solved; so is every quadric when ``enabled`` is false)."""
    n_q = len(packed.quadrics)
    out = np.zeros((max(n_q, 1), 8), dtype=packed.real)
    if n_q == 0 or not enabled:
        return out
    lits = packed.prim_literals.reshape(-1, 2)
    inst = np.repeat(np.arange(len(packed.prims)), packed.prims["lit_count"])
    q, s = lits[:, 0], lits[:, 1]
    boxes = packed.prim_boxes.astype(np.float64)
    lo = np.full((n_q, 3), np.inf)
    hi = np.full((n_q, 3), -np.inf)
    np.minimum.at(lo, q, boxes[inst, 0, :3])
    np.maximum.at(hi, q, boxes[inst, 1, :3])
    smin = np.full(n_q, 2)
    smax = np.full(n_q, -2)
    np.minimum.at(smin, q, s)
    np.maximum.at(smax, q, s)
    # a plane is solved as fast as its box is tested: never culled
    plane = ~np.any(packed.local_matrices[:, :3, :3] != 0, axis=(1, 2))
    sign = np.where((smin == smax) & ~plane, smin, 0)
    out[:, :3], out[:, 3], out[:, 4:7] = lo, sign, hi
    return out
