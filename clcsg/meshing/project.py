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


def newton(matrices, x0):
    """(x, converged) after Newton on the quadrics ``matrices`` (N, k, 4, 4) from ``x0``.

    A point leaves the iteration once its step is at the rounding of its coordinates
    (:data:`SETTLED` times its scale) or not finite: the later steps of the fixed
    :data:`ITERATIONS` could not move it further, so only the points still converging (most
    settle within a few steps, quadratic convergence) pay for the rest."""
    x = np.array(x0, dtype=np.float64, copy=True)
    k = matrices.shape[1]
    eye = 1e-300 * np.eye(k)
    live = np.arange(len(x))
    mats, xa = matrices, x
    with np.errstate(all="ignore"):
        for _ in range(ITERATIONS):
            f, j = residuals(mats, xa)
            jjt = np.matmul(j, j.transpose(0, 2, 1)) + eye
            ok = np.abs(np.linalg.det(jjt)) > 0
            lam = np.zeros_like(f)
            if ok.any():
                lam[ok] = np.linalg.solve(jjt[ok], f[ok][..., None])[..., 0]
            step = np.matmul(lam[:, None, :], j)[:, 0]
            moving = np.isfinite(step).all(axis=1)
            xa = np.where(moving[:, None], xa - step, xa)
            x[live] = xa
            moving &= np.abs(step).max(axis=1) > SETTLED * np.maximum(1.0, np.abs(xa).max(axis=1))
            if not moving.all():
                live, mats, xa = live[moving], mats[moving], xa[moving]
                if not len(live):
                    break
        d = first_order_distance(matrices, x)
    scale = np.maximum(1.0, np.abs(x).max(axis=1))
    return x, np.isfinite(d) & (d <= REL * scale) & np.isfinite(x).all(axis=1)
