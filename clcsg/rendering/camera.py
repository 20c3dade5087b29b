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

Framing
-------
:meth:`Camera.fit` frames what it is given from a direction: the projection of the points
(samples' positions, or the 8 corners of a bound) spans ``fill`` (90 %) of the frame in its
larger relative extent (width / W or height / H) and is centred.  :meth:`Camera.fit_silhouette`
frames the solid's silhouette itself: it ray traces two small probe images and fits their hit
points, so the default view of ``clcsg render --method raytrace`` is as tight as a view fitted
to samples.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from ..errors import UsageError
from ..cl.device import context_of

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


def _points_and_bound(subject) -> tuple[np.ndarray, np.ndarray]:
    """(points (N, 3), bound (2, 3)) of what :meth:`Camera.fit` frames."""
    pts = getattr(subject, "positions", None)
    if pts is None and not hasattr(subject, "bound"):
        try:
            arr = np.asarray(subject, dtype=np.float64)
        except (TypeError, ValueError):
            arr = None
        if arr is not None and arr.ndim == 2 and arr.shape[1] == 3 and arr.shape[0] != 2:
            pts = arr
    if pts is not None:
        pts = np.asarray(pts, dtype=np.float64).reshape(-1, 3)
        pts = pts[np.all(np.isfinite(pts), axis=1)]
        if len(pts):
            return pts, np.array([pts.min(axis=0), pts.max(axis=0)])
    b = _bound(subject)
    corners = np.array([[b[i][0], b[j][1], b[k][2]] for i in (0, 1) for j in (0, 1) for k in (0, 1)])
    return corners, b


def _framed_eye(points, eye, frame, tans, fill, centered=True, iterations=50) -> np.ndarray:
    """The eye, moved from ``eye`` along the view axes of ``frame`` (its directions are kept),
    at which ``points`` project centred and span ``fill`` of the larger relative extent (with
    ``centered=False`` only along the view axis, keeping every side (1 - fill) / 2 of the frame
    from the border).

    In the frame of the eye a point is (x, y, z) (right, up, forward) and projects to
    (x / z, y / z) (tangent units; the frame's half-width is tan of the half field of view).
    Moving the eye by (dx, dy) sideways and t backwards maps it to (x - dx, y - dy, z + t).
    For the two extreme points of an axis, a and b, centring and spanning fill are two linear
    equations, (x_a - dx) = k (z_a + t) and (x_b - dx) = -k (z_b + t) with k = fill * tan: each
    step solves them for the axis that needs the larger distance, centres the other axis at
    that distance, and repeats while the extreme points change.
    """
    fwd, right, upv = frame.forward, frame.right, frame.up
    eye = np.array(eye, dtype=np.float64)
    m = 0.5 * (1.0 + fill)
    for _ in range(iterations):
        rel = points - eye
        z = rel @ fwd
        if not np.all(z > 0):
            break
        xs, ys = rel @ right, rel @ upv
        axes = []
        for c, tan in ((xs, tans[0]), (ys, tans[1])):
            q = c / z
            a, b = int(np.argmax(q)), int(np.argmin(q))
            k = fill * tan
            if centered:
                t = 0.5 * ((c[a] - c[b]) / k - z[a] - z[b])
                shift = c[a] - k * (z[a] + t)
            else:  # looking at the center: the pair's extent is fill, or a side reaches m
                t = max(_spread_distance(c[a], z[a], c[b], z[b], 2 * k),
                        c[a] / (m * tan) - z[a], -c[b] / (m * tan) - z[b])
                shift = 0.0
            axes.append((t, shift, c, a, b))
        binding = 0 if axes[0][0] >= axes[1][0] else 1
        t, _, _, _, _ = axes[binding]
        t = max(t, 0.05 * float(z.max()) - float(z.min()))  # keep every point well in front
        shifts = []
        for k, (_, shift, c, a, b) in enumerate(axes):
            if centered and k != binding:  # centre the other axis at the chosen distance
                wa, wb = 1.0 / (z[a] + t), 1.0 / (z[b] + t)
                shift = (c[a] * wa + c[b] * wb) / (wa + wb)
            shifts.append(shift if centered else 0.0)
        step = shifts[0] * right + shifts[1] * upv - t * fwd
        eye = eye + step
        if float(np.linalg.norm(step)) <= 1e-12 * max(float(z.max()), 1e-300):
            break
    return eye


def _spread_distance(xa, za, xb, zb, width) -> float:
    """The t with xa / (za + t) - xb / (zb + t) = width (the spread falls as t grows)."""
    lo = max(-za, -zb) + 1e-12 * max(abs(za), abs(zb), 1e-300)
    def spread(t):
        return xa / (za + t) - xb / (zb + t)
    if spread(lo) <= width:
        return lo
    hi = max(abs(za), abs(zb), 1e-300)
    while spread(hi) > width:
        hi *= 2.0
    for _ in range(100):
        mid = 0.5 * (lo + hi)
        if spread(mid) > width:
            lo = mid
        else:
            hi = mid
    return hi


def _pixel_corner_points(camera, image) -> np.ndarray:
    """World points of the corners of every pixel that sees the surface, at its hit depth."""
    d00, dx, dy = camera.pixel_basis()
    i, j = np.nonzero(image.mask)
    depth = image.depth[i, j].astype(np.float64)
    out = []
    for di in (-0.5, 0.5):
        for dj in (-0.5, 0.5):
            d = d00 + (j + dj)[:, None] * dx + (i + di)[:, None] * dy
            d /= np.linalg.norm(d, axis=1, keepdims=True)
            out.append(camera.eye + depth[:, None] * d)
    return np.concatenate(out)


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
    sky: np.ndarray | None = None  # (3,) unit: the ``up`` given to look_at (the world's up, for lighting)

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
        sky = up / nu
        for a in (eye, target, fwd, r, u, sky):
            a.setflags(write=False)
        return cls(eye, target, fwd, r, u, fov, w, h, sky)

    @classmethod
    def fit(cls, subject, width=640, height=480, fov=45.0, direction=DEFAULT_DIRECTION, up=(0, 0, 1),
            fill=0.9, centered=True) -> "Camera":
        """A camera looking from ``direction`` (a vector from the target towards the eye) that
        frames ``subject``: its projection spans ``fill`` of the frame in its larger relative
        extent (width / W or height / H), centred in the image.  ``target`` is the point of the
        view axis at the depth of the subject's center (the center of its box).  With
        ``centered=False`` the camera looks at that center itself and only the distance is
        fitted: the extent spans at most ``fill`` and no side comes closer to the border than
        (1 - fill) / 2 of the frame.

        ``subject``: points ((N, 3), N != 2), anything with ``.positions`` (:class:`Samples`:
        the samples frame the silhouette closely), or a bound ((lo, hi) corners or anything
        with a ``.bound``: a Tape, Dnf, Scene), framed by its 8 corners.  If ``direction`` is
        parallel to ``up``, another up (the y axis, else x) is used.
        """
        points, b = _points_and_bound(subject)
        w, h = _size(width, height)
        fov = _fov(fov)
        direction = _vec3(direction, "direction")
        nd = np.linalg.norm(direction)
        if nd == 0.0:
            raise UsageError("direction must be a non-zero vector")
        direction = direction / nd
        fill = float(fill)
        if not (math.isfinite(fill) and 0.0 < fill <= 1.0):
            raise UsageError(f"fill must be in (0, 1], got {fill}")
        up = _vec3(up, "up")
        if abs(up @ direction) > (1 - 1e-9) * np.linalg.norm(up):
            up = np.array([0.0, 1.0, 0.0]) if abs(direction[1]) < 0.9 else np.array([1.0, 0.0, 0.0])
        center = 0.5 * (b[0] + b[1])
        radius = 0.5 * float(np.linalg.norm(b[1] - b[0]))
        if radius == 0.0:
            radius = max(1e-3 * max(np.abs(center).max(), 1.0), 1e-9)
        half_v = math.radians(fov) / 2
        half_h = math.atan(math.tan(half_v) * w / h)
        eye = center + radius / math.sin(min(half_v, half_h)) * direction  # the bounding sphere in view
        frame = cls.look_at(eye, center, up, fov, w, h)
        eye = _framed_eye(points, eye, frame, (math.tan(half_h), math.tan(half_v)), fill, bool(centered))
        target = eye + ((center - eye) @ frame.forward) * frame.forward
        return cls.look_at(eye, target, up, fov, w, h)

    @classmethod
    def fit_silhouette(cls, scene, width=640, height=480, fov=45.0, direction=DEFAULT_DIRECTION, up=(0, 0, 1),
                       fill=0.9, device=None, probe=64, passes=1) -> "Camera":
        """Like :meth:`fit`, but framing the solid's silhouette: starting from the fit of the
        scene's bound, ray trace a probe image (``probe`` pixels on its longer side) and fit
        the points its pixels see (each pixel's corners at its hit depth); ``passes`` times.
        One pass frames within about one probe pixel.  ``scene``: a Shape, Scene, path, Tape or
        Samples; ``device`` as in :func:`clcsg.raytrace`."""
        from .raytracer import as_tape, trace

        tape = as_tape(scene)
        cam = cls.fit(tape.bound, width, height, fov, direction, up, fill)
        if tape.empty:
            return cam
        ctx = context_of(device)
        pw, ph = (probe, max(1, round(probe * cam.height / cam.width))) if cam.width >= cam.height else \
            (max(1, round(probe * cam.width / cam.height)), probe)
        for _ in range(int(passes)):
            small = cam.resized(pw, ph)
            img = trace(ctx, tape, small)
            if not img.mask.any():
                break
            cam = cls.fit(_pixel_corner_points(small, img), width, height, fov, direction, up, fill)
        return cam

    def resized(self, width, height) -> "Camera":
        """The same view at another image size (the vertical field of view is kept)."""
        return replace(Camera.look_at(self.eye, self.target, self.up, self.fov, width, height), sky=self.sky)

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
    its azimuth, keeping its size and fov unless given) or what :meth:`Camera.fit` frames
    (points, Samples, a bound, Tape, Dnf): all views look at its center from one distance, the
    least at which each view frames it (``Camera.fit(..., centered=False)``); size defaults to
    640x480, fov to 45.
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
    dirs = [ce * (math.cos(2.0 * math.pi * k / n) * a + math.sin(2.0 * math.pi * k / n) * b) + se * up
            for k in range(n)]
    if isinstance(subject, Camera):
        target, dist = subject.target, float(np.linalg.norm(subject.eye - subject.target))
        fov = subject.fov if fov is None else fov
        width = subject.width if width is None else width
        height = subject.height if height is None else height
    else:
        # one circle for all views (a steady turntable): the distance at which every view
        # frames the subject (Camera.fit looking at its center), the largest of them
        width, height, fov = 640 if width is None else width, 480 if height is None else height, \
            45.0 if fov is None else fov
        fits = [Camera.fit(subject, width, height, fov, direction=d, up=up, centered=False) for d in dirs]
        _, box = _points_and_bound(subject)
        target = 0.5 * (box[0] + box[1])
        dist = max(float(np.linalg.norm(c.eye - target)) for c in fits)
    for d in dirs:
        yield Camera.look_at(target + dist * d, target, up, fov, width, height)
