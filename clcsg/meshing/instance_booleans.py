"""The solid as manifold3d Booleans of its instances' faceted meshes (:mod:`.facets`).

The instance program (:mod:`clcsg.compile.instance_program`: AND / OR rows over instance
leaves, complements at the leaves) is evaluated on manifolds.  A register holds a manifold M
and a polarity: M itself, or its complement, kept symbolic so that no complement is built
against a box:

    A & B = A n B      A & ~B = A - B     ~A & ~B = ~(A u B)
    A | B = A u B      A | ~B = ~(B - A)  ~A | ~B = ~(A n B)

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

import numpy as np

from ..cl.constants import OP_AND, OP_CONST, OP_COPY, OP_LEAF, OP_OR
from .facets import Facets, cuboid, instance_facets

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


def _clip_box(m3d, lo, hi, instance):
    return _manifold(m3d, cuboid(lo, hi, (0, 1, 2, 3, 4, 5), np.eye(4)), instance)


def _and(a, b):
    (ma, na), (mb, nb) = a, b
    if not na and not nb:
        return ma ^ mb, False
    if not na:
        return ma - mb, False
    if not nb:
        return mb - ma, False
    return ma + mb, True


def _or(a, b):
    (ma, na), (mb, nb) = a, b
    if not na and not nb:
        return ma + mb, False
    if not na:
        return mb - ma, True
    if not nb:
        return ma - mb, True
    return ma ^ mb, True


def facets_of(tape, tols):
    """Per instance of ``tape`` its :class:`~clcsg.meshing.facets.Facets` within its
    tolerance (``tols``, one per instance), or None if a kind has no closed form (the whole
    list is then None)."""
    lo, hi = (np.asarray(b, dtype=np.float64) for b in tape.bound)
    reach = (0.5 * (lo + hi), 0.5 * float(np.linalg.norm(hi - lo)) * 1.01 + 1e-9)
    out = []
    for inst, tol in zip(tape.instances, tols):
        f = instance_facets(inst, float(tol), reach)
        if f is None:
            return None
        out.append(f)
    return out


def boolean_mesh(tape, facets) -> Faceted:
    """The solid of ``tape`` from its instances' ``facets`` (:func:`facets_of`)."""
    import manifold3d as m3d

    n = len(tape.instances)
    lo, hi = (np.asarray(b, dtype=np.float64) for b in tape.bound)
    ops, n_regs = tape.instance_program
    regs: list = [None] * max(n_regs, 1)
    leaves: dict = {}
    empty = m3d.Manifold()
    for op, out, a, b in np.asarray(ops).tolist():
        if op == OP_LEAF:
            if a not in leaves:
                leaves[a] = _manifold(m3d, facets[a], a)
            regs[out] = (leaves[a], b < 0)
        elif op == OP_CONST:
            regs[out] = (empty, bool(a))  # TRUE: the complement of nothing
        elif op == OP_COPY:
            regs[out] = regs[a]
        elif op == OP_AND:
            regs[out] = _and(regs[a], regs[b])
        elif op == OP_OR:
            regs[out] = _or(regs[a], regs[b])
    solid, negated = regs[int(ops[-1][1])] if len(ops) else (empty, False)
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
    return Faceted(v, tri, fid // FACE_STRIDE, fid % FACE_STRIDE - 1, (lo, hi))


def _bbox(solid):
    b = np.asarray(solid.bounding_box(), dtype=np.float64).reshape(-1)
    return b[:3], b[3:]
