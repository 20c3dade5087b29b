"""A closed triangle mesh as an exact Boolean expression of its face planes (a solid BSP tree).

A binary space partition whose splitting planes are the mesh's own face planes (Naylor's
autopartition) ends in cells that no face crosses; such a cell is entirely inside or entirely
outside, and for a closed mesh with outward normals the side is known: a cell reached from the
back of its last splitter touches that splitter's face from the inside, so it is inside.  Each
node with plane ``H`` (inside half-space ``H-: n.x <= d``, outside ``H+``) then denotes

    S = (H- & S_back) | (H+ & S_front)        leaves: back = inside, front = outside

which folds to ``H-`` (both leaves), ``H- | S_front`` (back leaf), ``H- & S_back`` (front
leaf).  A convex mesh is one intersection of its face planes.  The planes are the exact planes
of the triangles, so the surface is a set of planar patches clipped by the expression itself;
no quadric and no triangle is approximated.

A plane with no triangle in front of it splits off nothing: ``H- & S_back`` with every
triangle behind, and that stays true in the back subset for every other such plane, so all the
planes of a node's triangles that have none in front are taken at once, as one AND with the
expression of the triangles on none of them (a convex mesh: one AND, one pass).

Triangles that span a splitter are cut (their parts keep the triangle's plane, which only the
node that takes that plane uses); triangles within ``eps`` of a splitter's plane are that
plane's and leave the tree there.
"""

from __future__ import annotations

import numpy as np

_BACK_LEAF, _FRONT_LEAF = "in", "out"
#: candidate splitters tried at a node: the one cutting the fewest triangles wins
_CANDIDATES = 6


def triangle_planes(tri: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Unit outward normals (k, 3) and offsets (k,) of triangles (k, 3, 3) (counter-clockwise
    seen from outside)."""
    n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    n = n / np.linalg.norm(n, axis=1, keepdims=True)
    d = np.einsum("ij,ij->i", n, tri[:, 0])
    return n, d


def _split(tri: np.ndarray, dist: np.ndarray, eps: float):
    """The parts of one triangle (3, 3) in front of and behind a plane (signed distances
    ``dist`` of its corners), as lists of triangles."""
    front, back = [], []
    poly_f, poly_b = [], []
    for i in range(3):
        j = (i + 1) % 3
        a, b, da, db = tri[i], tri[j], dist[i], dist[j]
        if da >= -eps:
            poly_f.append(a)
        if da <= eps:
            poly_b.append(a)
        if (da > eps and db < -eps) or (da < -eps and db > eps):
            p = a + (b - a) * (da / (da - db))
            poly_f.append(p)
            poly_b.append(p)
    for poly, out in ((poly_f, front), (poly_b, back)):
        for k in range(1, len(poly) - 1):
            out.append(np.array([poly[0], poly[k], poly[k + 1]]))
    return front, back


def _choose(tri_plane: np.ndarray, normals, offsets, tris, eps, rng) -> int:
    """Index (into ``tri_plane``) of a splitter among a few candidates: fewest cut triangles."""
    picks = rng.choice(len(tri_plane), size=min(_CANDIDATES, len(tri_plane)), replace=False)
    p = tri_plane[picks]
    dist = tris @ normals[p].T - offsets[p]  # (k, 3, candidates)
    hi, lo = dist.max(axis=1), dist.min(axis=1)
    cut = np.sum((hi > eps) & (lo < -eps), axis=0)
    front = np.sum(lo >= -eps, axis=0)
    cost = cut * 8 + np.abs(2 * front - len(tris))
    return int(picks[int(np.argmin(cost))])  # the first of the cheapest, as one at a time


def _partition(tris, planes, p, normals, offsets, eps):
    """Triangles (with their plane ids) in front of and behind plane ``p``; those on it drop."""
    dist = tris @ normals[p] - offsets[p]
    hi, lo = dist.max(axis=1), dist.min(axis=1)
    on = (hi <= eps) & (lo >= -eps)
    front = ~on & (lo >= -eps)
    back = ~on & (hi <= eps)
    cut = ~(on | front | back)
    ft, fp = [tris[front]], [planes[front]]
    bt, bp = [tris[back]], [planes[back]]
    for k in np.flatnonzero(cut):
        f, b = _split(tris[k], dist[k], eps)
        if f:
            ft.append(np.array(f))
            fp.append(np.full(len(f), planes[k]))
        if b:
            bt.append(np.array(b))
            bp.append(np.full(len(b), planes[k]))
    return (np.concatenate(ft), np.concatenate(fp)), (np.concatenate(bt), np.concatenate(bp))


def bsp_expression(tris: np.ndarray, planes: np.ndarray, normals, offsets, eps: float, seed: int = 0):
    """The solid of the closed, outward-oriented triangles ``tris`` (k, 3, 3) on face planes
    ``planes`` (k,) (indices into ``normals``/``offsets``) as a nested tuple expression:
    ``("plane", p)`` is the half-space n_p . x <= d_p, ``("not", e)``, ``("and", [...])``,
    ``("or", [...])``.  Built without recursion."""
    rng = np.random.default_rng(seed)
    # a task: (tris, planes, slot) where slot is the list cell that receives the sub-expression
    root: list = [None]
    stack = [(tris, planes, root, 0)]
    pending = []  # (node record) filled after its children, in reverse creation order
    while stack:
        t, pl, slot, i = stack.pop()
        uniq = np.unique(pl)
        behind = _behind_all(t, uniq, normals, offsets, eps)
        if len(behind):
            rest = _off_planes(t, pl, behind, normals, offsets, eps)
            node = {"planes": behind, "sub": [None], "slot": slot, "i": i}
            if rest.any():
                stack.append((t[rest], pl[rest], node["sub"], 0))
            pending.append(node)
            continue
        p = int(uniq[_choose(uniq, normals, offsets, t, eps, rng)])
        (ft, fp), (bt, bp) = _partition(t, pl, p, normals, offsets, eps)
        node = {"plane": p, "front": [_FRONT_LEAF], "back": [_BACK_LEAF], "slot": slot, "i": i}
        if len(ft):
            stack.append((ft, fp, node["front"], 0))
        if len(bt):
            stack.append((bt, bp, node["back"], 0))
        pending.append(node)
    for node in reversed(pending):
        if "planes" in node:
            items = [("plane", int(p)) for p in node["planes"]] + ([node["sub"][0]] if node["sub"][0] is not None else [])
            node["slot"][node["i"]] = items[0] if len(items) == 1 else _flat("and", items)
        else:
            node["slot"][node["i"]] = _fold(node["plane"], node["back"][0], node["front"][0])
    return root[0]


#: (point, plane) distances computed at once
_CHUNK = 1 << 22


def _behind_all(tris, uniq, normals, offsets, eps) -> np.ndarray:
    """The planes of ``uniq`` with every corner of ``tris`` behind or on them (a corner shared
    by several triangles is tested once per triangle: cheaper than finding the shared ones)."""
    pts = tris.reshape(-1, 3)
    step = max(1, _CHUNK // max(1, len(pts)))
    out = []
    for s in range(0, len(uniq), step):
        u = uniq[s:s + step]
        far = (pts @ normals[u].T - offsets[u]).max(axis=0)
        out.append(u[far <= eps])
    return np.concatenate(out)


def _off_planes(tris, planes, chosen, normals, offsets, eps) -> np.ndarray:
    """Mask of the triangles on none of the ``chosen`` planes (their own plane not chosen, and
    not within ``eps`` of a chosen one)."""
    keep = ~np.isin(planes, chosen)
    idx = np.flatnonzero(keep)
    step = max(1, _CHUNK // max(1, 3 * len(chosen)))
    for s in range(0, len(idx), step):
        k = idx[s:s + step]
        d = np.abs(tris[k].reshape(-1, 3) @ normals[chosen].T - offsets[chosen]).reshape(len(k), 3, -1)
        keep[k[np.any(np.all(d <= eps, axis=1), axis=1)]] = False
    return keep


def _fold(p, back, front):
    """(H- & back) | (H+ & front), with the leaves folded and like operations flattened."""
    h = ("plane", p)
    if back == _BACK_LEAF:
        if front == _FRONT_LEAF:
            return h
        return _flat("or", [h, front])
    inner = _flat("and", [h, back])
    if front == _FRONT_LEAF:
        return inner
    return _flat("or", [inner, _flat("and", [("not", h), front])])


def _flat(op, items):
    out = []
    for e in items:
        out.extend(e[1] if e[0] == op else [e])
    return (op, out)
