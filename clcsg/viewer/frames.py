"""Frames for the viewer: the page's orbit view as a :class:`~clcsg.Camera`, a render of a
model from it (splats or the exact ray tracer, optionally supersampled), and its encoding as
JPEG (while dragging) or PNG (at rest), plus the files the page's save buttons download.

The page describes a view by orbit parameters around a target, with z up::

    {"target": [x, y, z], "distance": d, "azimuth": deg, "elevation": deg, "fov": deg}

    eye = target + d (cos el cos az, cos el sin az, sin el)

A binary frame message is a little-endian uint32 n, n bytes of JSON header (id, size, format,
method, aa, timings) and the encoded image.
"""

from __future__ import annotations

import io
import json
import math
import struct
import time

import numpy as np

from ..cl import programs
from ..errors import UsageError
from ..rendering.camera import Camera
from ..rendering.raytracer import trace
from ..rendering.shading import Shading
from ..rendering.splat import OUTPUTS, rasterize
from ..rendering.supersample import MAX_SUBPIXELS, check_aa, supersample
from ..writers.output_files import png_bytes
from ..writers.ply import write_samples

#: the largest frame side the page may ask for
MAX_SIDE = 4096
#: elevation is kept this far from the poles (the up vector would be parallel to the view)
MAX_ELEVATION = 89.5
#: JPEG quality of the frames sent while dragging
JPEG_QUALITY = 85
#: seconds a resting frame may spend on supersampling (its aa is the largest that fits)
REST_BUDGET = 1.0
#: the resting frame's supersampling factors, tried from the largest
REST_AA = (3, 2)
#: seconds an exact ray traced frame may take: past it (predicted from the model's last warm
#: exact frame) the frame is traced at a smaller size
RAYTRACE_BUDGET = 2.0
#: a reduced exact frame keeps at least 1/MIN_SCALE of each side
MIN_SCALE = 16


def _number(view, key, lo=-math.inf, hi=math.inf) -> float:
    try:
        v = float(view[key])
    except (KeyError, TypeError, ValueError):
        got = view.get(key) if isinstance(view, dict) else view
        raise UsageError(f"view: {key} must be a number, got {got!r}") from None
    if not (math.isfinite(v) and lo <= v <= hi):
        raise UsageError(f"view: {key} must be a finite number in [{lo:g}, {hi:g}], got {v!r}")
    return v


def camera_of(view: dict, width, height) -> Camera:
    """The camera of an orbit view (see the module docstring) at ``width`` x ``height``."""
    if not isinstance(view, dict):
        raise UsageError(f"view must be an object, got {type(view).__name__}")
    w, h = _side(width, "width"), _side(height, "height")
    try:
        target = np.array([float(x) for x in view["target"]], dtype=np.float64)
    except (KeyError, TypeError, ValueError):
        raise UsageError("view: target must be 3 numbers") from None
    if target.shape != (3,) or not np.all(np.isfinite(target)):
        raise UsageError("view: target must be 3 finite numbers")
    d = _number(view, "distance", 0.0)
    if d <= 0:
        raise UsageError("view: distance must be positive")
    az = math.radians(_number(view, "azimuth"))
    el = math.radians(max(-MAX_ELEVATION, min(MAX_ELEVATION, _number(view, "elevation"))))
    fov = _number(view, "fov", 1.0, 170.0)
    eye = target + d * np.array([math.cos(el) * math.cos(az), math.cos(el) * math.sin(az), math.sin(el)])
    return Camera.look_at(eye, target, up=(0, 0, 1), fov=fov, width=w, height=h)


def _side(v, what) -> int:
    try:
        n = int(v)
    except (TypeError, ValueError):
        raise UsageError(f"{what} must be an integer, got {v!r}") from None
    if not 1 <= n <= MAX_SIDE:
        raise UsageError(f"{what} must be from 1 to {MAX_SIDE} pixels, got {n}")
    return n


def view_of(camera: Camera) -> dict:
    """The orbit view of ``camera`` (z up)."""
    rel = np.asarray(camera.eye) - np.asarray(camera.target)
    d = float(np.linalg.norm(rel))
    el = math.degrees(math.asin(max(-1.0, min(1.0, rel[2] / d))))
    return {"target": [float(x) for x in camera.target], "distance": d,
            "azimuth": math.degrees(math.atan2(rel[1], rel[0])), "elevation": el, "fov": float(camera.fov)}


def fitted_view(samples, width, height) -> dict:
    """The default view: :meth:`Camera.fit` of the samples (of the bound if there are none)."""
    subject = samples if len(samples) else samples.bound
    return view_of(Camera.fit(subject, _side(width, "width"), _side(height, "height")))


def render(context, model, camera, method: str = "splat", aa: int = 1, complete: bool = True):
    """The :class:`~clcsg.Image` of ``model`` from ``camera``: ``method`` ``"splat"`` (its
    samples, device buffers uploaded once per model) or ``"raytrace"`` (its tape).
    ``complete=False``: a frame for the page (splats: colour and ids read back, no depth or
    primitives; supersampled ids from a subpixel, no extra plain render)."""
    shading = Shading()
    if method == "splat":
        def at(cam):
            return rasterize(context, model.samples, cam, shading, stats=False,
                             read=OUTPUTS if complete else ("rgba", "ids"))
    elif method == "raytrace":
        def at(cam):
            return trace(context, model.tape.exact(), cam, shading)
    else:
        raise UsageError(f"method must be 'splat' or 'raytrace', got {method!r}")
    return supersample(at, camera, aa, shading.gamma, centre=complete)


def raytrace_camera(model, camera, budget: float = RAYTRACE_BUDGET) -> Camera:
    """``camera``, or the same view at the largest smaller size whose exact ray tracing should
    fit ``budget`` seconds, predicted from the model's last exact frame that built no program
    (its seconds per pixel); the first exact frame of a model is traced at full size."""
    rate = getattr(model, "raytrace_rate", None)
    w, h = camera.width, camera.height
    if not rate or rate * w * h <= budget:
        return camera
    scale = math.sqrt(budget / (rate * w * h))
    if scale >= 0.9:  # timing noise: not worth a smaller frame
        return camera
    return camera.resized(max(1, w // MIN_SCALE, int(w * scale)), max(1, h // MIN_SCALE, int(h * scale)))


def _exact_rest_aa(model, camera, budget: float = REST_BUDGET) -> int:
    """The supersampling of a resting exact frame: :func:`rest_aa` of its predicted plain
    time (1 while there is no prediction)."""
    rate = getattr(model, "raytrace_rate", None)
    aa = rest_aa(1e3 * rate * camera.width * camera.height, budget) if rate else 1
    return aa if camera.width * camera.height * aa * aa <= MAX_SUBPIXELS else 1


def encode(rgba: np.ndarray, fmt: str) -> bytes:
    """``"jpeg"`` (quality :data:`JPEG_QUALITY`) or ``"png"`` (fast compression) of an RGBA
    image, without its alpha channel (the background is opaque)."""
    from PIL import Image as PILImage

    im = PILImage.fromarray(np.ascontiguousarray(rgba[..., :3]))
    buf = io.BytesIO()
    if fmt == "jpeg":
        im.save(buf, format="JPEG", quality=JPEG_QUALITY)
    else:
        im.save(buf, format="PNG", compress_level=1)
    return buf.getvalue()


def frame(context, model, request: dict, aa: int = 1) -> tuple[bytes, dict]:
    """(binary frame message, its header) for a frame request of the page: ``view``,
    ``width``, ``height``, ``method``, ``quality`` (``"drag"``: JPEG, else PNG) and ``id``."""
    t0 = time.perf_counter()
    cam = camera_of(request.get("view"), request.get("width"), request.get("height"))
    method = request.get("method", "splat")
    full = (cam.width, cam.height)
    if method == "raytrace":
        cam = raytrace_camera(model, cam)
        rest = aa == 1 and request.get("quality") == "rest" and (cam.width, cam.height) == full
        img, aa = _exact(context, model, cam, aa, rest)
    else:
        img = render(context, model, cam, method, aa, complete=False)
    t1 = time.perf_counter()
    fmt = "jpeg" if request.get("quality") == "drag" else "png"
    data = encode(img.rgba, fmt)
    t2 = time.perf_counter()
    header = {"type": "frame", "id": request.get("id"), "version": model.version, "width": cam.width,
              "height": cam.height, "format": fmt, "method": method, "aa": aa, "quality": request.get("quality"),
              "reduced": (cam.width, cam.height) != full, "covered": int(img.mask.sum()),
              "render_ms": round(1e3 * (t1 - t0), 2),
              "encode_ms": round(1e3 * (t2 - t1), 2), "bytes": len(data)}
    return pack(header, data), header


def _exact(context, model, camera, aa: int, rest: bool):
    """(image, aa) of an exact frame.  ``rest``: a resting full-size frame, supersampled by
    :func:`_exact_rest_aa`; when the model has no prediction yet, its plain render is the probe
    that makes one (rendered again if it paid a one-off cost), and it is the frame unless a
    supersampled one fits."""
    img = None
    if rest and not model.raytrace_rate:
        img = _timed_trace(context, model, camera, 1)
        if not model.raytrace_rate:
            img = _timed_trace(context, model, camera, 1)
    if rest:
        aa = _exact_rest_aa(model, camera)
    if img is None or aa > 1:
        img = _timed_trace(context, model, camera, aa)
    return img, aa


def _timed_trace(context, model, camera, aa: int):
    """The exact image of ``camera`` at ``aa``; ``model.raytrace_rate`` becomes its seconds per
    traced pixel (of ``aa^2`` per pixel), unless it built a program (:func:`programs.builds`):
    that time is not the next frame's."""
    n, t0 = programs.builds(), time.perf_counter()
    img = render(context, model, camera, "raytrace", aa, complete=False)
    if programs.builds() == n:
        model.raytrace_rate = (time.perf_counter() - t0) / (camera.width * camera.height * aa * aa)
    return img


def pack(header: dict, data: bytes) -> bytes:
    """A binary frame message: uint32 header length, JSON header, image bytes."""
    h = json.dumps(header).encode()
    return struct.pack("<I", len(h)) + h + data


def unpack(message: bytes) -> tuple[dict, bytes]:
    """(header, image bytes) of a binary frame message."""
    (n,) = struct.unpack_from("<I", message)
    return json.loads(message[4:4 + n].decode()), message[4 + n:]


def rest_aa(render_ms: float, budget: float = REST_BUDGET) -> int:
    """The supersampling of a resting frame whose plain render took ``render_ms``: the largest
    of :data:`REST_AA` whose estimated time (aa^2 plain renders, plus a quarter for the
    larger buffers and the filter) fits the budget, else 1."""
    for n in REST_AA:
        if 1.25 * n * n * render_ms * 1e-3 <= budget:
            return n
    return 1


def warm_up(context, model) -> None:
    """Render a tiny splat frame of ``model``: builds the splat programs for its tape (and
    uploads its samples) before the first real frame."""
    if len(model.samples):
        cam = Camera.fit(model.samples.bound, 8, 6)
        render(context, model, cam)


def download(context, model, query, kind: str) -> tuple[bytes, str]:
    """(file contents, content type) of a save button: ``"png"`` (the view), ``"npz"`` (the
    view's rgba, depth, ids and primitives) or ``"ply"`` (the samples)."""
    if kind == "ply":
        return _ply_bytes(model.samples), "application/octet-stream"
    try:
        view = json.loads(query.get("view", ""))
    except ValueError:
        raise UsageError("view: not valid JSON") from None
    cam = camera_of(view, query.get("width"), query.get("height"))

    aa = check_aa(_side(query.get("aa", 1), "aa"), cam.width, cam.height)
    img = render(context, model, cam, query.get("method", "splat"), aa)
    if kind == "png":
        return png_bytes(img.rgba), "image/png"
    buf = io.BytesIO()
    np.savez_compressed(buf, rgba=img.rgba, depth=img.depth, ids=img.ids,
                        primitives=img.primitives if img.primitives is not None else np.full_like(img.ids, -1))
    return buf.getvalue(), "application/octet-stream"


def _ply_bytes(samples) -> bytes:
    import os
    import tempfile

    with tempfile.TemporaryDirectory(prefix="clcsg-view-") as tmp:
        path = os.path.join(tmp, "samples.ply")
        write_samples(samples, path)
        with open(path, "rb") as f:
            return f.read()
