"""Quadric surfaces in float64 numpy: the reference every kernel is tested against.

A quadric is a symmetric 4x4 matrix (paper eq. 2)

    Q = [[A, -b], [-b^T, c]],   Q(x) = x^T A x - 2 b^T x + c   (eq. 1, 3)

and its solid is the *inside* ``{x : Q(x) <= 0}``.  All point arguments are arrays of shape
(..., 3) and every operation is vectorized over the leading axes.
"""

from __future__ import annotations

import math

import numpy as np

from ..errors import ParameterError, TransformError

#: Order of the 10 unique coefficients of the symmetric matrix (upper triangle, row-major).
#: The kernels use the same order (``clcsg/cl/include/layout.h``).
COEFFICIENT_INDEX = ((0, 0), (0, 1), (0, 2), (0, 3), (1, 1), (1, 2), (1, 3), (2, 2), (2, 3), (3, 3))

#: Coefficients smaller than this (relative to the unit-norm matrix) are rounding noise.
_ZERO = 1e-13


def _as_points(x) -> np.ndarray:
    x = np.asarray(x, dtype=np.float64)
    if x.shape[-1] != 3:
        raise ParameterError(f"points must have shape (..., 3), got {x.shape}")
    return x


def _unit(v, what="axis") -> np.ndarray:
    v = np.asarray(v, dtype=np.float64).reshape(3)
    n = np.linalg.norm(v)
    if not np.isfinite(n) or n == 0.0:
        raise ParameterError(f"{what} must be a finite non-zero 3-vector, got {v.tolist()}")
    return v / n


def frame_z_to(axis) -> np.ndarray:
    """The rotation R (3x3) taking (0, 0, 1) to the unit ``axis`` by the shortest arc, so
    that the local x and y axes stay as close to the world's as possible (identity for +z)."""
    w = _unit(axis)
    z = np.array([0.0, 0.0, 1.0])
    c = float(w @ z)
    if c > 1.0 - 1e-15:
        return np.eye(3)
    if c < -1.0 + 1e-15:
        return np.diag([1.0, -1.0, -1.0])  # half turn about x
    k = np.cross(z, w)
    s = np.linalg.norm(k)
    k /= s
    K = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) + s * K + (1 - c) * (K @ K)


def affine(linear=None, translation=None) -> np.ndarray:
    """The 4x4 matrix of x -> linear @ x + translation."""
    m = np.eye(4)
    if linear is not None:
        m[:3, :3] = linear
    if translation is not None:
        m[:3, 3] = translation
    return m


def check_affine(m) -> np.ndarray:
    """Validate a 4x4 affine transform; raise :class:`TransformError` naming the problem."""
    m = np.asarray(m, dtype=np.float64)
    if m.shape == (3, 4):
        m = np.vstack([m, [0.0, 0.0, 0.0, 1.0]])
    if m.shape != (4, 4):
        raise TransformError(f"transform must be a 4x4 (or 3x4) matrix, got shape {m.shape}")
    if not np.all(np.isfinite(m)):
        raise TransformError("transform has NaN or infinite entries")
    scale = max(np.abs(m).max(), 1.0)
    if np.abs(m[3] - [0.0, 0.0, 0.0, 1.0]).max() > 1e-12 * scale:
        raise TransformError(f"transform is not affine: last row is {m[3].tolist()}, must be [0, 0, 0, 1]")
    lin = m[:3, :3]
    norm = np.abs(lin).max()
    det = np.linalg.det(lin)
    if norm == 0.0 or abs(det) <= 1e-12 * norm**3:
        raise TransformError(f"transform is singular (determinant {det:.3g})")
    return m



def ray_distance(f, g, lam_min, lam_max):
    """Conservative signed distance from Q's value ``f``, gradient norm ``g`` = 2 |A x - b| and
    the extreme eigenvalues of A at a point (eqs. 10, 11; arrays broadcast): inside (f < 0)
    -t+ with t+ the smallest positive root of f + g t + lam_max t^2, outside t- with t- the
    smallest positive root of f - g t + lam_min t^2, both as 2|f| / (g + sqrt(disc)), the small
    root without cancellation; no real root gives +-inf (no surface on any ray)."""
    inside = f < 0.0
    lam = np.where(inside, lam_max, -lam_min)
    af = np.abs(f)
    disc = g * g + 4.0 * lam * af
    with np.errstate(invalid="ignore", divide="ignore"):
        t = np.where(disc >= 0.0, 2.0 * af / (g + np.sqrt(np.maximum(disc, 0.0))), np.inf)
    t = np.where(af == 0.0, 0.0, t)
    return np.where(inside, -t, t)

class Quadric:
    """A quadric surface ``x^T Q x = 0`` with solid ``Q(x) <= 0``.

    Construct with the named constructors (``Quadric.sphere(...)`` etc.) or from a raw symmetric
    matrix.  Instances are immutable.
    """

    __slots__ = ("matrix",)

    def __init__(self, matrix):
        m = np.array(matrix, dtype=np.float64)
        if m.shape != (4, 4):
            raise ParameterError(f"a quadric is a 4x4 matrix, got shape {m.shape}")
        if not np.all(np.isfinite(m)):
            raise ParameterError("quadric matrix has NaN or infinite entries")
        m = 0.5 * (m + m.T)
        m.setflags(write=False)
        self.matrix = m

    # -- parts --------------------------------------------------------------------------------
    @property
    def A(self) -> np.ndarray:
        return self.matrix[:3, :3]

    @property
    def b(self) -> np.ndarray:
        return -self.matrix[:3, 3]

    @property
    def c(self) -> float:
        return float(self.matrix[3, 3])

    def coefficients(self) -> np.ndarray:
        """The 10 unique coefficients in :data:`COEFFICIENT_INDEX` order."""
        return np.array([self.matrix[i, j] for i, j in COEFFICIENT_INDEX])

    @classmethod
    def from_coefficients(cls, coef) -> "Quadric":
        coef = np.asarray(coef, dtype=np.float64).reshape(10)
        m = np.zeros((4, 4))
        for k, (i, j) in enumerate(COEFFICIENT_INDEX):
            m[i, j] = m[j, i] = coef[k]
        return cls(m)

    def __repr__(self) -> str:
        return f"Quadric({np.array2string(self.coefficients(), precision=6)})"

    def __eq__(self, other) -> bool:
        return isinstance(other, Quadric) and np.array_equal(self.matrix, other.matrix)

    def __hash__(self) -> int:
        return hash(self.matrix.tobytes())

    # -- evaluation (eq. 3, 4) ----------------------------------------------------------------
    def value(self, x) -> np.ndarray:
        """Q(x) = x^T A x - 2 b^T x + c."""
        x = _as_points(x)
        return np.einsum("...i,ij,...j->...", x, self.A, x) - 2.0 * x @ self.b + self.c

    def gradient(self, x) -> np.ndarray:
        """grad Q(x) = 2 (A x - b)  (eq. 4)."""
        x = _as_points(x)
        return 2.0 * (x @ self.A - self.b)

    def normal(self, x) -> np.ndarray:
        """Unit normal N(x) = grad Q / |grad Q|, pointing out of the solid (eq. 4)."""
        g = self.gradient(x)
        n = np.linalg.norm(g, axis=-1, keepdims=True)
        with np.errstate(invalid="ignore", divide="ignore"):
            return g / n

    def eigenvalue_range(self) -> tuple[float, float]:
        """(min lambda, max lambda) of A, used by the conservative distance (eqs. 10, 11)."""
        lam = np.linalg.eigvalsh(self.A)
        return float(lam[0]), float(lam[-1])

    # -- line intersection (eq. 5, 6) ---------------------------------------------------------
    def intersect_line(self, p, v) -> tuple[np.ndarray, np.ndarray]:
        """Parameters t1 <= t2 with Q(p + t v) = 0; NaN where a root does not exist.

        Q(p + t v) = a t^2 + 2 h t + c with a = v^T A v, h = v^T (A p - b), c = Q(p).  The
        roots are taken as q / a and c / q with q = -(h + sign(h) sqrt(h^2 - a c)): no
        cancellation between h and the square root, and for a -> 0 (a direction along which
        the quadric is degenerate) c / q tends to the single root of eq. 6 while q / a leaves
        to infinity and is reported as NaN.  A line lying on the surface has no isolated root.
        """
        p = _as_points(p)
        v = _as_points(v)
        # Solve from the point of the line closest to the quadric's center instead of from p:
        # with p far away, c = Q(p) and h^2 would be huge and cancel in h^2 - a c.
        vv = np.einsum("...i,...i->...", v, v)
        t0 = np.einsum("...i,...i->...", self.center - p, v) / np.where(vv > 0, vv, 1.0)
        lo, hi = self._intersect_from(p + t0[..., None] * v, v)
        return lo + t0, hi + t0

    @property
    def center(self) -> np.ndarray:
        """Min-norm least-squares solution q of A q = b (the center of a central quadric)."""
        return np.linalg.lstsq(self.A, self.b, rcond=1e-12)[0]

    def _intersect_from(self, p, v):
        a = np.einsum("...i,ij,...j->...", v, self.A, v)
        h = np.einsum("...i,...i->...", v, p @ self.A - self.b)
        c = self.value(p)
        a, h, c = np.broadcast_arrays(a, h, c)
        disc = h * h - a * c
        with np.errstate(invalid="ignore", divide="ignore", over="ignore"):
            sq = np.sqrt(np.where(disc >= 0.0, disc, np.nan))
            q = -(h + np.where(h >= 0.0, sq, -sq))
            r1 = np.where(a != 0.0, q / a, np.nan)
            r2 = np.where(q != 0.0, c / q, np.nan)
        r1 = np.where(np.isfinite(r1), r1, np.nan)
        r2 = np.where(np.isfinite(r2), r2, np.nan)
        # c == 0 and h == 0: q == 0 and r1 == 0 is the (double) root at p
        lo = np.fmin(r1, r2)
        hi = np.fmax(r1, r2)
        one = np.isnan(r1) ^ np.isnan(r2)
        lo = np.where(one, np.where(np.isnan(r1), r2, r1), lo)
        hi = np.where(one, np.nan, hi)
        return lo, hi

    # -- conservative signed distance (eqs. 8-12) -------------------------------------------
    def distance(self, x) -> np.ndarray:
        """Conservative signed distance d(x): |d| never exceeds the distance to the surface.

        With f = Q(x0), g = 2 |A x0 - b| and the extreme eigenvalues of A, eqs. 10 and 11
        bound Q along every unit ray x0 + t v.  Inside (f < 0) d = -t+ with t+ the smallest
        positive root of f + g t + lambda_max t^2; outside d = t- with t- the smallest positive
        root of f - g t + lambda_min t^2.  Both are computed as 2|f| / (g + sqrt(disc)), which
        is the small root without cancellation; no real root means no surface on any ray:
        d = +-inf.
        """
        x = _as_points(x)
        lam_min, lam_max = self.eigenvalue_range()
        f = self.value(x)
        g = 2.0 * np.linalg.norm(x @ self.A - self.b, axis=-1)
        return ray_distance(f, g, lam_min, lam_max)

    # -- algebra ------------------------------------------------------------------------------
    def complement(self) -> "Quadric":
        """The quadric whose solid is the closure of the outside: -Q."""
        return Quadric(-self.matrix)

    def transform(self, m) -> "Quadric":
        """Q' = M^-T Q M^-1 (eq. 17), so that Q'(M x) = Q(x)."""
        m = check_affine(m)
        inv = np.linalg.inv(m)
        return Quadric(inv.T @ self.matrix @ inv)

    def canonical(self) -> tuple["Quadric", int]:
        """(K, s) with Q = s * |Q| * K: K of unit Frobenius norm, first non-zero coefficient
        of K positive, s in {+1, -1}.  Coincident surfaces get the same K whatever their
        orientation; the orientation moves into the sign s (the literal's polarity)."""
        m = self.matrix
        norm = np.linalg.norm(m)
        if norm == 0.0:
            raise ParameterError("the zero matrix is not a quadric")
        k = m / norm
        k = np.where(np.abs(k) < _ZERO, 0.0, k)
        coef = [k[i, j] for i, j in COEFFICIENT_INDEX]
        first = next(c for c in coef if c != 0.0)
        s = 1 if first > 0 else -1
        return Quadric(s * k), s

    # -- constructors -------------------------------------------------------------------------
    @classmethod
    def half_space(cls, normal, offset=0.0) -> "Quadric":
        """Solid n . x <= offset (n is normalized first, offset scaled with it)."""
        n_raw = np.asarray(normal, dtype=np.float64).reshape(3)
        length = np.linalg.norm(n_raw)
        n = _unit(n_raw, "half-space normal")
        m = np.zeros((4, 4))
        m[:3, 3] = m[3, :3] = 0.5 * n
        m[3, 3] = -float(offset) / length
        return cls(m)

    @classmethod
    def slab(cls, normal, lo, hi) -> "Quadric":
        """Solid lo <= n . x <= hi for unit n: Q = (n.x - lo)(n.x - hi), two parallel planes."""
        n = _unit(normal, "slab normal")
        lo, hi = float(lo), float(hi)
        if not hi > lo:
            raise ParameterError(f"slab needs lo < hi, got {lo}, {hi}")
        m = np.zeros((4, 4))
        m[:3, :3] = np.outer(n, n)
        m[:3, 3] = m[3, :3] = -0.5 * (lo + hi) * n
        m[3, 3] = lo * hi
        return cls(m)

    @classmethod
    def _local(cls, diag, linear_z=0.0, const=0.0, center=(0, 0, 0), axis=(0, 0, 1)) -> "Quadric":
        """sum diag_i z_i^2 + linear_z z_3 + const in a frame whose z axis is ``axis``."""
        m = np.zeros((4, 4))
        m[:3, :3] = np.diag(np.asarray(diag, dtype=np.float64))
        m[2, 3] = m[3, 2] = 0.5 * linear_z
        m[3, 3] = const
        return cls(m).transform(affine(frame_z_to(axis), np.asarray(center, dtype=np.float64)))

    @classmethod
    def sphere(cls, center=(0, 0, 0), radius=1.0) -> "Quadric":
        r = _positive(radius, "sphere radius")
        return cls._local((1, 1, 1), const=-r * r, center=center)

    @classmethod
    def ellipsoid(cls, center=(0, 0, 0), radii=(1, 1, 1), rotation=None) -> "Quadric":
        """Semi-axes ``radii`` along the columns of ``rotation`` (identity by default)."""
        r = [_positive(v, "ellipsoid radius") for v in np.asarray(radii, dtype=float).reshape(3)]
        q = cls._local([1 / v**2 for v in r], const=-1.0)
        rot = np.eye(3) if rotation is None else np.asarray(rotation, dtype=np.float64)
        return q.transform(affine(rot, np.asarray(center, dtype=np.float64)))

    @classmethod
    def cylinder(cls, axis=(0, 0, 1), radius=1.0, center=(0, 0, 0)) -> "Quadric":
        """Infinite circular cylinder through ``center`` along ``axis``."""
        r = _positive(radius, "cylinder radius")
        return cls._local((1, 1, 0), const=-r * r, center=center, axis=axis)

    @classmethod
    def elliptic_cylinder(cls, axis=(0, 0, 1), radii=(1.0, 0.5), center=(0, 0, 0)) -> "Quadric":
        a, b = (_positive(v, "cylinder radius") for v in radii)
        return cls._local((1 / a**2, 1 / b**2, 0), const=-1.0, center=center, axis=axis)

    @classmethod
    def cone(cls, apex=(0, 0, 0), axis=(0, 0, 1), slope=1.0) -> "Quadric":
        """Infinite double cone x^2 + y^2 <= (slope z)^2 around ``axis`` (slope = tan of the
        half-angle)."""
        k = _positive(slope, "cone slope")
        return cls._local((1, 1, -k * k), center=apex, axis=axis)

    @classmethod
    def elliptic_paraboloid(cls, apex=(0, 0, 0), axis=(0, 0, 1), radii=(1.0, 1.0)) -> "Quadric":
        """x^2/a^2 + y^2/b^2 <= z: opens towards +axis."""
        a, b = (_positive(v, "paraboloid radius") for v in radii)
        return cls._local((1 / a**2, 1 / b**2, 0), linear_z=-1.0, center=apex, axis=axis)

    @classmethod
    def hyperbolic_paraboloid(cls, center=(0, 0, 0), axis=(0, 0, 1), radii=(1.0, 1.0)) -> "Quadric":
        """x^2/a^2 - y^2/b^2 <= z (a saddle)."""
        a, b = (_positive(v, "paraboloid radius") for v in radii)
        return cls._local((1 / a**2, -1 / b**2, 0), linear_z=-1.0, center=center, axis=axis)

    @classmethod
    def hyperboloid_one_sheet(cls, center=(0, 0, 0), axis=(0, 0, 1), radii=(1, 1, 1)) -> "Quadric":
        """x^2/a^2 + y^2/b^2 - z^2/c^2 <= 1 (waist radii a, b)."""
        a, b, c = (_positive(v, "hyperboloid radius") for v in radii)
        return cls._local((1 / a**2, 1 / b**2, -1 / c**2), const=-1.0, center=center, axis=axis)

    @classmethod
    def hyperboloid_two_sheets(cls, center=(0, 0, 0), axis=(0, 0, 1), radii=(1, 1, 1)) -> "Quadric":
        """x^2/a^2 + y^2/b^2 - z^2/c^2 <= -1: the inside of both sheets (vertices at z = +-c)."""
        a, b, c = (_positive(v, "hyperboloid radius") for v in radii)
        return cls._local((1 / a**2, 1 / b**2, -1 / c**2), const=1.0, center=center, axis=axis)


def _positive(v, what) -> float:
    v = float(v)
    if not (math.isfinite(v) and v > 0.0):
        raise ParameterError(f"{what} must be a positive finite number, got {v}")
    return v


