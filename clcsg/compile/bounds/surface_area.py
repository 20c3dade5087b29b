"""The CSG surface area per quadric, measured by random lines (Cauchy-Crofton), for the
expected sample count of the progress display.

Crofton's formula: for isotropic uniform random lines meeting a ball of radius R (a direction
uniform on the sphere, then a point uniform in the disc of radius R across the ball's center
orthogonal to it), a surface S inside the ball is crossed E[n] = 2 area(S) / (4 pi R^2) times
on average, so area(S) = 2 pi R^2 E[n].  Per quadric u: the ball around the box of u's regions
(:func:`clcsg.compile.bounds.regions.quadric_regions`, where u can carry CSG surface), LINES
lines, their (at most two) crossings of Q_u = 0 inside the regions, and per crossing the tape
run with u substituted on its two sides: a point is on the CSG surface exactly where the two
memberships differ.  The estimate has a relative error of about
1 / sqrt(crossings on the surface) or better: the lines are quasi-random (:func:`isotropic_lines`), the same every run.

A measurement, not a bound: the resource guard keeps its upper bounds
(:mod:`clcsg.compile.bounds.estimates`).  It runs the tape once over all crossings; scenes
whose tape times crossings pass :data:`MAX_WORK` are not measured (None).
"""

from __future__ import annotations

import math

import numpy as np

from ...cl.constants import OP_LEAF
from ...model.quadric import Quadric
from ..interpret import member_per_point

#: random lines per quadric
LINES = 256
#: the most (tape rows x crossings) a measurement may take (about a second of numpy)
MAX_WORK = 5e7


#: the generalized golden ratio of dimension 4 (the real root of x^5 = x + 1): the steps
#: 1 / PHI4^k of the R4 low-discrepancy sequence
PHI4 = 1.2207440846057596
R4_STEPS = np.array([PHI4 ** -k for k in range(1, 5)])


def isotropic_lines(center, R, n: int, seed=0):
    """``n`` isotropic uniform lines meeting the ball (center, R) as (directions, points), from
    the 4-D R4 sequence u_i = frac(s + i a) (quasi-random: the same every run, and spread more
    evenly than random numbers): the direction from (u_1, u_2) (z = 1 - 2 u_1 uniform, azimuth
    2 pi u_2), the point uniform in the disc of radius R across the center orthogonal to it, from
    (u_3, u_4) (radius R sqrt(u_3), angle 2 pi u_4).  ``seed`` shifts the sequence.  For many
    balls at once: ``center`` (..., 3), ``R`` and ``seed`` (...) give lines (..., n, 3)."""
    seed = np.asarray(seed)[..., None, None]
    i = np.arange(n, dtype=np.float64)[:, None]
    u = np.mod(0.5 + seed * R4_STEPS[::-1] + (i + 1) * R4_STEPS, 1.0)
    z, phi = 1.0 - 2.0 * u[..., 0], 2.0 * math.pi * u[..., 1]
    s = np.sqrt(np.maximum(0.0, 1.0 - z * z))
    d = np.stack([s * np.cos(phi), s * np.sin(phi), z], axis=-1)
    ref = np.where(np.abs(d[..., :1]) < 0.9, [[1.0, 0.0, 0.0]], [[0.0, 1.0, 0.0]])
    a1 = np.cross(d, ref)
    a1 /= np.linalg.norm(a1, axis=-1)[..., None]
    a2 = np.cross(d, a1)
    rho, ang = np.asarray(R, dtype=np.float64)[..., None] * np.sqrt(u[..., 2]), 2.0 * math.pi * u[..., 3]
    o = (np.asarray(center, dtype=np.float64)[..., None, :] + (rho * np.cos(ang))[..., None] * a1
         + (rho * np.sin(ang))[..., None] * a2)
    return d, o


def surface_areas(tape, regions, lines: int = LINES, seed: int = 0):
    """Per quadric of ``tape`` the measured area of the CSG surface on it (an array of
    ``len(tape.quadrics)``), or None past :data:`MAX_WORK`.  ``regions``: per quadric the
    boxes (k, 2, 3) where it can carry CSG surface."""
    used = sorted(set(int(q) for q in tape.ops[tape.ops[:, 0] == OP_LEAF, 2]))
    used = [u for u in used if len(regions[u])]
    if len(tape.ops) * lines * len(used) > 20 * MAX_WORK:  # most lines miss the regions, not this many
        return None
    pts, owner, weight = [], [], []
    balls, dirs, origins = [], (), ()
    for u in used:
        reg = np.asarray(regions[u], dtype=np.float64)
        lo, hi = reg[:, 0].min(axis=0), reg[:, 1].max(axis=0)
        center, R = 0.5 * (lo + hi), 0.5 * float(np.linalg.norm(hi - lo))
        if R > 0 and math.isfinite(R):
            balls.append((u, reg, center, R))
    if balls:  # all quadrics' lines at once
        dirs, origins = isotropic_lines(np.array([b[2] for b in balls]), np.array([b[3] for b in balls]), lines,
                                        seed + np.array([b[0] for b in balls]))
    for (u, reg, center, R), d, o in zip(balls, dirs, origins):
        # crossings on a region's face (a plane's regions are flat boxes) count as inside
        tol = 1e-9 * (1.0 + np.abs(reg).max())
        for t in Quadric(tape.quadrics[u]).intersect_line(o, d):
            ok = np.isfinite(t)
            x = o[ok] + t[ok, None] * d[ok]
            inside = np.any(np.all((x[:, None, :] >= reg[None, :, 0] - tol) & (x[:, None, :] <= reg[None, :, 1] + tol),
                                   axis=2), axis=1)
            pts.append(x[inside])
            owner.append(np.full(int(inside.sum()), u))
            weight.append(np.full(int(inside.sum()), 2.0 * math.pi * R * R / lines))
    area = np.zeros(len(tape.quadrics))
    if not pts or not sum(len(p) for p in pts):
        return area
    x, q, w = np.concatenate(pts), np.concatenate(owner), np.concatenate(weight)
    if len(tape.ops) * len(x) > MAX_WORK:
        return None
    minus, plus = member_per_point(tape.ops, tape.quadrics, x, q)
    on = minus != plus
    np.add.at(area, q[on], w[on])
    return area
