"""The cells of a uniform grid that the surface may cross, found by an octree descent over the
pruned tape: cost grows with the surface's area, not with the bound's volume.

The grid: cubes of side h, the lattice shifted off the scene's round numbers by a fixed
irrational fraction of h (so that no axis-aligned face of a part falls on grid points), padded
by two cells around the bound (every outermost grid point is outside the solid).  The root
cube has 2^L cells per side; each level keeps the boxes whose tape is not constant
(:func:`~clcsg.meshing.box_states.box_states`) and splits them in eight, down to level L.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .box_states import _LIVE, box_states

#: the lattice's shift, as a fraction of a cell (irrational, away from 0, 1/2 and 1/3)
GRID_SHIFT = (math.sqrt(2.0) - 1.0) * 0.25
#: cells of padding around the bound
PAD = 2


@dataclass
class Cells:
    """Leaf cells: integer corners ``ijk`` (C, 3) of cubes ``origin + h [ijk, ijk + 1]``, the
    quadrics each cell's pruned tape needs (C, U), the grid's ``size`` (points per axis)."""

    ijk: np.ndarray
    quadrics: np.ndarray
    origin: np.ndarray
    h: float
    size: int
    visited: int  # boxes tested over all levels


def surface_cells(tape, cells_per_side: int) -> Cells:
    """The leaf cells (about ``cells_per_side`` over the bound's longest side) the surface may
    cross, each with its pruned tape's quadrics."""
    lo, hi = np.asarray(tape.bound, dtype=np.float64)
    ext = float(np.max(hi - lo))
    ext = ext if ext > 0 else 1.0
    h = ext / max(int(cells_per_side), 2)
    origin = lo - (PAD + GRID_SHIFT) * h
    need = np.ceil((hi - lo) / h).astype(int) + 2 * PAD + 1
    level = max(1, int(math.ceil(math.log2(max(need.max(), 2)))))
    boxes = np.zeros((1, 3), dtype=np.int64)
    visited = 0
    for depth in range(level + 1):
        side = 1 << (level - depth)
        blo = origin + h * boxes * side
        keep = np.all(boxes * side < need, axis=1)
        boxes, blo = boxes[keep], blo[keep]
        visited += len(boxes)
        root, quads = box_states(tape, blo, blo + h * side, with_quadrics=depth == level)
        live = root == _LIVE
        boxes = boxes[live]
        if depth == level:
            quads = quads[live]
            break
        kids = np.array([[i, j, k] for i in (0, 1) for j in (0, 1) for k in (0, 1)], dtype=np.int64)
        boxes = (2 * boxes[:, None, :] + kids[None]).reshape(-1, 3)
    return Cells(boxes, quads, origin, h, (1 << level) + 1, visited)
