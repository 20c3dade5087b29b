"""The device sees exactly what the host packed, and quadric.h agrees with clcsg/quadric.py."""

from __future__ import annotations

import numpy as np
import pyopencl as cl
import pytest

import clcsg
from clcsg.cl.records import SceneBuffers, pack
from clcsg.cl.device import real_dtype
from clcsg.cl.programs import build
from clcsg.model.quadric import Quadric


def _out(ctx, n, dtype):
    return np.zeros(n, dtype=dtype), cl.Buffer(ctx.ctx, cl.mem_flags.WRITE_ONLY, max(1, n) * np.dtype(dtype).itemsize)


def test_kernel_reads_back_packed_buffers(cl_context):
    shape = (clcsg.box(2, color=(1, 0, 0)) - clcsg.cylinder(3, 0.5)) | clcsg.sphere(1, center=(0, 0, 2), color=(0, 0.5, 1, 0.5))
    dnf = clcsg.Scene(shape).normalize()
    real = real_dtype(cl_context)
    p = pack(dnf, real)
    b = SceneBuffers(cl_context, p)
    prg = build(cl_context, "cl/layout_check.cl", real=real)
    q = cl_context.queue
    U, L, T = len(p.quadrics), len(p.literals), len(p.terms)
    coef, bc = _out(cl_context, U * 10, real)
    lam, bl = _out(cl_context, U * 2, real)
    col, bcol = _out(cl_context, U * 4, np.float32)
    cl.Kernel(prg, "read_quadrics")(q, (U,), None, b.quadrics, bc, bl, bcol)
    lits, blit = _out(cl_context, L * 2, np.int32)
    cl.Kernel(prg, "read_literals")(q, (L,), None, b.literals, blit)
    ranges, br = _out(cl_context, T * 2, np.int32)
    bounds, bb = _out(cl_context, T * 6, real)
    cl.Kernel(prg, "read_terms")(q, (T,), None, b.terms, br, bb)
    for host, buf in ((coef, bc), (lam, bl), (col, bcol), (lits, blit), (ranges, br), (bounds, bb)):
        cl.enqueue_copy(q, host, buf)
    np.testing.assert_array_equal(coef.reshape(U, 10), p.quadrics["coef"])
    np.testing.assert_array_equal(lam.reshape(U, 2), np.column_stack([p.quadrics["lam_min"], p.quadrics["lam_max"]]))
    np.testing.assert_array_equal(col.reshape(U, 4), p.quadrics["color"])
    np.testing.assert_array_equal(lits.reshape(L, 2), np.column_stack([p.literals["quadric"], p.literals["sign"]]))
    np.testing.assert_array_equal(ranges.reshape(T, 2), np.column_stack([p.terms["first"], p.terms["count"]]))
    np.testing.assert_array_equal(bounds.reshape(T, 6), np.column_stack([p.terms["lo"], p.terms["hi"]]))
    # and the packing itself is faithful: literal table = DNF terms, colors per quadric
    flat = [lit for t in dnf.terms for lit in t]
    assert [tuple(x) for x in lits.reshape(L, 2)] == flat
    assert {tuple(np.round(c, 6)) for c in col.reshape(U, 4)} >= {(1, 0, 0, 1), (0, 0.5, 1, 0.5)}


QUADRICS = {
    "sphere": Quadric.sphere((0.3, -0.2, 0.1), 1.2),
    "cylinder": Quadric.cylinder((1, 1, 0), 0.7),
    "cone": Quadric.cone((0, 0, 0.2), (0, 1, 1), 0.5),
    "paraboloid": Quadric.elliptic_paraboloid((0, 0, -1), (0, 0, 1), (0.5, 0.8)),
    "saddle": Quadric.hyperbolic_paraboloid(radii=(0.7, 0.9)),
    "hyperboloid2": Quadric.hyperboloid_two_sheets(radii=(0.5, 0.6, 0.4)),
    "plane": Quadric.half_space((1, 2, 3), 0.5),
}


@pytest.mark.parametrize("name", sorted(QUADRICS))
def test_quadric_header_matches_reference(name, cl_context):
    real = real_dtype(cl_context)
    qd = QUADRICS[name]
    dnf = clcsg.Scene(clcsg.quadric(qd.matrix) & clcsg.box(4)).normalize()
    p = pack(dnf, real, origin=np.zeros(3))
    qi = next(i for i in range(dnf.n_quadrics) if np.allclose(np.abs(dnf.quadrics[i]), np.abs(qd.canonical()[0].matrix)))
    K = Quadric(p.local_matrices[qi])
    rng = np.random.default_rng(7)
    n = 4096
    pts = rng.uniform(-2, 2, (n, 3))
    dirs = rng.normal(size=(n, 3))
    dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
    b = SceneBuffers(cl_context, p)
    prg = build(cl_context, "cl/quadric_check.cl", real=real)
    mf = cl.mem_flags
    bp = cl.Buffer(cl_context.ctx, mf.READ_ONLY | mf.COPY_HOST_PTR, hostbuf=pts.astype(real))
    bd = cl.Buffer(cl_context.ctx, mf.READ_ONLY | mf.COPY_HOST_PTR, hostbuf=dirs.astype(real))
    outs = [_out(cl_context, n * k, real) for k in (1, 3, 1, 2)]
    cl.Kernel(prg, "eval")(cl_context.queue, (n,), None, b.quadrics, np.int32(qi), bp, bd, np.int32(n), *[o[1] for o in outs])
    for host, buf in outs:
        cl.enqueue_copy(cl_context.queue, host, buf)
    value, grad, dist, roots = (o[0] for o in outs)
    tol = 1e-9 if real == np.float64 else 1e-4
    scale = np.abs(K.value(pts)) + np.linalg.norm(K.gradient(pts), axis=1) + 1
    np.testing.assert_allclose(value, K.value(pts), atol=tol * scale.max())
    np.testing.assert_allclose(grad.reshape(n, 3), K.gradient(pts), atol=tol * scale.max())
    ref_d = K.distance(pts)
    fin = np.isfinite(ref_d)
    assert np.array_equal(np.isfinite(dist), fin)
    np.testing.assert_allclose(dist[fin], ref_d[fin], rtol=1e-6 if real == np.float64 else 1e-3, atol=tol)
    t1, t2 = K.intersect_line(pts, dirs)
    r = roots.reshape(n, 2)
    got = np.sort(r, axis=1)
    ref = np.sort(np.column_stack([t1, t2]), axis=1)
    both = np.isfinite(ref) & np.isfinite(got)
    np.testing.assert_allclose(got[both], ref[both], rtol=1e-6, atol=1e-6)
    assert np.mean(np.isfinite(got) == np.isfinite(ref)) > 0.999
