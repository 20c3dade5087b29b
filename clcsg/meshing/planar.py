"""Flat faces with few triangles: every planar patch re-triangulated from its boundary alone.

A planar patch is a connected set of triangles (sharing edges) whose vertices all lie on the
same plane quadric (and on no second plane: a sliver along a straight edge stays as it is).  Its boundary (the directed edges whose reverse is not in the patch) is a
set of closed loops in the plane: the outer loop and the holes.  The patch is replaced by an
ear-clipping triangulation of those loops (``mapbox_earcut``, in the plane's 2-D frame) with no
interior vertex: the boundary, hence every edge shared with the rest of the mesh, is
unchanged, so the mesh stays closed and manifold, and the new triangles lie exactly in the
plane.  A patch is left as it is when its boundary is not a set of simple loops (a vertex with
two outgoing boundary edges) or the new triangles do not cover the same area as the old
ones (a loop that crosses itself after rounding), and all patches keep their triangles if
the result is not closed (a safety net, :func:`closed`).
"""

from __future__ import annotations

import numpy as np

from .refine import common, edges_of

#: relative area mismatch beyond which a re-triangulated patch is rejected
AREA_TOL = 1e-6
#: the zigzag of the ear clipper's input, relative to the patch size
NUDGE = 1e-7


def _plane_patches(m):
    """(triangle indices, plane quadric) of each connected planar patch."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    planes = flat_quadrics(m.tape.quadrics)
    s = m.sets[m.triangles]
    shared = common(common(s[:, 0], s[:, 1]), s[:, 2])
    is_plane = np.isin(shared, planes)
    plane = np.where(is_plane.sum(axis=1) == 1,
                     np.take_along_axis(shared, np.argmax(is_plane, axis=1)[:, None], 1)[:, 0], -1)
    sel = np.flatnonzero(plane >= 0)
    if not len(sel):
        return []
    _, tri_edge = edges_of(m.triangles[sel])
    e = tri_edge.ravel()
    t = np.repeat(np.arange(len(sel)), 3)
    order = np.lexsort((t, e))
    e, t = e[order], t[order]
    same = (e[1:] == e[:-1]) & (plane[sel][t[1:]] == plane[sel][t[:-1]])
    a, b = t[:-1][same], t[1:][same]
    g = coo_matrix((np.ones(len(a)), (a, b)), shape=(len(sel), len(sel)))
    n, label = connected_components(g, directed=False)
    order = np.argsort(label, kind="stable")
    cuts = np.flatnonzero(np.diff(label[order])) + 1
    return [(sel[grp], int(plane[sel[grp[0]]])) for grp in np.split(order, cuts)]


def _loops(tri):
    """Boundary loops (lists of vertex ids, in the triangles' orientation), or None."""
    d = np.concatenate([tri[:, [0, 1]], tri[:, [1, 2]], tri[:, [2, 0]]])
    fwd = {(int(x), int(y)) for x, y in d}
    nxt: dict = {}
    for x, y in fwd:
        if (y, x) not in fwd:
            if x in nxt:
                return None
            nxt[x] = y
    loops = []
    while nxt:
        start, cur = next(iter(nxt.items()))
        loop = [start]
        del nxt[start]
        while cur != start:
            loop.append(cur)
            if cur not in nxt:
                return None
            cur = nxt.pop(cur)
        loops.append(loop)
    return loops


def flat_quadrics(quadrics) -> np.ndarray:
    """Indices of the quadrics made of planes: a plane (A = 0) or two parallel planes, a slab
    (A = lambda n n^T of rank one, b parallel to n).  One batched eigendecomposition."""
    m = np.asarray(quadrics, dtype=np.float64).reshape(-1, 4, 4)
    if not len(m):
        return np.zeros(0, dtype=np.int64)
    lam, vec = np.linalg.eigh(m[:, :3, :3])
    scale = 1e-12 * np.maximum(1.0, np.abs(m).max(axis=(1, 2)))
    big = np.abs(lam) > scale[:, None]
    count = big.sum(axis=1)
    n = vec[np.arange(len(m)), :, np.argmax(np.abs(lam), axis=1)]  # the largest eigenvalue's vector
    b = m[:, :3, 3]
    off = np.linalg.norm(b - np.einsum("ki,ki->k", b, n)[:, None] * n, axis=1)
    return np.flatnonzero((count == 0) | ((count == 1) & (off <= scale))).astype(np.int64)


def _frame(matrix, x):
    """Unit normal n (the gradient at ``x`` on the plane) and an orthonormal (u, w), u x w = n."""
    n = 2.0 * (matrix @ np.append(x, 1.0))[:3]
    n = n / np.linalg.norm(n)
    u = np.cross(n, [1.0, 0, 0] if abs(n[0]) < 0.9 else [0, 1.0, 0])
    u /= np.linalg.norm(u)
    return n, u, np.cross(n, u)


def _area2(p, tri):
    a, b, c = p[tri[:, 0]], p[tri[:, 1]], p[tri[:, 2]]
    return 0.5 * ((b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (b[:, 1] - a[:, 1]) * (c[:, 0] - a[:, 0]))


def _nudged(p):
    """A loop's 2-D points for the ear clipper, every other one moved a hair into the patch
    (to the left of the loop's direction): the clipper drops collinear and coinciding points
    (a straight sharp edge split at many points, a corner solved from two edges), which would
    leave a hole; a zigzag keeps every one.  Only the 2-D copy moves, not the vertices."""
    if len(p) < 3:
        return p
    size = float(np.ptp(p, axis=0).max())
    d = np.roll(p, -1, axis=0) - np.roll(p, 1, axis=0)
    left = np.stack([-d[:, 1], d[:, 0]], axis=1)
    ln = np.linalg.norm(left, axis=1, keepdims=True)
    left = np.divide(left, ln, out=np.zeros_like(left), where=ln > 0)
    odd = (np.arange(len(p)) % 2 == 1)[:, None]
    return p + np.where(odd, NUDGE * size * left, 0.0)


def _retriangulate(m, tri, plane):
    """New triangles for one patch, or None to keep it."""
    import mapbox_earcut

    loops = _loops(tri)
    if not loops:
        return None
    n, u, w = _frame(m.tape.quadrics[plane], m.vertices[tri[0, 0]])
    v = m.vertices
    old2 = np.stack([v[tri] @ u, v[tri] @ w], axis=-1)  # (T, 3, 2)
    flat = old2.reshape(-1, 2)
    old_area = _area2(flat, np.arange(len(flat)).reshape(-1, 3))
    sign = 1.0 if old_area.sum() >= 0 else -1.0
    ids = [np.array(lp) for lp in loops]
    pts = [np.stack([v[i] @ u, sign * (v[i] @ w)], axis=1) for i in ids]
    areas = [0.5 * np.sum(p[:, 0] * np.roll(p[:, 1], -1) - np.roll(p[:, 0], -1) * p[:, 1]) for p in pts]
    outer = int(np.argmax(areas))
    order = [outer] + [k for k in range(len(ids)) if k != outer]
    ring = np.concatenate([_nudged(pts[k]) for k in order])
    vid = np.concatenate([ids[k] for k in order])
    ends = np.cumsum([len(ids[k]) for k in order]).astype(np.uint32)
    out = np.asarray(mapbox_earcut.triangulate_float64(ring, ends), dtype=np.int64).reshape(-1, 3)
    if len(out) != len(ring) + 2 * (len(ids) - 1) - 2:
        return None
    new_area = _area2(ring, out)
    out = np.where((new_area < 0)[:, None], out[:, ::-1], out)
    total = abs(old_area.sum())
    if abs(np.abs(new_area).sum() - total) > AREA_TOL * max(total, 1e-300) * len(out):
        return None
    new = vid[out]
    return new if _closes(new, loops) else None


def _closes(tri, loops) -> bool:
    """The new triangles cover every boundary edge once in the loops' direction and pair up
    all their other edges: glued back, the mesh is closed and manifold."""
    d = np.concatenate([tri[:, [0, 1]], tri[:, [1, 2]], tri[:, [2, 0]]])
    if np.any(d[:, 0] == d[:, 1]):
        return False
    keys = {(int(a), int(b)) for a, b in d}
    if len(keys) != len(d):
        return False
    boundary = {(int(lp[k]), int(lp[(k + 1) % len(lp)])) for lp in loops for k in range(len(lp))}
    if not boundary <= keys:
        return False
    return all((b, a) in keys for a, b in keys - boundary) and not any((b, a) in keys for a, b in boundary)


def closed(tri) -> bool:
    """Every directed edge's reverse is present exactly once: closed, manifold edges and a
    consistent orientation."""
    n = np.int64(tri.max(initial=0) + 1)
    d = np.concatenate([tri[:, [0, 1]], tri[:, [1, 2]], tri[:, [2, 0]]]).astype(np.int64)
    fwd = np.sort(d[:, 0] * n + d[:, 1])
    rev = np.sort(d[:, 1] * n + d[:, 0])
    return bool(np.all(np.diff(fwd) > 0) and np.array_equal(fwd, rev))


def coarsen(m, stats: dict) -> None:
    """Re-triangulate every planar patch of ``m`` in place (each kept only if the whole mesh
    stays closed, :func:`closed`); drop unused vertices."""
    patches = skipped = 0
    pos = np.arange(len(m.triangles))  # where each original triangle is now
    for tri_idx, plane in _plane_patches(m):
        tri_idx = pos[tri_idx]
        t = _retriangulate(m, m.triangles[tri_idx], plane)
        if t is None:
            skipped += 1
            continue
        keep = np.ones(len(m.triangles), dtype=bool)
        keep[tri_idx] = False
        trial = np.concatenate([m.triangles[keep], t])
        if not closed(trial):
            skipped += 1
            continue
        remap = np.full(len(m.triangles), -1, dtype=np.int64)
        remap[keep] = np.arange(keep.sum())
        pos = remap[pos]  # the other patches' triangles keep their order, before the new ones
        m.triangles = trial
        patches += 1
    used = np.zeros(len(m.vertices), dtype=bool)
    used[m.triangles.ravel()] = True
    remap = np.cumsum(used) - 1
    m.vertices, m.sets = m.vertices[used], m.sets[used]
    m.triangles = remap[m.triangles]
    stats.update(planar_patches=patches, planar_patches_kept=skipped)
