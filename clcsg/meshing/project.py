"""Points onto one, two or three quadrics at once, by Newton's method in float64.

For k quadrics K_1..K_k (k <= 3) the residual is F_i(x) = x^T K_i x (homogeneous x) and the
Jacobian rows are grad K_i = 2 (K_i x)[:3].  The step is the minimum-norm solution of
J dx = -F, dx = -J^T (J J^T)^-1 F: for k = 1 the step along the gradient, for k = 2 onto the
intersection curve (the closest point to first order), for k = 3 the corner.  Convergence is
quadratic near a transversal intersection; a point counts as converged when every
first-order distance |F_i| / |grad K_i| is below ``rel`` times the point's scale.
"""

from __future__ import annotations

import numpy as np

#: Newton iterations
ITERATIONS = 40
#: converged: first-order distances below this times max(1, |x|)
REL = 1e-12
#: settled: a step below this times max(1, |x|) (a few units in the last place)
SETTLED = 4 * np.finfo(np.float64).eps
#: a point whose residuals are below this many units of rounding of the form is on its quadrics
ON_ULPS = 16
#: a step below this times max(1, |x|) that is no smaller than the one before is rounding noise
NOISE = 1e-9


def residuals(matrices, x):
    """(F (N, k), J (N, k, 3)) of the quadrics ``matrices`` (N, k, 4, 4) at ``x`` (N, 3)."""
    xh = np.concatenate([x, np.ones((len(x), 1))], axis=1)
    kx = np.matmul(matrices, xh[:, None, :, None])[..., 0]  # (N, k, 4)
    return (kx * xh[:, None, :]).sum(axis=2), 2.0 * kx[..., :3]


def first_order_distance(matrices, x) -> np.ndarray:
    """max_i |K_i(x)| / |grad K_i(x)| (N,): the distance to the intersection, to first order."""
    f, j = residuals(matrices, x)
    g = np.linalg.norm(j, axis=2)
    with np.errstate(divide="ignore", invalid="ignore"):
        d = np.where(g > 0, np.abs(f) / g, np.where(f == 0, 0.0, np.inf))
    return d.max(axis=1)


def line_distance(matrices, x) -> np.ndarray:
    """max_i of the distance from ``x`` (N, 3) along the gradient line of K_i to where the line
    meets K_i (N,): the root of K(x + t n) = K(x) + t |grad K| + t^2 n^T A n nearest to 0
    (n = grad K / |grad K|, A = K[:3, :3]; exact for a quadric), taken as
    2 |K(x)| / (|grad K| + sqrt(|grad K|^2 - 4 K(x) n^T A n)).  The line's point lies on the
    quadric, so this bounds the distance from above; it is the distance itself for a sphere or
    a cylinder (their gradient lines are normals), where the first-order |K| / |grad K|
    overstates a chord's sag by about s / 2R.  First order where the line misses the quadric."""
    t, _ = line_steps(matrices, x)
    return np.abs(t).max(axis=1)


def line_steps(matrices, x):
    """(t (N, k), n (N, k, 3)): per point of ``x`` and quadric K_i of ``matrices`` (N, k, 4, 4)
    the signed step t along the unit gradient n to K_i (:func:`line_distance`'s root; x + t n
    lies on K_i).  Infinite where the gradient vanishes off the quadric."""
    f, j = residuals(matrices, x)
    g = np.linalg.norm(j, axis=2)
    with np.errstate(divide="ignore", invalid="ignore"):
        n = j / g[..., None]
        bend = np.einsum("nki,nkij,nkj->nk", n, matrices[..., :3, :3], n)
        disc = g * g - 4.0 * f * bend
        d = np.where(disc >= 0, 2.0 * np.abs(f) / (g + np.sqrt(np.maximum(disc, 0.0))), np.abs(f) / g)
        d = np.where(g > 0, d, np.where(f == 0, 0.0, np.inf))
    return -np.sign(f) * d, np.nan_to_num(n)


def min_norm_step(f, j):
    """J^T (J J^T)^-1 F per row (F (N, k), J (N, k, 3), k <= 3) in closed form: for one row of
    J the step along it; for two the 2 x 2 inverse of J J^T; for three J^-1 F by the rows'
    cross products (Cramer).  Not finite where J J^T is singular."""
    k = j.shape[1]
    if k == 1:
        g = j[:, 0]
        return g * (f[:, 0] / np.einsum("ni,ni->n", g, g))[:, None]
    if k == 2:
        a, b = j[:, 0], j[:, 1]
        aa, ab, bb = (np.einsum("ni,ni->n", u, v) for u, v in ((a, a), (a, b), (b, b)))
        det = aa * bb - ab * ab
        la, lb = (bb * f[:, 0] - ab * f[:, 1]) / det, (aa * f[:, 1] - ab * f[:, 0]) / det
        return la[:, None] * a + lb[:, None] * b
    c0, c1, c2 = np.cross(j[:, 1], j[:, 2]), np.cross(j[:, 2], j[:, 0]), np.cross(j[:, 0], j[:, 1])
    det = np.einsum("ni,ni->n", j[:, 0], c0)
    return (f[:, 0, None] * c0 + f[:, 1, None] * c1 + f[:, 2, None] * c2) / det[:, None]


def newton(matrices, x0, reach=None):
    """(x, converged) after Newton on the quadrics ``matrices`` (N, k, 4, 4) from ``x0``.

    A point already on its quadrics to rounding (:func:`on_all`) does not move.  A point
    leaves the iteration once its step is at the rounding of its coordinates
    (:data:`SETTLED` times its scale), stops shrinking while below :data:`NOISE` times its
    scale (rounding noise of an ill-conditioned intersection), is not finite, or (with
    ``reach``) has gone farther than ``reach`` from its start (not converged: quadrics with no
    common point near it): the later steps of the fixed :data:`ITERATIONS` could not move it
    usefully, so only the points still converging (most settle within a few steps, quadratic
    convergence) pay for the rest."""
    x = np.array(x0, dtype=np.float64, copy=True)
    start = np.array(x0, dtype=np.float64)
    lost = np.zeros(len(x), dtype=bool)
    on = on_all(matrices, x)
    live = np.flatnonzero(~on)
    mats, xa, prev = matrices[live], x[live], np.full(len(live), np.inf)
    with np.errstate(all="ignore"):
        for _ in range(ITERATIONS if len(live) else 0):
            f, j = residuals(mats, xa)
            step = min_norm_step(f, j)
            moving = np.isfinite(step).all(axis=1)
            xa = np.where(moving[:, None], xa - step, xa)
            x[live] = xa
            scale = np.maximum(1.0, np.abs(xa).max(axis=1))
            size = np.abs(step).max(axis=1)
            moving &= (size > SETTLED * scale) & ~((size >= prev) & (size < NOISE * scale))
            if reach is not None:
                away = np.linalg.norm(xa - start[live], axis=1) > reach
                lost[live[away]] = True
                moving &= ~away
            prev = size
            if not moving.all():
                live, mats, xa, prev = live[moving], mats[moving], xa[moving], prev[moving]
                if not len(live):
                    break
        d = first_order_distance(matrices, x)
    scale = np.maximum(1.0, np.abs(x).max(axis=1))
    return x, ((np.isfinite(d) & (d <= REL * scale)) | on) & np.isfinite(x).all(axis=1) & ~lost


def on_all(matrices, x) -> np.ndarray:
    """Per point whether every K_i(x) is zero to rounding, |K_i(x)| <= :data:`ON_ULPS` eps
    max|K_i| (1 + |x|)^2: on the quadrics already, where a step could only do harm (at a
    cone's apex the gradient vanishes too, and |F| / |grad F| is rounding over rounding)."""
    f, _ = residuals(matrices, x)
    size = np.abs(matrices).max(axis=(2, 3))
    reach = (1.0 + np.abs(x).max(axis=1)) ** 2
    return np.all(np.abs(f) <= ON_ULPS * np.finfo(np.float64).eps * size * reach[:, None], axis=1)
