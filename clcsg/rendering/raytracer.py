"""The exact CSG ray tracer on the tape (``tiles.cl``, ``raytrace.cl``): the reference renderer.

:func:`raytrace` compiles a scene (or takes the tape of :class:`~clcsg.sampling.samples.Samples`)
and traces one ray per pixel.  The tape is first pruned per super-tile of :data:`SUPER_TILE`
x :data:`SUPER_TILE` tiles, then per 16 x 16 tile from its super-tile's tape, each over the part
of its frustum inside the scene bound, then per depth slab of the tile (:data:`SLABS` equal
slabs, each pruned from the tape of the slab pair holding it, that from its pair's, and so on up
to the tile's tape; its leaves renumbered to its own quadric list), so a
ray meets only the leaves near the stretch it walks.  Per ray and slab, front to back, each
listed quadric whose culling box (:mod:`~clcsg.rendering.ray_culling`) the ray's stretch meets
is solved once (the others keep one known sign along it); its roots classify its sign along the
whole ray.  The slab tape is pruned over the stretch (quadrics without a root in it become
constants), and the roots in the slab are visited in depth order until one is on the CSG
surface (the membership with the root's quadric substituted differs between its two sides, the
other leaves taken from the classification); past the first few, the rest of the stretch is
searched by bisection, a window whose pruned tape is constant holding no surface.  Exact from
any eye position, inside the solid included; the cost per ray is a box test per listed
quadric, a solve per quadric whose box it meets, and a pass over the slab tape per visited
root for the first few, then per window, not roots x leaves.  A work-item
traces :data:`~clcsg.cl.constants.RAY_LANES` neighbouring pixels of a row: the arithmetic that
does not branch (view rays, stretches, box tests, a slab's solves) runs on vectors over them with
the bits of the per-ray code, and their hits are shaded together.
"""

from __future__ import annotations

import time

import numpy as np

from ..compile.tape import Tape
from ..readers.scenes import as_scene
from ..cl.constants import RAY_LANES
from ..cl.device import choose_real, context_of
from ..cl.programs import build, event_seconds, kernel
from ..cl.memory import device_buffer, upload
from ..cl.records import TAPE_OP_DTYPE, SceneBuffers, pack
from ..errors import UsageError
from .camera import Camera
from .image import Image
from .ray_culling import cull_boxes
from .shading import Shading, pack_view
from .supersample import supersample

TILE = 16
#: tiles per side of a super-tile: the tape is pruned per super-tile first, each tile from its
#: super-tile's tape
SUPER_TILE = 4
#: depth slabs per tile, each with its own pruned tape: the leaves of a binary tree of depth
#: ranges over the tile's (each node's tape pruned from its parent's), so a power of two
SLABS = 8
SLAB_LEVELS = SLABS.bit_length() - 1
assert 1 << SLAB_LEVELS == SLABS
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
    """The :class:`~clcsg.compile.tape.Tape` to trace (:meth:`~clcsg.compile.tape.Tape.exact`)
    of a Tape, Samples, Scene, Shape or scene file path."""
    if isinstance(obj, Tape):
        return obj.exact()
    tape = getattr(obj, "tape", None)
    if isinstance(tape, Tape):
        return tape.exact()
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


def _grown(run, caps):
    """The sampler's overflow protocol: ``run(caps)`` returns the rows each buffer needed; it is
    re-run with larger buffers until all fit.  Returns the last result and the caps."""
    while True:
        result, need = run(caps)
        if all(n <= c for n, c in zip(need, caps)):
            return result, caps
        caps = [max(c, n + n // 2) for c, n in zip(caps, need)]


def _bound_args(tape, packed, real):
    """The scene bound in device coordinates as real3 kernel arguments, padded by the rounding
    that moving the quadrics to the origin leaves (a hit on a face of the bound stays in it)."""
    import pyopencl as cl

    pad = 1e-9 * (float(np.abs(tape.bound).max()) + float(np.linalg.norm(tape.bound[1] - tape.bound[0])))
    lo = (tape.bound[0] - packed.origin - pad).astype(real)
    hi = (tape.bound[1] - packed.origin + pad).astype(real)
    real3 = cl.cltypes.double3 if real == np.float64 else cl.cltypes.float3
    return (np.array([(lo[0], lo[1], lo[2], 0)], dtype=real3)[0], np.array([(hi[0], hi[1], hi[2], 0)], dtype=real3)[0])


def _rows_buffer(context, n: int, dtype, what: str):
    """An arena of ``n`` rows of ``dtype``: on Oclgrind zeroed from host memory (its
    uninitialized-value checker loses rows written into a fresh buffer and read back by the
    same work-item), elsewhere uninitialized (zeroing a large arena only costs time: a grazing
    view of a 2,500-hole plate has 0.9 GiB of tile tapes)."""
    nbytes = max(int(n), 1) * np.dtype(dtype).itemsize
    if context.info.is_oclgrind:
        return upload(context, np.zeros(max(int(n), 1), dtype=dtype), writable=True, what=what)
    return device_buffer(context, nbytes, what, hint="render a smaller image")


def prune_tiles(context, scene, view_buf, bound, width, height, real):
    """The super-tile tapes, the tile tapes, then the depth-slab tapes of every tile (tiles.cl).
    Returns the buffers of the ray kernel (slab arena, quadric lists, tile depth ranges, slab records), the largest
    slab quadric list, the kernel events and counters."""
    import pyopencl as cl

    q = context.queue
    prg = build(context, "rendering/tiles.cl", {"TAPE_REGS": scene.packed.n_regs, "TILE": TILE, "SLABS": SLABS,
                                                  "SLAB_LEVELS": SLAB_LEVELS, "SUPER_TILE": SUPER_TILE},
                real)
    ntx, nty = -(-width // TILE), -(-height // TILE)
    nt, n = ntx * nty, len(scene.packed.tape)
    # zeroed from host memory: tiles off the bound get no entries from the pruning kernels, and
    # Oclgrind's uninitialized-value checker trusts only host-initialized or written bytes
    tiles = upload(context, np.zeros(8 * nt, np.uint8), writable=True, what="tile tapes")
    tile_z = upload(context, np.zeros(2 * np.dtype(real).itemsize * nt, np.uint8), writable=True, what="tile depths")
    slabs = upload(context, np.zeros(16 * nt * SLABS, np.uint8), writable=True, what="slab tapes")
    counters = np.zeros(6, dtype=np.uint32)

    span = TILE * SUPER_TILE
    nsx, nsy = -(-width // span), -(-height // span)
    sup = upload(context, np.zeros(8 * nsx * nsy, np.uint8), writable=True, what="super-tile tapes")
    sup_z = upload(context, np.zeros(2 * np.dtype(real).itemsize * nsx * nsy, np.uint8), writable=True,
                   what="super-tile depths")

    def run_super(caps):
        arena = _rows_buffer(context, caps[0], TAPE_OP_DTYPE, "super-tile tapes")
        cbuf = upload(context, np.zeros(6, dtype=np.uint32), writable=True)
        rng = ((-(-nsx // 4) * 4, -(-nsy // 4) * 4), (4, 4))
        ev = kernel(prg, "prune_supertiles")(q, *rng, scene.quadrics, scene.tape, np.int32(n), view_buf, *bound,
                                             arena, np.uint32(caps[0]), cbuf, sup, sup_z)
        cl.enqueue_copy(q, counters, cbuf, wait_for=[ev])
        return (arena, ev), [int(counters[0])]

    (sup_arena, ev_super), _ = _grown(run_super, [nsx * nsy * (n + 1)])
    super_evals = int(counters[1])

    def run_tiles(caps):
        arena = _rows_buffer(context, caps[0], TAPE_OP_DTYPE, "tile tapes")
        cbuf = upload(context, np.zeros(6, dtype=np.uint32), writable=True)
        rng = ((-(-ntx // 4) * 4, -(-nty // 4) * 4), (4, 4))  # a fixed group shape, as PIXEL_GROUP
        ev = kernel(prg, "prune_tiles")(q, *rng, scene.quadrics, sup_arena, sup, sup_z, view_buf, *bound, arena,
                                        np.uint32(caps[0]), cbuf, tiles, tile_z)
        cl.enqueue_copy(q, counters, cbuf, wait_for=[ev])
        return (arena, ev), [int(counters[0])]

    (tile_arena, ev_tiles), _ = _grown(run_tiles, [max(nt * min(n + 1, 64), 4 * (n + 1))])
    tile_rows = int(counters[2])
    stats = {"tile_tape_mean": tile_rows / nt, "tile_leaves_max": int(counters[3]),
             "prune_evaluations": super_evals + int(counters[1])}
    work = -(-nt // 64) * 64
    scratch_rows = SLAB_LEVELS * (tile_rows + SLAB_LEVELS * nt) + 1  # SLAB_LEVELS blocks per tile (tiles.cl)
    scratch = _rows_buffer(context, scratch_rows, TAPE_OP_DTYPE, "slab scratch")

    def run_slabs(caps):
        arena = _rows_buffer(context, caps[0], TAPE_OP_DTYPE, "slab tapes")
        qlist = _rows_buffer(context, caps[1], np.int32, "slab quadric lists")
        cbuf = upload(context, np.zeros(6, dtype=np.uint32), writable=True)
        ev = kernel(prg, "prune_slabs")(q, (work,), (64,), scene.quadrics, tile_arena, tiles, tile_z, view_buf,
                                        *bound, np.int32(nt), scratch, np.uint32(scratch_rows), arena,
                                        np.uint32(caps[0]), qlist, np.uint32(caps[1]), cbuf, slabs)
        cl.enqueue_copy(q, counters, cbuf, wait_for=[ev])
        return (arena, qlist, ev), [int(counters[0]), int(counters[1])]

    guess = tile_rows + 16 * nt + n  # slab tapes are short; the overflow protocol grows the rest
    (arena, qlist, ev_slabs), _ = _grown(run_slabs, [guess, guess])
    stats.update(slab_tape_mean=int(counters[3]) / (nt * SLABS), slab_quadrics_max=int(counters[4]),
                 prune_evaluations=stats["prune_evaluations"] + int(counters[2]))
    return (arena, qlist, tile_z, slabs), int(counters[4]), (ev_super, ev_tiles, ev_slabs), stats


def local_quadrics(n: int) -> int:
    """The ray kernel's private list size for slabs of up to ``n`` quadrics: a power of two
    (one kernel build per size), at least 64 (so a view that moves does not rebuild it)."""
    return max(64, 1 << max(0, int(n) - 1).bit_length())


def trace(context, tape, camera, shading: Shading | None = None, precision="auto", origin=None,
          accelerate: bool = True) -> Image:
    """Ray trace ``tape`` from ``camera`` on ``context``.  ``accelerate``: skip the quadrics whose
    culling box a ray misses (:mod:`~clcsg.rendering.ray_culling`) and prune each slab tape per
    ray (``raytrace.cl``); False only to measure what they buy (the same image either way)."""
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
    bound = _bound_args(tape, packed, real)
    cull_buf = upload(context, cull_boxes(packed, accelerate))
    t_build = time.perf_counter()
    bufs, nq_max, prune_events, prune_stats = prune_tiles(context, scene, view_buf, bound, W, H, real)
    defines = {"TAPE_REGS": packed.n_regs, "TILE": TILE, "SLABS": SLABS, "SLAB_LEVELS": SLAB_LEVELS,
               "LOCAL_QUADRICS": local_quadrics(nq_max),
               "RAY_PRUNE": int(bool(accelerate))}
    prg = build(context, "rendering/raytrace.cl", defines, real)
    t_built = time.perf_counter()
    arena, qlist, tile_z, slabs = bufs
    ev = kernel(prg, "raytrace")(q, *pixel_range(-(-W // RAY_LANES), H), scene.quadrics, arena, qlist, cull_buf,
                                 *bound, tile_z, slabs, *scene.colour_args(), view_buf, *outs)
    # kept until the finish: pyopencl waits for a dropped host transfer's event at once
    reads = [cl.enqueue_copy(q, a, b, wait_for=[ev], is_blocking=False)
             for a, b in zip((depth, ids, prims, rgba), outs)]
    q.finish()
    t_end = time.perf_counter()
    prune_s = sum(event_seconds(e) for e in prune_events)
    stats = {
        "method": "raytrace",
        "normal_form": tape.shape,
        "device": context.info.describe(),
        "precision": "double" if real == np.float64 else "float",
        "width": W,
        "height": H,
        "quadrics": tape.n_quadrics,
        "tape_instructions": int(len(packed.tape)),
        "slabs": SLABS,
        "accelerated": bool(accelerate),
        **prune_stats,
        "covered_pixels": int((ids >= 0).sum()),
        "prune_s": prune_s,
        "kernel_s": event_seconds(ev) + prune_s,
        "build_s": t_built - t_build,
        "total_s": t_end - t_start,
    }
    return Image(rgba, depth, ids, prims, stats)
