"""The splat renderer (paper section 6): ``splat.cl`` rasterizes every sample into a 64-bit
depth|index framebuffer with local ray tracing and clipping by tape, ``resolve.cl`` recomputes
the winning hit per pixel and shades it in its primitive's colour.  Entry point: :func:`render`.

Statistics (``Image.stats``; counters only with ``stats=True``):

=====================  ===========================================================================
splats_drawn           samples whose screen bound is not empty
splats_culled          samples skipped by the per-splat back-face test (asked first)
splats_offscreen       samples not culled whose bound misses the screen (or is behind the eye)
bound_pixels           pixels visited in the splats' screen bounds
fragments              rays of a row's span (the rays meeting the ball and slab, grown by a
                       margin) that meet the ball
fragments_occluded     of those, rays skipped without a solve: their chord through the ball
                       starts behind the pixel's stored depth (early depth rejection)
clip_evaluations       clip-set quadric evaluations
fragments_passed       fragments that passed radius, clip and back-face tests and were nearer
                       than the pixel's word when read (depth tests; one already beaten is
                       dropped before its clip test)
atomics                atom_min calls (after the plain read)
covered_pixels         pixels showing the surface
overdraw               fragments per covered pixel
=====================  ===========================================================================
"""

from __future__ import annotations

import time

import numpy as np

from ..cl.constants import EMPTY_KEY, RESOLVE_LANES, SPLAT_COUNTERS
from ..cl.device import choose_real, context_of, require_int64_atomics
from ..cl.programs import build, event_seconds, kernel
from ..cl.memory import device_buffer, upload
from ..errors import UsageError
from .image import Image
from .raytracer import camera_or_fit, pixel_range
from .shading import Shading, pack_view
from .supersample import supersample
from ..compile.interpret import contains

#: fixed work-group size of the splat pass (see raytracer.PIXEL_GROUP: a size chosen by the
#: runtime would recompile the kernel for every new sample count)
SPLAT_GROUP = 64


def render(samples, camera=None, device=None, background=(1.0, 1.0, 1.0), precision: str = "auto",
           surface_aligned: bool = True, backface_culling: bool = True, stats: bool = True, aa: int = 1,
           **shading) -> Image:
    """Pixel-perfect splat rendering of :class:`~clcsg.Samples` (paper section 6).

    Per sample, one work-item loops over the screen bound of its splat; per pixel it solves
    the view ray against the sample's quadric near the sample (eqs. 5, 6), keeps the hit if it
    lies within the sample's radius and its clip program says it is on the CSG surface, and
    depth-tests it with a 64-bit ``atom_min``; a resolve pass recomputes the winning hit and
    shades it like :func:`clcsg.raytrace`.

    ``surface_aligned``: bound each splat by a box aligned with its normal whose height comes
    from the eigenvalue bound of the patch (paper section 6.1) instead of the whole ball.
    ``backface_culling``: skip splats and fragments that face away from the eye (only valid
    from outside; turned off automatically when the eye is inside the solid).  ``stats``:
    count fragments, clip evaluations, ... with atomic counters (``Image.stats``; off is a
    little faster).  ``aa``: N x N supersampling (:mod:`clcsg.rendering.supersample`: colours
    averaged in linear light, depth and ids those of the pixel centre).  Other arguments as in
    :func:`clcsg.raytrace`.  Requires 64-bit atomics (``cl_khr_int64_extended_atomics``), else
    :class:`~clcsg.errors.DeviceError`.
    """
    if not hasattr(samples, "device_buffers"):
        raise UsageError(f"render needs Samples (see clcsg.sample), got {type(samples).__name__}")
    cam = camera_or_fit(camera, samples.tape.bound)
    shade = Shading().with_options(background=background, **shading)
    ctx = context_of(device)

    def render_at(c):
        return rasterize(ctx, samples, c, shade, precision, surface_aligned, backface_culling, stats)

    return supersample(render_at, cam, aa, shade.gamma)


def eye_inside(tape, eye) -> bool:
    """Is the eye inside (or on) the solid?  Back-face culling is only valid from outside."""
    if tape.empty:
        return False
    if hasattr(tape, "contains"):  # a tape with point operands classifies by its surfels
        return bool(tape.contains(np.asarray(eye, dtype=np.float64).reshape(1, 3))[0])
    return bool(contains(tape.ops, tape.quadrics, np.asarray(eye, dtype=np.float64).reshape(1, 3))[0])


#: the per-pixel outputs of a render, in kernel order (:class:`~clcsg.rendering.image.Image`)
OUTPUTS = ("depth", "ids", "primitives", "rgba")


def _albedo_table(context, resolve_prg, scene, view_buf):
    """The per-view table the resolve pass reads: each primitive's albedo (and the fallback's,
    last); (albedo, its events).  It starts from host zeros (a few kB), which Oclgrind's
    uninitialized-value check follows into the kernel that fills it."""
    q = context.queue
    n_prims = len(scene.packed.prims)
    albedo = upload(context, np.zeros((n_prims + 1) * 4, np.float32), writable=True, what="albedo table")
    ev_albedo = kernel(resolve_prg, "albedo")(q, (-(-(n_prims + 1) // 64) * 64,), (64,), scene.prims,
                                              np.int32(n_prims), view_buf, albedo)
    return albedo, [ev_albedo]


def rasterize(context, samples, camera, shading=None, precision="auto", surface_aligned=True,
              backface_culling=True, stats=True, read=OUTPUTS) -> Image:
    """Render ``samples`` from ``camera`` on ``context``; ``read``: the outputs copied back
    (others are None in the Image; ``rgba`` and ``ids`` always)."""
    import pyopencl as cl

    require_int64_atomics(context, "the splat renderer (64-bit atom_min depth test)")
    if len(samples) >= 1 << 31:
        raise UsageError(f"too many samples for the kernel's int splat index: {len(samples)}")
    t_start = time.perf_counter()
    real = choose_real(context, precision)
    culling = bool(backface_culling)
    culling_note = None
    if culling and eye_inside(samples.tape, camera.eye):
        culling, culling_note = False, "off: the eye is inside the solid"
    scene, sample_buf, clip_buf, ids_buf = samples.device_buffers(context, real)
    W, H = camera.width, camera.height
    q = context.queue
    view_buf = upload(context, pack_view(camera, scene.packed.origin, real, shading))
    hint = "render a smaller image"
    fb = device_buffer(context, W * H * 8, "framebuffer", hint=hint)
    counters = np.zeros(len(SPLAT_COUNTERS), dtype=np.uint64)
    cnt_buf = upload(context, counters, writable=True)
    depth = np.empty((H, W), dtype=np.float32)
    ids = np.empty((H, W), dtype=np.int32)
    prims = np.empty((H, W), dtype=np.int32)
    rgba = np.empty((H, W, 4), dtype=np.uint8)
    outs = [device_buffer(context, a.nbytes, "image", False, hint) for a in (depth, ids, prims, rgba)]

    t_build = time.perf_counter()
    defines = {
        "SURFACE_ALIGNED": int(bool(surface_aligned)),
        "BACKFACE_CULLING": int(culling),
        "CLCSG_STATS": int(bool(stats)),
        "TAPE_REGS": scene.packed.n_regs,
    }
    splat_prg = build(context, "rendering/splat.cl", defines=defines, real=real)
    resolve_prg = build(context, "rendering/resolve.cl", real=real)
    t_built = time.perf_counter()

    ev_clear = cl.enqueue_fill_buffer(q, fb, np.uint64(EMPTY_KEY), 0, W * H * 8)
    n = len(samples)
    events = [ev_clear]
    if n:
        events.append(kernel(splat_prg, "splat")(
            q, (-(-n // SPLAT_GROUP) * SPLAT_GROUP,), (SPLAT_GROUP,), scene.quadrics, sample_buf, np.int32(n),
            clip_buf, view_buf, fb, cnt_buf,
            wait_for=[ev_clear]))
    n_prims = len(scene.packed.prims)
    albedo, table_events = _albedo_table(context, resolve_prg, scene, view_buf)
    ev_resolve = kernel(resolve_prg, "resolve")(
        q, *pixel_range(-(-W // RESOLVE_LANES), H), scene.quadrics, sample_buf, ids_buf, *scene.colour_args(), view_buf,
        fb, albedo,
        np.int32(n_prims), *outs, wait_for=events[-1:] + table_events)
    wanted = set(read) | {"ids", "rgba"}
    # kept until the finish: pyopencl waits for a dropped host transfer's event at once
    reads = [cl.enqueue_copy(q, a, b, wait_for=[ev_resolve], is_blocking=False)
             for name, a, b in zip(OUTPUTS, (depth, ids, prims, rgba), outs) if name in wanted]
    depth = depth if "depth" in wanted else None
    prims = prims if "primitives" in wanted else None
    reads.append(cl.enqueue_copy(q, counters, cnt_buf, wait_for=events[-1:], is_blocking=False))
    q.finish()
    t_end = time.perf_counter()

    covered = int((ids >= 0).sum())
    st = {
        "method": "splat", "device": context.info.describe(), "precision": "double" if real == np.float64 else "float",
        "width": W, "height": H, "samples": n, "radius": float(samples.radius),
        "surface_aligned": bool(surface_aligned), "backface_culling": culling, "covered_pixels": covered,
        "splat_s": event_seconds(events[-1]) if n else 0.0, "resolve_s": event_seconds(ev_resolve),
        "build_s": t_built - t_build, "total_s": t_end - t_start,
    }
    if culling_note:
        st["backface_culling_note"] = culling_note
    if stats:
        st.update({name: int(v) for name, v in zip(SPLAT_COUNTERS, counters)})
        st["overdraw"] = st["fragments"] / covered if covered else 0.0
    st["kernel_s"] = st["splat_s"] + st["resolve_s"]
    return Image(rgba, depth, ids, prims, st)
