"""Sub-cell features: bisecting the tetrahedra that hold what the grid is too coarse to see.

Marching tetrahedra sees the solid only through its vertices' labels and one crossing per
edge.  A feature thinner than a tetrahedron goes missing in two ways, both found exactly:

1. an edge crosses a stretch of the solid or of its outside between two membership changes
   (:func:`~.crossings.thin_stretches`), deeper than half the tolerance, on quadrics the
   tetrahedron's crossings do not both reach: a wall, fin or rod thinner than the edge;
2. a triangle edge joins two quadrics that no intersection curve joins near it (a step face
   between two coaxial cylinders or two parallel planes that no tetrahedron edge crosses):
   no later split finds that face, since no vertex is on its quadric.

Those tetrahedra are bisected (:mod:`.bisect`), the mesh closed again and the children's
pruned tapes recomputed over their boxes, until none is left, a cell's tetrahedra have been
bisected :data:`~.bisect.MAX_BISECTIONS` times (an eighth of its side) or after
:data:`MAX_ROUNDS`.  Only the tetrahedra made in a round are tested in the next, and each
crossing is solved once.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..compile.interpret import contains
from .bisect import MAX_BISECTIONS, SCALE, TET_EDGES, Tets, isin_sorted, kuhn_tets, refine_tets
from .box_states import _LIVE, box_states
from .crossings import crossings, thin_stretches
from .project import first_order_distance
from .refine import REACH, Surface, _solve, edge_planes, edges_of, on_curve
from ..model.marching_tetrahedra import triangulate


#: rounds of bisection at most: tetrahedra the closure made coarser than their neighbours are
#: tested in the rounds after the deepest (a tail of few)
MAX_ROUNDS = MAX_BISECTIONS + 3


class _Store:
    """Values by int64 key, kept sorted for lookups (columns of numpy arrays)."""

    def __init__(self, **columns):
        self.keys = np.zeros(0, dtype=np.int64)
        self.columns = columns

    def known(self, u) -> np.ndarray:
        """Which of the unique keys ``u`` are stored."""
        return isin_sorted(u, self.keys)

    def add(self, keys, **columns) -> None:
        allk = np.concatenate([self.keys, keys])
        order = np.argsort(allk, kind="stable")
        self.keys = allk[order]
        for name, values in columns.items():
            self.columns[name] = np.concatenate([self.columns[name], values])[order]

    def get(self, name, keys) -> np.ndarray:
        return self.columns[name][np.searchsorted(self.keys, keys)]


class Labels:
    """Membership of lattice points by key, each evaluated once, and a stable small id per
    point (the order they were first asked for)."""

    def __init__(self, evaluate):
        self.evaluate = evaluate
        self.store = _Store(inside=np.zeros(0, dtype=bool), id=np.zeros(0, dtype=np.int64))

    def __call__(self, keys) -> np.ndarray:
        keys = np.asarray(keys, dtype=np.int64)
        u, inv = np.unique(keys, return_inverse=True)
        new = u[~self.store.known(u)]
        if len(new):
            n = len(self.store.keys)
            self.store.add(new, inside=self.evaluate(new), id=np.arange(n, n + len(new)))
        return self.store.get("inside", u)[inv].reshape(keys.shape)

    def ids(self, keys) -> np.ndarray:
        """The ids of labelled points."""
        return self.store.get("id", np.asarray(keys, dtype=np.int64))


def edge_codes(labels, a, b) -> np.ndarray:
    """One int64 per edge between labelled lattice points ``a``, ``b`` (same shape), the same
    for (a, b) and (b, a)."""
    ia, ib = labels.ids(a), labels.ids(b)
    return np.minimum(ia, ib) * np.int64(1 << 32) + np.maximum(ia, ib)


class _Crossings:
    """Each marching edge's crossing, solved once: the edges persist across rounds of
    bisection wherever their tetrahedra were not cut."""

    def __init__(self):
        self.store = _Store(point=np.zeros((0, 3)), quadric=np.zeros(0, dtype=np.int64))
        self.fallbacks = 0

    def __call__(self, tape, labels, edges, lo_in, candidates, point) -> tuple:
        code = edge_codes(labels, edges[:, 0], edges[:, 1])
        new = np.flatnonzero(~self.store.known(code))
        if len(new):
            pa, pb = point(edges[new, 0]), point(edges[new, 1])
            lo = lo_in[new, None]
            x, q, fallbacks = crossings(tape, np.where(lo, pa, pb), np.where(lo, pb, pa),
                                        np.ones(len(new), bool), candidates[new])
            self.fallbacks += fallbacks
            self.store.add(code[new], point=x, quadric=q)
        return self.store.get("point", code), self.store.get("quadric", code)


@dataclass
class Marched:
    """Marching tetrahedra on the final mesh, its vertices on the exact surface: per crossed
    edge its crossing ``points`` (E, 3) and their quadric ``quadric`` (E,), triangles (T, 3)
    into them."""

    points: np.ndarray
    quadric: np.ndarray
    triangles: np.ndarray
    fallbacks: int


def _prune(tape, tets: Tets, point) -> None:
    """The pruned tapes of the new tetrahedra over their boxes (within the parent's)."""
    fresh = np.flatnonzero(~tets.pruned)
    if not len(fresh):
        return
    p = point(tets.keys(tets.xyz[fresh]))  # (F, 4, 3)
    root, needed = box_states(tape, p.min(axis=1), p.max(axis=1))
    tets.quadrics[fresh] &= needed & (root == _LIVE)[:, None]
    tets.pruned[fresh] = True


def _march(tape, tets: Tets, labels, solved, point) -> tuple:
    """Marching tetrahedra and the crossings, plus the tetrahedron of each triangle."""
    keys = tets.keys()
    inside = labels(keys)
    edges, lo_in, tri, edge_tet, tri_tet = triangulate(keys, tets.xyz, inside)
    verts, vq = solved(tape, labels, edges, lo_in, tets.quadrics[edge_tet], point)
    return Marched(verts, vq, tri, solved.fallbacks), tri_tet


def _unresolved_spans(tape, marched: Marched, tri_tet, check, tol) -> np.ndarray:
    """Triangles' tetrahedra (indices) with a triangle edge whose ends lie on two quadrics that
    no intersection curve on the solid's surface joins near it: :func:`~.refine.refine` would
    find none either, since the surface between them is on a third quadric no vertex is on
    (the step face between two coaxial cylinders or two parallel planes that no tetrahedron
    edge crosses, or the annulus between two cones whose own curve lies off the solid).  Only
    the triangles of the tetrahedra ``check`` (bool) are tested.  An edge whose quadrics have
    no curve near it at all is exempt when its middle is within ``tol`` of both (where two
    quadrics touch, a cylinder tangent to a plane, the edge is as close to the surface as a
    chord, and Newton has no crossing); a curve that Newton finds but that is no edge of the
    solid (:func:`~.refine.on_curve`) is not."""
    sets = np.full((len(marched.quadric), 3), -1, dtype=np.int64)
    sets[:, 0] = marched.quadric
    m = Surface(tape, marched.points, sets, marched.triangles)
    edges, tri_edge = edges_of(m.triangles)
    a, b = edges[:, 0], edges[:, 1]
    tested = np.zeros(len(edges), dtype=bool)
    tested[tri_edge[check[tri_tet]].ravel()] = True
    span = np.flatnonzero(tested & (marched.quadric[a] != marched.quadric[b]))
    if not len(span):
        return np.zeros(0, dtype=np.int64)
    mid = 0.5 * (m.vertices[a[span]] + m.vertices[b[span]])
    far = np.minimum(first_order_distance(tape.quadrics[marched.quadric[a[span]]][:, None], mid),
                     first_order_distance(tape.quadrics[marched.quadric[b[span]]][:, None], mid)) > tol
    sets = np.stack([marched.quadric[a[span]], marched.quadric[b[span]], np.full(len(span), -1)], axis=1)
    length = np.linalg.norm(m.vertices[a[span]] - m.vertices[b[span]], axis=1)
    x, found = _solve(tape, sets, mid, edge_planes(m, edges, tri_edge)[span])
    found &= np.linalg.norm(x - mid, axis=1) <= REACH * length
    ok = found.copy()
    ok[found] = on_curve(tape, x[found], sets[found, 0], sets[found, 1], 2.0 * tol)
    bad = np.zeros(len(edges), dtype=bool)
    bad[span[(found & ~ok) | (~found & far)]] = True
    return np.unique(tri_tet[bad[tri_edge].any(axis=1)])


def _thin_features(tape, tets: Tets, point, tol, check, labels, on) -> np.ndarray:
    """Tetrahedra ``check`` (bool (T,) in, out) with an edge that crosses a stretch of the
    solid or of its outside (:func:`~.crossings.thin_stretches`) deeper than ``tol`` whose
    quadrics are not both among the tetrahedron's crossings (``on``: sorted keys tet * U + q):
    there, marching misses a wall or a rod.  A stretch on quadrics the tetrahedron's triangles
    already reach is a curved patch clipped by the edge, which the later splits recover."""
    live = np.flatnonzero(check & tets.quadrics.any(axis=1))
    out = np.zeros(len(tets), dtype=bool)
    if not len(live):
        return out
    ek = tets.keys()[live][:, TET_EDGES]  # (L, 6, 2)
    uniq, first, inv = np.unique(edge_codes(labels, ek[..., 0], ek[..., 1]).ravel(),
                                 return_index=True, return_inverse=True)
    ends = ek.reshape(-1, 2)[first]
    holder = live[first // 6]
    e, qa, qb, depth = thin_stretches(tape, point(ends[:, 0]), point(ends[:, 1]), tets.quadrics[holder])
    deep = depth > tol
    e, qa, qb = e[deep], qa[deep], qb[deep]
    if not len(e):
        return out
    # every (tetrahedron, edge) slot against the stretches of its edge
    order = np.argsort(e, kind="stable")
    e, qa, qb = e[order], qa[order], qb[order]
    start = np.searchsorted(e, np.arange(len(uniq)))
    count = np.searchsorted(e, np.arange(len(uniq)), side="right") - start
    slot = np.flatnonzero(count[inv] > 0)
    reps = count[inv[slot]]
    slot_r = np.repeat(slot, reps)
    idx = np.repeat(start[inv[slot]], reps) + (np.arange(reps.sum()) - np.repeat(np.cumsum(reps) - reps, reps))
    tet = live[slot_r // 6]
    u = np.int64(tets.quadrics.shape[1])
    seen = isin_sorted(tet * u + qa[idx], on) & isin_sorted(tet * u + qb[idx], on)
    out[tet[~seen]] = True
    return out


def adapt(tape, grid, tol: float, stats: dict) -> Marched:
    """The grid's Kuhn tetrahedra, bisected where features are thinner than they are (and
    deeper than half the tolerance ``tol``), and marching tetrahedra on the result."""
    tets = kuhn_tets(grid)

    def point(keys):
        return grid.origin + (grid.h / SCALE) * tets.lattice(keys)

    labels = Labels(lambda keys: contains(tape.ops, tape.quadrics, point(keys)))
    solved = _Crossings()
    per_round = []
    new = np.ones(len(tets), dtype=bool)
    for _round in range(MAX_ROUNDS + 1):
        marched, tri_tet = _march(tape, tets, labels, solved, point)
        check = new & (tets.depth < MAX_BISECTIONS)  # the others were tested before
        on = np.unique(tri_tet.repeat(3) * np.int64(tets.quadrics.shape[1]) + marched.quadric[marched.triangles].ravel())
        flag = _thin_features(tape, tets, point, 0.5 * tol, check, labels, on)
        flag[_unresolved_spans(tape, marched, tri_tet, check, 0.5 * tol)] = True
        if not flag.any() or _round == MAX_ROUNDS:
            break
        per_round.append(int(flag.sum()))
        tets = refine_tets(tets, np.flatnonzero(flag))
        new = ~tets.pruned
        _prune(tape, tets, point)
    stats.update(tetrahedra=len(tets), bisected_per_round=per_round, deepest=int(tets.depth.max(initial=0)))
    return marched
