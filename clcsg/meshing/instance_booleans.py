"""The solid as manifold3d Booleans of its instances' faceted meshes (:mod:`.facets`).

The instance program (:mod:`clcsg.compile.instance_program`: AND / OR rows over instance
leaves, complements at the leaves) is read back into n-ary nodes (same-kind chains
flattened) and evaluated on manifolds by batched Booleans.  A node's value is a manifold M and
a polarity: M itself, or its complement, kept symbolic so that no complement is built
against a box:

    A n B n ~C n ~D = (A n B) - (C u D)       (no positive operand: ~(C u D))
    A u B u ~C u ~D = ~((C n D) - (A u B))    (no complement: A u B)

Only a complement left at the root is made real, as K - M with K the clip box (the scene's
bound); a result reaching out of K is intersected with it.

Each triangle of an input carries ``face_id = FACE_STRIDE * instance + tag + 1`` (tag: the
literal of the instance, -1 for a closing face, :data:`clcsg.meshing.facets.CLOSING`);
manifold3d keeps a face's ID through the Booleans, so every triangle of the result names the
instance and literal it lies on.  K's faces are instance ``len(instances)``, tags 0..5 (its
faces +x, -x, +y, -y, +z, -z).
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from ..cl.constants import OP_AND, OP_CONST, OP_COPY, OP_LEAF
from ..compile.tape import instance_matrices
from ..model.csg import Transformed, Union
from .facets import Facets, cuboid, instance_facets, shared_segments, unit_mesh

#: face IDs per instance: more than a primitive's literals (a box has six) plus the closing tag
FACE_STRIDE = 8


@dataclass
class Faceted:
    """The Booleans' result: a closed, outward mesh; per triangle its instance and tag."""

    vertices: np.ndarray  # (V, 3)
    triangles: np.ndarray  # (T, 3) int64
    instance: np.ndarray  # (T,) int64; len(instances) for a face of K
    tag: np.ndarray  # (T,) int64: literal index, or -1 (closing), or K's face 0..5
    clip: tuple  # K: (lo, hi)


def _manifold(m3d, facets: Facets, instance: int):
    ids = (FACE_STRIDE * instance + facets.tags + 1).astype(np.uint64)
    mesh = m3d.Mesh64(np.ascontiguousarray(facets.vertices, dtype=np.float64),
                      np.ascontiguousarray(facets.triangles, dtype=np.uint64), None, None, None, None, None, None,
                      np.ascontiguousarray(ids))
    return m3d.Manifold(mesh)


@lru_cache(maxsize=256)
def _unit_manifold(key):
    """(the manifold of :func:`~clcsg.meshing.facets.unit_mesh` (key), built once per process,
    the tag of each of its triangles in manifold3d's own order).  A copy made an original
    gives its triangles that order's index as face ID; the tags follow from the unit shape:
    a triangle with all three vertices at z = 1/2 is a frustum's top cap (1), at -1/2 its
    bottom (2), any other its side (0); a sphere's are all 0."""
    import manifold3d as m3d

    v, t, _ = unit_mesh(key)
    base = m3d.Manifold(m3d.Mesh64(np.ascontiguousarray(v, dtype=np.float64),
                                   np.ascontiguousarray(t, dtype=np.uint64)))
    own = base.to_mesh64()
    corners = np.asarray(own.tri_verts, dtype=np.int64).reshape(-1, 3)
    z = np.asarray(own.vert_properties, dtype=np.float64)[:, 2][corners]
    tags = np.zeros(len(z), dtype=np.int64)
    if key[0] == "round":
        tags[(z == 0.5).all(axis=1)] = 1
        tags[(z == -0.5).all(axis=1)] = 2
    return base, tags


def _placed(m3d, facets: Facets, instance: int, placed: dict):
    """The manifold of an instance's facets: a unit primitive's, built once and placed by its
    transform (a copy made an original: its triangles carry their index in the unit manifold
    as face ID, and ``placed`` maps its original ID to (instance, the unit manifold's tags)),
    else read in with its face IDs (:func:`_manifold`)."""
    if facets.unit is not None:
        base, tags = _unit_manifold(facets.unit[0])
        if base.status() == m3d.Error.NoError:
            got = base.transform(np.ascontiguousarray(facets.unit[1][:3, :4])).as_original()
            placed[int(got.original_id())] = (instance, tags)
            return got
    return _manifold(m3d, facets, instance)


def _clip_box(m3d, lo, hi, instance):
    return _manifold(m3d, cuboid(lo, hi, (0, 1, 2, 3, 4, 5), np.eye(4)), instance)


def _expression(ops):
    """The instance program as nested n-ary nodes: ("leaf", instance, negated), ("const", value),
    ("and" | "or", [children]) with same-kind chains flattened (a union of 2,500 holes is one
    node of 2,500 children, built by one batched Boolean)."""
    regs: dict = {}
    for op, out, a, b in np.asarray(ops).tolist():
        if op == OP_LEAF:
            regs[out] = ("leaf", a, b < 0)
        elif op == OP_CONST:
            regs[out] = ("const", bool(a))
        elif op == OP_COPY:
            regs[out] = regs[a]
        else:
            kind = "and" if op == OP_AND else "or"
            kids = []
            for c in (regs[a], regs[b]):
                kids += c[1] if c[0] == kind else [c]
            regs[out] = (kind, kids)
    return regs[int(np.asarray(ops)[-1][1])] if len(ops) else ("const", False)


class _Builder:
    """Manifolds of expression nodes: (manifold, negated) per node, shared nodes once."""

    def __init__(self, m3d, leaves):
        self.m3d, self.leaves, self.memo = m3d, leaves, {}
        self.empty = m3d.Manifold()

    def batch(self, parts, op):
        if len(parts) == 1:
            return parts[0]
        return self.m3d.Manifold.batch_boolean(parts, op)

    def build(self, node):
        key = id(node)
        if key not in self.memo:
            self.memo[key] = (node, self._build(node))  # the node kept alive: its id stays unique
        return self.memo[key][1]

    def _build(self, node):
        kind = node[0]
        if kind == "leaf":
            return self.leaves(node[1]), node[2]
        if kind == "const":
            return self.empty, node[1]  # TRUE: the complement of nothing
        absorbing = kind == "or"  # the constant that decides the node: TRUE for or, FALSE for and
        pos, neg = [], []
        for child in node[1]:
            m, negated = self.build(child)
            if child[0] == "const":
                if child[1] == absorbing:
                    return self.empty, absorbing
                continue
            (neg if negated else pos).append(m)
        add, meet = self.m3d.OpType.Add, self.m3d.OpType.Intersect
        if kind == "and":  # A n B n ~C n ~D = (A n B) - (C u D)
            if not pos:
                return (self.batch(neg, add), True) if neg else (self.empty, True)
            whole = self.batch(pos, meet)
            return (whole - self.batch(neg, add) if neg else whole), False
        # A u B u ~C u ~D = ~((C n D) - (A u B))
        if not neg:
            return (self.batch(pos, add) if pos else self.empty), False
        whole = self.batch(neg, meet)
        return (whole - self.batch(pos, add) if pos else whole), True


def common_frame(shape, instances):
    """(G, per instance its matrix below G): G is the product of the transforms every
    instance lies under (a scene rotated as a whole), the matrices those the walk below them
    gives, so that the Booleans run in the frame where the scene was modelled (axis-aligned
    boxes stay exactly axis-aligned: G^-1 times a world matrix would carry its rounding).
    (identity, world matrices) where there is no such transform or the walks disagree."""
    g = np.eye(4)
    node = shape
    while True:
        if isinstance(node, Transformed):
            g, node = g @ node.matrix, node.operand
        elif isinstance(node, Union) and len(node.operands) == 1:
            node = node.operands[0]
        else:
            break
    world = [np.asarray(i.matrix, dtype=np.float64) for i in instances]
    if np.array_equal(g, np.eye(4)):
        return g, world
    local = instance_matrices(node)
    if len(local) != len(instances) or any(n is not i.node for (n, _), i in zip(local, instances)):
        return np.eye(4), world
    return g, [m for _, m in local]


def facets_of(tape, tols, frame=None, on_surface=None):
    """Per instance of ``tape`` its :class:`~clcsg.meshing.facets.Facets` within its
    tolerance (``tols``, one per instance) in the frame ``frame`` = (G, matrices below G)
    (default: the world), or None if a kind has no closed form (the whole list is then
    None).  ``on_surface(points)``: per world point whether it lies on the solid's surface,
    so that a cylinder or cone whose side is hidden does not set the segments of those it
    shares a circle with (:func:`~clcsg.meshing.facets.shared_segments`)."""
    g, mats = frame if frame is not None else (np.eye(4), [i.matrix for i in tape.instances])
    lo, hi = (np.asarray(b, dtype=np.float64) for b in tape.bound)
    inv = np.linalg.inv(g)
    stretch = float(np.linalg.svd(g[:3, :3], compute_uv=False)[0])
    center = inv[:3, :3] @ (0.5 * (lo + hi)) + inv[:3, 3]
    radius = (0.5 * float(np.linalg.norm(hi - lo)) * 1.01 + 1e-9) * float(np.linalg.svd(inv[:3, :3], compute_uv=False)[0])
    out = []
    hidden = None
    if on_surface is not None:
        def hidden(points):
            shown = on_surface(points.reshape(-1, 3) @ g[:3, :3].T + g[:3, 3])
            return ~shown.reshape(points.shape[:2]).any(axis=1)
    segments = shared_segments(tape.instances, np.asarray(tols, dtype=np.float64) / stretch, mats, hidden)
    for inst, tol, m in zip(tape.instances, tols, mats):
        f = instance_facets(inst, float(tol) / stretch, (center, radius), m, segments.get(inst.index))
        if f is None:
            return None
        out.append(f)
    return out


def boolean_mesh(tape, facets, frame=np.eye(4)) -> Faceted:
    """The solid of ``tape`` from its instances' ``facets`` (:func:`facets_of`), built in the
    frame ``frame`` (G of :func:`common_frame`) and returned in world coordinates."""
    import manifold3d as m3d

    n = len(tape.instances)
    lo, hi = (np.asarray(b, dtype=np.float64) for b in tape.bound)
    leaves: dict = {}

    placed: dict = {}

    def leaf(i):
        if i not in leaves:
            leaves[i] = _placed(m3d, facets[i], i, placed)
        return leaves[i]

    solid, negated = _Builder(m3d, leaf).build(_expression(tape.instance_program[0]))
    if not np.array_equal(frame, np.eye(4)):
        solid = solid.transform(np.ascontiguousarray(frame[:3, :4]))
    if negated:
        solid = _clip_box(m3d, lo, hi, n) - solid
    else:
        blo, bhi = _bbox(solid)
        span = 1e-9 * max(1.0, float(np.abs(np.concatenate([lo, hi])).max()))
        if np.any(blo < lo - span) or np.any(bhi > hi + span):
            solid = solid ^ _clip_box(m3d, lo, hi, n)
    got = solid.to_mesh64()
    v = np.array(got.vert_properties, dtype=np.float64)[:, :3]
    tri = np.array(got.tri_verts, dtype=np.int64).reshape(-1, 3)
    fid = np.array(got.face_id, dtype=np.int64)
    instance, tag = fid // FACE_STRIDE, fid % FACE_STRIDE - 1
    runs = np.asarray(got.run_index, dtype=np.int64) // 3
    for r, oid in enumerate(np.asarray(got.run_original_id).tolist()):
        if int(oid) in placed:
            i, tags = placed[int(oid)]
            instance[runs[r]:runs[r + 1]] = i
            tag[runs[r]:runs[r + 1]] = tags[fid[runs[r]:runs[r + 1]]]
    return Faceted(v, tri, instance, tag, (lo, hi))


def _bbox(solid):
    b = np.asarray(solid.bounding_box(), dtype=np.float64).reshape(-1)
    return b[:3], b[3:]
