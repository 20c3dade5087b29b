"""Rendering entry points: the exact ray tracer and the splat renderer (paper section 6).

    img = clcsg.raytrace(shape, camera)              # exact global CSG ray tracing
    img = clcsg.render(clcsg.sample(shape, r), camera)   # splats with local ray tracing + clipping
    img.save("out.png"); img.depth; img.ids; img.stats

Both return a :class:`~clcsg.image.Image` and shade with the same code (kernels/shade.h), so
for the same hit they produce the same pixel.
"""

from __future__ import annotations

from .camera import Camera
from .errors import UsageError
from .image import Image


def as_dnf(obj):
    """A :class:`~clcsg.host.dnf.Dnf` from a Dnf, Samples, Scene, Shape or scene file path."""
    from .host.dnf import Dnf
    from .scene import as_scene

    if isinstance(obj, Dnf):
        return obj
    dnf = getattr(obj, "dnf", None)
    if isinstance(dnf, Dnf):
        return dnf
    return as_scene(obj).normalize()


def _camera(camera, bound) -> Camera:
    if camera is None:
        return Camera.fit(bound)
    if not isinstance(camera, Camera):
        raise UsageError(f"camera must be a clcsg.camera.Camera, got {type(camera).__name__}")
    return camera


def raytrace(scene, camera: Camera | None = None, device=None, background=(1.0, 1.0, 1.0),
             precision: str = "auto", **shading) -> Image:
    """Exact global ray tracing of a CSG scene (reference renderer).

    ``scene``: a Shape, Scene, scene file path, Dnf or Samples (its scene is traced).
    ``camera``: a :class:`~clcsg.camera.Camera` (default: :meth:`Camera.fit` to the scene
    bound at 640x480).  ``device``: None (default device), a spec string (``"cpu"``, ``"0:1"``)
    or a Context.  ``background``: RGBA/RGB in [0, 1].  ``precision``: ``"auto"`` (double where
    the device has fp64), ``"double"`` or ``"float"``.  Further keywords are
    :class:`~clcsg.host.raytracer.Shading` options (ambient, diffuse, specular, shininess,
    gamma, key).

    Per pixel, per DNF term: all roots of the term's quadrics along the ray (eqs. 5, 6), the
    first root at which every other literal of the term holds, the nearest over terms.
    """
    from .host.raytracer import Shading, context_of, trace

    dnf = as_dnf(scene)
    cam = _camera(camera, dnf.bound)
    shade = Shading().with_options(background=background, **shading)
    return trace(context_of(device), dnf, cam, shade, precision)


def render(samples, camera: Camera | None = None, device=None, background=(1.0, 1.0, 1.0),
           precision: str = "auto", surface_aligned: bool = True, backface_culling: bool = True,
           stats: bool = True, **shading) -> Image:
    """Pixel-perfect splat rendering of :class:`~clcsg.samples.Samples` (paper section 6).

    Per sample, one work-item loops over the screen bound of its splat; per pixel it solves
    the view ray against the sample's quadric near the sample (eqs. 5, 6), keeps the hit if it
    lies within the sample's radius and inside every literal of its clip set, and depth-tests
    it with a 64-bit ``atom_min``; a resolve pass recomputes the winning hit and shades it like
    :func:`raytrace`.

    ``surface_aligned``: bound each splat by a box aligned with its normal whose height comes
    from the eigenvalue bound of the patch (paper section 6.1) instead of the whole ball.
    ``backface_culling``: skip splats and fragments that face away from the eye (only valid
    from outside; turned off automatically when the eye is inside the solid).  ``stats``:
    count fragments, clip evaluations, ... with atomic counters (``Image.stats``; off is a
    little faster).  Other arguments as in :func:`raytrace`.  Requires 64-bit atomics
    (``cl_khr_int64_extended_atomics``), else :class:`~clcsg.errors.DeviceError`.
    """
    from .host.raytracer import Shading, context_of
    from .host.splat import rasterize

    if not hasattr(samples, "device_buffers"):
        raise UsageError(f"render needs Samples (see clcsg.sample), got {type(samples).__name__}")
    cam = _camera(camera, samples.dnf.bound)
    shade = Shading().with_options(background=background, **shading)
    return rasterize(context_of(device), samples, cam, shade, precision, surface_aligned,
                     backface_culling, stats)
