"""Point-sampled solids as CSG operands (surfels), after Wicke, Teschner and Gross, "CSG Tree
Rendering for Point-Sampled Objects": the solid, its transforms, and its inside/outside test.

A surfel s is a disk: center c_s, unit outward normal n_s, radius r_s.  The surfels sample the
boundary of a solid S; the solid itself is only known through them.  A surfel *clips* a point x
if x lies in front of its tangent plane:

    clips(s, x)  <=>  (x - c_s) . n_s > 0                                    (paper eq. 3)

Classification from the two surfels s1, s2 whose centers are nearest to x (section 3.1.1):
the pair is *concave* if each clips the other's center, (c2 - c1) . n1 > 0 and
(c1 - c2) . n2 > 0, and *convex* otherwise; then

    concave:  x in S  <=>  not clips(s1, x)  or  not clips(s2, x)            (eq. 4)
    convex:   x in S  <=>  not clips(s1, x)  and not clips(s2, x)            (eq. 5)

Near a convex edge the solid is the intersection of the two half-spaces, near a concave one
their union; on a smooth patch both half-spaces nearly coincide and the rule is the one-surfel
test (eq. 3).  Points on a tangent plane count as inside (the solid is closed).  A cloud of
one surfel is its half-space.

The surfels must cover the surface (every surface point within the radius of a surfel); the
sampler (:mod:`clcsg.sampling.surfel_csg`) relies on it when it decides which splats need
clipping.  Nearest centers come from a k-d tree (:class:`scipy.spatial.cKDTree`).
"""

from __future__ import annotations

import numpy as np

from ..errors import ParameterError
from .polyhedron import polyhedron
from .surfel_surface import surface_mesh
from .csg import Complement, Difference, Intersection, Shape, Transformed, Union, _color


class Surfels(Shape):
    """A solid given by oriented surface samples: ``points`` (n, 3), unit outward ``normals``
    (n, 3), ``radii`` (n,).  A leaf of the CSG graph; :func:`clcsg.sample` keeps or drops its
    surfels by the rest of the tree and classifies the other operands' samples against it."""

    __slots__ = ("points", "normals", "radii", "color", "source", "_tree", "_solid", "_moved")

    def __init__(self, points, normals, radii, color=None, source: str = "surfels"):
        self.points, self.normals, self.radii = checked(points, normals, radii, source)
        self.color = _color(color)
        self.source = source
        self._tree = None
        self._solid = None
        self._moved: dict = {}  # transform bytes -> transformed copy (keeps its tree and solid)

    def __len__(self) -> int:
        return len(self.points)

    def __repr__(self) -> str:
        return f"surfels({len(self)} points)"

    @property
    def tree(self):
        """The k-d tree of the centers, built on first use."""
        if self._tree is None:
            from scipy.spatial import cKDTree  # an optional dependency: only point operands need it

            # boxes not shrunk to the points: for a query point far inside a closed cloud
            # (all centers at nearly one distance) the search visits about 9x fewer nodes
            self._tree = cKDTree(self.points, compact_nodes=False)
        return self._tree

    def solid(self):
        """The solid as a mesh operand (:func:`~clcsg.model.polyhedron.polyhedron` of
        :func:`~clcsg.model.surfel_surface.surface_mesh`), built on first use: what the exact
        ray tracer, ``clcsg.mesh``, the point queries and ``clcsg info`` see of the cloud."""
        if self._solid is None:
            v, f = surface_mesh(self)
            self._solid = polyhedron(v, f, self.color, self.source,
                                     label=f"surfel surface of {len(self)} points ({len(f)} triangles)")
        return self._solid

    def box(self) -> tuple[np.ndarray, np.ndarray]:
        """(lo, hi) of the centers grown by the largest radius: it holds every disk."""
        r = float(self.radii.max())
        return self.points.min(axis=0) - r, self.points.max(axis=0) + r

    def transformed(self, matrix) -> "Surfels":
        """The surfels under the affine map ``matrix`` (4, 4): centers x' = M x, normals by
        M^-T (renormalized), radii scaled by |det M|^(1/3) (exact for similarities)."""
        m = np.asarray(matrix, dtype=np.float64)
        if np.allclose(m, np.eye(4)):
            return self
        moved = self._moved.get(m.tobytes())
        if moved is not None:
            return moved
        a = m[:3, :3]
        p = self.points @ a.T + m[:3, 3]
        n = self.normals @ np.linalg.inv(a)
        n /= np.linalg.norm(n, axis=1, keepdims=True)
        r = self.radii * abs(np.linalg.det(a)) ** (1.0 / 3.0)
        moved = self._moved[m.tobytes()] = Surfels(p, n, r, self.color, self.source)
        return moved

    def nearest(self, x, k: int = 1):
        """(distances, indices) of the ``k`` centers nearest to each point of ``x`` (m, 3)."""
        k = min(k, len(self))
        d, i = self.tree.query(np.asarray(x, dtype=np.float64).reshape(-1, 3), k=k, workers=-1)
        return d.reshape(len(d), k), i.reshape(len(i), k)

    def contains(self, x) -> np.ndarray:
        """Membership of the points ``x`` (m, 3) by the two-nearest-surfel rule (eqs. 3-5)."""
        return self.classify(x)[2]

    def classify(self, x) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(distance, index) of the center nearest to each point of ``x`` (m, 3) and its
        membership (:meth:`contains`), from one query of the two nearest."""
        x = np.asarray(x, dtype=np.float64).reshape(-1, 3)
        d, idx = self.nearest(x, 2)
        c, n = self.points[idx], self.normals[idx]  # (m, k, 3)
        behind = np.einsum("mkj,mkj->mk", x[:, None, :] - c, n) <= 0.0
        if idx.shape[1] == 1:
            return d[:, 0], idx[:, 0], behind[:, 0]
        concave = concave_pairs(c[:, 0], n[:, 0], c[:, 1], n[:, 1])
        return d[:, 0], idx[:, 0], np.where(concave, behind[:, 0] | behind[:, 1], behind[:, 0] & behind[:, 1])


def concave_pairs(c1, n1, c2, n2) -> np.ndarray:
    """Whether the surfel pairs (c1, n1), (c2, n2) are concave: each clips the other's center."""
    return (np.einsum("mj,mj->m", c2 - c1, n1) > 0.0) & (np.einsum("mj,mj->m", c1 - c2, n2) > 0.0)


def checked(points, normals, radii, source: str = "surfels"):
    """(points, unit normals, radii) as float64 arrays, or a one-line :class:`ParameterError`
    naming ``source`` and the reason."""
    def arr(v, what):
        try:
            a = np.asarray(v, dtype=np.float64)
        except (TypeError, ValueError):
            raise ParameterError(f"{source}: {what} must be numbers") from None
        return a

    p = arr(points, "points")
    if p.ndim != 2 or p.shape[1] != 3:
        raise ParameterError(f"{source}: points must be an (n, 3) array, got shape {p.shape}")
    if not len(p):
        raise ParameterError(f"{source}: no points (a point operand needs at least one surfel)")
    bad = ~np.isfinite(p).all(axis=1)
    if bad.any():
        raise ParameterError(f"{source}: point {int(np.flatnonzero(bad)[0])} is not finite (NaN or inf)")
    n = arr(normals, "normals")
    if n.shape != p.shape:
        raise ParameterError(f"{source}: normals must have the shape of the points {p.shape}, got {n.shape}")
    with np.errstate(all="ignore"):
        length = np.linalg.norm(n, axis=1)
    bad = ~(np.isfinite(length) & (length > 0))
    if bad.any():
        raise ParameterError(f"{source}: normal {int(np.flatnonzero(bad)[0])} is zero or not finite")
    r = np.broadcast_to(arr(radii, "radii"), (len(p),)) if np.ndim(radii) == 0 else arr(radii, "radii")
    if r.shape != (len(p),):
        raise ParameterError(f"{source}: radii must be one number or one per point ({len(p)}), got shape {r.shape}")
    bad = ~(np.isfinite(r) & (r > 0))
    if bad.any():
        i = int(np.flatnonzero(bad)[0])
        raise ParameterError(f"{source}: radius {i} is {r[i]:g}; radii must be positive and finite")
    return p.copy(), n / length[:, None], np.array(r, dtype=np.float64)


def surfels(points, normals, radii, color=None) -> Surfels:
    """A point-sampled solid as a CSG operand: surfels at ``points`` (n, 3) with outward
    ``normals`` (n, 3) and ``radii`` (one number or n)."""
    return Surfels(points, normals, radii, color)


def has_surfels(shape: Shape) -> bool:
    """Does the graph of ``shape`` hold a point operand?"""
    seen, stack = set(), [shape]
    while stack:
        s = stack.pop()
        if id(s) in seen:
            continue
        seen.add(id(s))
        if isinstance(s, Surfels):
            return True
        stack.extend(s.children())
    return False


def operands(shape) -> dict:
    """The point operands of ``shape``: (node id, world transform bytes) -> the surfels in
    world coordinates, in tree order."""
    out: dict = {}
    stack = [(shape, np.eye(4))]
    seen = set()
    while stack:
        node, m = stack.pop()
        key = (id(node), m.tobytes())
        if key in seen:
            continue
        seen.add(key)
        if isinstance(node, Surfels):
            out[key] = node.transformed(m)
        elif isinstance(node, Transformed):
            stack.append((node.operand, m @ node.matrix))
        else:
            stack.extend((c, m) for c in reversed(node.children()))
    return out


def substitute(shape, replace):
    """``shape`` with every point operand replaced by ``replace(key, surfels)``, a shape in
    world coordinates (the accumulated transform is undone around it)."""
    memo: dict = {}
    ops = operands(shape)

    def walk(node, m):
        key = (id(node), m.tobytes())
        if key in memo:
            return memo[key]
        if isinstance(node, Surfels):
            out = replace(key, ops[key])
            if not np.allclose(m, np.eye(4)):
                out = Transformed(out, np.linalg.inv(m))
        elif isinstance(node, Transformed):
            out = Transformed(walk(node.operand, m @ node.matrix), node.matrix)
        elif isinstance(node, Complement):
            out = Complement(walk(node.operand, m))
        elif isinstance(node, (Union, Intersection, Difference)):
            out = type(node)([walk(c, m) for c in node.operands])  # a Construction is a Union of its body
        else:
            out = node
        memo[key] = out
        return out

    return walk(shape, np.eye(4))


def with_surfaces(shape):
    """``shape`` with every point operand replaced by its :meth:`Surfels.solid` (in world
    coordinates), or ``shape`` itself when it has none: the solid the exact paths see."""
    if not has_surfels(shape):
        return shape
    return substitute(shape, lambda key, cloud: cloud.solid())
