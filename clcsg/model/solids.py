"""Solids people think in, each expanded into an intersection of quadric literals.

=========================  ==================================================================
kind                       literals
=========================  ==================================================================
box                        six half-spaces (not three slabs: a face shared by two boxes is
                           then one and the same quadric)
cylinder                   infinite cylinder and two cap half-spaces
cone                       double cone and two cap half-spaces (frustum; r1 or r2 may be 0);
                           r1 == r2 gives a cylinder
sphere, ellipsoid          one quadric
halfspace, slab            one quadric
quadric                    a raw 4x4 matrix (solid Q(x) <= 0)
infinite_cylinder,         one unbounded quadric each, placed with center/apex and axis
elliptic_cylinder,
double_cone,
elliptic_paraboloid,
hyperbolic_paraboloid,
hyperboloid_one_sheet,
hyperboloid_two_sheets
=========================  ==================================================================

Every constructor takes ``color=(r, g, b[, a])`` in [0, 1].
"""

from __future__ import annotations

import inspect

import numpy as np

from ..errors import ParameterError

from .csg import Primitive
from .csg import _vec3 as _v3
from .quadric import Quadric, frame_z_to


def _pos(v, what, allow_zero=False):
    v = float(v)
    if not np.isfinite(v) or v < 0 or (v == 0 and not allow_zero):
        raise ParameterError(f"{what} must be a {'non-negative' if allow_zero else 'positive'} finite number, got {v}")
    return v


def _box(size=1.0, center=(0, 0, 0)):
    s = _v3(size, "box size")
    if np.any(s <= 0):
        raise ParameterError(f"box size must be positive, got {s.tolist()}")
    c = _v3(center, "box center")
    out = []
    for k in range(3):
        e = np.zeros(3)
        e[k] = 1.0
        out.append(Quadric.half_space(e, c[k] + s[k] / 2))
        out.append(Quadric.half_space(-e, -(c[k] - s[k] / 2)))
    return out


def _caps(center, axis, height):
    w = frame_z_to(axis)[:, 2]
    c = _v3(center, "center")
    h = _pos(height, "height")
    top = c + w * h / 2
    bottom = c - w * h / 2
    return [Quadric.half_space(w, w @ top), Quadric.half_space(-w, -(w @ bottom))]


def _cylinder(height=1.0, radius=1.0, center=(0, 0, 0), axis=(0, 0, 1)):
    r = _pos(radius, "cylinder radius")
    return [Quadric.cylinder(axis, r, _v3(center, "cylinder center"))] + _caps(center, axis, height)


def _cone(height=1.0, r1=1.0, r2=0.0, center=(0, 0, 0), axis=(0, 0, 1)):
    r1 = _pos(r1, "cone r1", allow_zero=True)
    r2 = _pos(r2, "cone r2", allow_zero=True)
    h = _pos(height, "cone height")
    if r1 == 0 and r2 == 0:
        raise ParameterError("cone needs r1 > 0 or r2 > 0")
    if r1 == r2:
        return _cylinder(h, r1, center, axis)
    w = frame_z_to(axis)[:, 2]
    c = _v3(center, "cone center")
    # radius r(z) = r1 + (r2 - r1) (z + h/2) / h vanishes at the apex
    z_apex = -h / 2 + h * r1 / (r1 - r2)
    slope = abs(r2 - r1) / h
    return [Quadric.cone(c + w * z_apex, w, slope)] + _caps(center, axis, h)


def _sphere(radius=1.0, center=(0, 0, 0)):
    return [Quadric.sphere(_v3(center, "sphere center"), radius)]


def _ellipsoid(radii=(1, 1, 1), center=(0, 0, 0)):
    return [Quadric.ellipsoid(_v3(center, "ellipsoid center"), _v3(radii, "ellipsoid radii"))]


def _halfspace(normal=(0, 0, 1), offset=0.0):
    return [Quadric.half_space(_v3(normal, "half-space normal"), float(offset))]


def _slab(normal=(0, 0, 1), lo=-0.5, hi=0.5):
    return [Quadric.slab(_v3(normal, "slab normal"), lo, hi)]


def _quadric(matrix):
    m = np.asarray(matrix, dtype=np.float64)
    if m.shape == (10,):
        return [Quadric.from_coefficients(m)]
    if m.shape != (4, 4) or not np.all(np.isfinite(m)):
        raise ParameterError("quadric matrix must be 4x4 finite numbers (or 10 coefficients)")
    if not np.allclose(m, m.T, rtol=0, atol=1e-12 * max(1.0, np.abs(m).max())):
        raise ParameterError("quadric matrix must be symmetric")
    if np.abs(m).max() == 0:
        raise ParameterError("quadric matrix must not be zero")
    return [Quadric(m)]


def _single(ctor):
    def make(**kw):
        return [ctor(**kw)]

    make.__signature__ = inspect.signature(ctor)
    return make


#: kind -> function(**params) -> list of Quadric
KINDS = {
    "box": _box,
    "cylinder": _cylinder,
    "cone": _cone,
    "sphere": _sphere,
    "ellipsoid": _ellipsoid,
    "halfspace": _halfspace,
    "slab": _slab,
    "quadric": _quadric,
    "infinite_cylinder": _single(Quadric.cylinder),
    "elliptic_cylinder": _single(Quadric.elliptic_cylinder),
    "double_cone": _single(Quadric.cone),
    "elliptic_paraboloid": _single(Quadric.elliptic_paraboloid),
    "hyperbolic_paraboloid": _single(Quadric.hyperbolic_paraboloid),
    "hyperboloid_one_sheet": _single(Quadric.hyperboloid_one_sheet),
    "hyperboloid_two_sheets": _single(Quadric.hyperboloid_two_sheets),
}


def parameters(kind: str) -> dict:
    """Parameter names of ``kind`` and their defaults (inspect.Parameter.empty if required)."""
    return dict(_signature(kind)[0])


def _signature(kind: str):
    """(names and defaults, the set of names, the required names) of ``kind``, computed once."""
    sig = _SIGNATURES.get(kind)
    if sig is None:
        known = {name: p.default for name, p in inspect.signature(KINDS[kind]).parameters.items()}
        sig = _SIGNATURES[kind] = (known, frozenset(known), [k for k, d in known.items() if d is inspect.Parameter.empty])
    return sig


_SIGNATURES: dict = {}


def literals(kind: str, params: dict) -> list[Quadric]:
    """Expand a primitive into the quadrics whose insides intersect to the solid."""
    if kind not in KINDS:
        raise ParameterError(f"unknown primitive kind {kind!r}; known: {', '.join(sorted(KINDS))}")
    known, names, required = _signature(kind)
    if not names.issuperset(params):
        unknown = set(params) - names
        raise ParameterError(f"{kind} has no parameter {sorted(unknown)[0]!r}; it takes {', '.join(known)}")
    missing = [k for k in required if k not in params]
    if missing:
        raise ParameterError(f"{kind} needs parameter {missing[0]!r}")
    return KINDS[kind](**params)


def _make(kind, color, **params):
    return Primitive(kind, params, color)


def box(size=1.0, center=(0, 0, 0), color=None) -> Primitive:
    """Axis-aligned box of ``size`` (scalar or 3 values) centered at ``center``."""
    return _make("box", color, size=size, center=center)


def cylinder(height=1.0, radius=1.0, center=(0, 0, 0), axis=(0, 0, 1), color=None) -> Primitive:
    """Finite circular cylinder centered at ``center`` along ``axis``."""
    return _make("cylinder", color, height=height, radius=radius, center=center, axis=axis)


def cone(height=1.0, r1=1.0, r2=0.0, center=(0, 0, 0), axis=(0, 0, 1), color=None) -> Primitive:
    """Cone frustum: radius r1 at center - axis*height/2, r2 at the other end."""
    return _make("cone", color, height=height, r1=r1, r2=r2, center=center, axis=axis)


def sphere(radius=1.0, center=(0, 0, 0), color=None) -> Primitive:
    return _make("sphere", color, radius=radius, center=center)


def ellipsoid(radii=(1, 1, 1), center=(0, 0, 0), color=None) -> Primitive:
    return _make("ellipsoid", color, radii=radii, center=center)


def halfspace(normal=(0, 0, 1), offset=0.0, color=None) -> Primitive:
    """The solid normal . x <= offset."""
    return _make("halfspace", color, normal=normal, offset=offset)


def slab(normal=(0, 0, 1), lo=-0.5, hi=0.5, color=None) -> Primitive:
    """The solid lo <= normal . x <= hi (one quadric: two parallel planes)."""
    return _make("slab", color, normal=normal, lo=lo, hi=hi)


def quadric(matrix, color=None) -> Primitive:
    """A raw quadric: 4x4 symmetric matrix, solid x^T Q x <= 0."""
    return _make("quadric", color, matrix=np.asarray(matrix, dtype=float).tolist())
