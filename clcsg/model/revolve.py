"""rotate_extrude: a 2-D profile in the half-plane x >= 0 turned about the z axis, exactly.

The profile's x is the distance r = sqrt(X^2 + Y^2) from the axis and its y is Z, so a point
is inside iff (r, Z) is in the profile; the Booleans stay and each half-plane leaf
a r + b z <= d becomes (for r >= 0):

* a = 0: the plane b Z <= d;
* b = 0: a cylinder (r <= d / a for a > 0, its complement r >= d / a for a < 0);
* otherwise, with the double cone K: a^2 r^2 <= (d - b Z)^2 and the half-space H: b Z <= d
  (the side of the apex plane the profile edge is on): a > 0 gives K & H, a < 0 gives H | ~K.

A conic leaf (a circle) sweeps a torus, a quartic: refused.  A partial ``angle`` intersects
with the wedge 0 <= phi <= angle (two half-spaces through the axis; their union past 180
degrees), measured counter-clockwise from +x as in OpenSCAD.
"""

from __future__ import annotations

import math

import numpy as np

from .construction import Construction, plane, raw, tube
from .csg import Complement, Difference, Intersection, Union
from .profile import Profile, ProfileError


def _leaf(node, color):
    if node.op == "conic":
        raise ProfileError("rotate_extrude() of a circle sweeps a torus, a quartic surface, not a quadric; "
                           "nearest exact alternative: a polygon profile (its edges sweep cones and cylinders), "
                           "or sphere() for a circle centered on the axis")
    a, b, d = node.data
    if abs(a) <= 1e-15:
        return plane((0, 0, b), d, color)
    if abs(b) <= 1e-15:
        if a > 0:  # r <= d / a
            return tube((0, 0, 0), (0, 0, 1), d / a, color) if d > 0 else Union([])
        # r >= d / a: everything when d / a <= 0
        return Complement(tube((0, 0, 0), (0, 0, 1), d / a, color)) if d < 0 else Complement(Union([]))
    m = np.diag([a * a, a * a, -b * b, -d * d])
    m[2, 3] = m[3, 2] = b * d
    cone = raw(m, color)
    half = plane((0, 0, b), d, color)
    return Intersection([cone, half]) if a > 0 else Union([half, Complement(cone)])


def _wedge(angle, color):
    t = math.radians(angle)
    lower = plane((0, -1, 0), 0.0, color)  # y >= 0: phi in [0, 180]
    upper = plane((-math.sin(t), math.cos(t), 0), 0.0, color)  # clockwise of the ray at phi = t
    return Intersection([lower, upper]) if angle <= 180 else Union([lower, upper])


def revolve(profile: Profile, angle=360.0, color=None):
    """The exact solid of revolution of ``profile`` (OpenSCAD's ``rotate_extrude``)."""
    if not isinstance(profile, Profile):
        raise ProfileError(f"revolve needs a 2-D Profile, got {type(profile).__name__}")
    ang = float(angle)
    if not math.isfinite(ang) or ang == 0:
        raise ProfileError(f"revolve angle must be finite and non-zero, got {ang}")
    ang = max(min(ang, 360.0), -360.0)
    spec = None if profile.spec is None else {"revolve": {"profile": profile.spec, "angle": ang}}
    if profile.bbox is None:
        raise ProfileError("rotate_extrude() profile has no bound")
    x0, _, x1, _ = profile.bbox
    if x0 < 0:
        if x1 > 0:
            raise ProfileError("rotate_extrude() profile has points on both sides of the axis x = 0; "
                               "OpenSCAD refuses this too: keep the profile in x >= 0")
        profile = profile.mirror((1, 0))
    body = profile.map(lambda n: _leaf(n, color), Union, Intersection, lambda k: Difference(k), lambda: Union([]))
    if abs(ang) < 360:
        wedge = _wedge(abs(ang), color)
        if ang < 0:
            wedge = wedge.transform(np.diag([1.0, -1.0, 1.0, 1.0]))
        body = Intersection([body, wedge])
    label = f"rotate_extrude of {profile.describe()}" + ("" if abs(ang) == 360 else f" ({ang:g} degrees)")
    x0, y0, x1, y1 = profile.bbox
    return Construction("revolve", label, body, box=((-x1, -x1, y0), (x1, x1, y1)), spec=spec)
