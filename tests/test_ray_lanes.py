"""The ray tracer's eight-lane arithmetic (clcsg/rendering/raytrace.cl, pixel.h): a work-item's
lanes normalize their view rays and normals (pixel_normalize8), meet boxes (ray_box8) and
classify a slab's quadrics (ray_classify8) as real8 vectors, and must get the bits of the
per-ray functions (normalize, ray_box_inv, ray_classify) lane for lane, so the image is the
one the per-pixel kernel drew.  Inputs include the degenerate cases: zero, tiny and huge
vectors, rays parallel to box faces and to cylinder axes (a = 0), planes, no roots, eyes on
the surface."""

from __future__ import annotations

import numpy as np
import pytest

from clcsg.cl import programs
from clcsg.rendering.raytracer import SLAB_LEVELS, SLABS, TILE

SRC = """
#include "raytrace.cl"

/* 8 vectors per work-item: normalize() one by one and pixel_normalize8 on the lanes */
__kernel void normalize_both(__global const real *p, __global real *one, __global real *lanes)
{
    int g = get_global_id(0);
    real x[8], y[8], z[8];
    for (int l = 0; l < 8; ++l) {
        real3 v = vload3(8 * g + l, p);
        vstore3(normalize(v), 8 * g + l, one);
        x[l] = v.x; y[l] = v.y; z[l] = v.z;
    }
    real8 X = vload8(0, x), Y = vload8(0, y), Z = vload8(0, z);
    pixel_normalize8(&X, &Y, &Z);
    vstore8(X, 0, x); vstore8(Y, 0, y); vstore8(Z, 0, z);
    for (int l = 0; l < 8; ++l) vstore3((real3)(x[l], y[l], z[l]), 8 * g + l, lanes);
}

/* work-item (ray group g, quadric k): the eye, eight rays v[8 g + l]; per ray r1, r2, kind of
 * ray_classify and of ray_classify8, and [t0, t1] of ray_box_inv and of ray_box8 on box k */
__kernel void classify_both(__global const quadric_rec *qs, __global const real *eye, __global const real *v,
                            __global const real *box, __global real *one, __global real *lanes)
{
    int g = get_global_id(0), k = get_global_id(1), n = get_global_size(0) * 8;
    real3 e = vload3(0, eye);
    quadric q = quadric_load(qs, k);
    real3 lo = vload3(2 * k, box), hi = vload3(2 * k + 1, box);
    real x[8], y[8], z[8];
    for (int l = 0; l < 8; ++l) {
        real3 d = vload3(8 * g + l, v);
        real r1, r2;
        int kind = ray_classify(q, e, d, &r1, &r2);
        real2 t = ray_box_inv(e, clamp(1 / d, (real3)(-0.5 * REAL_MAX), (real3)(0.5 * REAL_MAX)), lo, hi);
        vstore4((real4)(r1, r2, kind, t.x), k * n + 8 * g + l, one);
        one[4 * n * get_global_size(1) + k * n + 8 * g + l] = t.y;
        x[l] = d.x; y[l] = d.y; z[l] = d.z;
    }
    real8 X = vload8(0, x), Y = vload8(0, y), Z = vload8(0, z), r1, r2, t0, t1;
    int8 kind = ray_classify8(q, e, X, Y, Z, &r1, &r2);
    ray_box8(e, ray_inverse8(X), ray_inverse8(Y), ray_inverse8(Z), lo, hi, &t0, &t1);
    real a[8], b[8], c[8], d[8], f[8];
    vstore8(r1, 0, a); vstore8(r2, 0, b); vstore8(convert_real8(kind), 0, c); vstore8(t0, 0, d);
    vstore8(t1, 0, f);
    for (int l = 0; l < 8; ++l) {
        vstore4((real4)(a[l], b[l], c[l], d[l]), k * n + 8 * g + l, lanes);
        lanes[4 * n * get_global_size(1) + k * n + 8 * g + l] = f[l];
    }
}

/* work-item g: a slab of NQ listed quadrics classified on eight lanes (r1, r2, kind per quadric
 * and lane), its tape (rows of tape g), the lanes' stretches [ta, tb]; per lane the hit and
 * depth that slab_hit finds, and those of first_root_hits8 with its decided bit (hit -2 where
 * it leaves the lane to slab_hit) */
#define NQ 6
__kernel void first_roots_both(__global const real *r1, __global const real *r2, __global const uchar *kind,
                               __global const tape_op *tapes, __global const int *rows, __global const real *stretch,
                               __global int *one_hit, __global real *one_depth, __global int *lanes_hit,
                               __global real *lanes_depth)
{
    int g = get_global_id(0);
    lane_roots lr;
    for (int m = 0; m < NQ; ++m)
        for (int l = 0; l < 8; ++l) {
            lr.r1[m][l] = r1[(g * NQ + m) * 8 + l];
            lr.r2[m][l] = r2[(g * NQ + m) * 8 + l];
            lr.kind[m][l] = kind[(g * NQ + m) * 8 + l];
        }
    __global const tape_op *t = tapes + rows[2 * g];
    int n = rows[2 * g + 1];
    real ta[8], tb[8];
    for (int l = 0; l < 8; ++l) {
        ta[l] = stretch[(2 * g) * 8 + l];
        tb[l] = stretch[(2 * g + 1) * 8 + l];
    }
    ray_roots rr;
    for (int l = 0; l < 8; ++l) {
        real d = NAN;
        one_hit[8 * g + l] = slab_hit(0, t, n, 0, NQ, 0, (real3)(0), (real3)(0, 0, 1), (real3)(INFINITY, INFINITY, 1), 0,
                                      ta[l], tb[l], &lr, l, &rr, &d);
        one_depth[8 * g + l] = d;
    }
    int hit[8];
    real depth[8];
    for (int l = 0; l < 8; ++l) {
        hit[l] = -1;
        depth[l] = NAN;
    }
    int decided = first_root_hits8(t, n, NQ, &lr, vload8(0, ta), vload8(0, tb), 0xff, hit, depth);
    for (int l = 0; l < 8; ++l) {
        lanes_hit[8 * g + l] = (decided >> l & 1) ? hit[l] : -2;
        lanes_depth[8 * g + l] = depth[l];
    }
}
"""


def _program(cl_context, real):
    import pyopencl as cl

    defines = {"TAPE_REGS": 8, "TILE": TILE, "SLABS": SLABS, "SLAB_LEVELS": SLAB_LEVELS, "LOCAL_QUADRICS": 64}
    opts = programs.build_options(defines, real=real) + ["-I", programs.package_dir("cl/include"),
                                                         "-I", programs.package_dir("rendering")]
    return cl.Program(cl_context.ctx, programs._wrapped(cl_context, SRC)).build(options=opts)


def _real(cl_context):
    return np.float64 if cl_context.info.fp64 else np.float32


def _bits(a):
    return np.ascontiguousarray(a).view(np.uint64 if a.dtype == np.float64 else np.uint32)


def _run(cl_context, name, shape, inputs, outputs):
    import pyopencl as cl

    prg = _program(cl_context, _real(cl_context))
    mf = cl.mem_flags
    ctx, q = cl_context.ctx, cl_context.queue
    ins = [x if isinstance(x, cl.Buffer) else cl.Buffer(ctx, mf.READ_ONLY | mf.COPY_HOST_PTR, hostbuf=x)
           for x in inputs]
    outs = [cl.Buffer(ctx, mf.WRITE_ONLY, o.nbytes) for o in outputs]
    getattr(prg, name)(q, shape, None, *ins, *outs)
    for o, b in zip(outputs, outs):
        cl.enqueue_copy(q, o, b)
    q.finish()


def test_pixel_normalize8_is_normalize_bit_for_bit(cl_context):
    real = _real(cl_context)
    rng = np.random.default_rng(11)
    n = 8 * 4096
    p = rng.normal(size=(n, 3)) * np.exp(rng.uniform(-8, 8, size=(n, 1)))
    p[:64] = 0  # zero vectors, one per lane position and mixed with others below
    p[64:128] *= 1e-160 if real == np.float64 else 1e-21  # |p|^2 under the smallest normal
    p[128:192] *= 1e160 if real == np.float64 else 1e21  # |p|^2 overflows
    p[192:256] = np.eye(3)[rng.integers(0, 3, 64)] * rng.choice([-1, 1], (64, 1))  # axis directions
    p[256:320:3] = 0  # lanes of one group mixing zero and regular vectors
    p = rng.permutation(p[:512], axis=0).tolist() + p[512:].tolist()
    p = np.asarray(p, dtype=real)
    one, lanes = np.empty_like(p), np.empty_like(p)
    _run(cl_context, "normalize_both", (n // 8,), [p], [one, lanes])
    assert np.array_equal(_bits(one), _bits(lanes))
    finite = np.isfinite(one).all(axis=1) & (np.abs(p).sum(axis=1) > 0)
    assert np.allclose(np.linalg.norm(one[finite], axis=1), 1, atol=1e-5)


def _quadrics(rng, real):
    """Coefficient rows (xx xy xz xw yy yz yw zz zw ww) of spheres, cylinders along the axes,
    cones, planes, random quadrics."""
    rows = []
    for axis in range(3):  # x^2 + y^2 - r^2 (about axis): a = 0 for rays along it
        A = np.eye(3)
        A[axis, axis] = 0
        rows.append((A, np.zeros(3), -0.25))
    rows.append((np.eye(3), np.zeros(3), -1.0))  # sphere
    rows.append((np.diag([1.0, 1.0, -0.3]), np.zeros(3), 0.0))  # cone through the origin
    for k in range(3):  # planes: A = 0, a line along every ray
        b = np.zeros(3)
        b[k] = 0.5
        rows.append((np.zeros((3, 3)), b, 0.1 * k))
    for _ in range(24):
        M = rng.normal(size=(3, 3))
        rows.append((M + M.T, rng.normal(size=3), rng.normal()))
    out = []
    for A, b, c in rows:  # Q(p) = p^T A p - 2 b^T p + c; the records hold -b (layout.h)
        out.append([A[0, 0], A[0, 1], A[0, 2], -b[0], A[1, 1], A[1, 2], -b[1], A[2, 2], -b[2], c])
    return np.asarray(out, dtype=real)


@pytest.mark.parametrize("eye, kinds", [((0.3, -2.0, 0.4), {0, 1, 2}), ((0.0, 0.0, 0.0), {0, 1, 2, 3}),
                                        ((0.0, 0.5, 0.0), {0, 1, 2, 3}), ((3.0, 1.0, -2.0), {0, 1, 2})])
def test_ray_classify8_and_ray_box8_are_the_per_ray_functions_bit_for_bit(cl_context, eye, kinds):
    """(0, 0, 0): the eye at the cone's apex; (0, 0.5, 0): on the cylinder about x, so the ray
    along x lies in it (kind 3).  ``kinds``: the sign patterns the rays must reach (bits 0-1).
    The boxes take ray_inverse8's clamped inverses on both sides (rays along the axes and
    parallel to faces have zero components); the box intervals are checked against float64
    below."""
    real = _real(cl_context)
    rng = np.random.default_rng(5)
    coef = _quadrics(rng, real)
    rec = np.zeros((len(coef), 10), dtype=real)  # quadric_rec: coef[10]
    rec[:] = coef
    n = 8 * 64
    v = rng.normal(size=(n, 3))
    v[:48] = np.eye(3)[np.arange(48) % 3] * np.where(np.arange(48) % 2, 1, -1)[:, None]  # along the axes
    v[48:64, 2] = 0  # parallel to the z faces
    v /= np.linalg.norm(v, axis=1, keepdims=True)
    v = v.astype(real)
    lo = rng.uniform(-2, 0, size=(len(coef), 3))
    box = np.stack([lo, lo + rng.uniform(0.5, 3, size=lo.shape)], 1).astype(real)
    box[0] = [[0.0, -1.0, -1.0], [1.0, 1.0, 1.0]]  # a face through the eye at the origin
    nq = len(coef)
    one = np.empty(5 * n * nq, dtype=real)
    lanes = np.empty_like(one)
    _run(cl_context, "classify_both", (n // 8, nq), [rec, np.asarray(eye, dtype=real), v, box], [one, lanes])
    assert np.array_equal(_bits(one), _bits(lanes))
    seen = set(one[: 4 * n * nq].reshape(-1, 4)[:, 2].astype(int) % 4)
    assert kinds <= seen
    # the interval holds every t where the ray is in the closed box, and only such t (float64
    # at points along the ray): rays parallel to a face plane included
    t0 = lanes[: 4 * n * nq].reshape(nq, n, 4)[:, :, 3].astype(np.float64)
    t1 = lanes[4 * n * nq :].reshape(nq, n).astype(np.float64)
    ts = np.linspace(-6, 6, 241)
    e = np.asarray(eye, dtype=np.float64)
    tol = 1e-9 if real == np.float64 else 1e-4
    for k in range(nq):
        p = e + ts[None, :, None] * v.astype(np.float64)[:, None, :]
        inside = np.all((p >= box[k, 0] - tol) & (p <= box[k, 1] + tol), axis=2)
        strictly = np.all((p > box[k, 0] + tol) & (p < box[k, 1] - tol), axis=2)
        loose = (ts[None, :] >= t0[k][:, None] - tol) & (ts[None, :] <= t1[k][:, None] + tol)
        tight = (ts[None, :] >= t0[k][:, None] + tol) & (ts[None, :] <= t1[k][:, None] - tol)
        assert not (strictly & ~loose).any(), f"box {k}: a point inside the box outside [t0, t1]"
        assert not (tight & ~inside).any(), f"box {k}: a point of [t0, t1] outside the box"


def _random_slab_tape(rng, nq):
    """A random boolean tape over listed quadrics 0..nq-1 (tape_op rows: op, out, a, b), in SSA
    form with one register per row (at most 8 rows, the program's TAPE_REGS)."""
    from clcsg.cl.constants import OP_AND, OP_CONST, OP_LEAF, OP_OR

    rows = []
    for k in range(int(rng.integers(1, 9))):
        if k < 2 or rng.random() < 0.4:
            if rng.random() < 0.05:
                rows.append((OP_CONST, k, int(rng.integers(0, 2)), 0))
            else:
                rows.append((OP_LEAF, k, int(rng.integers(0, nq)), int(rng.choice([-1, 1]))))
        else:
            a, b = rng.choice(k, size=2)
            rows.append((int(rng.choice([OP_AND, OP_OR])), k, int(a), int(b)))
    return rows


def test_first_root_hits8_decides_lanes_as_slab_hit_does(cl_context):
    """The eight-lane first visits (first_root_hits8) against slab_hit lane by lane on random
    slabs: roots and stretch ends drawn from a few values, so roots tie with each other and
    with the stretch's ends (a root at ta, ta = 0), culled quadrics, every kind of sign pattern.
    A lane it decides gets slab_hit's hit and depth, or no hit where slab_hit finds none; on
    these random slabs (random tapes, many roots per stretch) two thirds of the lanes are decided."""
    real = _real(cl_context)
    rng = np.random.default_rng(11)
    groups, nq = 4000, 6
    values = np.array([0.0, 0.5, 1.0, 1.5, 2.0, 3.0, np.inf])
    r = np.sort(rng.choice(values, size=(groups, nq, 8, 2)), axis=-1)
    kind = rng.integers(0, 4, size=(groups, nq, 8)) | (rng.random((groups, nq, 8)) < 0.5) * 4
    none = r[..., 0] == np.inf
    kind = np.where(none, kind & 4, kind)  # no root: a constant sign (or zero along the ray)
    one = (kind & 3) == 1
    r[..., 1] = np.where(one, r[..., 0], r[..., 1])  # a line has one root
    culled = rng.random((groups, nq, 8)) < 0.15
    r = np.where(culled[..., None], np.inf, r)
    kind = np.where(culled, (kind & 4) | 8, kind)
    ends = np.sort(rng.choice(values[:-1], size=(groups, 8, 2)), axis=-1)
    tapes, rows = [], []
    for _ in range(groups):
        t = _random_slab_tape(rng, nq)
        rows.append((sum(len(x) for x in tapes), len(t)))
        tapes.append(t)
    tape = np.array([row for t in tapes for row in t], dtype=np.int32)
    out = [np.empty(8 * groups, np.int32), np.empty(8 * groups, real), np.empty(8 * groups, np.int32),
           np.empty(8 * groups, real)]
    _run(cl_context, "first_roots_both", (groups,),
         [np.ascontiguousarray(r[..., 0], dtype=real), np.ascontiguousarray(r[..., 1], dtype=real),
          kind.astype(np.uint8), tape, np.array(rows, np.int32), np.ascontiguousarray(ends.transpose(0, 2, 1), dtype=real)],
         out)
    one_hit, one_depth, lanes_hit, lanes_depth = out
    decided = lanes_hit != -2
    assert decided.mean() > 0.5
    assert np.array_equal(lanes_hit[decided], one_hit[decided])
    hits = decided & (one_hit >= 0)
    assert hits.sum() > 1000 and (decided & (one_hit < 0)).sum() > 1000
    assert np.array_equal(_bits(lanes_depth[hits]), _bits(one_depth[hits]))
