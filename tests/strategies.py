"""Shared hypothesis strategies: quadrics of every type, affine maps and CSG shape graphs.

    from strategies import quadric_cases, affine_maps, shapes, bounded_primitives

* :func:`quadric_cases` draws a :class:`QuadricCase`: a quadric from every named constructor
  of :class:`clcsg.quadric.Quadric` (or a raw random symmetric matrix), optionally moved by a
  well-conditioned affine map, together with the world-space directions along which it is
  degenerate (v^T A v = 0: cylinder axes, paraboloid axes, plane directions, cone generators).
* :func:`affine_maps` draws 4x4 affine matrices R1 diag(s) R2 + t with s in [1/smax, smax]
  (condition number <= smax^2), optionally mirrored.
* :func:`primitive_params` / :func:`any_primitives` cover every kind in
  :data:`clcsg.solids.KINDS`; :func:`bounded_primitives` only the bounded solids.
* :func:`shapes` draws CSG graphs (union / intersection / difference / complement, transforms,
  nesting) whose leaves come from a small pool and whose sub-trees are sometimes reused, so
  the graphs share nodes (DAGs, not just trees).
* :func:`csg_programs` draws random programs as a dataset pipeline would (boxes, spheres,
  cylinders, cone frusta, rotated and scaled, in unions / differences / intersections up to
  three deep, within [-6, 6]^3): a :class:`clcsg.model.random_programs.RandomProgram` with the
  Shape and its OpenSCAD ``.csg`` text.

All values are plain floats, tuples and numpy arrays in a unit-ish range.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from hypothesis import strategies as st

from clcsg.model import csg, solids
from clcsg.model.quadric import Quadric, affine, frame_z_to


# -- numbers and vectors ------------------------------------------------------------------------
def floats(lo: float, hi: float) -> st.SearchStrategy[float]:
    """Finite floats in [lo, hi]; magnitudes below 1e-12 become 0 (hypothesis likes values such
    as 3e-216, whose squares underflow: a float64 range artefact, not geometry)."""
    return st.floats(lo, hi, allow_nan=False, allow_infinity=False).map(lambda v: 0.0 if abs(v) < 1e-12 else v)


def vec3(lo: float = -1.0, hi: float = 1.0) -> st.SearchStrategy[np.ndarray]:
    return st.tuples(floats(lo, hi), floats(lo, hi), floats(lo, hi)).map(lambda t: np.array(t, dtype=np.float64))


def unit_vectors() -> st.SearchStrategy[np.ndarray]:
    """Unit 3-vectors, axis-aligned ones included (hypothesis finds them by shrinking)."""
    return vec3(-1.0, 1.0).map(_normalized_or_z)


def _normalized_or_z(v):
    n = np.linalg.norm(v)
    return v / n if n > 0.1 else np.array([0.0, 0.0, 1.0])  # no filter: shrinks to +z


def rotations() -> st.SearchStrategy[np.ndarray]:
    """3x3 rotation matrices from unit quaternions."""

    def to_matrix(q):
        w, x, y, z = q / np.linalg.norm(q)
        return np.array(
            [
                [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
            ]
        )

    quat = st.tuples(*[floats(-1.0, 1.0)] * 4).map(np.array)
    return quat.map(lambda q: to_matrix(q) if np.linalg.norm(q) > 0.1 else np.eye(3))


@st.composite
def affine_maps(draw, max_scale: float = 2.0, max_translation: float = 2.0, mirror: bool = True) -> np.ndarray:
    """Well-conditioned 4x4 affine maps: R1 diag(s) R2 + t, s in [1/max_scale, max_scale]."""
    r1 = draw(rotations())
    r2 = draw(rotations())
    s = np.array([draw(floats(1.0 / max_scale, max_scale)) for _ in range(3)])
    if mirror and draw(st.booleans()):
        s[0] = -s[0]
    t = draw(vec3(-max_translation, max_translation))
    return affine(r1 @ np.diag(s) @ r2, t)


def fibonacci_sphere(n: int) -> np.ndarray:
    """n roughly uniform unit directions (n, 3)."""
    i = np.arange(n) + 0.5
    z = 1.0 - 2.0 * i / n
    r = np.sqrt(np.maximum(0.0, 1.0 - z * z))
    phi = i * math.pi * (3.0 - math.sqrt(5.0))
    return np.column_stack([r * np.cos(phi), r * np.sin(phi), z])


# -- quadrics -----------------------------------------------------------------------------------
#: every named constructor of Quadric, plus "raw" (random symmetric matrix)
QUADRIC_KINDS = (
    "half_space",
    "slab",
    "sphere",
    "ellipsoid",
    "cylinder",
    "elliptic_cylinder",
    "cone",
    "elliptic_paraboloid",
    "hyperbolic_paraboloid",
    "hyperboloid_one_sheet",
    "hyperboloid_two_sheets",
    "raw",
)


@dataclass
class QuadricCase:
    kind: str
    quadric: Quadric
    #: world-space unit directions with v^T A v = 0 (exactly, before rounding)
    degenerate_dirs: list = field(default_factory=list)
    #: the affine map applied to the constructed quadric (None: untransformed)
    transform: np.ndarray | None = None
    #: a point on the surface (world space), where one is known
    surface_point: np.ndarray | None = None

    def __repr__(self) -> str:  # short, for hypothesis' falsifying-example output
        t = "" if self.transform is None else f", transform={np.round(self.transform, 17).tolist()}"
        return f"QuadricCase({self.kind}, {self.quadric!r}{t})"


def _radius():
    return floats(0.2, 2.0)


def _perp(w: np.ndarray) -> np.ndarray:
    return frame_z_to(w)[:, 0]


@st.composite
def _named_quadric(draw, kind: str) -> QuadricCase:
    center = draw(vec3())
    if kind == "raw":
        m = np.array([[draw(floats(-1.0, 1.0)) for _ in range(4)] for _ in range(4)])
        m = m + m.T
        m[np.abs(m) < 1e-6] = 0.0  # no denormal-ish noise: every coefficient is clearly 0 or not
        if np.abs(m).max() < 0.1:
            m[0, 0] = 1.0
        return QuadricCase(kind, Quadric(m))
    if kind == "half_space":
        n = draw(unit_vectors())
        off = draw(floats(-1.0, 1.0))
        scale = draw(floats(0.5, 2.0))
        q = Quadric.half_space(n * scale, off * scale)
        return QuadricCase(kind, q, [_perp(n), np.cross(n, _perp(n))], surface_point=n * off)
    if kind == "slab":
        n = draw(unit_vectors())
        lo = draw(floats(-1.0, 0.5))
        hi = lo + draw(floats(0.1, 1.5))
        return QuadricCase(kind, Quadric.slab(n, lo, hi), [_perp(n), np.cross(n, _perp(n))], surface_point=n * hi)
    if kind == "sphere":
        r = draw(_radius())
        return QuadricCase(kind, Quadric.sphere(center, r), surface_point=center + r * np.array([0.0, 0.0, 1.0]))
    if kind == "ellipsoid":
        radii = np.array([draw(_radius()) for _ in range(3)])
        rot = draw(rotations())
        q = Quadric.ellipsoid(center, radii, rot)
        # the surface point is found by casting a ray, not from radii[0]: it does not depend on
        # which semi-axis Quadric.ellipsoid puts along which column of the rotation
        t = q.intersect_line(center, rot[:, 0])[1]
        return QuadricCase(kind, q, surface_point=center + float(t) * rot[:, 0])
    axis = draw(unit_vectors())
    u = _perp(axis)
    if kind == "cylinder":
        r = draw(_radius())
        return QuadricCase(kind, Quadric.cylinder(axis, r, center), [axis], surface_point=center + r * u)
    if kind == "elliptic_cylinder":
        radii = (draw(_radius()), draw(_radius()))
        q = Quadric.elliptic_cylinder(axis, radii, center)
        return QuadricCase(kind, q, [axis], surface_point=center + radii[0] * frame_z_to(axis)[:, 0])
    if kind == "cone":
        k = draw(floats(0.2, 3.0))
        gen = (axis + k * u) / math.hypot(1.0, k)
        return QuadricCase(kind, Quadric.cone(center, axis, k), [gen], surface_point=center + gen)
    if kind == "elliptic_paraboloid":
        radii = (draw(_radius()), draw(_radius()))
        return QuadricCase(kind, Quadric.elliptic_paraboloid(center, axis, radii), [axis], surface_point=center)
    if kind == "hyperbolic_paraboloid":
        a, b = draw(_radius()), draw(_radius())
        f = frame_z_to(axis)
        # x^2/a^2 - y^2/b^2 = z: the axis and the asymptotic directions (a, +-b, 0) are null
        asym = [(a * f[:, 0] + s * b * f[:, 1]) / math.hypot(a, b) for s in (1.0, -1.0)]
        q = Quadric.hyperbolic_paraboloid(center, axis, (a, b))
        return QuadricCase(kind, q, [axis, *asym], surface_point=center)
    if kind in ("hyperboloid_one_sheet", "hyperboloid_two_sheets"):
        a, b, c = draw(_radius()), draw(_radius()), draw(_radius())
        f = frame_z_to(axis)
        # asymptotic-cone directions: x^2/a^2 - z^2/c^2 = 0 in the (u, axis) plane
        gen = (a * f[:, 0] + c * f[:, 2]) / math.hypot(a, c)
        ctor = getattr(Quadric, kind)
        q = ctor(center, axis, (a, b, c))
        sp = center + (a * f[:, 0] if kind == "hyperboloid_one_sheet" else c * f[:, 2])
        return QuadricCase(kind, q, [gen], surface_point=sp)
    raise ValueError(kind)


@st.composite
def quadric_cases(draw, kinds=QUADRIC_KINDS, transformed: bool | None = None) -> QuadricCase:
    """A :class:`QuadricCase`; ``transformed`` True / False / None (either)."""
    kind = draw(st.sampled_from(kinds))
    case = draw(_named_quadric(kind))
    if transformed is None:
        transformed = draw(st.booleans())
    if transformed:
        m = draw(affine_maps())
        lin = m[:3, :3]
        dirs = [lin @ d for d in case.degenerate_dirs]
        dirs = [d / np.linalg.norm(d) for d in dirs]
        sp = None if case.surface_point is None else m[:3, :3] @ case.surface_point + m[:3, 3]
        case = QuadricCase(kind, case.quadric.transform(m), dirs, m, sp)
    return case


def quadrics(kinds=QUADRIC_KINDS, transformed: bool | None = None) -> st.SearchStrategy[Quadric]:
    return quadric_cases(kinds, transformed).map(lambda c: c.quadric)


# -- primitives (clcsg.solids) ------------------------------------------------------------------
def _tup3(lo=-1.0, hi=1.0):
    return st.tuples(floats(lo, hi), floats(lo, hi), floats(lo, hi))


def _dir3():
    return unit_vectors().map(lambda v: tuple(float(x) for x in v))


def _pos(lo=0.2, hi=1.5):
    return floats(lo, hi)


def _sym_matrix():
    def build(vals):
        m = np.zeros((4, 4))
        iu = np.triu_indices(4)
        m[iu] = vals
        m = m + np.triu(m, 1).T
        return m.tolist()

    return st.lists(floats(-1.0, 1.0), min_size=10, max_size=10).filter(
        lambda v: max(abs(x) for x in v) > 0.1
    ).map(build)


def _cone_radii():
    """(r1, r2) in [0, 1] with max >= 0.1; either may be 0 (a cone to its apex)."""
    return st.tuples(floats(0.0, 1.0), floats(0.1, 1.0), st.booleans()).map(lambda t: (t[0], t[1]) if t[2] else (t[1], t[0]))


#: kind -> strategy of (required, optional) parameter dicts; every kind of solids.KINDS
_PARAMS = {
    "box": ({}, {"size": st.one_of(_pos(), _tup3(0.2, 1.5)), "center": _tup3()}),
    "cylinder": ({}, {"height": _pos(), "radius": _pos(0.1, 1.0), "center": _tup3(), "axis": _dir3()}),
    "cone": None,  # r1, r2 drawn together, see primitive_params
    "sphere": ({}, {"radius": _pos(), "center": _tup3()}),
    "ellipsoid": ({}, {"radii": st.one_of(_pos(), _tup3(0.2, 1.5)), "center": _tup3()}),
    "halfspace": ({}, {"normal": _dir3(), "offset": floats(-1.0, 1.0)}),
    "slab": None,  # lo < hi
    "quadric": None,  # matrix or coefficients
    "infinite_cylinder": ({}, {"axis": _dir3(), "radius": _pos(), "center": _tup3()}),
    "elliptic_cylinder": ({}, {"axis": _dir3(), "radii": st.tuples(_pos(), _pos()), "center": _tup3()}),
    "double_cone": ({}, {"apex": _tup3(), "axis": _dir3(), "slope": _pos(0.2, 3.0)}),
    "elliptic_paraboloid": ({}, {"apex": _tup3(), "axis": _dir3(), "radii": st.tuples(_pos(), _pos())}),
    "hyperbolic_paraboloid": ({}, {"center": _tup3(), "axis": _dir3(), "radii": st.tuples(_pos(), _pos())}),
    "hyperboloid_one_sheet": ({}, {"center": _tup3(), "axis": _dir3(), "radii": _tup3(0.2, 1.5)}),
    "hyperboloid_two_sheets": ({}, {"center": _tup3(), "axis": _dir3(), "radii": _tup3(0.2, 1.5)}),
}
PRIMITIVE_KINDS = tuple(_PARAMS)
BOUNDED_KINDS = ("box", "cylinder", "cone", "sphere", "ellipsoid")


@st.composite
def primitive_params(draw, kind: str) -> dict:
    """Valid parameters for ``kind`` (a random subset of the optional ones: defaults apply)."""
    if kind == "cone":
        r1, r2 = draw(_cone_radii())
        opt = {"height": _pos(), "center": _tup3(), "axis": _dir3()}
        params = draw(st.fixed_dictionaries({}, optional=opt))
        params.update(r1=r1, r2=r2)
        return params
    if kind == "slab":
        lo = draw(floats(-1.0, 0.5))
        hi = lo + draw(floats(0.1, 1.0))
        params = draw(st.fixed_dictionaries({}, optional={"normal": _dir3()}))
        params.update(lo=lo, hi=hi)
        return params
    if kind == "quadric":
        m = draw(_sym_matrix())
        if draw(st.booleans()):
            m = [m[i][j] for i in range(4) for j in range(i, 4)]  # the 10 coefficients
        return {"matrix": m}
    required, optional = _PARAMS[kind]
    return draw(st.fixed_dictionaries(required, optional=optional))


def colors():
    c = st.tuples(floats(0.0, 1.0), floats(0.0, 1.0), floats(0.0, 1.0))
    return st.one_of(st.none(), c, c.flatmap(lambda t: floats(0.0, 1.0).map(lambda a: (*t, a))))


@st.composite
def any_primitives(draw, kinds=PRIMITIVE_KINDS) -> csg.Primitive:
    kind = draw(st.sampled_from(kinds))
    return csg.Primitive(kind, draw(primitive_params(kind)), draw(colors()))


@st.composite
def bounded_primitives(draw, tilted: bool = True) -> csg.Primitive:
    """box, sphere, ellipsoid, cylinder, cone (axes tilted unless ``tilted=False``) within
    about [-2, 2]^3."""
    kind = draw(st.sampled_from(BOUNDED_KINDS))
    color = draw(colors())
    center = draw(_tup3())
    if kind == "box":
        return solids.box(draw(st.one_of(_pos(0.3, 1.5), _tup3(0.3, 1.5))), center, color)
    if kind == "sphere":
        return solids.sphere(draw(_pos(0.3, 1.2)), center, color)
    if kind == "ellipsoid":
        return solids.ellipsoid(draw(_tup3(0.3, 1.2)), center, color)
    axis = draw(_dir3()) if tilted else draw(st.sampled_from([(1.0, 0, 0), (0, 1.0, 0), (0, 0, 1.0)]))
    if kind == "cylinder":
        return solids.cylinder(draw(_pos(0.3, 1.5)), draw(_pos(0.2, 0.8)), center, axis, color)
    r1, r2 = draw(_cone_radii())
    return solids.cone(draw(_pos(0.3, 1.5)), r1, r2, center, axis, color)


# -- CSG graphs ---------------------------------------------------------------------------------
OPERATIONS = ("union", "intersection", "difference", "complement")


@st.composite
def shapes(
    draw,
    leaves=None,
    max_depth: int = 3,
    max_arity: int = 3,
    operations=OPERATIONS,
    transforms: bool = True,
    share: bool = True,
    max_translation: float = 0.5,
) -> csg.Shape:
    """A CSG graph with an operation at the root (a transform edge may sit above it).
    Leaves are drawn into a pool of 1-4 primitives first and picked from it,
    and finished sub-trees are sometimes picked again, so nodes are shared.  Transforms
    (Transformed edges) sit on any node.  Operations are built with the classes, not the
    flattening helpers, so nesting is kept as drawn."""
    leaves = bounded_primitives() if leaves is None else leaves
    pool = draw(st.lists(leaves, min_size=1, max_size=4))
    built: list[csg.Shape] = []

    def build(depth: int) -> csg.Shape:
        choice = draw(st.integers(0, 9))
        if depth >= max_depth or (depth > 0 and choice < 3):  # the root is an operation
            node = pool[draw(st.integers(0, len(pool) - 1))]
        elif share and choice == 3 and built:
            node = built[draw(st.integers(0, len(built) - 1))]
        else:
            op = draw(st.sampled_from(operations))
            if op == "complement":
                node = csg.Complement(build(depth + 1))
            else:
                n = draw(st.integers(1, max_arity))
                kids = [build(depth + 1) for _ in range(n)]
                cls = {"union": csg.Union, "intersection": csg.Intersection, "difference": csg.Difference}[op]
                node = cls(kids)
        if transforms and draw(st.integers(0, 3)) == 3:
            node = csg.Transformed(node, draw(affine_maps(max_scale=1.5, max_translation=max_translation)))
        built.append(node)
        return node

    return build(0)


def shared_nodes(shape: csg.Shape) -> set[int]:
    """ids of the nodes of ``shape`` with more than one incoming edge."""
    parents: dict[int, int] = {}
    for node in csg.walk(shape):
        for c in node.children():
            parents[id(c)] = parents.get(id(c), 0) + 1
    return {i for i, n in parents.items() if n > 1}


# -- random programs ----------------------------------------------------------------------------
def csg_programs(max_depth: int = 3) -> st.SearchStrategy:
    """:func:`clcsg.model.random_programs.random_program` driven by hypothesis' own randomness
    (``st.randoms()``): every draw of the generator is a hypothesis choice, so failures shrink
    towards fewer levels, fewer operands and smaller parameters."""
    from clcsg.model.random_programs import random_program

    return st.randoms(use_true_random=False).map(lambda r: random_program(r, max_depth=max_depth))
