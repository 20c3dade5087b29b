"""Pinhole cameras: the pixel <-> ray contract shared by the ray tracer, the splat renderer,
the numpy oracle in the tests and every other tool.

Contract
--------
A camera sits at ``eye`` and looks along the unit ``forward`` = (target - eye) / |target - eye|.
``up`` is made orthogonal to ``forward`` (Gram-Schmidt) and ``right`` = forward x up, so that
(right, up, -forward) is a right-handed frame.  ``fov`` is the *vertical* field of view in
degrees; pixels are square.  With

    f = (H / 2) / tan(fov / 2)                       (focal length in pixels)

the pixel in row ``i`` (row 0 at the top) and column ``j`` is the ray from ``eye`` through the
image-plane point ((j + 0.5) / W, (i + 0.5) / H), i.e. with un-normalized direction

    d(i, j) = forward + ((j + 0.5) - W/2) / f * right - ((i + 0.5) - H/2) / f * up
            = d00 + j * dx + i * dy,
    d00 = forward + (0.5 - W/2) / f * right - (0.5 - H/2) / f * up,
    dx = right / f,   dy = -up / f,

and unit direction v = d / |d|.  The kernels evaluate exactly ``d00 + j dx + i dy`` and
normalize, as :meth:`Camera.rays` does.  A world point p projects to continuous pixel
coordinates (x, y) = (W/2 + f (p - eye).right / z, H/2 - f (p - eye).up / z) with
z = (p - eye).forward; pixel (i, j) covers [j, j + 1) x [i, i + 1).

*Depth* everywhere in clcsg is the distance along the unit view ray: depth = |p - eye| for the
hit point p (not the z coordinate).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..errors import UsageError

#: default view direction of :meth:`Camera.fit` (from the target towards the eye): a 3/4 view
#: from the front-right and above, with z up.
DEFAULT_DIRECTION = (0.62, -0.95, 0.55)


def _vec3(v, what) -> np.ndarray:
    try:
        a = np.asarray(v, dtype=np.float64).reshape(-1)
    except (TypeError, ValueError):
        raise UsageError(f"{what} must be 3 numbers, got {v!r}") from None
    if a.shape != (3,):
        raise UsageError(f"{what} must be 3 numbers, got {np.asarray(v).tolist()}")
    if not np.all(np.isfinite(a)):
        raise UsageError(f"{what} must be finite, got {a.tolist()}")
    return a


def _size(width, height) -> tuple[int, int]:
    try:
        w, h = int(width), int(height)
    except (TypeError, ValueError):
        raise UsageError(f"image size must be two positive integers, got {width!r}x{height!r}") from None
    if w != width or h != height or w <= 0 or h <= 0:
        raise UsageError(f"image size must be two positive integers, got {width}x{height}")
    if w * h > 1 << 28:
        raise UsageError(f"image size {w}x{h} is too large (at most 2^28 pixels)")
    return w, h


def _fov(fov) -> float:
    try:
        f = float(fov)
    except (TypeError, ValueError):
        raise UsageError(f"fov must be a number of degrees in (0, 180), got {fov!r}") from None
    if not (math.isfinite(f) and 0.0 < f < 180.0):
        raise UsageError(f"fov must be a number of degrees in (0, 180), got {fov}")
    return f


def _bound(subject) -> np.ndarray:
    """A (2, 3) bound from an array-like or from an object with ``.bound`` (Dnf, Scene)."""
    b = getattr(subject, "bound", subject)
    if b is None and hasattr(subject, "normalize"):
        b = subject.normalize().bound
    try:
        b = np.asarray(b, dtype=np.float64)
    except (TypeError, ValueError):
        raise UsageError(f"a bound is two corners (lo, hi), got {subject!r}") from None
    if b.shape != (2, 3) or not np.all(np.isfinite(b)) or np.any(b[1] < b[0]):
        raise UsageError(f"a bound is two finite corners lo <= hi, got {b.tolist()}")
    return b


@dataclass(frozen=True)
class Camera:
    """A pinhole camera (see the module docstring for the pixel/ray contract).

    Build one with :meth:`look_at` or :meth:`fit`; the fields are derived and validated there.
    """

    eye: np.ndarray  # (3,)
    target: np.ndarray  # (3,)
    forward: np.ndarray  # (3,) unit
    right: np.ndarray  # (3,) unit
    up: np.ndarray  # (3,) unit, orthogonal to forward
    fov: float  # vertical, degrees
    width: int
    height: int

    # -- construction -------------------------------------------------------------------------
    @classmethod
    def look_at(cls, eye, target, up=(0, 0, 1), fov=45.0, width=640, height=480) -> "Camera":
        """A pinhole at ``eye`` looking at ``target``; ``up`` is made orthogonal to the view
        direction; ``fov`` is the vertical field of view in degrees."""
        eye = _vec3(eye, "eye")
        target = _vec3(target, "target")
        up = _vec3(up, "up")
        w, h = _size(width, height)
        fov = _fov(fov)
        d = target - eye
        dist = np.linalg.norm(d)
        scale = max(np.abs(eye).max(), np.abs(target).max(), 1e-300)
        if not dist > 1e-12 * scale:
            raise UsageError(f"eye and target must differ, both are {eye.tolist()}")
        fwd = d / dist
        nu = np.linalg.norm(up)
        if nu == 0.0:
            raise UsageError("up must be a non-zero vector")
        u = up - (up @ fwd) * fwd
        nrm = np.linalg.norm(u)
        if not nrm > 1e-9 * nu:
            raise UsageError(f"up {up.tolist()} is parallel to the view direction {fwd.tolist()}")
        u = u / nrm
        r = np.cross(fwd, u)
        r /= np.linalg.norm(r)
        u = np.cross(r, fwd)  # exactly orthonormal
        for a in (eye, target, fwd, r, u):
            a.setflags(write=False)
        return cls(eye, target, fwd, r, u, fov, w, h)

    @classmethod
    def fit(cls, bound, width=640, height=480, fov=45.0, direction=DEFAULT_DIRECTION, up=(0, 0, 1),
            margin=1.05) -> "Camera":
        """A camera looking at the center of ``bound`` from ``direction`` (a vector from the
        target towards the eye), far enough that the bound's circumscribed sphere (radius R)
        is inside the view: distance = margin * R / sin(min(fov_v, fov_h) / 2).

        ``bound`` is (lo, hi) corners or anything with a ``.bound`` (a Dnf, Samples' dnf).  If
        ``direction`` is parallel to ``up``, another up (the y axis, else x) is used.
        """
        b = _bound(bound)
        w, h = _size(width, height)
        fov = _fov(fov)
        direction = _vec3(direction, "direction")
        nd = np.linalg.norm(direction)
        if nd == 0.0:
            raise UsageError("direction must be a non-zero vector")
        direction = direction / nd
        center = 0.5 * (b[0] + b[1])
        radius = 0.5 * float(np.linalg.norm(b[1] - b[0]))
        if radius == 0.0:
            radius = max(1e-3 * max(np.abs(center).max(), 1.0), 1e-9)
        half_v = math.radians(fov) / 2
        half_h = math.atan(math.tan(half_v) * w / h)
        dist = float(margin) * radius / math.sin(min(half_v, half_h))
        up = _vec3(up, "up")
        if abs(up @ direction) > (1 - 1e-9) * np.linalg.norm(up):
            up = np.array([0.0, 1.0, 0.0]) if abs(direction[1]) < 0.9 else np.array([1.0, 0.0, 0.0])
        return cls.look_at(center + dist * direction, center, up, fov, w, h)

    def resized(self, width, height) -> "Camera":
        """The same view at another image size (the vertical field of view is kept)."""
        return Camera.look_at(self.eye, self.target, self.up, self.fov, width, height)

    # -- the pixel / ray contract -------------------------------------------------------------
    @property
    def focal(self) -> float:
        """f = (H / 2) / tan(fov / 2): focal length in pixels."""
        return 0.5 * self.height / math.tan(math.radians(self.fov) / 2)

    def pixel_basis(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(d00, dx, dy): the un-normalized direction of pixel (i, j) is d00 + j dx + i dy."""
        f = self.focal
        dx = self.right / f
        dy = -self.up / f
        d00 = self.forward + (0.5 - 0.5 * self.width) * dx + (0.5 - 0.5 * self.height) * dy
        return d00, dx, dy

    def rays(self) -> tuple[np.ndarray, np.ndarray]:
        """(origins (H, W, 3), unit directions (H, W, 3)) float64, row 0 at the top."""
        d00, dx, dy = self.pixel_basis()
        i = np.arange(self.height, dtype=np.float64)[:, None, None]
        j = np.arange(self.width, dtype=np.float64)[None, :, None]
        d = d00 + j * dx + i * dy
        d = d / np.linalg.norm(d, axis=-1, keepdims=True)
        o = np.broadcast_to(self.eye, d.shape).copy()
        return o, d

    def project(self, points) -> tuple[np.ndarray, np.ndarray]:
        """(xy (..., 2) continuous pixel coordinates (column, row), z (...) distance along
        ``forward``); pixel (i, j) covers x in [j, j + 1), y in [i, i + 1).  Points with
        z <= 0 are behind the eye and get NaN coordinates."""
        p = np.asarray(points, dtype=np.float64) - self.eye
        z = p @ self.forward
        f = self.focal
        with np.errstate(divide="ignore", invalid="ignore"):
            x = 0.5 * self.width + f * (p @ self.right) / z
            y = 0.5 * self.height - f * (p @ self.up) / z
        bad = ~(z > 0)
        x = np.where(bad, np.nan, x)
        y = np.where(bad, np.nan, y)
        return np.stack([x, y], axis=-1), z

    def pixel_of(self, point) -> tuple[int, int]:
        """(row, column) of the pixel whose area the projection of ``point`` falls in."""
        xy, z = self.project(np.asarray(point, dtype=np.float64).reshape(3))
        if not z > 0:
            raise UsageError(f"point {np.asarray(point).tolist()} is behind the camera")
        return int(math.floor(xy[1])), int(math.floor(xy[0]))

    def __repr__(self) -> str:
        e = ", ".join(f"{v:.6g}" for v in self.eye)
        t = ", ".join(f"{v:.6g}" for v in self.target)
        return f"Camera(eye=({e}), target=({t}), fov={self.fov:g}, {self.width}x{self.height})"


def orbit(subject, n=8, elevation=25.0, width=None, height=None, fov=None, up=(0, 0, 1)):
    """Yield ``n`` cameras on a circle around the scene, ``elevation`` degrees above the plane
    orthogonal to ``up``, equally spaced in azimuth.

    ``subject`` is a :class:`Camera` (orbit around its target at its distance, starting from
    its azimuth, keeping its size and fov unless given) or a bound / Dnf (each view fitted like
    :meth:`Camera.fit`; size defaults to 640x480, fov to 45).
    """
    try:
        n = int(n)
    except (TypeError, ValueError):
        raise UsageError(f"orbit needs a positive number of views, got {n!r}") from None
    if n <= 0:
        raise UsageError(f"orbit needs a positive number of views, got {n}")
    el = float(elevation)
    if not (math.isfinite(el) and -90.0 < el < 90.0):
        raise UsageError(f"elevation must be in (-90, 90) degrees, got {elevation}")
    up = _vec3(up, "up")
    if np.linalg.norm(up) == 0.0:
        raise UsageError("up must be a non-zero vector")
    up = up / np.linalg.norm(up)
    # an orthonormal frame (a, b, up) of the orbit plane
    if isinstance(subject, Camera):
        start = subject.eye - subject.target
        start = start - (start @ up) * up
        if np.linalg.norm(start) < 1e-12 * max(np.linalg.norm(subject.eye - subject.target), 1e-300):
            start = subject.right
    else:
        start = np.array(DEFAULT_DIRECTION, dtype=np.float64)
        start = start - (start @ up) * up
        if np.linalg.norm(start) == 0.0:
            start = np.array([1.0, 0.0, 0.0]) - up[0] * up
    a = start / np.linalg.norm(start)
    b = np.cross(up, a)
    ce, se = math.cos(math.radians(el)), math.sin(math.radians(el))
    for k in range(n):
        phi = 2.0 * math.pi * k / n
        d = ce * (math.cos(phi) * a + math.sin(phi) * b) + se * up
        if isinstance(subject, Camera):
            dist = float(np.linalg.norm(subject.eye - subject.target))
            yield Camera.look_at(
                subject.target + dist * d, subject.target, up,
                subject.fov if fov is None else fov,
                subject.width if width is None else width,
                subject.height if height is None else height,
            )
        else:
            yield Camera.fit(subject, 640 if width is None else width, 480 if height is None else height,
                             45.0 if fov is None else fov, direction=d, up=up)
