"""Random CSG programs as a dataset pipeline draws them, as a :class:`Shape` and as OpenSCAD text.

    import numpy as np
    from clcsg.model.random_programs import random_program

    prog = random_program(np.random.default_rng(7), max_depth=3)
    prog.shape        # the clcsg Shape
    prog.csg          # the same program as OpenSCAD CSG export (``openscad -o x.csg`` form)

Grammar (every number rounded to 6 decimals, so the text and the Shape hold the same floats)::

    program  := node(depth 0)
    node     := leaf | op                       (the root is an op when max_depth > 0)
    op       := [multmatrix(R about the op's center)] union | difference | intersection
                of 2 or 3 nodes one level deeper (at most ``max_depth`` levels of ops)
    leaf     := multmatrix(T R S) { cube | sphere | cylinder | cone frustum }
                cube(size = [a, b, c], center = true);  sphere(r = r);
                cylinder(h = h, r1 = r, r2 = r, center = true);
                cylinder(h = h, r1 = r1, r2 = r2, center = true)    (r1 != r2, one may be 0)

S is a per-axis scale in [0.6, 1.6], R a random rotation, T a translation.  Every node is
drawn inside a ball (center, radius) that lies in its parent's ball, and the root's ball lies
in the box [-6, 6]^3 (the 12-unit box around the origin), so every program does.  The
operands of an intersection overlap (their centers are close), the first operand of a
difference is about as large as the difference and the subtracted ones are smaller, so most
programs are not empty.

``rng`` may be a :class:`numpy.random.Generator`, a :class:`random.Random` (hypothesis'
``st.randoms()`` shrinks through it) or an int seed.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from . import csg, solids
from .quadric import affine

#: half the side of the box every program lies in
HALF_EXTENT = 6.0

KINDS = ("cube", "sphere", "cylinder", "cone")
OPS = ("union", "difference", "intersection")


@dataclass
class RandomProgram:
    """A random program: the Shape, its OpenSCAD CSG text and a few counts."""

    shape: csg.Shape
    csg: str
    primitives: int
    depth: int  # levels of operations

    def __repr__(self) -> str:
        return f"RandomProgram({self.primitives} primitives, depth {self.depth}):\n{self.csg}"


class _Rng:
    """The few draws the generator needs, from numpy's Generator or Python's Random."""

    def __init__(self, rng):
        if isinstance(rng, (int, np.integer)):
            rng = np.random.default_rng(int(rng))
        self.r = rng
        self.np = isinstance(rng, np.random.Generator)

    def uniform(self, lo: float, hi: float) -> float:
        return float(self.r.uniform(lo, hi))

    def integer(self, lo: int, hi: int) -> int:
        """lo <= n <= hi."""
        return int(self.r.integers(lo, hi + 1)) if self.np else self.r.randint(lo, hi)

    def choice(self, seq):
        return seq[self.integer(0, len(seq) - 1)]

    def unit(self) -> np.ndarray:
        """A unit vector: a point of the cube [-1, 1]^3 projected (no rejection loop, so that
        every draw is a fixed number of choices; not uniform on the sphere, which does not
        matter here)."""
        v = np.array([self.uniform(-1.0, 1.0) for _ in range(3)])
        n = float(np.linalg.norm(v))
        return v / n if n > 1e-3 else np.array([0.0, 0.0, 1.0])


def _r(v: float) -> float:
    """Rounded to 6 decimals (and -0.0 -> 0.0): the number both outputs use."""
    return float(round(float(v), 6)) + 0.0


def _num(v: float) -> str:
    """A float as the text that reads back to the same float."""
    v = float(v)
    return str(int(v)) if v.is_integer() and abs(v) < 1e15 else repr(v)


def _vec(values) -> str:
    return "[" + ", ".join(_num(v) for v in values) + "]"


def _rotation(rng: _Rng) -> np.ndarray:
    return csg.rotation_matrix(rng.unit(), rng.uniform(0.0, 360.0))


def _matrix_text(m: np.ndarray) -> str:
    return "multmatrix([" + ", ".join(_vec(row) for row in m) + "])"


class _Builder:
    def __init__(self, rng: _Rng, max_depth: int):
        self.rng = rng
        self.max_depth = max_depth
        self.primitives = 0
        self.depth = 0

    # a leaf within the ball (c, rho)
    def leaf(self, c: np.ndarray, rho: float, indent: str):
        rng = self.rng
        self.primitives += 1
        kind = rng.choice(KINDS)
        scale = np.array([rng.uniform(0.6, 1.6) for _ in range(3)])
        rot = _rotation(rng)
        # local dimensions relative to 1, then scaled so that the transformed solid lies in a
        # ball of radius rho * f around the leaf's center
        if kind == "cube":
            dims = [rng.uniform(0.4, 1.0) for _ in range(3)]
            r_local = 0.5 * math.sqrt(sum(d * d for d in dims))
        elif kind == "sphere":
            dims = [1.0]
            r_local = 1.0
        elif kind == "cylinder":
            dims = [rng.uniform(0.4, 2.0), rng.uniform(0.3, 1.0)]  # h, r
            r_local = math.hypot(dims[0] / 2, dims[1])
        else:
            r1, r2 = rng.uniform(0.3, 1.0), rng.uniform(0.0, 1.0)
            if rng.integer(0, 3) == 0:
                r2 = 0.0
            if rng.integer(0, 1):
                r1, r2 = r2, r1
            dims = [rng.uniform(0.4, 2.0), r1, r2]
            r_local = math.hypot(dims[0] / 2, max(r1, r2))
        f = rng.uniform(0.6, 1.0)
        k = f * rho / (float(scale.max()) * r_local)
        dims = [_r(d * k) for d in dims]  # sizes stay >= ~0.01 (balls shrink to ~3% at depth 3)
        # the leaf's center: within the ball, so that its own ball (radius f rho) stays inside
        off = rng.unit() * rng.uniform(0.0, (1.0 - f) * rho)
        m = affine(rot @ np.diag(scale), c + off)
        m = np.vectorize(_r)(m)
        m[3] = (0.0, 0.0, 0.0, 1.0)
        if kind == "cube":
            prim = solids.box(tuple(dims))
            text = f"cube(size = {_vec(dims)}, center = true);"
        elif kind == "sphere":
            prim = solids.sphere(dims[0])
            text = f"sphere($fn = 0, $fa = 12, $fs = 2, r = {_num(dims[0])});"
        elif kind == "cylinder":
            h, r = dims
            prim = solids.cylinder(h, r)
            text = (f"cylinder($fn = 0, $fa = 12, $fs = 2, h = {_num(h)}, r1 = {_num(r)}, "
                    f"r2 = {_num(r)}, center = true);")
        else:
            h, r1, r2 = dims
            prim = solids.cone(h, r1, r2)
            text = (f"cylinder($fn = 0, $fa = 12, $fs = 2, h = {_num(h)}, r1 = {_num(r1)}, "
                    f"r2 = {_num(r2)}, center = true);")
        shape = csg.Transformed(prim, m)
        lines = f"{indent}{_matrix_text(m)} {{\n{indent}\t{text}\n{indent}}}\n"
        return shape, lines

    def node(self, c: np.ndarray, rho: float, depth: int, indent: str):
        rng = self.rng
        if depth >= self.max_depth or (depth > 0 and rng.uniform(0.0, 1.0) < 0.3):
            return self.leaf(c, rho, indent)
        self.depth = max(self.depth, depth + 1)
        op = rng.choice(OPS)
        n = rng.integer(2, 3)
        rotate = rng.integer(0, 3) == 0
        inner = indent + "\t" if rotate else indent
        kids = []
        for i in range(n):
            if op == "union":
                d, f = rng.uniform(0.0, 0.5), rng.uniform(0.5, 0.8)
            elif op == "intersection":
                d, f = rng.uniform(0.0, 0.25), None
            elif i == 0:  # the first operand of a difference
                d, f = rng.uniform(0.0, 0.2), None
            else:  # subtracted operands
                d, f = rng.uniform(0.1, 0.6), rng.uniform(0.3, 0.7)
            off = rng.unit() * d * rho
            r_child = (1.0 - d) * rho if f is None else min(f, 1.0 - d) * rho
            kids.append(self.node(c + off, r_child, depth + 1, inner + "\t"))
        cls = {"union": csg.Union, "difference": csg.Difference, "intersection": csg.Intersection}[op]
        shape = cls([k[0] for k in kids])
        body = "".join(k[1] for k in kids)
        text = f"{inner}{op}() {{\n{body}{inner}}}\n"
        if rotate:
            # a rotation about the op's center keeps the subtree in its ball
            rot = _rotation(rng)
            m = affine(rot, c - rot @ c)
            m = np.vectorize(_r)(m)
            m[3] = (0.0, 0.0, 0.0, 1.0)
            shape = csg.Transformed(shape, m)
            text = f"{indent}{_matrix_text(m)} {{\n{text}{indent}}}\n"
        return shape, text


def random_program(rng=None, max_depth: int = 3) -> RandomProgram:
    """A random program (see the module docstring for the grammar)."""
    r = _Rng(np.random.default_rng() if rng is None else rng)
    b = _Builder(r, int(max_depth))
    c = np.array([r.uniform(-2.0, 2.0) for _ in range(3)])
    room = HALF_EXTENT - float(np.abs(c).max())
    rho = r.uniform(0.6, 0.98) * room  # a margin for the 6-decimal rounding
    shape, text = b.node(c, rho, 0, "")
    return RandomProgram(shape, text, b.primitives, b.depth)


__all__ = ["RandomProgram", "random_program", "HALF_EXTENT"]
