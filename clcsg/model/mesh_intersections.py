"""Whether a closed mesh intersects itself: the first pair of triangles that cross.

Candidate pairs are the triangles whose bounding boxes overlap (a box tree's query), minus
the pairs that share a point (neighbours meet along their shared edge or corner by design).
Each candidate is tested exactly as Moeller's interval test does it, in float64: the corners
of each triangle on both sides of the other's plane, then the two segments in which the
triangles meet the line of the two planes overlap by more than the tolerance.  Coplanar pairs
(normals within 1e-6 radians) are left out (they cannot cross without an edge of one entering the other's plane elsewhere,
which a neighbouring pair then shows, or they overlap in the plane: a doubled face, whose edges
the edge check already counts).
"""

from __future__ import annotations

import warnings

import numpy as np

from .bvh import BoxTree

#: sine of the angle below which two triangles count as coplanar (their line is ill-conditioned;
#: meshes written in float32 have neighbouring triangles of one flat face this far apart)
_PARALLEL = 1e-6


def _candidates(lo, hi, t, tol):
    """(i, j), i < j, of the triangles whose boxes overlap (within ``tol``) and that share no
    point: a :class:`~clcsg.model.bvh.BoxTree` over the boxes grown by ``tol``, queried by
    the boxes themselves, so the work follows the overlapping pairs (a sweep along one axis
    compared every triangle of a plate with every other one in its column)."""
    i, j = BoxTree(lo - tol, hi + tol).query(lo, hi)
    keep = i < j
    i, j = i[keep], j[keep]
    shared = np.any(t[i][:, :, None] == t[j][:, None, :], axis=(1, 2))
    return i[~shared], j[~shared]


def _interval(p, d, axis_dir, tol):
    """Per pair, the interval (lo, hi) along ``axis_dir`` of the segment where a triangle
    (corners p (m, 3, 3), signed distances d (m, 3) to the other plane) meets that plane."""
    vals = []
    for a, b in ((0, 1), (1, 2), (2, 0)):
        da, db = d[:, a], d[:, b]
        cross = (da * db) < 0
        w = np.where(cross, da / np.where(cross, da - db, 1.0), 0.0)
        x = p[:, a] + (p[:, b] - p[:, a]) * w[:, None]
        vals.append(np.where(cross, np.einsum("mi,mi->m", x, axis_dir), np.nan))
        on = np.abs(da) <= tol
        vals.append(np.where(on, np.einsum("mi,mi->m", p[:, a], axis_dir), np.nan))
    v = np.stack(vals, axis=1)
    return np.nanmin(v, axis=1), np.nanmax(v, axis=1)


def first_intersection(v: np.ndarray, t: np.ndarray, tol: float):
    """The first pair (i, j) of triangles (rows of ``t`` into points ``v``) that cross each
    other by more than ``tol``, or None."""
    tri = v[t]
    lo, hi = tri.min(axis=1), tri.max(axis=1)
    i, j = _candidates(lo, hi, t, tol)
    if not len(i):
        return None
    a, b = tri[i], tri[j]
    na = np.cross(a[:, 1] - a[:, 0], a[:, 2] - a[:, 0])
    nb = np.cross(b[:, 1] - b[:, 0], b[:, 2] - b[:, 0])
    na /= np.linalg.norm(na, axis=1, keepdims=True)
    nb /= np.linalg.norm(nb, axis=1, keepdims=True)
    da = np.einsum("mki,mi->mk", a - b[:, :1], nb)  # a's corners against b's plane
    db = np.einsum("mki,mi->mk", b - a[:, :1], na)
    straddle = ~(np.all(da > tol, axis=1) | np.all(da < -tol, axis=1) | np.all(db > tol, axis=1) | np.all(db < -tol, axis=1))
    line = np.cross(na, nb)
    norm = np.linalg.norm(line, axis=1)
    keep = straddle & (norm > _PARALLEL) & ~np.all(np.abs(da) <= tol, axis=1)
    if not np.any(keep):
        return None
    a, b, da, db, i, j = a[keep], b[keep], da[keep], db[keep], i[keep], j[keep]
    line = line[keep] / norm[keep, None]
    with warnings.catch_warnings():  # a row without a point: nan, no overlap
        warnings.simplefilter("ignore", RuntimeWarning)
        a_lo, a_hi = _interval(a, da, line, tol)
        b_lo, b_hi = _interval(b, db, line, tol)
    cross = (np.minimum(a_hi, b_hi) - np.maximum(a_lo, b_lo)) > tol
    hits = np.flatnonzero(cross)
    if not len(hits):
        return None
    k = hits[np.lexsort((j[hits], i[hits]))[0]]
    return int(i[k]), int(j[k])


def _components(t, n_points):
    """Per triangle, the label of its connected component (triangles sharing a point)."""
    parent = np.arange(n_points)

    def find(x):
        while parent[x] != x:
            parent[x] = parent[parent[x]]
            x = parent[x]
        return x

    for a, b, c in t:
        ra, rb, rc = find(a), find(b), find(c)
        parent[rb] = ra
        parent[find(rc)] = ra
    roots = np.array([find(x) for x in t[:, 0]])
    return np.unique(roots, return_inverse=True)[1].reshape(-1)


def winding(v, t, p):
    """The winding number of the triangles at point p (solid angles, Van Oosterom and
    Strackee): 1 inside a closed outward shell, -1 inside an inward one, 0 outside."""
    a, b, c = v[t[:, 0]] - p, v[t[:, 1]] - p, v[t[:, 2]] - p
    la, lb, lc = (np.linalg.norm(x, axis=1) for x in (a, b, c))
    det = np.einsum("ij,ij->i", a, np.cross(b, c))
    den = la * lb * lc + np.einsum("ij,ij->i", a, b) * lc + np.einsum("ij,ij->i", b, c) * la \
        + np.einsum("ij,ij->i", c, a) * lb
    return float(np.arctan2(det, den).sum() / (2 * np.pi))


def first_bad_shell(v, t, tol):
    """The first triangle of a shell (a connected component) with a winding number other than 0
    or 1 on either side of it (nested shells of the same orientation, an inward shell outside
    every other) or with none of its own on either side (a shell without volume, such as a face
    and its reverse), or None.  The winding number is read on both sides of the centre of each
    shell's largest triangle: the other shells' there, plus the shell's own on that side."""
    label = _components(t, len(v))
    if label.max() == 0:
        return None
    for k in range(label.max() + 1):
        own = np.flatnonzero(label == k)
        tri = v[t[own]]
        n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
        big = int(np.argmax(np.linalg.norm(n, axis=1)))
        unit = n[big] / np.linalg.norm(n[big])
        centre = tri[big].mean(axis=0)
        others = t[label != k]
        base = round(winding(v, others, centre))  # the other shells do not pass here
        sides = [round(winding(v, t[own], centre + s * 10 * tol * unit)) for s in (1, -1)]
        if any(base + w not in (0, 1) for w in sides) or not any(sides):  # not any: a shell without volume
            return int(own[big])
    return None
