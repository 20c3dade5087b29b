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
    return principal_frame_list([q.matrix])[0]


def principal_frame_list(matrices) -> list:
    """:class:`PrincipalFrame` of each of ``matrices`` (n, 4, 4) (:func:`principal_frames`)."""
    U, lam, center, beta, gamma = principal_frames(matrices)
    return [PrincipalFrame(U=U[k], lam=lam[k], center=center[k], beta=beta[k], gamma=float(gamma[k]))
            for k in range(len(lam))]


def mat_vec(M, v):
    """M @ v for stacks (n, 3, 3) and (n, 3)."""
    return np.einsum("nij,nj->ni", M, v)


def mat_t_vec(M, v):
    """M^T @ v for stacks (n, 3, 3) and (n, 3)."""
    return np.einsum("nji,nj->ni", M, v)


def principal_frames(matrices):
    """(U (n, 3, 3), lam (n, 3), center (n, 3), beta (n, 3), gamma (n,)) of the quadrics
    ``matrices`` (n, 4, 4) (symmetrized), each row of its matrix alone: A = U diag(lam) U^T
    (eigh; |lam| <= EIGEN_SNAP max |lam| snapped to 0), a plane's frame with u_3 along b,
    right-handed U, the min-norm center and the local beta (LINEAR_SNAP) and gamma."""
    M = np.asarray(matrices, dtype=np.float64).reshape(-1, 4, 4)
    M = 0.5 * (M + M.transpose(0, 2, 1))
    A, b, c = M[:, :3, :3], -M[:, :3, 3], M[:, 3, 3]
    scale = np.maximum(np.abs(M).max(axis=(1, 2), initial=0.0), 1e-300)
    lam, U = np.linalg.eigh(A) if len(M) else (np.zeros((0, 3)), np.zeros((0, 3, 3)))
    lmax = np.abs(lam).max(axis=1, initial=0.0)
    lam = np.where(np.abs(lam) <= EIGEN_SNAP * np.maximum(lmax, 1e-300)[:, None], 0.0, lam)
    plane = lmax <= EIGEN_SNAP * scale
    if plane.any():
        bp = b[plane]
        bn = np.linalg.norm(bp, axis=1)
        w = np.where(bn[:, None] > 0, bp / np.where(bn > 0, bn, 1.0)[:, None], [0.0, 0.0, 1.0])
        helper = np.where((np.abs(w[:, 0]) < 0.9)[:, None], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0])
        u = np.cross(helper, w)
        u /= np.linalg.norm(u, axis=1)[:, None]
        U = U.copy()
        U[plane] = np.stack([u, np.cross(w, u), w], axis=2)
        lam[plane] = 0.0
    flip = np.linalg.det(U) < 0 if len(M) else np.zeros(0, bool)
    if flip.any():
        U = U.copy()
        U[flip, :, 0] = -U[flip, :, 0]
    ub = mat_t_vec(U, b)
    nz = lam != 0.0
    zc = np.where(nz, ub / np.where(nz, lam, 1.0), 0.0)
    center = mat_vec(U, zc)
    beta = mat_t_vec(U, mat_vec(A, center) - b)
    beta = np.where(nz, 0.0, beta)
    beta = np.where(np.abs(beta) <= LINEAR_SNAP * scale[:, None], 0.0, beta)
    gamma = np.einsum("ni,ni->n", center, mat_vec(A, center)) - 2.0 * np.einsum("ni,ni->n", b, center) + c
    return U, lam, center, beta, gamma
