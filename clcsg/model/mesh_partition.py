"""A large mesh as a k-d tree of local solid BSPs: its expression stays local, so a region's
pruned tape holds the face planes near it, not every plane whose half-space crosses it.

A mesh's face planes are unbounded: a convex mesh of N faces is one intersection of N
half-spaces, and over a region of size r every plane within r of it crosses it (on a sphere of
radius R tessellated finer than r, about N r / (2 R) of them).  Pruning by intervals cannot
tell that most are redundant there, so the tapes of every cell grew with N.

A k-d tree over the triangles fixes that.  Each node's cell C (an axis-aligned box) is split by
the plane x_k = c into C- (x_k <= c) and C+; its expression is

    S_C = (H & S_C-) | (~H & S_C+)        H: the half-space x_k <= c (a split plane)

which equals the mesh's solid on C when S_C- and S_C+ equal it on their halves.  A leaf cell
holds the triangles meeting it, clipped to it; the solid BSP of those pieces
(:func:`~clcsg.model.bsp.bsp_expression`) equals the mesh's solid on the leaf: no other part
of the surface meets the cell, so every BSP leaf region met with the cell is free of surface
and touches a piece of its last splitter's face from the side its orientation says (the
argument of :mod:`clcsg.model.bsp`, within the cell).  Every split coordinate lies in a gap
between vertex coordinates wider than 4 ``eps``, so the only surface within 2 ``eps`` of a cell
is the continuation of its own pieces, on their planes: each leaf's expression holds on its
cell grown by ``eps``.

Outside its cell, a leaf's expression is never used (the split planes above it send every
point elsewhere), so a leaf's face planes carry the cell as their support
(:class:`~clcsg.model.polyhedron.FacePlane`): a region that misses the cell takes them as
constants, and the split plane that separates the region from the cell decides the branch
exactly (a half-space's side of a box is exact), so the pruned expression is exact over the
region.  Split planes bound no surface (the two sides agree on them), so they carry no face
box and the sampler starts no task on them; no mesh face lies on a split plane.
"""

from __future__ import annotations

import numpy as np

from .bsp import _split, bsp_expression

#: a cell with at most this many distinct face planes is a leaf
LEAF_PLANES = 64
#: a split that leaves a side with more than this share of the cell's triangles is not made
MIN_GAIN = 0.9
#: where splits are tried, as quantiles of the triangles' centroids along each axis
CUT_QUANTILES = (0.3, 0.4, 0.5, 0.6, 0.7)
#: depth of the tree at most (a fan of many faces around one point cannot be split apart)
MAX_DEPTH = 48


def partition_expression(tris: np.ndarray, planes: np.ndarray, normals, offsets, eps: float, lo, hi,
                         leaf_planes: int | None = None):
    """The solid of the closed, outward-oriented triangles ``tris`` (k, 3, 3) on face planes
    ``planes`` (k,) within the box [lo, hi] (which holds the mesh) as a nested tuple
    expression: ``("split", axis, c, k)`` is the half-space x_axis <= c splitting cell k of
    ``splits``, ``("face", p, leaf)`` the half-space of face plane p in cell ``leaf`` of
    ``leaves``, and ``("not", e)``, ``("and", [...])``, ``("or", [...])``.  Returns (expression,
    leaves, splits): leaves [(cell lo, cell hi, {plane: (lo, hi) of its pieces})], splits
    [(cell lo, cell hi)].  Built without recursion."""
    leaf_planes = LEAF_PLANES if leaf_planes is None else leaf_planes
    leaves: list = []
    splits: list = []
    root: list = [None]
    pending = []  # split nodes, filled after their children
    stack = [(tris, planes, np.asarray(lo, dtype=np.float64), np.asarray(hi, dtype=np.float64), root, 0, 0)]
    while stack:
        t, pl, clo, chi, slot, i, depth = stack.pop()
        cut = None
        if len(np.unique(pl)) > leaf_planes and depth < MAX_DEPTH:
            cut = _cut(t, pl, clo, chi, eps)
        if cut is not None:
            axis, c, (bt, bp), (ft, fp) = cut
            blo, bhi, flo, fhi = clo.copy(), chi.copy(), clo.copy(), chi.copy()
            bhi[axis] = flo[axis] = c
            node = {"split": ("split", axis, float(c), len(splits)), "back": [None], "front": [None], "slot": slot,
                    "i": i}
            splits.append((clo, chi))
            stack.append((bt, bp, blo, bhi, node["back"], 0, depth + 1))
            stack.append((ft, fp, flo, fhi, node["front"], 0, depth + 1))
            pending.append(node)
            continue
        leaf = len(leaves)
        boxes = {}
        for p in np.unique(pl).tolist():
            pts = t[pl == p].reshape(-1, 3)
            boxes[p] = (pts.min(axis=0), pts.max(axis=0))
        leaves.append((clo, chi, boxes))
        slot[i] = _relabel(bsp_expression(t, pl, normals, offsets, eps), leaf)
    for node in reversed(pending):
        h = node["split"]
        node["slot"][node["i"]] = ("or", [("and", [h, node["back"][0]]), ("and", [("not", h), node["front"][0]])])
    return root[0], leaves, splits


def _cut(t, pl, clo, chi, eps):
    """(axis, c, (back triangles, planes), (front triangles, planes)) of the best split of the
    cell's triangles ``t`` (planes ``pl``): on each axis, at the gaps between vertex
    coordinates nearest a few quantiles of the triangles' centroids, the one cutting the
    fewest triangles (a cut triangle is in both cells) among those leaving at most
    :data:`MIN_GAIN` of the triangles on either side; None where there is none."""
    cen = t.mean(axis=1)
    best, best_cost = None, None
    for axis in range(3):
        lo_t, hi_t = t[:, :, axis].min(axis=1), t[:, :, axis].max(axis=1)
        x = t[:, :, axis].reshape(-1)
        for quant in CUT_QUANTILES:
            c = _gap(x, float(np.quantile(cen[:, axis], quant)), clo[axis], chi[axis], eps)
            if c is None:
                continue
            cut = int(np.sum((lo_t < c) & (hi_t > c)))
            n_back, n_front = int(np.sum(lo_t < c)), int(np.sum(hi_t > c))
            if max(n_back, n_front) > MIN_GAIN * len(t) or not n_back or not n_front:
                continue
            cost = cut + 0.25 * abs(n_back - n_front)
            if best_cost is None or cost < best_cost:
                best, best_cost = (axis, c), cost
    if best is None:
        return None
    axis, c = best
    back, front = _clip(t, pl, axis, c)
    return int(axis), c, back, front


def _gap(x, m, lo, hi, eps):
    """The midpoint of the gap wider than 4 ``eps`` between consecutive distinct values of ``x``
    inside (lo + eps, hi - eps) nearest ``m``; None if there is none.  Every value is then
    more than 2 eps from the split."""
    u = np.unique(x[(x > lo + eps) & (x < hi - eps)])
    if len(u) < 2:
        return None
    wide = (u[1:] - u[:-1]) > 4.0 * eps
    if not wide.any():
        return None
    mids = (0.5 * (u[1:] + u[:-1]))[wide]
    return float(mids[np.argmin(np.abs(mids - m))])


def _clip(t, pl, axis, c):
    """Per side of x_axis = c (back x <= c, front x >= c), the triangles' pieces on it and
    their planes: whole triangles, and the two sides of those that span the plane (no corner
    lies on it, see :func:`_gap`)."""
    d = t[:, :, axis] - c
    lo_d, hi_d = d.min(axis=1), d.max(axis=1)
    parts = {"back": ([t[hi_d < 0]], [pl[hi_d < 0]]), "front": ([t[lo_d > 0]], [pl[lo_d > 0]])}
    for k in np.flatnonzero((hi_d > 0) & (lo_d < 0)):
        f, b = _split(t[k], d[k], 0.0)
        for side, pieces in (("front", f), ("back", b)):
            if pieces:
                parts[side][0].append(np.array(pieces))
                parts[side][1].append(np.full(len(pieces), pl[k]))
    return tuple((np.concatenate(parts[s][0]).reshape(-1, 3, 3), np.concatenate(parts[s][1]).astype(np.int64))
                 for s in ("back", "front"))


def _relabel(expr, leaf):
    """A leaf's BSP expression with ``("plane", p)`` as ``("face", p, leaf)`` (no recursion)."""
    out: dict = {}
    stack = [(expr, False)]
    while stack:
        e, done = stack.pop()
        if id(e) in out:
            continue
        if e[0] == "plane":
            out[id(e)] = ("face", e[1], leaf)
        elif not done:
            stack.append((e, True))
            stack.extend((c, False) for c in (e[1] if e[0] in ("and", "or") else [e[1]]))
        elif e[0] == "not":
            out[id(e)] = ("not", out[id(e[1])])
        else:
            out[id(e)] = (e[0], [out[id(c)] for c in e[1]])
    return out[id(expr)]
