"""Occupancy and conservative signed distance at given points, on the device (``query.cl``).

Both queries run the scene's root tape (:mod:`clcsg.compile.tape`) once per point, without
substitution:

* :func:`inside`: the tape over booleans, each leaf (q, s) the closed test ``s K_q(p) <= 0``:
  membership of the closed solid (a point on the surface of a subtracted solid is outside,
  as in :func:`clcsg.contains`).
* :func:`distance`: the tape over reals, each leaf ``s d_q(p)`` with d_q the conservative
  distance of quadric q (negative where K_q < 0, ``|d_q(p)|`` at most the distance from p to
  the zero set of K_q), AND = max, OR = min.  The result f is a *signed lower bound*: f < 0
  inside, f > 0 outside, f = 0 only where a leaf is 0, and ``|f(p)| <= dist(p, boundary)``.
  By induction over the tape: for an operand with value a the open ball B(p, |a|) lies
  entirely inside the operand's solid if a < 0 and entirely outside if a > 0 (true for a leaf,
  whose quadric keeps its sign within |d_q|).  For max(a, b) < 0 both are < 0 and the smaller
  ball B(p, min(|a|, |b|)) is in both solids, so in the intersection; for max(a, b) = a > 0,
  B(p, a) misses the first solid, so the intersection; min is the same with the roles of
  inside and outside exchanged.  So B(p, |f|) holds no boundary point.

Points are given in world coordinates (float64) and shifted to the device's coordinates
(world - the bound's center) before the cast to the device's precision.  The solid may be
unbounded (a complement, a half-space): the queries need no bound.
"""

from __future__ import annotations

import numpy as np

from ..cl.device import context_of, real_dtype
from ..cl.programs import build, kernel
from ..cl.records import SceneBuffers, pack
from ..errors import UnboundedError, UsageError
from ..readers.scenes import as_scene

#: points per kernel launch (bounds the device buffers)
CHUNK = 1 << 20


def _tape(scene, pts):
    """The root tape of a Shape, Scene, scene file path, Tape or Samples.  The tree tape does
    not depend on the bound (it only frames sampling and rendering), so an unbounded solid is
    compiled with the box of the query points as its bound."""
    if hasattr(scene, "ops") and hasattr(scene, "quadrics") and hasattr(scene, "n_regs"):
        return scene
    if hasattr(scene, "tape") and hasattr(scene, "positions"):
        return scene.tape
    sc = as_scene(scene)
    try:
        return sc.compile()
    except UnboundedError:
        box = np.array([pts.min(0), pts.max(0)]) if len(pts) else np.array([[-1.0] * 3, [1.0] * 3])
        return as_scene(sc, box + [[-1.0], [1.0]]).compile()


def _points(points) -> tuple[np.ndarray, tuple]:
    try:
        p = np.asarray(points, dtype=np.float64)
    except (TypeError, ValueError):
        raise UsageError("points must be numbers, an array of shape (..., 3)") from None
    if p.ndim == 0 or p.shape[-1] != 3:
        raise UsageError(f"points must have shape (..., 3), got {p.shape}")
    if not np.isfinite(p).all():
        raise UsageError("points must be finite")
    return p.reshape(-1, 3), p.shape[:-1]


def _run(scene, points, device, kernel_name: str, out_dtype):
    """Kernel ``kernel_name`` of ``query.cl`` over ``points``; one output per point."""
    import pyopencl as cl

    pts, shape = _points(points)
    tape = _tape(scene, pts)
    ctx = context_of(device)
    real = np.dtype(real_dtype(ctx))
    out_dtype = real if out_dtype is None else np.dtype(out_dtype)
    result = np.zeros(len(pts), dtype=out_dtype)
    if len(pts) == 0:
        return result.reshape(shape)
    packed = pack(tape, real)
    buffers = SceneBuffers(ctx, packed)
    prg = build(ctx, "queries/query.cl", {"TAPE_REGS": max(1, tape.n_regs)}, real)
    k = kernel(prg, kernel_name)
    mf = cl.mem_flags
    n = min(CHUNK, len(pts))
    pbuf = cl.Buffer(ctx.ctx, mf.READ_ONLY, n * 3 * real.itemsize)
    obuf = cl.Buffer(ctx.ctx, mf.WRITE_ONLY, n * out_dtype.itemsize)
    for lo in range(0, len(pts), CHUNK):
        chunk = np.ascontiguousarray(pts[lo:lo + CHUNK] - packed.origin, dtype=real)
        m = len(chunk)
        # kept until the blocking read: pyopencl waits for a dropped transfer's event at once
        written = cl.enqueue_copy(ctx.queue, pbuf, chunk, is_blocking=False)
        k(ctx.queue, (m,), None, buffers.quadrics, buffers.tape, np.int32(len(tape.ops)), pbuf, np.int32(m), obuf)
        cl.enqueue_copy(ctx.queue, result[lo:lo + m], obuf)
        del written
    ctx.queue.finish()
    return result.reshape(shape)


def inside(scene, points, device=None) -> np.ndarray:
    """Membership of ``points`` (..., 3) in the closed solid of ``scene`` (a Shape, Scene, scene
    file path, Tape or Samples): a bool array of shape (...).  ``device`` as in
    :func:`clcsg.sample`."""
    return _run(scene, points, device, "query_inside", np.uint8).astype(bool)


def distance(scene, points, device=None) -> np.ndarray:
    """A conservative signed distance at ``points`` (..., 3): negative inside the solid,
    positive outside, and never larger in absolute value than the distance to the surface
    (see the module docstring); float64 array of shape (...), computed in the device's
    precision (float32 where the device has no fp64)."""
    return _run(scene, points, device, "query_distance", None).astype(np.float64)
