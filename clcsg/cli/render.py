"""``clcsg render``: sample and splat-render a scene (or ray trace it) to an image."""

from __future__ import annotations

from ..errors import UsageError
from ..rendering.camera import Camera
from ..rendering.raytracer import raytrace
from ..rendering.splat import render

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
    from .app import positive_int

    p.add_argument("--max-samples", metavar="N", type=positive_int, default=None,
                   help="splat method: stop with exit code 5 before sampling if the estimate passes N "
                        "samples (default: 50000000)")
    if "--device" not in getattr(p, "_option_string_actions", {}):
        p.add_argument("--device", metavar="D", default=None, help="OpenCL device ('cpu', 'gpu', 'P:D')")


def add_parser(subparsers):
    """``add_<name>_parser`` for the dispatch table of clcsg/cli.py."""
    from .app import add_subcommand

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
    from .app import parse_floats

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
    from .app import parse_floats

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


def run(args) -> int:
    """Run ``clcsg render`` (argparse namespace from :func:`add_render_arguments`)."""
    import math
    import time

    import numpy as np

    from .app import parse_floats
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
    normal_form = getattr(args, "normal_form", "tree")
    tape = scene.compile(normal_form)
    ctx = get_context(getattr(args, "device", None))
    stats = {}
    if tape.empty:
        import warnings

        from ..rendering.image import Image

        warnings.warn(f"{args.scene}: the solid is empty; the image is all background", stacklevel=2)
        w, h = size
        bg = np.round(255 * np.asarray((tuple(background) + (1.0,))[:4])).astype(np.uint8)
        img = Image(np.broadcast_to(bg, (h, w, 4)).copy(), np.full((h, w), np.inf, np.float32),
                    np.full((h, w), -1, np.int32), np.full((h, w), -1, np.int32),
                    {"method": args.method, "covered_pixels": 0, "total_seconds": 0.0})
        what = "empty solid"
    elif args.method == "raytrace":
        camera = cli_camera(args, tape.bound)
        img = raytrace(tape, camera, device=ctx, background=background)
        what = "ray traced"
    else:
        from ..sampling.sampler import sample

        camera = cli_camera(args, tape.bound)
        if radius is None:
            diag = float(np.linalg.norm(tape.bound[1] - tape.bound[0]))
            radius = diag / 100 if diag > 0 else 1.0
        t0 = time.perf_counter()
        samples = sample(scene, radius, device=ctx, progress=False, normal_form=normal_form,
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
