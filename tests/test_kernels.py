"""The device headers agree with the float64 references: quadric.h with clcsg/model/quadric.py,
tape.h (interpreters and pruning) with clcsg/compile/interpret.py."""

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


QUADRICS = {
    "sphere": Quadric.sphere((0.3, -0.2, 0.1), 1.2),
    "cylinder": Quadric.cylinder((1, 1, 0), 0.7),
    "cone": Quadric.cone((0, 0, 0.2), (0, 1, 1), 0.5),
    "paraboloid": Quadric.elliptic_paraboloid((0, 0, -1), (0, 0, 1), (0.5, 0.8)),
    "saddle": Quadric.hyperbolic_paraboloid(radii=(0.7, 0.9)),
    "hyperboloid2": Quadric.hyperboloid_two_sheets(radii=(0.5, 0.6, 0.4)),
    "plane": Quadric.half_space((1, 2, 3), 0.5),
}


def _packed_quadric(name, cl_context):
    """(real, the packed scene of QUADRICS[name] cut by a box, its index there, its reference
    in the packed local frame)."""
    real = real_dtype(cl_context)
    qd = QUADRICS[name]
    tape = clcsg.Scene(clcsg.quadric(qd.matrix) & clcsg.box(4)).compile()
    p = pack(tape, real, origin=np.zeros(3))
    qi = next(i for i in range(tape.n_quadrics) if np.allclose(np.abs(tape.quadrics[i]), np.abs(qd.canonical()[0].matrix)))
    return real, p, qi, Quadric(p.local_matrices[qi])


@pytest.mark.parametrize("name", sorted(QUADRICS))
def test_quadric_header_matches_reference(name, cl_context):
    real, p, qi, K = _packed_quadric(name, cl_context)
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


@pytest.mark.parametrize("name", sorted(QUADRICS))
def test_distance_at_least_is_the_quotients_comparison(name, cl_context):
    """quadric_distance_at_least (the pruning's leaf test, without the square root and the
    division) answers |quadric_distance| >= R wherever R is not within 1e-6 of the distance,
    for reaches from 0 to twice the distance (and a few much larger)."""
    real, p, qi, K = _packed_quadric(name, cl_context)
    rng = np.random.default_rng(11)
    n = 4096
    pts = rng.uniform(-2, 2, (n, 3))
    d = np.abs(K.distance(pts))
    scale = rng.uniform(0, 2, n)
    scale[::16] = 1e3
    reach = np.where(np.isfinite(d), d * scale, rng.uniform(0, 4, n))
    b = SceneBuffers(cl_context, p)
    prg = build(cl_context, "cl/quadric_check.cl", real=real)
    mf = cl.mem_flags
    bp = cl.Buffer(cl_context.ctx, mf.READ_ONLY | mf.COPY_HOST_PTR, hostbuf=pts.astype(real))
    br = cl.Buffer(cl_context.ctx, mf.READ_ONLY | mf.COPY_HOST_PTR, hostbuf=reach.astype(real))
    dist, bd = _out(cl_context, n, real)
    got, bg = _out(cl_context, n, np.int32)
    cl.Kernel(prg, "distance_at_least")(cl_context.queue, (n,), None, b.quadrics, np.int32(qi), bp, br, np.int32(n),
                                        bd, bg)
    cl.enqueue_copy(cl_context.queue, dist, bd)
    cl.enqueue_copy(cl_context.queue, got, bg)
    r = reach.astype(real)
    clear = np.abs(np.abs(dist) - r) > (1e-6 if real == np.float64 else 1e-3) * np.maximum(r, 1e-12)
    want = np.abs(dist) >= r
    assert clear.mean() > 0.9
    np.testing.assert_array_equal(got[clear].astype(bool), want[clear])


TAPE_SCENES = {
    "drilled_block": clcsg.box(2) - clcsg.cylinder(3, 0.5) - clcsg.cylinder(3, 0.5, axis=(1, 0, 0)),
    "spheres_and_boxes": (clcsg.sphere(1) | clcsg.box(1, center=(0.8, 0, 0))) & ~clcsg.box((0.5, 3, 3)).rotate((0, 0, 1), 30),
    "nested": clcsg.difference(clcsg.box(3), clcsg.difference(clcsg.box(2.5), clcsg.difference(clcsg.box(2), clcsg.sphere(1.2)))),
}


@pytest.mark.parametrize("name", sorted(TAPE_SCENES))
def test_tape_header_matches_reference(name, cl_context):
    """tape_eval / tape_member at random points and tape_prune over random regions (balls and
    oriented boxes, with and without substitution) give what the numpy reference gives,
    pruned rows included, and every pruned tape agrees with the original inside its region."""
    from clcsg.cl.memory import upload
    from clcsg.compile import interpret

    real = real_dtype(cl_context)
    tape = clcsg.Scene(TAPE_SCENES[name]).compile()
    p = pack(tape, real, origin=np.zeros(3))
    b = SceneBuffers(cl_context, p)
    prg = build(cl_context, "cl/tape_check.cl", {"TAPE_REGS": tape.n_regs}, real=real)
    q = cl_context.queue
    rng = np.random.default_rng(3)
    n = len(tape.ops)
    for self_q in (-1, int(tape.leaves[0, 2]), int(tape.leaves[-1, 2])):
        pts = rng.uniform(-2, 2, (2000, 3))
        f, bf = _out(cl_context, 2 * len(pts), real)
        bits, bb = _out(cl_context, len(pts), np.uint32)
        cl.Kernel(prg, "eval")(q, (len(pts),), None, b.quadrics, b.tape, np.int32(n), np.int32(self_q),
                               upload(cl_context, pts.astype(real)), np.int32(len(pts)), bf, bb)
        cl.enqueue_copy(q, f, bf)
        cl.enqueue_copy(q, bits, bb)
        fm, fp = interpret.evaluate(tape.ops, p.local_matrices, pts, self_q)
        rtol = 1e-9 if real == np.float64 else 1e-4
        np.testing.assert_allclose(f.reshape(-1, 2), np.column_stack([fm, fp]), rtol=rtol, atol=rtol)
        mm, mp = interpret.member(tape.ops, p.local_matrices, pts, self_q)
        np.testing.assert_array_equal(bits, mm.astype(np.uint32) | (mp.astype(np.uint32) << 1))
        # regions: balls and oriented boxes of many sizes
        m = 300
        c = rng.uniform(-2, 2, (m, 3))
        axes = rng.normal(size=(m, 3, 3)) * rng.uniform(0, 0.6, (m, 1, 1)) * (rng.random((m, 1, 1)) < 0.5)
        rho = rng.uniform(0, 0.8, m)
        regions = np.column_stack([c, axes.reshape(m, 9), rho]).astype(real)
        out = np.zeros(m * (n + 1), dtype=p.tape.dtype)
        bo = cl.Buffer(cl_context.ctx, cl.mem_flags.READ_WRITE, out.nbytes)
        res, br = _out(cl_context, 4 * m, np.int32)
        cl.Kernel(prg, "prune")(q, (m,), None, b.quadrics, b.tape, np.int32(n), np.int32(self_q),
                                upload(cl_context, regions), np.int32(m), bo, br)
        cl.enqueue_copy(q, out, bo)
        cl.enqueue_copy(q, res, br)
        res = res.reshape(m, 4)
        rows = out.view(np.int32).reshape(m, n + 1, 4)
        assert res[:, 3].all(), "the decide-only pass disagrees with the writing pass"
        same = 0
        for i in range(m):
            got = rows[i, res[i, 1]:res[i, 1] + res[i, 2]]
            ref, decided, _ = interpret.prune(tape.ops, p.local_matrices, c[i], rho[i], self_q, axes=axes[i])
            if real == np.float64:
                np.testing.assert_array_equal(got, ref)
                assert decided == res[i, 0]
                same += 1
            # the pruned tape is the tape inside the region: check at points of the region
            u = rng.uniform(-1, 1, (64, 3))
            w = rng.normal(size=(64, 3))
            w *= (rho[i] * rng.random(64) / np.linalg.norm(w, axis=1))[:, None]
            x = c[i] + u @ axes[i] + w
            a0, a1 = interpret.member(tape.ops, p.local_matrices, x, self_q)
            b0, b1 = interpret.member(got, p.local_matrices, x, self_q)
            assert np.array_equal(a0, b0) and np.array_equal(a1, b1)
            if res[i, 0] and self_q >= 0:
                assert np.all((a0 != a1) == (res[i, 0] < 0))
        assert same == m or real != np.float64
        # the sampler's clip programs built in private memory from the count pass's record are
        # the rows the written path gives
        cl.Kernel(prg, "prune_private")(q, (m,), None, b.quadrics, b.tape, np.int32(n), np.int32(self_q),
                                        upload(cl_context, regions), np.int32(m), bo, br)
        both = np.zeros(m, dtype=np.int32)
        cl.enqueue_copy(q, both, br)
        assert np.all(both != 0), "a tape built from the count pass differs from the written one"
        assert (both == 1).sum() >= m // 2
