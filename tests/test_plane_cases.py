"""plane_cases.h: which conics plane_conic_semidefinite takes as semidefinite (the test for a
quadric that touches a plane task without crossing it), against numpy's eigenvalues, on
semidefinite conics of rank 1 to 3 (a tangent cylinder's conic has rank 1) and on conics with
an eigenvalue of each sign; which conics plane_line_factor takes as a live plane's line times
a linear factor of one sign over a cell, against the factors they were made of; the sign pair
two parallel planes, or two nested conics, cannot have, against random points; and
task_plane_factor against quadrics made as mu S + P L."""

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


def _coefficients(H):
    """The 10 coefficients (xx, xy, xz, xw, yy, yz, yw, zz, zw, ww) of a symmetric 4x4 matrix."""
    return np.array([H[0, 0], H[0, 1], H[0, 2], H[0, 3], H[1, 1], H[1, 2], H[1, 3], H[2, 2], H[2, 3], H[3, 3]])


def _plane_matrix(n, d):
    """n.x - d as a symmetric 4x4 matrix ((x, 1)^T H (x, 1))."""
    H = np.zeros((4, 4))
    H[:3, 3] = H[3, :3] = np.asarray(n) / 2
    H[3, 3] = -d
    return H


def _run(cl_context, name, arrays, n, out_dtype):
    real = real_dtype(cl_context)
    mf = cl.mem_flags
    bufs = [cl.Buffer(cl_context.ctx, mf.READ_ONLY | mf.COPY_HOST_PTR, hostbuf=np.ascontiguousarray(a, dtype=real))
            for a in arrays]
    out = np.zeros(n, dtype=out_dtype)
    dst = cl.Buffer(cl_context.ctx, mf.WRITE_ONLY, out.nbytes)
    prg = build(cl_context, "sampling/plane_cases_check.cl", real=real)
    cl.Kernel(prg, name)(cl_context.queue, (n,), None, *bufs, np.int32(n), dst)
    cl.enqueue_copy(cl_context.queue, out, dst)
    return out


@settings(max_examples=20, deadline=None)
@given(seed=st.integers(0, 2**32 - 1))
def test_parallel_planes_lose_the_sign_pair_no_point_has(seed, cl_context):
    if real_dtype(cl_context) != np.float64:
        return
    rng = np.random.default_rng(seed)
    n = 32
    a, b, pairs = [], [], []
    pts = rng.uniform(-4, 4, size=(20000, 3))
    for i in range(n):
        u = rng.normal(size=3)
        u /= np.linalg.norm(u)
        da, db = rng.uniform(-2, 2, size=2)
        flip = rng.choice([-1.0, 1.0])
        A, B = _plane_matrix(u * rng.uniform(0.5, 2), da), _plane_matrix(flip * u * rng.uniform(0.5, 2), flip * db)
        a.append(_coefficients(A))
        b.append(_coefficients(B))
        hom = np.c_[pts, np.ones(len(pts))]
        sa = np.einsum("ij,jk,ik->i", hom, A, hom) > 0
        sb = np.einsum("ij,jk,ik->i", hom, B, hom) > 0
        pairs.append({int(x) | 2 * int(y) for x, y in zip(sa, sb)})  # case bits: 0 A positive, 1 B positive
    got = _run(cl_context, "parallel", (a, b), n, np.uint32)
    for mask, seen in zip(got, pairs):
        dropped = [c for c in range(4) if mask >> c & 1]
        assert len(dropped) == 1, (mask, seen)
        assert dropped[0] not in seen  # no point has the dropped pair
    # planes that are not parallel keep every pair
    tilted = [_coefficients(_plane_matrix(rng.normal(size=3), 0.3)) for _ in range(n)]
    assert np.all(_run(cl_context, "parallel", (a, tilted), n, np.uint32) == 0)


@settings(max_examples=20, deadline=None)
@given(seed=st.integers(0, 2**32 - 1))
def test_task_plane_factor_finds_the_factor_and_its_sign(seed, cl_context):
    """Q = mu S + sym(P L) meets the plane P in S's conic; on S, Q = P L: the sign of L over a box
    where it has one; 0 where L changes sign in the box, and for Q perturbed."""
    if real_dtype(cl_context) != np.float64:
        return
    rng = np.random.default_rng(seed)
    n = 48
    S_, P_, Q_, boxes, want = [], [], [], [], []
    for i in range(n):
        M = rng.normal(size=(4, 4))
        S = (M + M.T) / 2
        p = rng.normal(size=4)
        l = rng.normal(size=4)
        Q = rng.uniform(0.3, 3) * rng.choice([-1, 1]) * S + (np.outer(p, l) + np.outer(l, p)) / 2
        c = rng.uniform(-2, 2, size=3)
        axes = np.diag(rng.uniform(0.01, 0.5, size=3))
        spread = np.abs(axes @ l[:3]).sum()
        kind = i % 3  # 0: L of one sign over the box, 1: L changes sign there, 2: Q perturbed
        l[3] = -(l[:3] @ c) + (0.0 if kind == 1 else rng.choice([-1, 1]) * spread * rng.uniform(1.2, 3))
        Q = rng.uniform(0.3, 3) * rng.choice([-1, 1]) * S + (np.outer(p, l) + np.outer(l, p)) / 2
        if kind == 2:
            Q = Q + 1e-6 * np.abs(Q).max() * np.diag([1.0, 0, 0, 0])
        S_.append(_coefficients(S))
        P_.append(_coefficients(_plane_matrix(p[:3], -p[3])))
        Q_.append(_coefficients(Q))
        boxes.append(np.concatenate([c, axes.ravel()]))
        want.append(int(np.sign(l[:3] @ c + l[3])) if kind == 0 else 0)
    got = _run(cl_context, "plane_factor", (S_, P_, Q_, boxes), n, np.int32)
    assert np.array_equal(got, np.array(want)), (got, want)


@settings(max_examples=20, deadline=None)
@given(seed=st.integers(0, 2**32 - 1))
def test_nested_conics_lose_the_sign_pair_no_point_has(seed, cl_context):
    """a = mu b + delta (a constant of either sign): the pair (b positive, a negative) or the
    reverse has no point of the plane; a = mu b + a linear term is not nested."""
    if real_dtype(cl_context) != np.float64:
        return
    rng = np.random.default_rng(seed)
    n = 32
    pts = rng.uniform(-4, 4, size=(20000, 2))
    hom = np.c_[pts, np.ones(len(pts))]
    a_, b_, seen, kinds = [], [], [], []
    for i in range(n):
        M = rng.normal(size=(3, 3))
        B = (M + M.T) / 2
        A = rng.uniform(0.3, 3) * B
        nested = i % 2 == 0
        if nested:
            A[2, 2] += rng.choice([-1, 1]) * rng.uniform(0.05, 1.0)
        else:
            A[0, 2] += 0.3
            A[2, 0] += 0.3
        a_.append(_entries(A[:2, :2], 2 * A[:2, 2], A[2, 2]))
        b_.append(_entries(B[:2, :2], 2 * B[:2, 2], B[2, 2]))
        sa = np.einsum("ij,jk,ik->i", hom, A, hom) > 0
        sb = np.einsum("ij,jk,ik->i", hom, B, hom) > 0
        seen.append({int(x) | 2 * int(y) for x, y in zip(sa, sb)})  # case bits: 0 a positive, 1 b positive
        kinds.append(nested)
    got = _run(cl_context, "nested", (a_, b_), n, np.uint32)
    for mask, pairs, nested in zip(got, seen, kinds):
        dropped = [c for c in range(4) if mask >> c & 1]
        if nested:
            assert len(dropped) == 1 and dropped[0] not in pairs, (mask, pairs)
        else:
            assert mask == 0
