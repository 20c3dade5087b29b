"""plane_cases.h: which conics plane_conic_semidefinite takes as semidefinite (the test for a
quadric that touches a plane task without crossing it), against numpy's eigenvalues, on
semidefinite conics of rank 1 to 3 (a tangent cylinder's conic has rank 1) and on conics with
an eigenvalue of each sign; and which conics plane_line_factor takes as a live plane's line
times a linear factor of one sign over a cell, against the factors they were made of."""

from __future__ import annotations

import numpy as np
import pyopencl as cl
from hypothesis import given, settings
from hypothesis import strategies as st

from clcsg.cl.device import real_dtype
from clcsg.cl.programs import build


def _conics(rng, rank, n):
    """n symmetric 3x3 matrices normalized to a largest entry of 1: semidefinite of the given
    rank (either sign), or (rank 0) with a clearly negative and a clearly positive eigenvalue."""
    q, _ = np.linalg.qr(rng.normal(size=(n, 3, 3)))
    lam = rng.uniform(0.05, 1.0, size=(n, 3))
    if rank:
        lam[:, rank:] = 0
        lam *= rng.choice([-1.0, 1.0], size=(n, 1))
    else:
        lam[:, 0] *= -1
    m = q @ (lam[:, :, None] * q.transpose(0, 2, 1))
    return m / np.abs(m).max(axis=(1, 2), keepdims=True)


def _semidefinite(cl_context, m):
    real = real_dtype(cl_context)
    entries = np.stack([m[:, 0, 0], m[:, 0, 1], m[:, 1, 1], m[:, 0, 2], m[:, 1, 2], m[:, 2, 2]], axis=1)
    prg = build(cl_context, "sampling/plane_cases_check.cl", real=real)
    mf = cl.mem_flags
    src = cl.Buffer(cl_context.ctx, mf.READ_ONLY | mf.COPY_HOST_PTR, hostbuf=np.ascontiguousarray(entries, dtype=real))
    out = np.zeros(len(m), dtype=np.int32)
    dst = cl.Buffer(cl_context.ctx, mf.WRITE_ONLY, out.nbytes)
    cl.Kernel(prg, "semidefinite")(cl_context.queue, (len(m),), None, src, np.int32(len(m)), dst)
    cl.enqueue_copy(cl_context.queue, out, dst)
    return out


@settings(max_examples=30, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), rank=st.sampled_from([0, 1, 2, 3]))
def test_semidefinite_conics_are_told_from_indefinite_ones(seed, rank, cl_context):
    m = _conics(np.random.default_rng(seed), rank, 64)
    got = _semidefinite(cl_context, m)
    if rank == 0:
        assert np.all(got == 0), np.linalg.eigvalsh(m)[got != 0]
    else:
        want = np.where(np.trace(m, axis1=1, axis2=2) > 0, 1, 2)  # positive or negative semidefinite
        assert np.array_equal(got, want), np.linalg.eigvalsh(m)[got != want]


def _entries(q, lin, const):
    """Conic entries (xx, xy, yy, x1, y1, 11) of x.q.x + lin.x + const, normalized."""
    e = np.array([q[0, 0], q[0, 1], q[1, 1], lin[0] / 2, lin[1] / 2, const])
    return e / np.abs(e).max()


@settings(max_examples=30, deadline=None)
@given(seed=st.integers(0, 2**32 - 1))
def test_line_factor_is_found_with_its_sign(seed, cl_context):
    """c = l f for random lines l and factors f: the sign of f over a rectangle where it has one
    (a margin of a tenth of its range), 0 where f changes sign there; 0 for c plus a small
    quadratic term (no longer divisible by l)."""
    real = real_dtype(cl_context)
    if real != np.float64:
        return  # plane_cases.h finds no relation without double precision
    rng = np.random.default_rng(seed)
    n = 96
    lines, conics, rects, want = [], [], [], []
    for i in range(n):
        lx, ly, l0 = rng.normal(size=3)
        fx, fy = rng.normal(size=2)
        cx, cy = rng.uniform(-3, 3, size=2)
        hx, hy = rng.uniform(0.01, 1, size=2)
        x0, x1, y0, y1 = cx - hx, cx + hx, cy - hy, cy + hy
        spread = abs(fx) * hx + abs(fy) * hy
        kind = i % 3  # 0: f > 0 over the rectangle, 1: f changes sign there, 2: not divisible
        f0 = -(fx * cx + fy * cy) + (0.0 if kind == 1 else rng.choice([-1, 1]) * spread * rng.uniform(1.1, 3))
        q = np.array([[lx * fx, (lx * fy + ly * fx) / 2], [(lx * fy + ly * fx) / 2, ly * fy]])
        lin = np.array([lx * f0 + l0 * fx, ly * f0 + l0 * fy])
        const = l0 * f0
        if kind == 2:
            q = q + 1e-6 * np.abs(q).max() * np.eye(2)
        conics.append(_entries(q, lin, const))
        lines.append(np.array([0, 0, 0, lx / 2, ly / 2, l0]) / max(abs(lx / 2), abs(ly / 2), abs(l0)))
        rects.append([x0, x1, y0, y1])
        want.append(int(np.sign(f0 + fx * cx + fy * cy)) if kind == 0 else 0)
    mf = cl.mem_flags
    bufs = [cl.Buffer(cl_context.ctx, mf.READ_ONLY | mf.COPY_HOST_PTR, hostbuf=np.ascontiguousarray(a, dtype=real))
            for a in (conics, lines, rects)]
    out = np.zeros(n, dtype=np.int32)
    dst = cl.Buffer(cl_context.ctx, mf.WRITE_ONLY, out.nbytes)
    prg = build(cl_context, "sampling/plane_cases_check.cl", real=real)
    cl.Kernel(prg, "line_factor")(cl_context.queue, (n,), None, *bufs, np.int32(n), dst)
    cl.enqueue_copy(cl_context.queue, out, dst)
    assert np.array_equal(out, np.array(want)), (out, want)
