"""Rendering entry points: the exact ray tracer and the splat renderer (paper section 6).

    img = clcsg.raytrace(shape, camera)              # exact global CSG ray tracing
    img = clcsg.render(clcsg.sample(shape, r), camera)   # splats with local ray tracing + clipping
    img.save("out.png"); img.depth; img.ids; img.stats

Both return a :class:`~clcsg.image.Image` and shade with the same code (kernels/shade.h), so
for the same hit they produce the same pixel.
"""

from __future__ import annotations

from .camera import Camera
from ..errors import UsageError
from .image import Image


def as_dnf(obj):
    """A :class:`~clcsg.host.dnf.Dnf` from a Dnf, Samples, Scene, Shape or scene file path."""
    from ..compile.dnf import Dnf
    from ..model.scene import as_scene

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
    from .raytracer import Shading, context_of, trace

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
    from .raytracer import Shading, context_of
    from .splat import rasterize

    if not hasattr(samples, "device_buffers"):
        raise UsageError(f"render needs Samples (see clcsg.sample), got {type(samples).__name__}")
    cam = _camera(camera, samples.dnf.bound)
    shade = Shading().with_options(background=background, **shading)
    return rasterize(context_of(device), samples, cam, shade, precision, surface_aligned,
                     backface_culling, stats)


# -- command line: `clcsg render` ------------------------------------------------------------------

RENDER_DESCRIPTION = """
    Render a scene to PNG.  The default method samples the CSG surface (clcsg sample) and draws
    the samples as splats with local quadric ray tracing and clipping (paper section 6):
    pixel-perfect, like the exact ray tracer (--method raytrace), which needs no sampling.
    Without --eye/--target the camera fits the scene's bounding sphere in a 3/4 view.
"""

RENDER_EPILOG = """
    examples:
      clcsg render examples/bracket.json -o bracket.png
      clcsg render part.json -o part.png -r 0.05 --size 1280x960 --eye 4,-5,3 --target 0,0,0
      clcsg render part.json -o ref.png --method raytrace --depth ref_depth.npy --ids ref_ids.npy
"""


def add_render_arguments(parser) -> None:
    """Add the ``clcsg render`` arguments to an argparse parser.  ``--device`` is added only
    if the parser does not have it yet (``cli.add_subcommand`` adds it)."""
    p = parser
    p.add_argument("scene", metavar="SCENE", help="scene file (.json or OpenSCAD .csg)")
    p.add_argument("-o", "--output", metavar="OUT.png", required=True, help="image file to write (PNG)")
    p.add_argument("-r", "--radius", metavar="R", default=None,
                   help="splat radius in scene units (default: 1/100 of the scene bound's diagonal)")
    p.add_argument("--method", choices=("splat", "raytrace"), default="splat",
                   help="splat (sample, then render splats; default) or raytrace (exact ray tracing)")
    p.add_argument("--size", metavar="WxH", default="640x480", help="image size in pixels (default 640x480)")
    p.add_argument("--eye", metavar="X,Y,Z", default=None, help="camera position (default: fitted)")
    p.add_argument("--target", metavar="X,Y,Z", default=None,
                   help="point the camera looks at (default: the center of the scene bound)")
    p.add_argument("--up", metavar="X,Y,Z", default="0,0,1", help="up direction (default 0,0,1)")
    p.add_argument("--fov", metavar="DEG", default="45", help="vertical field of view in degrees (default 45)")
    p.add_argument("--background", metavar="R,G,B[,A]", default="1,1,1",
                   help="background color, components in [0, 1] (or 0-255 if any is above 1); default white")
    p.add_argument("--depth", metavar="DEPTH.npy", default=None,
                   help="write the depth (distance along the view ray, inf on background) as float32 .npy")
    p.add_argument("--ids", metavar="IDS.npy", default=None,
                   help="write the visible quadric index per pixel (-1 on background) as int32 .npy")
    p.add_argument("--stats", metavar="S.json", default=None, help="write render (and sampling) statistics as JSON")
    p.add_argument("--no-surface-aligned", action="store_true",
                   help="splat bounds from the whole ball instead of the surface-aligned slab")
    p.add_argument("--no-backface-culling", action="store_true", help="do not cull back-facing splats")
    from ..cli.app import positive_int

    p.add_argument("--max-samples", metavar="N", type=positive_int, default=None,
                   help="splat method: stop with exit code 5 before sampling if the estimate passes N "
                        "samples (default: 50000000)")
    if "--device" not in getattr(p, "_option_string_actions", {}):
        p.add_argument("--device", metavar="D", default=None, help="OpenCL device ('cpu', 'gpu', 'P:D')")


def add_render_parser(subparsers):
    """``add_<name>_parser`` for the dispatch table of clcsg/cli.py."""
    from ..cli.app import add_subcommand

    p = add_subcommand(subparsers, "render", help="render a scene to PNG (splats or exact ray tracing)",
                       description=RENDER_DESCRIPTION, epilog=RENDER_EPILOG)
    add_render_arguments(p)
    return p


def parse_size(text) -> tuple[int, int]:
    """``"640x480"`` -> (640, 480)."""
    parts = str(text).lower().replace("*", "x").split("x")
    try:
        w, h = (int(v) for v in parts)
    except ValueError:
        raise UsageError(f"--size: expected WIDTHxHEIGHT such as 640x480, got {text!r}") from None
    if w <= 0 or h <= 0:
        raise UsageError(f"--size: width and height must be positive, got {text!r}")
    if w * h > 1 << 26:
        raise UsageError(f"--size: {w}x{h} is too large (at most 2^26 pixels)")
    return w, h


def parse_background(text) -> tuple[float, ...]:
    """``"R,G,B[,A]"``: components in [0, 1], or 0-255 if any is above 1."""
    from ..cli.app import parse_floats

    parts = str(text).replace(",", " ").split()
    if len(parts) not in (3, 4):
        raise UsageError(f"--background: expected R,G,B or R,G,B,A, got {text!r}")
    v = parse_floats(text, len(parts), "--background")
    if any(x > 1.0 for x in v):
        v = tuple(x / 255.0 for x in v)
    if not all(0.0 <= x <= 1.0 for x in v):
        raise UsageError(f"--background: components must be in [0, 1] (or 0-255), got {text!r}")
    return v


def cli_camera(args, bound) -> Camera:
    """The camera of ``clcsg render``'s options: fitted to ``bound`` unless --eye/--target."""
    from ..cli.app import parse_floats

    w, h = parse_size(args.size)
    (fov,) = parse_floats(args.fov, 1, "--fov")
    up = parse_floats(args.up, 3, "--up")
    center = 0.5 * (bound[0] + bound[1])
    if args.eye is None and args.target is None:
        return Camera.fit(bound, w, h, fov=fov, up=up)
    target = center if args.target is None else parse_floats(args.target, 3, "--target")
    if args.eye is None:
        fitted = Camera.fit(bound, w, h, fov=fov, up=up)
        import numpy as np

        eye = np.asarray(target) + (fitted.eye - fitted.target)
    else:
        eye = parse_floats(args.eye, 3, "--eye")
    return Camera.look_at(eye, target, up=up, fov=fov, width=w, height=h)


def cli_render(args) -> int:
    """Run ``clcsg render`` (argparse namespace from :func:`add_render_arguments`)."""
    import math
    import time

    import numpy as np

    from ..cli.app import parse_floats
    from ..cl.device import get_context
    from ..model.scene import load

    background = parse_background(args.background)
    size = parse_size(args.size)
    radius = None
    if args.radius is not None:
        (radius,) = parse_floats(args.radius, 1, "--radius")
        if radius <= 0:
            raise UsageError(f"--radius must be positive, got {args.radius}")
    scene = load(args.scene)
    dnf = scene.normalize()
    ctx = get_context(getattr(args, "device", None))
    stats = {}
    if not dnf.n_terms:
        import warnings

        from .image import Image

        warnings.warn(f"{args.scene}: the solid is empty; the image is all background", stacklevel=2)
        w, h = size
        bg = np.round(255 * np.asarray((tuple(background) + (1.0,))[:4])).astype(np.uint8)
        img = Image(np.broadcast_to(bg, (h, w, 4)).copy(), np.full((h, w), np.inf, np.float32),
                    np.full((h, w), -1, np.int32), {"method": args.method, "covered_pixels": 0,
                                                   "total_seconds": 0.0})
        what = "empty solid"
    elif args.method == "raytrace":
        camera = cli_camera(args, dnf.bound)
        img = raytrace(dnf, camera, device=ctx, background=background)
        what = "ray traced"
    else:
        from ..sampling.sampler import sample

        camera = cli_camera(args, dnf.bound)
        if radius is None:
            diag = float(np.linalg.norm(dnf.bound[1] - dnf.bound[0]))
            radius = diag / 100 if diag > 0 else 1.0
        t0 = time.perf_counter()
        samples = sample(scene, radius, device=ctx, progress=False,
                         max_samples=getattr(args, "max_samples", None))
        t_sample = time.perf_counter() - t0
        stats["sampling"] = dict(samples.stats)
        img = render(samples, camera, device=ctx, background=background,
                     surface_aligned=not args.no_surface_aligned,
                     backface_culling=not args.no_backface_culling)
        what = f"{len(samples)} splats (r = {radius:.6g}, sampled in {t_sample:.3f} s)"
    img.stats.update(stats)
    img.save(args.output)
    if args.depth:
        img.save_depth(args.depth)
    if args.ids:
        img.save_ids(args.ids)
    if args.stats:
        img.save_stats(args.stats)
    st = img.stats
    secs = st.get("kernel_seconds", float("nan"))
    ms = f"{1e3 * secs:.1f} ms on the device" if math.isfinite(secs) else f"{st['total_seconds']:.3f} s"
    print(f"{what}: {size[0]}x{size[1]}, {st['covered_pixels']} surface pixels, {ms} -> {args.output}")
    return 0
