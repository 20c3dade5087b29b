"""The resolve pass's shortcuts in shade.h: the colour encoding through the per-view table gives
the bytes of the direct encoding (power functions), and the highlight cut drops no term above
2^-64."""

from __future__ import annotations

import math

import numpy as np
import pytest

from clcsg.cl import programs
from clcsg.cl.constants import SHADE_BINS
from clcsg.rendering.camera import Camera
from clcsg.rendering.shading import Shading, highlight_cut, pack_view

SRC = """
#include "shade.h"
__kernel void table(__global const view_rec *vw, __global ushort *out)
{
    int b = get_global_id(0);
    if (b <= SHADE_BINS) out[b] = shade_table_entry(vw, b);
}
__kernel void both(__global const view_rec *vw, __global const ushort *table, __global const float4 *c,
                   __global uchar4 *direct, __global uchar4 *tabled)
{
    int k = get_global_id(0);
    float4 x = c[k];
    direct[k] = shade_encode(vw, x.xyz, x.w);
    tabled[k] = shade_encode_table(vw, table, x.xyz, x.w);
}
"""


def colours(rng, n):
    """Random colours in [0, 1], the bins' ends and their float neighbours, and a NaN."""
    edges = np.arange(SHADE_BINS + 1, dtype=np.float32) / np.float32(SHADE_BINS)
    near = np.concatenate([edges, np.nextafter(edges, np.float32(0)), np.nextafter(edges, np.float32(1))])
    near = np.clip(near, 0, 1).astype(np.float32)
    c = rng.random((n, 4), dtype=np.float32)
    c[:, :3] **= 3  # many dark values, where the bytes are densest
    e = np.stack([near, rng.permutation(near), rng.permutation(near), rng.random(len(near), dtype=np.float32)], 1)
    c = np.concatenate([c, e]).astype(np.float32)
    c[0, 1] = np.nan
    return c


@pytest.mark.parametrize("gamma", [2.2, 1.0, 0.45, 3.7])
def test_the_encoding_table_gives_the_direct_bytes(cl_context, gamma):
    import pyopencl as cl

    real = np.float64 if cl_context.info.fp64 else np.float32
    opts = programs.build_options(real=real) + ["-I", programs.package_dir("cl/include"),
                                                "-I", programs.package_dir("rendering")]
    prg = cl.Program(cl_context.ctx, programs._wrapped(cl_context, SRC)).build(options=opts)
    q = cl_context.queue
    view = pack_view(Camera.look_at((3, 2, 1), (0, 0, 0), width=8, height=8), np.zeros(3), real,
                     Shading().with_options(gamma=gamma))
    mf = cl.mem_flags
    vbuf = cl.Buffer(cl_context.ctx, mf.READ_ONLY | mf.COPY_HOST_PTR, hostbuf=view)
    table = np.empty(SHADE_BINS + 1, np.uint16)
    tbuf = cl.Buffer(cl_context.ctx, mf.READ_WRITE, table.nbytes)
    prg.table(q, (SHADE_BINS + 1,), None, vbuf, tbuf)
    cl.enqueue_copy(q, table, tbuf)
    assert table[SHADE_BINS] == 255
    assert 0 < np.mean(table == 0x100) < 0.2  # split bins exist, and are few
    c = colours(np.random.default_rng(7), 200_000)
    cbuf = cl.Buffer(cl_context.ctx, mf.READ_ONLY | mf.COPY_HOST_PTR, hostbuf=c)
    direct, tabled = np.empty((len(c), 4), np.uint8), np.empty((len(c), 4), np.uint8)
    dbuf, xbuf = (cl.Buffer(cl_context.ctx, mf.WRITE_ONLY, direct.nbytes) for _ in range(2))
    prg.both(q, (len(c),), None, vbuf, tbuf, cbuf, dbuf, xbuf)
    cl.enqueue_copy(q, direct, dbuf)
    cl.enqueue_copy(q, tabled, xbuf)
    assert np.array_equal(direct, tabled)
    # and the direct bytes are the encoding (float64 reference, one level of rounding slack)
    ok = np.isfinite(c).all(axis=1)
    ref = np.floor(np.concatenate([c[ok, :3] ** (1 / gamma), c[ok, 3:]], 1) * 255 + 0.5)
    assert np.abs(direct[ok].astype(int) - ref).max() <= 1


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
