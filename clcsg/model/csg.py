"""The CSG graph: primitives, Boolean operations and transforms.

A scene is a directed acyclic graph of :class:`Shape` nodes.  Leaves are :class:`Primitive`
solids (each an intersection of quadric literals, see :mod:`clcsg.solids`); inner nodes are
variadic :class:`Union`, :class:`Intersection`, :class:`Difference`, unary :class:`Complement`
and :class:`Transformed` (a 4x4 affine matrix on the edge to its child).  Nodes are immutable,
so a sub-graph may be shared by several parents.

    part = clcsg.box(2).translate((0, 0, 1)) - clcsg.cylinder(2.5, 0.5)
    scene = part | ~clcsg.sphere(3)
"""

from __future__ import annotations

import math
from typing import Iterable, Sequence

import numpy as np

from ..errors import ParameterError, OperandError

from .quadric import Quadric, affine, check_affine


class Shape:
    """Base of all CSG nodes.  Combine with ``|``, ``&``, ``-``, ``~``."""

    __slots__ = ()

    # -- Booleans -----------------------------------------------------------------------------
    def __or__(self, other: "Shape") -> "Shape":
        return union(self, other)

    def __and__(self, other: "Shape") -> "Shape":
        return intersection(self, other)

    def __sub__(self, other: "Shape") -> "Shape":
        return difference(self, other)

    def __invert__(self) -> "Shape":
        return Complement(self)

    # -- transforms ---------------------------------------------------------------------------
    def transform(self, matrix) -> "Shape":
        """Apply a 4x4 affine matrix (x -> M x)."""
        return Transformed(self, matrix)

    def translate(self, offset) -> "Shape":
        return self.transform(affine(translation=_vec3(offset, "translation")))

    def scale(self, factor) -> "Shape":
        """Scale by a scalar or per-axis factors."""
        f = np.broadcast_to(np.asarray(factor, dtype=np.float64), (3,))
        return self.transform(affine(np.diag(f)))

    def rotate(self, axis, degrees: float) -> "Shape":
        """Rotate by ``degrees`` about ``axis`` (through the origin, right-hand rule)."""
        return self.transform(affine(rotation_matrix(axis, degrees)))

    def children(self) -> Sequence["Shape"]:
        return ()


def _literals(kind: str, params: dict):
    """The quadric literals of a primitive of ``kind`` (the registry lives in solids.py, which
    imports this module)."""
    from .solids import literals

    return literals(kind, params)


class Primitive(Shape):
    """A named solid (box, sphere, ...) with parameters and a color.

    ``kind`` and ``params`` are what scene files store; :func:`clcsg.solids.literals` expands
    them into the quadrics whose insides intersect to the solid.  The parameters are checked
    (by expanding them) when the primitive is made, but the quadrics are kept only from the
    first call of :meth:`quadrics` on: a model read from a large file holds its primitives'
    parameters (a tuple of values, the names shared by all primitives of a kind) and not four
    to six 4x4 matrices each.
    """

    __slots__ = ("kind", "_names", "_values", "color", "_quadrics")

    def __init__(self, kind: str, params: dict, color=None):
        params = dict(params)
        # raises the solid's own errors now, not when it is compiled; kept for quadrics()
        self._quadrics = tuple(_literals(kind, params))
        self.kind = kind
        names = tuple(params)
        self._names = _NAMES.setdefault(names, names)
        self._values = tuple(params.values())
        self.color = _color(color)

    @property
    def params(self) -> dict:
        """The parameters (a new dict each time: the primitive is immutable)."""
        return dict(zip(self._names, self._values))

    def quadrics(self) -> tuple[Quadric, ...]:
        return self._quadrics

    def __repr__(self) -> str:
        return f"{self.kind}({', '.join(f'{k}={_short(v)}' for k, v in self.params.items())})"


#: one tuple of parameter names per distinct set (shared by the primitives that use it)
_NAMES: dict = {}


class Operation(Shape):
    __slots__ = ("operands",)
    symbol = "?"

    def __init__(self, operands: Iterable[Shape]):
        ops = tuple(operands)
        for o in ops:
            if not isinstance(o, Shape):
                raise OperandError(f"CSG operand must be a Shape, got {type(o).__name__}")
        self.operands = ops

    def children(self):
        return self.operands

    def __repr__(self) -> str:
        return f"{type(self).__name__.lower()}({', '.join(map(repr, self.operands))})"


class Union(Operation):
    """Points in any operand (empty union: nothing)."""


class Intersection(Operation):
    """Points in all operands (needs at least one operand)."""

    def __init__(self, operands):
        super().__init__(operands)
        if not self.operands:
            raise ParameterError("intersection needs at least one operand")


class Difference(Operation):
    """The first operand minus all the others."""

    def __init__(self, operands):
        super().__init__(operands)
        if not self.operands:
            raise ParameterError("difference needs at least one operand")


class Complement(Shape):
    __slots__ = ("operand",)

    def __init__(self, operand: Shape):
        if not isinstance(operand, Shape):
            raise OperandError(f"CSG operand must be a Shape, got {type(operand).__name__}")
        self.operand = operand

    def children(self):
        return (self.operand,)

    def __repr__(self) -> str:
        return f"~{self.operand!r}"


class Transformed(Shape):
    __slots__ = ("operand", "matrix")

    def __init__(self, operand: Shape, matrix):
        if not isinstance(operand, Shape):
            raise OperandError(f"CSG operand must be a Shape, got {type(operand).__name__}")
        self.operand = operand
        m = check_affine(matrix)
        m.setflags(write=False)
        self.matrix = m

    def children(self):
        return (self.operand,)

    def __repr__(self) -> str:
        return f"transform({self.operand!r})"


def union(*shapes: Shape) -> Shape:
    return Union(_flatten(shapes, Union))


def intersection(*shapes: Shape) -> Shape:
    return Intersection(_flatten(shapes, Intersection))


def difference(first: Shape, *rest: Shape) -> Shape:
    return Difference((first, *rest))


def _flatten(shapes, kind):
    out = []
    for s in shapes:
        if isinstance(s, (list, tuple)):
            out.extend(_flatten(s, kind))
        elif type(s) is kind:
            out.extend(s.operands)
        else:
            out.append(s)
    return out


def rotation_matrix(axis, degrees: float) -> np.ndarray:
    """3x3 rotation by ``degrees`` about ``axis`` (Rodrigues)."""
    a = _vec3(axis, "rotation axis")
    n = np.linalg.norm(a)
    if n == 0.0:
        raise ParameterError("rotation axis must be non-zero")
    x, y, z = a / n
    t = math.radians(float(degrees))
    c, s = math.cos(t), math.sin(t)
    k = np.array([[0, -z, y], [z, 0, -x], [-y, x, 0]])
    return c * np.eye(3) + s * k + (1 - c) * np.outer((x, y, z), (x, y, z))


def walk(shape: Shape):
    """Every distinct node reachable from ``shape`` (each shared node once)."""
    seen = set()
    stack = [shape]
    while stack:
        s = stack.pop()
        if id(s) in seen:
            continue
        seen.add(id(s))
        yield s
        stack.extend(s.children())


def _vec3(v, what) -> np.ndarray:
    a = np.asarray(v, dtype=np.float64)
    if a.shape == ():
        a = np.full(3, float(a))
    if a.shape != (3,) or not np.all(np.isfinite(a)):
        raise ParameterError(f"{what} must be 3 finite numbers, got {np.asarray(v).tolist()}")
    return a


DEFAULT_COLOR = (0.8, 0.8, 0.8, 1.0)


def _color(color):
    if color is None:
        return DEFAULT_COLOR
    c = [float(x) for x in color]
    if len(c) == 3:
        c.append(1.0)
    if len(c) != 4 or not all(0.0 <= x <= 1.0 for x in c):
        raise ParameterError(f"color must be 3 or 4 numbers in [0, 1], got {list(color)}")
    c = tuple(c)
    if 0.0 in c and any(math.copysign(1.0, x) < 0.0 for x in c):
        return c  # -0.0 == 0.0: not shared with the tuple that has 0.0
    if len(_COLORS) >= _COLOR_CACHE:
        _COLORS.clear()
    return _COLORS.setdefault(c, c)


#: colors in use, one tuple each (a model's primitives mostly share a few colors)
_COLORS: dict = {}
_COLOR_CACHE = 4096


def _short(v):
    if isinstance(v, np.ndarray):
        return v.tolist()
    return v


def contains(shape: Shape, points) -> np.ndarray:
    """Membership of ``points`` (..., 3) in the solid, evaluated on the graph itself.

    This is the direct definition (no normalization): the reference the DNF is checked
    against.  Points exactly on a surface count as inside.  The graph is evaluated without
    recursion (deep chains are fine), and a node reached again under the same chain of
    transforms is evaluated once (a DAG costs its number of distinct nodes, not of paths).
    """
    pts = np.asarray(points, dtype=np.float64)
    flat = pts.reshape(-1, 3)
    return _contains(shape, flat).reshape(pts.shape[:-1])


def _contains(shape: Shape, x: np.ndarray) -> np.ndarray:
    """Post-order evaluation with an explicit stack (:class:`_Membership`)."""
    return _Membership(x).evaluate(shape)


def _combine(node, vals: list, n: int) -> np.ndarray:
    """The membership of an operation node from its operands' memberships."""
    if isinstance(node, Union):
        out = np.zeros(n, dtype=bool)
        for v in vals:
            out |= v
    elif isinstance(node, Intersection):
        out = np.ones(n, dtype=bool)
        for v in vals:
            out &= v
    elif isinstance(node, Difference):
        out = vals[0].copy()
        for v in vals[1:]:
            out &= ~v
    elif isinstance(node, Complement):
        out = ~vals[0]
    else:  # Transformed
        out = vals[0]
    return out


class _Membership:
    """Which points ``x`` lie in a CSG graph, evaluated post-order with an explicit stack.

    A *frame* is the point array in the coordinates of a node: frame 0 is ``x``; the operand
    of a Transformed node T seen in frame f is in frame (T, f), whose points are f's points
    mapped by T's inverse (as the recursive definition did, edge by edge).  Results are keyed
    by (node, frame); a result is dropped once all its parents have used it and a frame once
    its Transformed node is done, so memory follows the depth of the graph, not its size.
    """

    def __init__(self, x: np.ndarray):
        self.x = x
        self.frame_ids: dict = {}  # (id(Transformed), parent frame) -> frame id
        self.frames = {0: x}
        self.uses: dict = {}  # (id(node), frame) -> parents that have not used it yet
        self.results: dict = {}

    def child_frames(self, node, f):
        if isinstance(node, Transformed):
            key = (id(node), f)
            cf = self.frame_ids.get(key)
            if cf is None:
                cf = self.frame_ids[key] = len(self.frame_ids) + 1
            return [(node.operand, cf)]
        if isinstance(node, (Union, Intersection, Difference)):
            return [(c, f) for c in node.operands]
        if isinstance(node, Complement):
            return [(node.operand, f)]
        if isinstance(node, Primitive):
            return []
        raise OperandError(f"not a CSG node: {type(node).__name__}")

    def count_uses(self, shape) -> None:
        """Pass 1: how many parents use each (node, frame)."""
        seen = set()
        stack = [(shape, 0)]
        while stack:
            node, f = stack.pop()
            key = (id(node), f)
            if key in seen:
                continue
            seen.add(key)
            for c, cf in self.child_frames(node, f):
                ck = (id(c), cf)
                self.uses[ck] = self.uses.get(ck, 0) + 1
                if ck not in seen:
                    stack.append((c, cf))

    def take(self, key):
        n = self.uses[key] - 1
        self.uses[key] = n
        return self.results.pop(key) if n == 0 else self.results[key]

    def leaf(self, node, f) -> np.ndarray:
        pts = self.frames[f]
        out = np.ones(len(pts), dtype=bool)
        for q in node.quadrics():
            out &= q.value(pts) <= 0.0
        return out

    def evaluate(self, shape) -> np.ndarray:
        """Pass 2: every (node, frame) after its operands."""
        self.count_uses(shape)
        stack = [(shape, 0, False)]
        while stack:
            node, f, expanded = stack.pop()
            key = (id(node), f)
            if key in self.results:
                continue
            kids = self.child_frames(node, f)
            if not expanded and kids:
                stack.append((node, f, True))
                for c, cf in reversed(kids):
                    if (id(c), cf) not in self.results:
                        if isinstance(node, Transformed) and cf not in self.frames:
                            inv = np.linalg.inv(node.matrix)
                            self.frames[cf] = self.frames[f] @ inv[:3, :3].T + inv[:3, 3]
                        stack.append((c, cf, False))
                continue
            if isinstance(node, Primitive):
                self.results[key] = self.leaf(node, f)
                continue
            self.results[key] = _combine(node, [self.take((id(c), cf)) for c, cf in kids], len(self.x))
            if isinstance(node, Transformed):  # its operand's frame is no longer needed
                self.frames.pop(kids[0][1], None)
        return self.results[(id(shape), 0)]
