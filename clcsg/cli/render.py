"""``clcsg render``: sample and splat-render a scene (or ray trace it, or render saved samples)."""

from __future__ import annotations

import os
import textwrap
import warnings

import numpy as np

from ..cl.device import get_context
from ..errors import UsageError
from ..model.colors import ColorError, parse_color_text, recolor_defaults, scheme_color
from ..pipeline import Pipeline
from ..readers import scenes
from ..rendering.camera import Camera, _fov, _vec3
from ..rendering.image import Image
from ..rendering.supersample import check_aa
from ..writers.output_files import check_image_output, check_output
from ..writers.samples_npz import load_samples
from .app import SUMMARIES, UNRESOLVED_HELP, add_subcommand, parse_floats, parse_radius, positive_int
from .runs import Run

RENDER_DESCRIPTION = """
    Render a scene to an image (.png, .jpg, .webp or .tif, by the extension of OUT).  The
    default method samples the CSG surface (clcsg sample) and draws the samples as splats
    with local quadric ray tracing and clipping (paper section 6): pixel-perfect, like the
    exact ray tracer (--method raytrace), which needs no sampling.  SCENE may also be samples
    saved by `clcsg sample -o S.npz`: they are drawn as they are, without sampling again.
    Without --eye/--target the camera frames the solid in a 3/4 view from the front right and
    above: its silhouette (found by a small probe ray trace) spans 90% of the image, the same
    view for both methods.
"""

RENDER_EPILOG = """
    examples:
      clcsg render examples/bracket.json -o bracket.png
      clcsg render part.json -o part.webp -r 0.05 --size 1280x960 --eye 4,-5,3 --target 0,0,0
      clcsg render part.json -o ref.png --method raytrace --depth ref_depth.npy --ids ref_ids.npy
      clcsg render model.csg -o model.png --colors openscad --background '#ffffe5'
      clcsg render part.json -o part.png --transparent
      clcsg render part.json -o smooth.png --aa 3          # 3 x 3 supersampling
      clcsg sample part.json -r 0.02 -o part.npz && clcsg render part.npz -o part.png
"""

SAMPLE_FILES = (".npz", ".ply")


def add_render_arguments(parser) -> None:
    """Add the ``clcsg render`` arguments to an argparse parser.  ``--device`` is added only
    if the parser does not have it yet (``cli.add_subcommand`` adds it)."""
    p = parser
    p.add_argument("scene", metavar="SCENE",
                   help="scene file (.json, OpenSCAD .csg or .scad) or samples saved as .npz by clcsg sample")
    p.add_argument("-o", "--output", metavar="OUT.png", required=True,
                   help="image file to write: .png, .jpg/.jpeg (no alpha), .webp (lossless) or .tif/.tiff")
    p.add_argument("-r", "--radius", metavar="R", default=None,
                   help="splat radius: scene units, or a percentage of the scene bound's diagonal (default: 1%%)")
    p.add_argument("--method", choices=("splat", "raytrace"), default="splat",
                   help="splat (sample, then render splats; default) or raytrace (exact ray tracing)")
    p.add_argument("--normal-form", choices=("tree", "dnf"), default="tree",
                   help="the CSG tree itself (default) or the paper's disjunctive normal form (same image)")
    p.add_argument("--size", metavar="WxH", default="640x480", help="image size in pixels (default 640x480)")
    p.add_argument("--eye", metavar="X,Y,Z", default=None, help="camera position (default: fitted)")
    p.add_argument("--target", metavar="X,Y,Z", default=None,
                   help="point the camera looks at (default: the center of the scene bound)")
    p.add_argument("--up", metavar="X,Y,Z", default="0,0,1", help="up direction (default 0,0,1)")
    p.add_argument("--fov", metavar="DEG", default="45", help="vertical field of view in degrees (default 45)")
    p.add_argument("--background", metavar="COLOR", default="1,1,1",
                   help="background: R,G,B[,A] in [0, 1] (or 0-255 if any is above 1), a color name (white) or "
                        "#rrggbb[aa]; default white")
    p.add_argument("--transparent", action="store_true",
                   help="transparent background (alpha 0; formats without alpha show the background color)")
    p.add_argument("--colors", choices=("clcsg", "openscad"), default="clcsg",
                   help="color of primitives without one: clcsg's light grey (default) or OpenSCAD's default "
                        "face color #f9d72c (its Cornfield scheme)")
    p.add_argument("--depth", metavar="DEPTH.npy", default=None,
                   help="write the depth (distance along the view ray, inf on background) as float32 .npy")
    p.add_argument("--ids", metavar="IDS.npy", default=None,
                   help="write the visible quadric index per pixel (-1 on background) as int32 .npy")
    p.add_argument("--stats", metavar="S.json", default=None, help="write render (and sampling) statistics as JSON")
    p.add_argument("--aa", metavar="N", type=positive_int, default=1,
                   help="N x N supersampling: smooth edges, colours averaged in linear light; depth and ids stay "
                        "those of the pixel centre (default 1: off; at most 8)")
    p.add_argument("--no-surface-aligned", action="store_true",
                   help="splat bounds from the whole ball instead of the surface-aligned slab")
    p.add_argument("--no-backface-culling", action="store_true", help="do not cull back-facing splats")
    p.add_argument("--max-samples", metavar="N", type=positive_int, default=None,
                   help="splat method: stop with exit code 5 before sampling if the estimate passes N "
                        "samples (default: 50000000)")
    if "--device" not in getattr(p, "_option_string_actions", {}):
        p.add_argument("--device", metavar="D", default=None, help="OpenCL device ('cpu', 'gpu', 'P:D')")


def add_parser(subparsers):
    """``add_<name>_parser`` for the dispatch table of clcsg/cli.py."""
    p = add_subcommand(subparsers, "render", help=SUMMARIES["render"],
                       description=RENDER_DESCRIPTION,
                       epilog=textwrap.dedent(RENDER_EPILOG) + textwrap.dedent(UNRESOLVED_HELP))
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
    """``"R,G,B[,A]"`` (components in [0, 1], or 0-255 if any is above 1), a color name or
    ``#hex`` (:func:`clcsg.model.colors.parse_color_text`)."""
    try:
        return parse_color_text(text, allow_255=True)
    except ColorError as e:
        raise UsageError(f"--background: {e}") from None


def view_options(args) -> dict:
    """The camera options (--size, --fov, --up, --eye, --target), parsed and checked."""
    w, h = parse_size(args.size)
    (fov,) = parse_floats(args.fov, 1, "--fov")
    _fov(fov)
    up = parse_floats(args.up, 3, "--up")
    if not any(up):
        raise UsageError("--up must be a non-zero vector")
    eye = None if args.eye is None else _vec3(parse_floats(args.eye, 3, "--eye"), "--eye")
    target = None if args.target is None else _vec3(parse_floats(args.target, 3, "--target"), "--target")
    if eye is not None and target is not None and np.array_equal(eye, target):
        raise UsageError(f"--eye and --target: eye and target must differ, both are {eye.tolist()}")
    return {"w": w, "h": h, "fov": fov, "up": up, "eye": eye, "target": target}


def cli_camera(args, bound, fit=None) -> Camera:
    """The camera of ``clcsg render``'s options: ``fit(w, h, fov, up)`` (default: fitted to
    ``bound``) unless --eye/--target; --target alone keeps the fitted view direction and
    distance, --eye alone looks at the center of ``bound``."""
    v = view_options(args)
    w, h, fov, up = v["w"], v["h"], v["fov"], v["up"]
    if fit is None:
        def fit(w, h, fov, up):
            return Camera.fit(bound, w, h, fov=fov, up=up)
    center = 0.5 * (np.asarray(bound[0]) + np.asarray(bound[1]))
    if v["eye"] is None and v["target"] is None:
        return fit(w, h, fov, up)
    target = center if v["target"] is None else v["target"]
    if v["eye"] is None:
        fitted = fit(w, h, fov, up)
        eye = np.asarray(target) + (fitted.eye - fitted.target)
    else:
        eye = v["eye"]
    return Camera.look_at(eye, target, up=up, fov=fov, width=w, height=h)


def _check_outputs(args) -> None:
    """Every output path, before any work."""
    check_image_output(args.output)
    for option, path, ext, what in (("--depth", args.depth, ".npy", "depth"), ("--ids", args.ids, ".npy", "ids"),
                                    ("--stats", args.stats, ".json", "statistics")):
        if path:
            check_output(path, ext, what, option)


def _saved_samples(args, run):
    """The samples of a ``.npz`` SCENE (None for a scene file)."""
    ext = os.path.splitext(str(args.scene))[1].lower()
    if ext not in SAMPLE_FILES:
        return None
    if ext == ".ply":
        raise UsageError(f"{args.scene}: a PLY point cloud has no CSG tape to clip the splats with; "
                         "save samples for rendering as .npz (clcsg sample -o samples.npz)")
    if args.method == "raytrace":
        raise UsageError(f"--method raytrace needs a scene file (.json, .csg, .scad), not saved samples ({args.scene})")
    if args.radius is not None:
        raise UsageError(f"--radius does not apply to saved samples ({args.scene}): they keep the radius they "
                         "were sampled with")

    with run.step("load", f"loading {args.scene}"):
        return load_samples(args.scene)


def _empty_image(size, background, method):
    w, h = size
    bg = np.round(255 * np.asarray(background[:4])).astype(np.uint8)
    return Image(np.broadcast_to(bg, (h, w, 4)).copy(), np.full((h, w), np.inf, np.float32),
                 np.full((h, w), -1, np.int32), np.full((h, w), -1, np.int32),
                 {"method": method, "covered_pixels": 0, "total_s": 0.0})


def _render_options(args) -> dict:
    """The checked image options: size, background, aa and the default colour."""
    background = parse_background(args.background)
    if args.transparent:
        background = background[:3] + (0.0,)
        if os.path.splitext(args.output)[1].lower() in (".jpg", ".jpeg"):
            warnings.warn(f"{args.output}: JPEG has no alpha channel: the background is {background[:3]}, "
                          "not transparent", stacklevel=3)
    view = view_options(args)
    size = (view["w"], view["h"])
    aa = check_aa(getattr(args, "aa", 1), *size)
    try:
        default_color = scheme_color(getattr(args, "colors", "clcsg"))
    except ColorError as e:
        raise UsageError(f"--colors: {e}") from None
    return {"size": size, "background": background, "aa": aa, "default_color": default_color}


def _raytraced(args, run, pipe, opts):
    recolor_defaults(pipe.tape, opts["default_color"])
    with run.step("frame", "framing the view (probe ray trace)"):
        camera = cli_camera(args, pipe.tape.bound, lambda w, h, fov, up: pipe.camera(w, h, fov, up))
    with run.step("render", f"ray tracing {camera.width}x{camera.height}"):
        img = pipe.image(camera, method="raytrace", background=opts["background"], aa=opts["aa"])
    return img, "ray traced"


def _splatted(args, run, pipe, samples, radius, opts):
    """Splats of ``samples`` (sampled here at ``radius`` when None)."""
    stats = {}
    if samples is None:
        with run.step("sample", "sampling: building the OpenCL program"):
            samples = pipe.samples(radius, progress=None, max_samples=getattr(args, "max_samples", None))
        stats["sampling"] = dict(samples.stats)
    if opts["default_color"] is not None:
        samples.with_default_color(opts["default_color"])
    with run.step("frame", "framing the view (probe ray trace)"):
        camera = cli_camera(args, samples.bound, lambda w, h, fov, up: pipe.camera(w, h, fov, up, tape=samples.tape))
    with run.step("render", f"rendering {len(samples):,} splats at {camera.width}x{camera.height}"):
        img = pipe.image(camera, samples, surface_aligned=not args.no_surface_aligned,
                         backface_culling=not args.no_backface_culling, background=opts["background"], aa=opts["aa"])
    img.stats.update(stats)
    return img, f"{len(samples):,} splats (r = {samples.radius:.6g})", samples


def run(args) -> int:
    """Run ``clcsg render`` (argparse namespace from :func:`add_render_arguments`)."""
    _check_outputs(args)  # before any work: an unknown extension fails at once
    opts = _render_options(args)
    radius = None if args.radius is None else parse_radius(args.radius)
    run = Run("render")
    samples = _saved_samples(args, run)
    pipe = Pipeline(None, normal_form=getattr(args, "normal_form", "tree"))
    if samples is None:
        with run.step("load", f"loading {args.scene}"):
            pipe.scene = scenes.load(args.scene)
        with run.step("compile", "compiling the scene"):
            tape = pipe.tape
    else:
        tape = samples.tape
    pipe.device = get_context(getattr(args, "device", None))
    if tape.empty:
        warnings.warn(f"{args.scene}: the solid is empty; the image is all background", stacklevel=2)
        img, what = _empty_image(opts["size"], opts["background"], args.method), "empty solid"
    elif args.method == "raytrace":
        img, what = _raytraced(args, run, pipe, opts)
    else:
        img, what, samples = _splatted(args, run, pipe, samples, radius, opts)
    with run.step("write", f"writing {args.output}"):
        for path, save in ((args.output, img.save), (args.depth, img.save_depth), (args.ids, img.save_ids),
                           (args.stats, img.save_stats)):
            if path:
                save(path)
                run.wrote(path)
    covered = int(img.stats.get("covered_pixels", 0))
    size = opts["size"]
    run.summary(f"{what}: {size[0]}x{size[1]}, {covered:,} surface pixels", method=args.method,
                covered_pixels=covered, samples=None if samples is None else len(samples))
    return 0
