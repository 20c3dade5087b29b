"""Local refinement of a snapped facets mesh: edges whose chords sag too far split at points
solved onto their surface or curve, instead of faceting the primitives again.

A triangle fails the chord checks of :mod:`.exact_facets` when one of its edges runs along an
intersection curve and its midpoint lies farther than the tolerance from the curve (a hole's
rim on a slope, where the curve bends more sharply than either surface's circle), or when the
triangle lies farther than the tolerance from its own quadric.  Such an edge, with C the
quadrics of the (one or two) triangles beside it, is split at the point x of C nearest to its
midpoint m (Newton, :func:`~.project.newton`: onto the surface for one quadric, onto the
curve for two).  The chord's sag is about k L^2 / 8 for a curve of curvature k: halving the
edge quarters it.  Both triangles of a split edge split at the same vertex (the red-green
pattern of :func:`~.refine.split_triangles`), so the mesh stays closed, oriented and
2-manifold.

The split is refused, and the caller facets again, when an edge's ends do not both lie on C
(it spans a feature), Newton does not converge within half the edge's length of m, x is not
on the solid's surface (the straddle test), or a new triangle turns over (its normal against
its parent's).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .project import first_order_distance, newton
from .refine import split_triangles
from .snap import STRADDLE, straddles

#: an edge of a triangle off its quadric is split when its midpoint is farther than this many
#: tolerances from the quadric (a triangle's interior sags about 4/3 as far as its edges)
EDGE_SHARE = 0.5


@dataclass
class Split:
    """The refined mesh: vertices (the new ones last, ``before`` their edges' midpoints),
    triangles, per vertex its quadrics, per triangle its quadric, the triangle it came from
    and whether it is new (its parent was split)."""

    vertices: np.ndarray
    triangles: np.ndarray
    sets: np.ndarray
    quadric: np.ndarray
    before: np.ndarray
    parent: np.ndarray
    fresh: np.ndarray


def edge_sides(edges, tri_edge, quad):
    """Per edge the quadrics of its two triangles (E, 2) (-1 where a triangle has none)."""
    side = np.full((len(edges), 2), -1, dtype=np.int64)
    flat_edge, flat_tri = tri_edge.reshape(-1), np.repeat(np.arange(len(tri_edge)), 3)
    order = np.argsort(flat_edge, kind="stable")
    first = np.concatenate([[True], flat_edge[order][1:] != flat_edge[order][:-1]])
    side[flat_edge[order][first], 0] = quad[flat_tri[order][first]]
    side[flat_edge[order][~first], 1] = quad[flat_tri[order][~first]]
    return side


def edges_to_split(tape, vertices, triangles, quad, tri_edge, far_edge, off_quadric, tol):
    """The edges to split (bool per edge): the far crease edges, and of each triangle off its
    quadric the edges on that quadric whose midpoints are more than :data:`EDGE_SHARE`
    tolerances from it (all of its edges on the quadric if none is).  None if a triangle off
    its quadric has no edge on it."""
    out = far_edge.copy()
    rows = np.flatnonzero(off_quadric)
    if not len(rows):
        return out
    v = vertices[triangles[rows]]
    q = tape.quadrics[quad[rows]][:, None]
    mids = 0.5 * (v + np.roll(v, -1, axis=1))
    dist = np.stack([first_order_distance(q, mids[:, k]) for k in range(3)], 1)
    pick = ~(dist <= EDGE_SHARE * tol)
    none = ~pick.any(axis=1)
    pick[none] = True
    out[tri_edge[rows][pick]] = True
    return out


def split_far(tape, vertices, triangles, sets, quad, before, edges, tri_edge, split, contains):
    """The mesh with the ``split`` edges split (see the module docstring), or None where one of
    them cannot be."""
    e = np.flatnonzero(split)
    side = edge_sides(edges, tri_edge, quad)[e]
    two = (side[:, 1] >= 0) & (side[:, 1] != side[:, 0])
    if (side[:, 0] < 0).any():
        return None
    a, b = edges[e, 0], edges[e, 1]
    for k in (0, 1):
        q = side[:, k]
        on = (sets[a] == q[:, None]).any(axis=1) & (sets[b] == q[:, None]).any(axis=1)
        if not np.all(on | ((k == 1) & ~two)):
            return None
    mid = 0.5 * (vertices[a] + vertices[b])
    half = 0.5 * np.linalg.norm(vertices[a] - vertices[b], axis=1)
    x = np.empty_like(mid)
    for count, rows in ((1, np.flatnonzero(~two)), (2, np.flatnonzero(two))):
        if len(rows):
            got, ok = newton(tape.quadrics[side[rows, :count]], mid[rows])
            if not np.all(ok & (np.linalg.norm(got - mid[rows], axis=1) <= half[rows])):
                return None
            x[rows] = got
    eps = STRADDLE * max(1.0, float(np.abs(x).max()))
    if not straddles(x, contains, eps).all():
        return None
    mid_vertex = np.full(len(edges), -1, dtype=np.int64)
    mid_vertex[e] = len(vertices) + np.arange(len(e))
    all_v = np.concatenate([vertices, x])
    tri, parent = split_triangles(triangles, tri_edge, mid_vertex, all_v, with_parents=True)
    fresh = (mid_vertex[tri_edge] >= 0).any(axis=1)[parent]
    if not _flip_turned(all_v, tri, _normals(vertices, triangles)[parent], quad[parent], len(vertices), fresh):
        return None
    new_sets = np.full((len(e), sets.shape[1]), -1, dtype=np.int64)
    new_sets[:, 0] = side[:, 0]
    new_sets[two, 1] = side[two, 1]
    return Split(all_v, tri, np.concatenate([sets, new_sets]), quad[parent], np.concatenate([before, mid]), parent,
                 fresh)


def _normals(v, t):
    return np.cross(v[t[:, 1]] - v[t[:, 0]], v[t[:, 2]] - v[t[:, 0]])


def _flip_turned(v, tri, ref, quad, n_old: int, fresh) -> bool:
    """Make every triangle face the way of ``ref`` (its parent's normal), in place: a new
    triangle that turned over (its new vertex m, on a curve that bulges into the face, crossed
    the edge opposite it: a sliver of the Booleans' triangulation) has that edge flipped with
    the triangle across it when both lie on one quadric, (m, u, w) + (w, u, q) ->
    (m, u, q) + (m, q, w), up to :data:`FLIP_PASSES` times (a new triangle still turned holds m
    and has its opposite edge flipped on the next pass, Lawson's walk).  Flipped triangles
    become ``fresh``.  False where that does not set every triangle upright."""
    for _ in range(FLIP_PASSES):
        turned = np.flatnonzero(np.einsum("ij,ij->i", _normals(v, tri), ref) <= 0)
        if not len(turned):
            return True
        keys = (tri * np.int64(len(v)) + np.roll(tri, -1, axis=1)).ravel()  # directed edges (k, k+1)
        order = np.argsort(keys)
        changed = set()
        for t in turned.tolist():
            newer = np.flatnonzero(tri[t] >= n_old)
            if not len(newer) or t in changed:
                return False
            k = int(newer[0])
            m, u, w = (int(tri[t, (k + i) % 3]) for i in range(3))
            at = np.searchsorted(keys[order], w * len(v) + u)
            if at >= len(keys) or keys[order[at]] != w * len(v) + u:
                return False
            j = int(order[at]) // 3
            q = int(tri[j, (int(order[at]) % 3 + 2) % 3])
            if j in changed or quad[j] != quad[t]:
                return False
            tri[t], tri[j], ref[t] = (m, u, q), (m, q, w), ref[j]  # still turned: flipped on next pass
            fresh[t] = fresh[j] = True
            changed.update((t, j))
    return not (np.einsum("ij,ij->i", _normals(v, tri), ref) <= 0).any()


#: passes of :func:`_flip_turned`
FLIP_PASSES = 4
