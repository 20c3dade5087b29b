"""A built solid that remembers how it was built: an extrusion, a revolution, a hull, a sum.

:class:`Construction` is a :class:`~clcsg.model.csg.Union` of one operand, the exact quadric
CSG the construction expands to, so every stage that understands unions (compile, bounds,
``contains``, the oracle) needs nothing new.  It adds ``label`` ("hull of 8 spheres"),
``surfaces`` (the unique quadric surfaces by type: "6 planes, 12 cylinders, 8 spheres") and,
for convex polytopes, ``vertices``, and for extruded circles ``disks`` (what ``hull`` and
``minkowski`` read their operands as).

Leaf helpers build the Primitive literals the constructions use, all with one color.
"""

from __future__ import annotations

from collections import Counter

import numpy as np

from .csg import Complement, Intersection, Primitive, Shape, Union

_ORDER = ("plane", "cylinder", "elliptic cylinder", "cone", "sphere", "ellipsoid", "quadric")


class Construction(Union):
    __slots__ = ("label", "surfaces", "vertices", "kind", "spec", "disks", "bounds_proxy")

    def __init__(self, kind: str, label: str, body: Shape, vertices=None, box=None, spec=None, disks=None,
                 surfaces=None):
        #: for a cylinder or cone built otherwise (an extruded circle): its two cap disks
        #: ((center, radius), (center, radius)), perpendicular to z; what hull() needs
        self.disks = disks
        #: how to build it again (scene files): {"extrude": {...}} with a JSON profile, or
        #: ("hull" | "minkowski", operand shapes); None: saved as its expansion
        self.spec = spec
        #: unique surfaces by type (``surfaces``: known to the builder, else counted)
        self.surfaces = count_surfaces(body) if surfaces is None else dict(surfaces)
        if box is not None:
            body = bounded(body, *box)
        super().__init__([body])
        self.kind = kind
        self.label = label
        self.vertices = None if vertices is None else np.asarray(vertices, dtype=np.float64)
        #: a shape holding this one that the bounds use in its place (None: itself)
        self.bounds_proxy = None

    def describe(self) -> str:
        """'hull of 8 spheres: 6 planes, 12 cylinders, 8 spheres'."""
        parts = [f"{n} {k}{'s' if n != 1 else ''}" for k, n in sorted(self.surfaces.items(), key=lambda kv: _ORDER.index(kv[0]))]
        return f"{self.label}: {', '.join(parts) if parts else 'empty'}"

    def __repr__(self):
        return f"Construction({self.describe()!r})"


def surface_type(m: np.ndarray) -> str:
    """A quadric matrix's surface type, from the eigenvalues of its quadratic part."""
    a = m[:3, :3]
    w = np.linalg.eigvalsh(a)
    # relative to the quadratic part itself (a cone far from the origin has a huge constant
    # term), but above rounding of the whole matrix (a moved plane's A is noise)
    tol = max(1e-9 * np.abs(a).max(), 1e-13 * np.abs(m).max(), 1e-300)
    nz = w[np.abs(w) > tol]
    if len(nz) == 0:
        return "plane"
    same = bool(np.all(nz > 0) or np.all(nz < 0))
    equal = np.allclose(nz, nz[0], rtol=1e-9)
    if len(nz) == 3 and same:
        return "sphere" if equal else "ellipsoid"
    if len(nz) == 2 and same:
        return "cylinder" if equal else "elliptic cylinder"
    if len(nz) == 3 and abs(np.linalg.det(m)) <= 1e-9 * np.abs(m).max() ** 4:
        return "cone"
    return "quadric"


def _key(m):
    v = m / np.abs(m).max()
    i = np.flatnonzero(np.abs(v.ravel()) > 1e-12)[0]
    v = v * np.sign(v.ravel()[i])
    return tuple(np.round(v.ravel(), 9))


def count_surfaces(shape: Shape) -> dict:
    """Unique surfaces by type, bounding boxes (:func:`bounded`) left out."""
    seen, done, stack = {}, set(), [shape]
    while stack:
        node = stack.pop()
        if id(node) in done:
            continue
        done.add(id(node))
        stack.extend(node.operands[:1] if isinstance(node, Bounded) else node.children())
        if isinstance(node, Primitive):
            for q in node.quadrics():
                seen.setdefault(_key(q.matrix), surface_type(q.matrix))
    return dict(Counter(seen.values()))


class Bounded(Intersection):
    """A body and the box around it that only serves the bounds (see :func:`bounded`)."""


def bounded(body: Shape, lo, hi) -> Shape:
    """``body`` inside its bounding box ``lo``..``hi`` grown by 1/1000 of the diagonal (and a
    little more than rounding), so that the box's planes never reach the surface: the box only
    gives the compile step's bounds (which are boxes of single literals, and the half-spaces
    and cones of a construction are unbounded one by one) a finite start."""
    lo, hi = np.asarray(lo, dtype=np.float64), np.asarray(hi, dtype=np.float64)
    grow = 1e-3 * np.linalg.norm(hi - lo) + 1e-9 * np.abs(np.r_[lo, hi]).max() + 1e-300
    lo, hi = lo - grow, hi + grow
    box = Primitive("box", {"size": (hi - lo).tolist(), "center": ((hi + lo) / 2).tolist()})
    return Bounded([body, box])


def first_color(shapes) -> tuple | None:
    """The color of the first primitive found in ``shapes`` (None if there is none)."""
    for s in shapes:
        stack = [s]
        while stack:
            n = stack.pop()
            if isinstance(n, Primitive):
                return n.color
            stack.extend(reversed(n.children()))
    return None


# -- leaves ----------------------------------------------------------------------------------
def plane(normal, offset, color=None) -> Primitive:
    """The half-space normal . x <= offset."""
    return Primitive("halfspace", {"normal": [float(v) for v in normal], "offset": float(offset)}, color)


def raw(matrix, color=None) -> Primitive:
    return Primitive("quadric", {"matrix": np.asarray(matrix, dtype=float).tolist()}, color)


def ball(center, radius, color=None) -> Primitive:
    return Primitive("sphere", {"radius": float(radius), "center": [float(v) for v in center]}, color)


def tube(point, axis, radius, color=None) -> Primitive:
    """Infinite circular cylinder."""
    return Primitive("infinite_cylinder", {"axis": [float(v) for v in axis], "radius": float(radius),
                                           "center": [float(v) for v in point]}, color)


def not_(shape: Shape) -> Shape:
    return Complement(shape)
