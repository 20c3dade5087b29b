"""Zero-length edges collapsed: a corner or curve point solved from two edges of one triangle is
one point, so its two vertices become one.

An edge (a, b) whose ends coincide (to :data:`COINCIDENT` of the coordinates' scale) is
collapsed, b into a, when the link condition holds: the vertices adjacent to both a and b are
exactly the two opposite the edge.  Then the two triangles of the edge (zero area) disappear,
every other triangle of b takes a, and the mesh stays closed, oriented and 2-manifold (the
link condition is what guarantees it).  The merged vertex lies on the quadrics of both.
Coincident vertices that no edge joins are merged as well, where the mesh stays closed.
"""

from __future__ import annotations

from collections import defaultdict

import numpy as np

from .planar import closed
from .refine import edges_of

#: ends closer than this, relative to max(1, largest |coordinate|), coincide
COINCIDENT = 1e-12
#: groups of coincident vertices tried for a merge at most (each a check of the whole mesh)
MAX_MERGE_GROUPS = 1000


def collapse_coincident(m, stats: dict, unjoined: bool = True) -> None:
    """Collapse the zero-length edges of ``m`` in place (those that keep the mesh manifold),
    and merge coincident vertices no edge joins if ``unjoined`` (not where the mesh comes
    from manifold3d, which keeps such vertices apart on purpose: two cubes touching along an
    edge)."""
    edges, _ = edges_of(m.triangles)
    scale = max(1.0, float(np.abs(m.vertices).max(initial=0.0)))
    length = np.linalg.norm(m.vertices[edges[:, 0]] - m.vertices[edges[:, 1]], axis=1)
    cand = edges[length <= COINCIDENT * scale]
    done = _collapse_edges(m, cand) if len(cand) else 0
    stats.update(collapsed_edges=done, merged_vertices=_merge_unjoined(m, scale) if unjoined else 0)


def _collapse_edges(m, cand) -> int:
    """Collapse the edges ``cand`` (E, 2) where the link condition holds; returns how many."""
    tri = [list(t) for t in m.triangles]
    alive = [True] * len(tri)
    of = defaultdict(set)
    for k, t in enumerate(tri):
        for v in t:
            of[v].add(k)
    merged = {}
    done = 0
    for a, b in cand:
        a, b = _root(merged, int(a)), _root(merged, int(b))
        if a == b or not _collapse(tri, alive, of, a, b):
            continue
        merged[b] = a
        own = [q for q in m.sets[a] if q >= 0]
        own += [q for q in m.sets[b] if q >= 0 and q not in own]
        _store_set(m, a, own)
        done += 1
    m.triangles = np.array([t for t, ok in zip(tri, alive) if ok], dtype=np.int64).reshape(-1, 3)
    if m.faces is not None:
        m.faces = m.faces[np.array(alive, dtype=bool)]
    return done


def _merge_unjoined(m, scale) -> int:
    """Coincident vertices (one corner solved for two neighbouring triangles) become one,
    group by group: the triangles of the others take the first, those left with a repeated
    vertex or folded onto a twin of opposite orientation disappear.  A group is merged only
    if the mesh stays closed (:func:`~.planar.closed`; where two sheets of the solid touch at
    a point, it does not); returns how many vertices merged."""
    key = np.round(m.vertices / (COINCIDENT * scale)).astype(np.int64)
    _, which, count = np.unique(key, axis=0, return_inverse=True, return_counts=True)
    which = which.ravel()
    merged = 0
    for g in np.flatnonzero(count > 1)[:MAX_MERGE_GROUPS]:
        group = np.flatnonzero(which == g)
        keep, rest = group[0], group[1:]
        target = np.arange(len(m.vertices))
        target[rest] = keep
        tri = target[m.triangles]
        kept = np.flatnonzero((tri[:, 0] != tri[:, 1]) & (tri[:, 1] != tri[:, 2]) & (tri[:, 2] != tri[:, 0]))
        _, inv, twins = np.unique(np.sort(tri[kept], axis=1), axis=0, return_inverse=True, return_counts=True)
        kept = kept[twins[inv.ravel()] == 1]
        tri = tri[kept]
        if not len(tri) or not closed(tri):
            continue
        if m.faces is not None:
            m.faces = m.faces[kept]
        own = [q for q in m.sets[keep] if q >= 0]
        for v in rest:
            own += [q for q in m.sets[v] if q >= 0 and q not in own]
        _store_set(m, keep, own)
        m.triangles = tri
        merged += len(rest)
    return merged


def _store_set(m, v, own) -> None:
    """Vertex ``v``'s quadrics become ``own``: all of them, the sets widened to fit, if the
    surface allows it (``m.wide``), else as many as fit (the refinement solves at most three)."""
    w = m.sets.shape[1]
    if m.wide and len(own) > w:
        m.sets = np.pad(m.sets, ((0, 0), (0, len(own) - w)), constant_values=-1)
        w = len(own)
    m.sets[v] = (own + [-1] * w)[:w]


def _root(merged, v):
    while v in merged:
        v = merged[v]
    return v


def _collapse(tri, alive, of, a, b) -> bool:
    both = [k for k in of[a] & of[b]]
    if len(both) != 2:
        return False
    opposite = {v for k in both for v in tri[k] if v not in (a, b)}
    na = {v for k in of[a] for v in tri[k]} - {a}
    nb = {v for k in of[b] for v in tri[k]} - {b}
    if (na & nb) != opposite or len(opposite) != 2:
        return False
    for k in both:
        alive[k] = False
        for v in tri[k]:
            of[v].discard(k)
    for k in list(of[b]):
        tri[k] = [a if v == b else v for v in tri[k]]
        of[a].add(k)
    of[b] = set()
    return True
