"""Meshes of scenes with point operands or large mesh operands: the operands' own meshes
combined with the meshes of the quadric parts by manifold3d's Booleans.

The mesher (:mod:`.mesher`) places every vertex on the exact surface and every sharp edge on
the exact curve where two quadrics meet; its cost grows with the surfaces a cell holds, and a
cloud's surface mesh (:mod:`clcsg.model.surfel_surface`) or an imported STL brings thousands
of face planes.  Such an operand already is a closed triangle mesh, so the scene is meshed by
its tree instead, clipped to a box K that holds the solid (the tape's bound grown by 1% of its
diagonal):

* a sub-graph without such operands is meshed by the mesher within the tolerance, an
  unbounded one (a complement, a half-space) as ``sub & K``; the variadic Booleans group
  their plain operands into one sub-graph, so each group is meshed once;
* a point operand is its surface mesh, a mesh operand its own triangles, in world
  coordinates;
* union, intersection and difference are manifold3d's exact Booleans of those meshes, a
  complement is K minus its operand (Booleans commute with the clip to K:
  (A - B) & K = (A & K) - (B & K), ~A & K = K - (A & K)).

The result is closed and 2-manifold (manifold3d's guarantee); vertices of the quadric parts
lie on their surfaces, those where a quadric part meets an operand lie on the quadric part's
triangles, within the tolerance of the quadric.  Each triangle keeps the colour of the piece it
comes from; ``quadric``, ``primitive`` and ``vertex_quadrics`` are -1 (they name entries of one
tape, and the pieces have their own).
"""

from __future__ import annotations

import numpy as np

from ..errors import SceneError, UnboundedError
from ..model.construction import Construction
from ..model.csg import DEFAULT_COLOR, Complement, Difference, Intersection, Primitive, Transformed, Union, walk
from ..model.scene import Scene
from ..model.solids import box
from ..model.surfel_surface import surface_mesh
from ..model.surfels import Surfels

#: a mesh operand of more distinct face planes than this is combined by Booleans, not meshed
#: by the mesher (whose cost grows with the planes a cell holds)
MESH_OPERAND_PLANES = 64


def is_operand(node) -> bool:
    """Is ``node`` a point operand, or a mesh operand past :data:`MESH_OPERAND_PLANES` planes?"""
    if isinstance(node, Surfels):
        return True
    return (isinstance(node, Construction) and node.kind == "mesh"
            and node.surfaces.get("plane", 0) > MESH_OPERAND_PLANES)


def needs_booleans(shape) -> bool:
    """Does the graph of ``shape`` hold an operand that :func:`mesh_by_booleans` combines?"""
    return any(is_operand(n) for n in walk(shape))


def _holding(shape) -> set:
    """The ids of the nodes of ``shape``'s graph with an operand at or below them: one
    post-order walk (a node's children are done before it), so each node is visited once."""
    out, done, stack = set(), set(), [(shape, False)]
    while stack:
        node, expanded = stack.pop()
        if id(node) in done:
            continue
        if not expanded:
            stack.append((node, True))
            stack.extend((c, False) for c in node.children() if id(c) not in done)
            continue
        done.add(id(node))
        if is_operand(node) or any(id(c) in out for c in node.children()):
            out.add(id(node))
    return out


def _color(node):
    """RGBA of an operand: its own colour, or its first primitive's."""
    color = getattr(node, "color", None)
    if color is None:
        color = next((n.color for n in walk(node) if isinstance(n, Primitive) and n.color is not None), None)
    return np.asarray(DEFAULT_COLOR if color is None else color, dtype=np.float64)


class _Booleans:
    """The manifolds of the pieces, built by the scene's tree (see the module docstring), and
    per manifold3d original ID the colours of its input triangles."""

    def __init__(self, manifold3d, sc: Scene, tol: float, cells: int, mesh_plain):
        self.m3d, self.sc, self.tol, self.cells, self.mesh_plain = manifold3d, sc, tol, cells, mesh_plain
        lo, hi = (np.asarray(b, dtype=np.float64) for b in sc.compile().bound)
        grow = 0.01 * float(np.linalg.norm(hi - lo))
        self.lo, self.hi = lo - grow, hi + grow
        self.clip = box(self.hi - self.lo, center=0.5 * (self.lo + self.hi))
        self.colors: dict[int, np.ndarray] = {}
        self.memo: dict = {}
        self.mixed = _holding(sc.shape)

    def add(self, vertices, triangles, colors):
        """A manifold of ``vertices`` (n, 3) and outward ``triangles`` (k, 3), colours (k, 4)."""
        if not len(triangles):
            return self.m3d.Manifold()
        mesh = self.m3d.Mesh64(vert_properties=np.ascontiguousarray(vertices, dtype=np.float64),
                               tri_verts=np.ascontiguousarray(triangles, dtype=np.uint64))
        m = self.m3d.Manifold(mesh).as_original()
        if m.status() != self.m3d.Error.NoError:
            raise SceneError(f"{self.sc.source}: a piece of {len(triangles)} triangles is not a closed 2-manifold for "
                             f"the Booleans ({m.status().name})")
        self.colors[m.original_id()] = np.asarray(colors, dtype=np.float64)
        return m

    def holds_operand(self, node) -> bool:
        return id(node) in self.mixed

    def plain(self, node, m):
        """The mesher's mesh of a sub-graph without operands; an unbounded one clipped to K."""
        world = node if np.allclose(m, np.eye(4)) else Transformed(node, m)
        sub = Scene(world, None, self.sc.source)
        try:
            empty = sub.compile().empty
        except UnboundedError:
            sub = Scene(Intersection([world, self.clip]), None, self.sc.source)
            empty = sub.compile().empty
        if empty:
            return self.m3d.Manifold()
        got = self.mesh_plain(sub, self.tol, self.cells)
        return self.add(got.vertices, got.triangles, got.colors)

    def operand(self, node, m):
        """A point operand's surface mesh, or a mesh operand's triangles, in world coordinates."""
        if isinstance(node, Surfels):
            v, f = surface_mesh(node.transformed(m))
        else:
            mesh = node.spec["mesh"]
            v = np.asarray(mesh["points"], dtype=np.float64) @ m[:3, :3].T + m[:3, 3]
            f = np.asarray(mesh["faces"], dtype=np.int64)
            if np.linalg.det(m[:3, :3]) < 0:
                f = f[:, ::-1]
        return self.add(v, f, np.tile(_color(node), (len(f), 1)))

    def build(self, node, m):
        """The manifold of ``node`` under the world transform ``m`` (shared nodes once)."""
        key = (id(node), m.tobytes())
        if key not in self.memo:
            self.memo[key] = self._build(node, m)
        return self.memo[key]

    def _build(self, node, m):
        if not self.holds_operand(node):
            return self.plain(node, m)
        if is_operand(node):
            return self.operand(node, m)
        if isinstance(node, Transformed):
            return self.build(node.operand, m @ node.matrix)
        if isinstance(node, Complement):
            return self.m3d.Manifold.cube(self.hi - self.lo).translate(self.lo) - self.build(node.operand, m)
        ops, op = list(node.children()), self.m3d.OpType
        if isinstance(node, Difference):
            head = self.build(ops[0], m)
            return self.m3d.Manifold.batch_boolean([head, *self.group(Union, ops[1:], m)], op.Subtract)
        if isinstance(node, Intersection):
            return self.m3d.Manifold.batch_boolean(self.group(Intersection, ops, m), op.Intersect)
        if isinstance(node, Union):  # a Construction is a Union too
            return self.m3d.Manifold.batch_boolean(self.group(Union, ops, m), op.Add)
        raise SceneError(f"{self.sc.source}: cannot mesh a {type(node).__name__} node")

    def group(self, kind, ops, m):
        """The manifolds of ``ops``: the plain ones meshed together as one ``kind`` node."""
        plain_ops = [c for c in ops if not self.holds_operand(c)]
        out = [self.build(c, m) for c in ops if self.holds_operand(c)]
        if plain_ops:
            out.append(self.plain(plain_ops[0] if len(plain_ops) == 1 else kind(plain_ops), m))
        return out

    def triangle_colors(self, got) -> np.ndarray:
        """(T, 4) colours of the result's triangles, through manifold3d's runs and face IDs."""
        n = len(np.asarray(got.tri_verts))
        colors = np.tile(np.asarray(DEFAULT_COLOR, dtype=np.float64), (n, 1))
        run_index = np.asarray(got.run_index, dtype=np.int64) // 3
        face_id = np.asarray(got.face_id, dtype=np.int64)
        for k, oid in enumerate(np.asarray(got.run_original_id, dtype=np.int64)):
            table = self.colors.get(int(oid))
            if table is not None:
                colors[run_index[k]:run_index[k + 1]] = table[face_id[run_index[k]:run_index[k + 1]]]
        return colors


def mesh_by_booleans(sc: Scene, tol: float, cells: int, mesh_plain):
    """(vertices, triangles, colours) of ``sc``'s solid, see the module docstring;
    ``mesh_plain(scene, tol, cells)`` is the mesher on a scene without such operands."""
    import manifold3d  # the mesh extra: only scenes with point or large mesh operands need it

    if sc.compile().empty:
        raise SceneError(f"{sc.source}: the solid is empty: there is nothing to mesh")
    booleans = _Booleans(manifold3d, sc, tol, cells, mesh_plain)
    got = booleans.build(sc.shape, np.eye(4)).to_mesh64()
    v = np.array(np.asarray(got.vert_properties)[:, :3], dtype=np.float64)  # owned, writable copies
    tri = np.array(got.tri_verts, dtype=np.int64).reshape(-1, 3)
    return v, tri, booleans.triangle_colors(got)
