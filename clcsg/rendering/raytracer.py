"""The exact CSG ray tracer on the tape (``raytrace.cl``): the reference renderer.

:func:`raytrace` compiles a scene (or takes the tape of :class:`~clcsg.sampling.samples.Samples`)
and traces one ray per pixel: the tape is first pruned per 16 x 16 tile over the part of the
tile's frustum inside the scene bound (so a ray tests only the leaves near it), then every
root along the ray is tried in depth order until one is on the CSG surface (the membership
with the root's quadric substituted differs between its two sides).  Exact from any eye
position, inside the solid included.
"""

from __future__ import annotations

import time

import numpy as np

from ..compile.tape import Tape
from ..readers.scenes import as_scene
from ..cl.device import choose_real, context_of
from ..cl.programs import build, event_seconds, kernel
from ..cl.memory import device_buffer, upload
from ..cl.records import SceneBuffers, pack
from ..errors import UsageError
from .camera import Camera
from .image import Image
from .shading import Shading, pack_view
from .supersample import supersample

TILE = 16
#: fixed work-group shape of the per-pixel kernels (raytrace, resolve): PoCL compiles a kernel
#: variant per work-group size, so one chosen by the runtime per image size would cost a
#: compilation (about half a second) at every new size, e.g. each time a viewer window resizes
PIXEL_GROUP = (16, 4)


def pixel_range(width: int, height: int) -> tuple[tuple[int, int], tuple[int, int]]:
    """(global, local) sizes of a per-pixel kernel: the image rounded up to whole
    :data:`PIXEL_GROUP` groups (the kernels skip the pixels outside it)."""
    gx, gy = PIXEL_GROUP
    return (-(-width // gx) * gx, -(-height // gy) * gy), PIXEL_GROUP


def as_tape(obj, normal_form: str = "tree"):
    """A :class:`~clcsg.compile.tape.Tape` from a Tape, Samples, Scene, Shape or scene file path."""
    if isinstance(obj, Tape):
        return obj
    tape = getattr(obj, "tape", None)
    if isinstance(tape, Tape):
        return tape
    return as_scene(obj).compile(normal_form)


def camera_or_fit(camera, bound) -> Camera:
    if camera is None:
        return Camera.fit(bound)
    if not isinstance(camera, Camera):
        raise UsageError(f"camera must be a clcsg.Camera, got {type(camera).__name__}")
    return camera


def raytrace(scene, camera: Camera | None = None, device=None, background=(1.0, 1.0, 1.0),
             precision: str = "auto", normal_form: str = "tree", aa: int = 1, **shading) -> Image:
    """Exact ray tracing of a CSG scene (the reference renderer).

    ``scene``: a Shape, Scene, scene file path, Tape or Samples (its tape is traced).
    ``camera``: a :class:`~clcsg.Camera` (default: :meth:`Camera.fit` to the scene bound at
    640x480).  ``device``: None (default device), a spec string (``"cpu"``, ``"0:1"``) or a
    Context.  ``background``: RGBA/RGB in [0, 1].  ``precision``: ``"auto"`` (double where the
    device has fp64), ``"double"`` or ``"float"``.  ``normal_form``: ``"tree"`` or ``"dnf"``
    (the same image either way).  ``aa``: N x N supersampling (see :func:`clcsg.render`).
    Further keywords are :class:`~clcsg.rendering.shading.Shading` options (ambient, diffuse,
    specular, shininess, gamma, key).
    """
    tape = as_tape(scene, normal_form)
    cam = camera_or_fit(camera, tape.bound)
    shade = Shading().with_options(background=background, **shading)
    ctx = context_of(device)
    return supersample(lambda c: trace(ctx, tape, c, shade, precision), cam, aa, shade.gamma)


def trace(context, tape, camera, shading: Shading | None = None, precision="auto", origin=None) -> Image:
    """Ray trace ``tape`` from ``camera`` on ``context``."""
    import pyopencl as cl

    t_start = time.perf_counter()
    real = choose_real(context, precision)
    packed = pack(tape, real=real, origin=origin)
    scene = SceneBuffers(context, packed)
    W, H = camera.width, camera.height
    view_buf = upload(context, pack_view(camera, packed.origin, real, shading))
    q = context.queue
    depth = np.empty((H, W), dtype=np.float32)
    ids = np.empty((H, W), dtype=np.int32)
    prims = np.empty((H, W), dtype=np.int32)
    rgba = np.empty((H, W, 4), dtype=np.uint8)
    outs = [device_buffer(context, a.nbytes, "image", False, "render a smaller image") for a in (depth, ids, prims, rgba)]
    t_build = time.perf_counter()
    defines = {"TAPE_REGS": packed.n_regs, "TILE": TILE}
    prg = build(context, "rendering/raytrace.cl", defines, real)
    t_built = time.perf_counter()

    # per-tile pruning, with the overflow protocol of the sampler's arena
    ntx, nty = -(-W // TILE), -(-H // TILE)
    n = len(packed.tape)
    # padded by the rounding that moving the quadrics to the origin leaves (relative to the
    # world coordinates): a hit on a face of the bound must stay inside it
    pad = 1e-9 * (float(np.abs(tape.bound).max()) + float(np.linalg.norm(tape.bound[1] - tape.bound[0])))
    lo = (tape.bound[0] - packed.origin - pad).astype(real)
    hi = (tape.bound[1] - packed.origin + pad).astype(real)
    real3 = cl.cltypes.double3 if real == np.float64 else cl.cltypes.float3
    blo = np.array([(lo[0], lo[1], lo[2], 0)], dtype=real3)[0]
    bhi = np.array([(hi[0], hi[1], hi[2], 0)], dtype=real3)[0]
    tiles = upload(context, np.zeros(2 * ntx * nty, dtype=np.int32), writable=True)
    counters = np.zeros(3, dtype=np.uint32)
    cap = max(ntx * nty * min(n + 1, 64), 4 * (n + 1))
    while True:
        # from host memory: Oclgrind's uninitialized-value checker loses rows written into a
        # fresh buffer and read back by the same work-item
        arena = upload(context, np.zeros(cap, dtype=packed.tape.dtype), writable=True)
        counters[:] = 0
        counters_buf = upload(context, counters, writable=True)  # host data, not a write into a used buffer
        tile_range = ((-(-ntx // 4) * 4, -(-nty // 4) * 4), (4, 4))  # a fixed group shape, as PIXEL_GROUP
        ev_prune = kernel(prg, "prune_tiles")(q, *tile_range, scene.quadrics, scene.tape, np.int32(n), view_buf,
                                              blo, bhi, arena, np.uint32(cap), counters_buf, tiles)
        cl.enqueue_copy(q, counters, counters_buf, wait_for=[ev_prune])
        if int(counters[0]) <= cap:
            break
        cap = int(counters[0]) + int(counters[0]) // 2
    ev = kernel(prg, "raytrace")(q, *pixel_range(W, H), scene.quadrics, arena, blo, bhi, tiles, *scene.colour_args(),
                                 view_buf, *outs)
    for a, b in zip((depth, ids, prims, rgba), outs):
        cl.enqueue_copy(q, a, b, wait_for=[ev])
    q.finish()
    t_end = time.perf_counter()
    stats = {
        "method": "raytrace",
        "normal_form": tape.shape,
        "device": context.info.describe(),
        "precision": "double" if real == np.float64 else "float",
        "width": W,
        "height": H,
        "quadrics": tape.n_quadrics,
        "tape_instructions": int(n),
        "tile_tape_mean": int(counters[2]) / (ntx * nty),
        "prune_evaluations": int(counters[1]),
        "covered_pixels": int((ids >= 0).sum()),
        "prune_s": event_seconds(ev_prune),
        "kernel_s": event_seconds(ev) + event_seconds(ev_prune),
        "build_s": t_built - t_build,
        "total_s": t_end - t_start,
    }
    return Image(rgba, depth, ids, prims, stats)
