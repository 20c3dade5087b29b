"""Quadric analysis in float64: principal frame and the heightfields of the sampling planes.

Paper section 3.2 with the degenerate cases it skips.  Write
A = U diag(lambda) U^T (eigh) and take the center q as the min-norm least-squares solution of
A q = b (pseudo-inverse; eigenvalues with |lambda| <= 1e-12 max|lambda| count as zero).  In
local coordinates z = U^T (x - q):

    Q = sum_m (lambda_m z_m^2 + 2 beta_m z_m) + gamma,
    beta = U^T (A q - b),   gamma = q^T A q - 2 b^T q + c.

beta_m vanishes wherever lambda_m != 0.  For the sampling plane whose normal is axis k with
in-plane coordinates (x, y) = (z_i, z_j) and height t = z_k:

    lambda_k t^2 + 2 beta_k t + R(x, y) = 0,   R = lambda_i x^2 + 2 beta_i x + lambda_j y^2 + 2 beta_j y + gamma

* lambda_k != 0: two sheets t = +-sqrt(-R / lambda_k) (eq. 7);
* lambda_k == 0, beta_k != 0: one sheet t = -R / (2 beta_k) (paraboloid along its axis, eq. 6;
  a plane, A = 0, has U chosen so that u_k is parallel to b);
* lambda_k == 0, beta_k == 0: a cylinder along u_k: plane k owns no point and is skipped.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..model.quadric import Quadric

#: eigenvalues below this fraction of the largest count as zero
EIGEN_SNAP = 1e-12
#: linear terms below this fraction of the coefficient scale count as zero
LINEAR_SNAP = 1e-12


@dataclass(frozen=True)
class PrincipalFrame:
    """Local frame of a quadric: x = q + U z, Q = sum(lam z^2 + 2 beta z) + gamma."""

    U: np.ndarray  # (3, 3) columns are the principal axes u_m (right-handed)
    lam: np.ndarray  # (3,) eigenvalues (snapped zeros are exactly 0)
    center: np.ndarray  # (3,) q
    beta: np.ndarray  # (3,) nonzero only on null axes
    gamma: float



def principal_frame(q: Quadric) -> PrincipalFrame:
    """Eigen-decomposition, min-norm center and local coefficients of ``q``."""
    A, b, c = q.A, q.b, q.c
    scale = max(np.abs(q.matrix).max(), 1e-300)
    lam, U = np.linalg.eigh(A)
    lmax = np.abs(lam).max()
    lam = np.where(np.abs(lam) <= EIGEN_SNAP * max(lmax, 1e-300), 0.0, lam)
    if lmax <= EIGEN_SNAP * scale:
        # a plane (A = 0): choose the frame with u_3 along b so that plane 3 is its heightfield
        lam = np.zeros(3)
        bn = np.linalg.norm(b)
        w = b / bn if bn > 0 else np.array([0.0, 0.0, 1.0])
        helper = np.array([1.0, 0.0, 0.0]) if abs(w[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
        u = np.cross(helper, w)
        u /= np.linalg.norm(u)
        U = np.column_stack([u, np.cross(w, u), w])
    if np.linalg.det(U) < 0:
        U = U.copy()
        U[:, 0] = -U[:, 0]
    # min-norm solution of A q = b in the eigenbasis
    ub = U.T @ b
    zc = np.where(lam != 0.0, ub / np.where(lam != 0.0, lam, 1.0), 0.0)
    center = U @ zc
    beta = U.T @ (A @ center - b)
    beta = np.where(lam != 0.0, 0.0, beta)
    beta = np.where(np.abs(beta) <= LINEAR_SNAP * scale, 0.0, beta)
    gamma = float(center @ A @ center - 2.0 * b @ center + c)
    return PrincipalFrame(U=U, lam=lam, center=center, beta=beta, gamma=gamma)
