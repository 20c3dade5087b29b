"""Host side of the exact ray tracer (``kernels/raytrace.cl``) and of the view record and
shading options it shares with the splat renderer (``kernels/shade.h``).

:func:`trace` renders a :class:`~clcsg.host.dnf.Dnf` with one work-item per pixel: per DNF
term all roots of the term's quadrics along the pixel's ray, the first root at which every
other literal of the term holds, the nearest over terms.  The public entry point is
:func:`clcsg.render.raytrace`.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, replace

import numpy as np

from ..errors import DeviceError, UsageError


# -- the view record (kernels/shade.h) ------------------------------------------------------------


def view_dtype(real) -> np.dtype:
    """numpy mirror of ``view_rec`` in kernels/shade.h (C natural alignment)."""
    return np.dtype(
        [
            ("eye", real, 3),
            ("d00", real, 3),
            ("dx", real, 3),
            ("dy", real, 3),
            ("forward", real, 3),
            ("right", real, 3),
            ("up", real, 3),
            ("focal", real),
            ("width", np.int32),
            ("height", np.int32),
            ("background", np.float32, 4),
            ("key", np.float32, 3),
            ("ambient", np.float32),
            ("diffuse", np.float32),
            ("specular", np.float32),
            ("shininess", np.float32),
            ("gamma", np.float32),
        ],
        align=True,
    )


def parse_color(c, what="background") -> tuple[float, float, float, float]:
    """RGBA in [0, 1] from 3 or 4 numbers in [0, 1] (alpha defaults to 1)."""
    try:
        v = [float(x) for x in c]
    except (TypeError, ValueError):
        raise UsageError(f"{what} must be 3 or 4 numbers in [0, 1], got {c!r}") from None
    if len(v) == 3:
        v.append(1.0)
    if len(v) != 4 or not all(math.isfinite(x) and 0.0 <= x <= 1.0 for x in v):
        raise UsageError(f"{what} must be 3 or 4 numbers in [0, 1], got {list(c)}")
    return tuple(v)


@dataclass(frozen=True)
class Shading:
    """Blinn-Phong shading shared by both renderers (kernels/shade.h).

    Two white lights: a headlight at the eye and a key light whose direction is given in the
    camera frame as weights of (right, up, backward = -forward).  Quadric colors are taken as
    display values, linearized with ``gamma``, lit, and encoded again with 1 / ``gamma``.
    ``background`` (RGBA in [0, 1]) is written unlit.
    """

    background: tuple = (1.0, 1.0, 1.0, 1.0)
    ambient: float = 0.12
    diffuse: float = 0.85
    specular: float = 0.25
    shininess: float = 40.0
    gamma: float = 2.2
    key: tuple = (-0.4, 0.6, 0.7)

    def with_options(self, **kw) -> "Shading":
        unknown = set(kw) - set(self.__dataclass_fields__)
        if unknown:
            raise UsageError(f"unknown shading option {sorted(unknown)[0]!r}; known: {', '.join(self.__dataclass_fields__)}")
        if "background" in kw and kw["background"] is not None:
            kw["background"] = parse_color(kw["background"])
        kw = {k: v for k, v in kw.items() if v is not None}
        s = replace(self, **kw)
        for name in ("ambient", "diffuse", "specular", "shininess", "gamma"):
            v = float(getattr(s, name))
            if not (math.isfinite(v) and v >= 0) or (name == "gamma" and v == 0):
                raise UsageError(f"shading option {name} must be a non-negative number, got {getattr(s, name)}")
        return s


def pack_view(camera, origin, real, shading: Shading | None = None) -> np.ndarray:
    """The ``view_rec`` of ``camera`` in device coordinates (eye - origin), one element."""
    shading = shading or Shading()
    rec = np.zeros(1, dtype=view_dtype(real))
    d00, dx, dy = camera.pixel_basis()
    rec["eye"] = np.asarray(camera.eye, dtype=np.float64) - np.asarray(origin, dtype=np.float64)
    rec["d00"] = d00
    rec["dx"] = dx
    rec["dy"] = dy
    rec["forward"] = camera.forward
    rec["right"] = camera.right
    rec["up"] = camera.up
    rec["focal"] = camera.focal
    rec["width"] = camera.width
    rec["height"] = camera.height
    rec["background"] = parse_color(shading.background)
    kr, ku, kb = shading.key
    key = kr * camera.right + ku * camera.up - kb * camera.forward
    rec["key"] = key / np.linalg.norm(key)
    for name in ("ambient", "diffuse", "specular", "shininess", "gamma"):
        rec[name] = getattr(shading, name)
    return rec


# -- device and precision -------------------------------------------------------------------------


def context_of(device):
    """A clcsg Context from None / a device spec string / a Context."""
    from ..cl.device import get_context

    if device is None or isinstance(device, str):
        return get_context(device)
    if hasattr(device, "ctx") and hasattr(device, "queue"):
        return device
    raise UsageError(f"device must be a device spec string or a clcsg Context, got {type(device).__name__}")


def choose_real(context, precision="auto"):
    """numpy float type for the kernels: 'auto' (double where the device has fp64, unless
    CLCSG_PRECISION=float forces float32; see device.real_dtype), 'double', 'float'."""
    from ..cl.device import real_dtype

    if precision in (None, "auto"):
        return np.dtype(real_dtype(context))
    if precision in ("double", "float64", np.float64):
        if not context.info.fp64:
            raise DeviceError(f"device {context.info.describe()} has no fp64 (cl_khr_fp64); use precision='float'")
        return np.dtype(np.float64)
    if precision in ("float", "float32", np.float32):
        return np.dtype(np.float32)
    raise UsageError(f"precision must be 'auto', 'double' or 'float', got {precision!r}")


_kernels: dict = {}


def kernel(prg, name: str):
    """The kernel ``name`` of a built program, retrieved once per program."""
    import pyopencl as cl

    key = (id(prg), name)
    k = _kernels.get(key)
    if k is None or k[0] is not prg:
        k = _kernels[key] = (prg, cl.Kernel(prg, name))
    return k[1]


def event_seconds(ev) -> float:
    try:
        return (ev.profile.end - ev.profile.start) * 1e-9
    except Exception:  # queue without profiling
        return float("nan")


# -- the ray tracer ------------------------------------------------------------------------------


def trace(context, dnf, camera, shading: Shading | None = None, precision="auto", origin=None):
    """Ray trace ``dnf`` from ``camera`` on ``context``; returns a :class:`clcsg.image.Image`."""
    import pyopencl as cl

    from .image import Image
    from ..cl import programs
    from ..cl.records import SceneBuffers, pack

    t_start = time.perf_counter()
    real = choose_real(context, precision)
    packed = pack(dnf, real=real, origin=origin)
    scene = SceneBuffers(context, packed)
    W, H = camera.width, camera.height
    view = pack_view(camera, packed.origin, real, shading)
    mf = cl.mem_flags
    view_buf = cl.Buffer(context.ctx, mf.READ_ONLY | mf.COPY_HOST_PTR, hostbuf=view)
    depth = np.empty((H, W), dtype=np.float32)
    ids = np.empty((H, W), dtype=np.int32)
    rgba = np.empty((H, W, 4), dtype=np.uint8)
    d_buf = cl.Buffer(context.ctx, mf.WRITE_ONLY, depth.nbytes)
    i_buf = cl.Buffer(context.ctx, mf.WRITE_ONLY, ids.nbytes)
    c_buf = cl.Buffer(context.ctx, mf.WRITE_ONLY, rgba.nbytes)
    t_build = time.perf_counter()
    prg = programs.build(context, "rendering/raytrace.cl", real=real)
    t_built = time.perf_counter()
    diag = float(np.linalg.norm(dnf.bound[1] - dnf.bound[0])) if dnf.n_terms else 1.0
    pad = real.type(1e-6 * diag + 1e-30)
    knl = kernel(prg, "raytrace")
    q = context.queue
    ev = knl(q, (W, H), None, scene.quadrics, scene.literals, scene.terms, np.int32(scene.n_terms), pad,
             view_buf, d_buf, i_buf, c_buf)
    cl.enqueue_copy(q, depth, d_buf, wait_for=[ev])
    cl.enqueue_copy(q, ids, i_buf, wait_for=[ev])
    cl.enqueue_copy(q, rgba, c_buf, wait_for=[ev])
    q.finish()
    t_end = time.perf_counter()
    stats = {
        "method": "raytrace",
        "device": context.info.describe(),
        "precision": "double" if real == np.float64 else "float",
        "width": W,
        "height": H,
        "terms": dnf.n_terms,
        "quadrics": dnf.n_quadrics,
        "covered_pixels": int((ids >= 0).sum()),
        "kernel_seconds": event_seconds(ev),
        "build_seconds": t_built - t_build,
        "total_seconds": t_end - t_start,
    }
    return Image(rgba, depth, ids, stats)
