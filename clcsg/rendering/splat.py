"""Host side of the splat renderer (paper section 6): ``kernels/splat.cl`` rasterizes every
sample into a 64-bit depth|index framebuffer, ``kernels/resolve.cl`` recomputes the winning
hit per pixel and shades it.  The public entry point is :func:`clcsg.render.render`.

Statistics (``Image.stats``; counters only with ``stats=True``):

=====================  ===========================================================================
splats_drawn           samples whose screen bound is not empty
splats_culled          samples skipped by the per-splat back-face test
splats_offscreen       samples whose bound misses the screen (or is behind the eye)
bound_pixels           pixels visited in the splats' screen bounds
fragments              ray-quadric solves (rays that pass the ball / box test)
clip_evaluations       clip-set quadric evaluations
fragments_passed       fragments that passed radius, clip and back-face tests (depth tests)
atomics                atom_min calls (after the plain read)
covered_pixels         pixels showing the surface
overdraw               fragments per covered pixel
=====================  ===========================================================================
"""

from __future__ import annotations

import time

import numpy as np

from ..errors import UsageError

COUNTERS = (
    "splats_drawn",
    "splats_culled",
    "splats_offscreen",
    "bound_pixels",
    "fragments",
    "clip_evaluations",
    "fragments_passed",
    "atomics",
)

EMPTY = np.uint64(0xFFFFFFFFFFFFFFFF)


def _buffers(samples, context, real):
    """(SceneBuffers, sample buffer, clip buffer) in precision ``real``."""
    import pyopencl as cl

    from ..cl.records import LITERAL_DTYPE, SceneBuffers, pack, sample_dtype

    if np.dtype(samples.packed.real) == real:
        return samples.device_buffers(context)
    packed = pack(samples.dnf, real=real, origin=samples.packed.origin)
    src = samples.records()
    rec = np.zeros(len(src), dtype=sample_dtype(real))
    for name in src.dtype.names:
        rec[name] = src[name]
    clip = np.zeros(len(samples.clip_literals), dtype=LITERAL_DTYPE)
    if len(clip):
        clip["quadric"] = samples.clip_literals[:, 0]
        clip["sign"] = samples.clip_literals[:, 1]
    mf = cl.mem_flags

    def up(a):
        data = a if a.size else np.zeros(1, dtype=a.dtype)
        return cl.Buffer(context.ctx, mf.READ_ONLY | mf.COPY_HOST_PTR, hostbuf=data)

    return SceneBuffers(context, packed), up(rec), up(clip)


def eye_inside(dnf, eye) -> bool:
    """Is the eye inside (or on) the solid?  Back-face culling is only valid from outside."""
    if not dnf.n_terms:
        return False
    return bool(dnf.contains(np.asarray(eye, dtype=np.float64).reshape(1, 3))[0])


def rasterize(context, samples, camera, shading=None, precision="auto", surface_aligned=True,
              backface_culling=True, stats=True):
    """Render ``samples`` from ``camera``; returns a :class:`clcsg.image.Image`."""
    import pyopencl as cl

    from .image import Image
    from ..cl import programs
    from ..cl.device import require_int64_atomics
    from .raytracer import choose_real, event_seconds, kernel, pack_view

    require_int64_atomics(context, "the splat renderer (64-bit atom_min depth test)")
    if len(samples) >= 1 << 31:
        raise UsageError(f"too many samples for the kernel's int splat index: {len(samples)}")
    t_start = time.perf_counter()
    real = choose_real(context, precision)
    culling = bool(backface_culling)
    culling_note = None
    if culling and eye_inside(samples.dnf, camera.eye):
        culling, culling_note = False, "off: the eye is inside the solid"
    scene, sample_buf, clip_buf = _buffers(samples, context, real)
    W, H = camera.width, camera.height
    view = pack_view(camera, samples.packed.origin, real, shading)
    mf = cl.mem_flags
    ctx, q = context.ctx, context.queue
    view_buf = cl.Buffer(ctx, mf.READ_ONLY | mf.COPY_HOST_PTR, hostbuf=view)
    fb = cl.Buffer(ctx, mf.READ_WRITE, W * H * 8)
    counters = np.zeros(len(COUNTERS), dtype=np.uint64)
    cnt_buf = cl.Buffer(ctx, mf.READ_WRITE | mf.COPY_HOST_PTR, hostbuf=counters)
    depth = np.empty((H, W), dtype=np.float32)
    ids = np.empty((H, W), dtype=np.int32)
    rgba = np.empty((H, W, 4), dtype=np.uint8)
    d_buf = cl.Buffer(ctx, mf.WRITE_ONLY, depth.nbytes)
    i_buf = cl.Buffer(ctx, mf.WRITE_ONLY, ids.nbytes)
    c_buf = cl.Buffer(ctx, mf.WRITE_ONLY, rgba.nbytes)

    t_build = time.perf_counter()
    defines = {
        "SURFACE_ALIGNED": int(bool(surface_aligned)),
        "BACKFACE_CULLING": int(culling),
        "CLCSG_STATS": int(bool(stats)),
    }
    splat_prg = programs.build(context, "rendering/splat.cl", defines=defines, real=real)
    resolve_prg = programs.build(context, "rendering/resolve.cl", real=real)
    t_built = time.perf_counter()

    ev_clear = cl.enqueue_fill_buffer(q, fb, EMPTY, 0, W * H * 8)
    n = len(samples)
    events = [ev_clear]
    if n:
        ev_splat = kernel(splat_prg, "splat")(
            q, (n,), None, scene.quadrics, sample_buf, np.int32(n), clip_buf, view_buf, fb, cnt_buf,
            wait_for=[ev_clear],
        )
        events.append(ev_splat)
    ev_resolve = kernel(resolve_prg, "resolve")(
        q, (W, H), None, scene.quadrics, sample_buf, view_buf, fb, d_buf, i_buf, c_buf, wait_for=events[-1:]
    )
    cl.enqueue_copy(q, depth, d_buf, wait_for=[ev_resolve])
    cl.enqueue_copy(q, ids, i_buf, wait_for=[ev_resolve])
    cl.enqueue_copy(q, rgba, c_buf, wait_for=[ev_resolve])
    cl.enqueue_copy(q, counters, cnt_buf, wait_for=events[-1:])
    q.finish()
    t_end = time.perf_counter()

    covered = int((ids >= 0).sum())
    st = {
        "method": "splat",
        "device": context.info.describe(),
        "precision": "double" if real == np.float64 else "float",
        "width": W,
        "height": H,
        "samples": n,
        "radius": float(samples.radius),
        "surface_aligned": bool(surface_aligned),
        "backface_culling": culling,
        "covered_pixels": covered,
        "splat_seconds": event_seconds(events[-1]) if n else 0.0,
        "resolve_seconds": event_seconds(ev_resolve),
        "build_seconds": t_built - t_build,
        "total_seconds": t_end - t_start,
    }
    if culling_note:
        st["backface_culling_note"] = culling_note
    if stats:
        st.update({name: int(v) for name, v in zip(COUNTERS, counters)})
        st["overdraw"] = st["fragments"] / covered if covered else 0.0
    st["kernel_seconds"] = st["splat_seconds"] + st["resolve_seconds"]
    return Image(rgba, depth, ids, st)
