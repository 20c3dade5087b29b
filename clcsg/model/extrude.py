"""linear_extrude: a 2-D profile swept along z, optionally scaled towards the top, exactly.

The solid between z0 and z0 + h (z0 = 0, or -h/2 when centered) is

    {(x, y, z) : (x / kx(z), y / ky(z)) in P},   k(z) = 1 + (s - 1) (z - z0) / h,

with k > 0 inside the slab (scale s >= 0).  With X = (x, y, z, 1) and the linear forms
kx(X), ky(X), every leaf of the profile becomes one quadric and the Booleans stay:

* half-plane a x + b y <= d with one scale k: a x + b y - d k(z) <= 0, a plane (through the
  apex when s != 1);
* conic [x y 1] C [x y 1]^T <= 0: with u = (x, y, k(z)) = L X, X^T (L^T C L) X <= 0 is the
  conic scaled by k^2 > 0: an (elliptic, possibly oblique) cylinder or cone;
* half-plane with kx != ky: multiplying by kx ky > 0 gives a x ky + b y kx - d kx ky <= 0,
  a ruled quadric (a hyperbolic paraboloid); a conic then has degree 4 and is refused.

Two cap half-spaces bound the slab.  ``twist`` turns the edges into helicoids: refused.
"""

from __future__ import annotations

import numpy as np

from .construction import Construction, plane, raw
from .csg import Difference, Intersection, Union
from .profile import Profile, ProfileError


def _sym(p, q):
    return 0.5 * (np.outer(p, q) + np.outer(q, p))


def extrude(profile: Profile, height=1.0, center=False, scale=1.0, twist=0.0, color=None):
    """The exact linear extrusion of ``profile`` (OpenSCAD's ``linear_extrude``)."""
    if not isinstance(profile, Profile):
        raise ProfileError(f"extrude needs a 2-D Profile, got {type(profile).__name__}")
    h = float(height)
    if not (np.isfinite(h) and h > 0):
        raise ProfileError(f"extrude height must be positive, got {h}")
    if twist:
        raise ProfileError("linear_extrude(twist = ...) sweeps helicoids, which are not quadrics; "
                           "nearest exact alternative: twist = 0 (rotate the whole extrusion instead)")
    s = np.broadcast_to(np.asarray(scale, dtype=np.float64), (2,)).astype(float)
    if not np.all(np.isfinite(s)) or np.any(s < 0):
        raise ProfileError(f"extrude scale must be non-negative, got {s.tolist()}")
    z0 = -h / 2 if center else 0.0
    # k(X) = (s - 1)/h z + 1 - (s - 1) z0 / h as a row over (x, y, z, 1)
    kx = np.array([0, 0, (s[0] - 1) / h, 1 - (s[0] - 1) * z0 / h])
    ky = np.array([0, 0, (s[1] - 1) / h, 1 - (s[1] - 1) * z0 / h])
    ex, ey = np.eye(4)[0], np.eye(4)[1]
    uniform = s[0] == s[1]

    def leaf(node):
        if node.op == "line":
            a, b, d = node.data
            if uniform:
                v = a * ex + b * ey - d * kx
                return plane(v[:3], -v[3], color)
            return raw(a * _sym(ex, ky) + b * _sym(ey, kx) - d * _sym(kx, ky), color)
        if not uniform:
            raise ProfileError(f"linear_extrude(scale = {s.tolist()}) of a circle or ellipse with unequal x and y scales "
                               "sweeps a quartic surface; nearest exact alternative: equal scales")
        lm = np.vstack([ex, ey, kx])
        return raw(lm.T @ node.data @ lm, color)

    body = profile.map(leaf, Union, Intersection, lambda k: Difference(k), lambda: Union([]))
    caps = [plane((0, 0, 1), z0 + h, color), plane((0, 0, -1), -z0, color)]
    solid = Intersection([body, *caps])
    sc = "" if np.all(s == 1) else f", scale {s[0]:g}" if uniform else f", scale {s.tolist()}"
    verts = None
    if profile.loops is not None and len(profile.loops) == 1 and _convex(profile.loops[0]):
        lp = profile.loops[0]
        top = lp * s
        verts = np.vstack([np.c_[lp, np.full(len(lp), z0)], np.c_[top, np.full(len(lp), z0 + h)]])
    if profile.bbox is None:
        raise ProfileError("linear_extrude() of an unbounded profile")
    x0, y0, x1, y1 = profile.bbox
    xs, ys = [x0, x1, x0 * s[0], x1 * s[0]], [y0, y1, y0 * s[1], y1 * s[1]]
    box = ((min(xs), min(ys), z0), (max(xs), max(ys), z0 + h))
    spec = None if profile.spec is None else {"extrude": {"profile": profile.spec, "height": h, "center": bool(center),
                                                          "scale": float(s[0]) if uniform else s.tolist()}}
    disks = None
    if profile.circle is not None and uniform:
        (cx, cy), rc = profile.circle
        disks = (((cx, cy, z0), rc), ((cx * s[0], cy * s[0], z0 + h), rc * s[0]))
    return Construction("extrude", f"linear_extrude of {profile.describe()} (height {h:g}{sc})", solid, verts, box, spec,
                        disks)


def _convex(lp):
    d = np.roll(lp, -1, axis=0) - lp
    c = d[:, 0] * np.roll(d[:, 1], -1) - d[:, 1] * np.roll(d[:, 0], -1)
    return bool(np.all(c > 0) or np.all(c < 0))
