"""plane_cases.h: which conics plane_conic_semidefinite takes as semidefinite (the test for a
quadric that touches a plane task without crossing it), against numpy's eigenvalues, on
semidefinite conics of rank 1 to 3 (a tangent cylinder's conic has rank 1) and on conics with
an eigenvalue of each sign."""

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
