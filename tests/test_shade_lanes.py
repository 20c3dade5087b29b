"""The resolve pass's shading in shade.h: the float8 lighting and encoding of RESOLVE_LANES
pixels (shade_light8, shade_encode8) give the bytes of the ray tracer's scalar ones
(shade_light, shade_encode), the encoding is c^(1 / gamma) (a float64 reference), and the
highlight cut drops no term above 2^-64."""

from __future__ import annotations

import math

import numpy as np
import pytest

from clcsg.cl import programs
from clcsg.rendering.camera import Camera
from clcsg.rendering.shading import Shading, highlight_cut, pack_view

SRC = """
#include "shade.h"
/* per pixel k: albedo a[k], normal n[k], view ray v[k]; 8 consecutive pixels per work-item */
__kernel void both(__global const view_rec *vw, __global const float4 *a, __global const float4 *n,
                   __global const float4 *v, __global uchar4 *scalar, __global uchar4 *lanes)
{
    int g = get_global_id(0);
    float buf[10][8];
    for (int l = 0; l < 8; ++l) {
        int k = 8 * g + l;
        float4 A = a[k], N = n[k], V = v[k];
        scalar[k] = shade_encode(vw, shade_light(vw, A, N.xyz, V.xyz), A.w);
        buf[0][l] = A.x; buf[1][l] = A.y; buf[2][l] = A.z; buf[3][l] = A.w;
        buf[4][l] = N.x; buf[5][l] = N.y; buf[6][l] = N.z;
        buf[7][l] = V.x; buf[8][l] = V.y; buf[9][l] = V.z;
    }
    float8 cx, cy, cz;
    shade_light8(vw, vload8(0, buf[0]), vload8(0, buf[1]), vload8(0, buf[2]), vload8(0, buf[4]),
                 vload8(0, buf[5]), vload8(0, buf[6]), vload8(0, buf[7]), vload8(0, buf[8]), vload8(0, buf[9]),
                 &cx, &cy, &cz);
    uchar r[8], gg[8], b[8];
    vstore8(shade_encode8(vw, cx), 0, r);
    vstore8(shade_encode8(vw, cy), 0, gg);
    vstore8(shade_encode8(vw, cz), 0, b);
    for (int l = 0; l < 8; ++l)
        lanes[8 * g + l] = (uchar4)(r[l], gg[l], b[l], convert_uchar_sat(buf[3][l] * 255.0f + 0.5f));
}
__kernel void encode(__global const view_rec *vw, __global const float4 *c, __global uchar4 *out)
{
    int k = get_global_id(0);
    out[k] = shade_encode(vw, c[k].xyz, c[k].w);
}
"""


def _program(cl_context):
    import pyopencl as cl

    real = np.float64 if cl_context.info.fp64 else np.float32
    opts = programs.build_options(real=real) + ["-I", programs.package_dir("cl/include"),
                                                "-I", programs.package_dir("rendering")]
    return cl.Program(cl_context.ctx, programs._wrapped(cl_context, SRC)).build(options=opts)


def _unit(rng, n):
    x = rng.normal(size=(n, 3))
    x /= np.linalg.norm(x, axis=1, keepdims=True)
    return np.concatenate([x, np.zeros((n, 1))], 1).astype(np.float32)


@pytest.mark.parametrize("gamma, specular, shininess", [(2.2, 0.18, 32.0), (1.0, 1.0, 1.0), (0.45, 5.0, 200.0),
                                                        (3.7, 0.0, 8.0)])
def test_the_lanes_shade_like_the_scalar_body(cl_context, gamma, specular, shininess):
    import pyopencl as cl

    prg = _program(cl_context)
    view = pack_view(Camera.look_at((3, 2, 1), (0, 0, 0), width=8, height=8), np.zeros(3),
                     np.float64 if cl_context.info.fp64 else np.float32,
                     Shading().with_options(gamma=gamma, specular=specular, shininess=shininess))
    rng = np.random.default_rng(3)
    n = 8 * 8192
    a = rng.random((n, 4), dtype=np.float32)
    nrm, v = _unit(rng, n), _unit(rng, n)
    v[: n // 8, :3] = -nrm[: n // 8, :3]  # head-on: the highlight's peak
    mf = cl.mem_flags
    ctx, q = cl_context.ctx, cl_context.queue
    vbuf, abuf, nbuf, rbuf = (cl.Buffer(ctx, mf.READ_ONLY | mf.COPY_HOST_PTR, hostbuf=x) for x in (view, a, nrm, v))
    scalar, lanes = np.empty((n, 4), np.uint8), np.empty((n, 4), np.uint8)
    sbuf, lbuf = (cl.Buffer(ctx, mf.WRITE_ONLY, scalar.nbytes) for _ in range(2))
    prg.both(q, (n // 8,), None, vbuf, abuf, nbuf, rbuf, sbuf, lbuf)
    cl.enqueue_copy(q, scalar, sbuf)
    cl.enqueue_copy(q, lanes, lbuf)
    diff = np.abs(scalar.astype(int) - lanes.astype(int))
    assert diff.max() <= 1
    assert np.mean(diff.max(axis=1) > 0) < 1e-3
    assert len(np.unique(scalar[:, 0])) > 100  # the colours span the range


@pytest.mark.parametrize("gamma", [2.2, 1.0, 0.45, 3.7])
def test_the_encoding_is_the_gamma_power(cl_context, gamma):
    import pyopencl as cl

    prg = _program(cl_context)
    view = pack_view(Camera.look_at((3, 2, 1), (0, 0, 0), width=8, height=8), np.zeros(3),
                     np.float64 if cl_context.info.fp64 else np.float32, Shading().with_options(gamma=gamma))
    rng = np.random.default_rng(7)
    c = rng.random((100_000, 4), dtype=np.float32)
    c[:, :3] **= 3  # many dark values, where the bytes are densest
    c[:8] = [[0, 0, 0, 0], [1, 1, 1, 1], [0.5, 0.25, 1e-30, 0.5]] + [[1e-7, 1e-4, 0.999, 0.2]] * 5
    mf = cl.mem_flags
    ctx, q = cl_context.ctx, cl_context.queue
    vbuf, cbuf = (cl.Buffer(ctx, mf.READ_ONLY | mf.COPY_HOST_PTR, hostbuf=x) for x in (view, c))
    out = np.empty((len(c), 4), np.uint8)
    obuf = cl.Buffer(ctx, mf.WRITE_ONLY, out.nbytes)
    prg.encode(q, (len(c),), None, vbuf, cbuf, obuf)
    cl.enqueue_copy(q, out, obuf)
    ref = np.floor(np.concatenate([c[:, :3].astype(np.float64) ** (1 / gamma), c[:, 3:]], 1) * 255 + 0.5)
    assert np.abs(out.astype(int) - ref).max() <= 1
    assert out[0, 0] == 0 and out[1].tolist() == [255] * 4


@pytest.mark.parametrize("specular, shininess", [(0.18, 32.0), (1.0, 1.0), (5.0, 200.0), (1e-3, 0.5), (0.0, 8.0)])
def test_the_highlight_cut_drops_only_terms_under_2_to_the_minus_64(specular, shininess):
    cut = highlight_cut(specular, shininess)
    if specular == 0:
        assert cut == math.inf
        return
    assert 0 <= cut <= 1
    assert specular * np.float64(np.float32(cut)) ** shininess <= 2.0 ** -64 * (1 + 1e-5)
    assert specular * min(1.0, cut * 1.01) ** shininess > 2.0 ** -64 or cut * 1.01 >= 1


def test_no_highlight_cut_for_shininess_0():
    assert highlight_cut(0.18, 0.0) == -1.0
