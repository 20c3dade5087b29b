"""Where each quadric's surface can carry CSG surface: boxes for the resource guard."""

from __future__ import annotations

import numpy as np

from ...model.quadric import Quadric
from .exact_boxes import is_empty, literals_box, meet



def quadric_regions(table, instances, bound=None) -> list[np.ndarray]:
    """For every quadric of ``table`` the boxes where its surface can carry CSG surface.

    The CSG surface lies on the union of the primitives' boundaries, and the part of it on
    quadric q lies on the faces (boundary parts on q) of the primitive instances holding q,
    inside those instances' boxes.  So the boxes of those faces, intersected with the instance
    boxes and the scene bound, cover it; their areas bound the work of sampling q.

    ``table``: (U, 4, 4) the caller's unique (canonical) quadric matrices.
    ``instances``: one item per primitive instance, either an object with ``literals`` and
    ``box`` attributes (and optionally ``face_boxes``) or a tuple ``(literals, box)`` /
    ``(literals, box, face_boxes)``:

    * ``literals``: (index into table, sign) of the primitive's own literals (solid
      sign K(x) <= 0), in the primitive's order;
    * ``box``: (2, 3) where the instance's boundary can carry CSG surface (the
      :attr:`PrimitiveInstance.box` of :func:`tree_bounds`, or just the primitive's box), None
      for nowhere;
    * ``face_boxes``: (n, 2, 3) per literal (lo > hi: none); computed here when missing.

    ``bound``: (2, 3) scene bound or None.  Returns a list of U arrays of shape (k_u, 2, 3)
    (k_u = 0: the quadric carries no surface).
    """
    table = np.asarray(table, dtype=np.float64).reshape(-1, 4, 4)
    out: list[list] = [[] for _ in range(len(table))]
    bnd = None if bound is None else (np.asarray(bound[0], dtype=np.float64), np.asarray(bound[1], dtype=np.float64))
    for item in instances:
        if isinstance(item, tuple):
            lits, box = item[0], item[1]
            faces = item[2] if len(item) > 2 else None
        else:
            lits, box = item.literals, item.box
            faces = getattr(item, "face_boxes", None)
        if box is None or is_empty(box):
            continue
        box = (np.asarray(box[0], dtype=np.float64), np.asarray(box[1], dtype=np.float64))
        if bnd is not None:
            box = meet(box, bnd)
            if is_empty(box):
                continue
        lits = [(int(q), int(s)) for q, s in lits]
        if faces is None:
            res = literals_box([(Quadric(table[q]), s) for q, s in lits], box, faces=True)
            if res is None:
                continue
            faces = res[1]
        faces = np.asarray(faces, dtype=np.float64)
        for (q, _), f in zip(lits, faces):
            r = meet((f[0], f[1]), box)
            if not is_empty(r):
                out[q].append(np.array(r))
    return [np.array(r, dtype=np.float64).reshape(-1, 2, 3) for r in out]


def unique_quadrics(instances, same: float = 1e-9):
    """(table (U, 4, 4), [(literals, box, face_boxes)]) for :class:`PrimitiveInstance` objects:
    their world quadrics stored once in canonical form (:meth:`Quadric.canonical`: unit norm,
    first non-zero coefficient positive; coefficients within ``same`` are one quadric), for
    callers without a quadric table of their own (tests, benchmarks)."""
    coefs: list[np.ndarray] = []
    grid: dict = {}

    def add(m):
        k, s = Quadric(m).canonical()
        c = k.coefficients()
        key = tuple(np.round(c / (4 * same)).astype(np.int64))
        for d in _neighbours(key):
            for idx in grid.get(d, ()):
                if np.abs(coefs[idx] - c).max() < same:
                    return idx, s
        coefs.append(c)
        grid.setdefault(key, []).append(len(coefs) - 1)
        return len(coefs) - 1, s

    items = [(inst.literals(add), inst.box, inst.face_boxes) for inst in instances]
    table = np.array([Quadric.from_coefficients(c).matrix for c in coefs]).reshape(-1, 4, 4)
    return table, items


def _neighbours(key):
    yield key
    for i in range(len(key)):
        for d in (-1, 1):
            yield key[:i] + (key[i] + d,) + key[i + 1:]

