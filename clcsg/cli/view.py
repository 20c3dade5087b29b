"""``clcsg view``: a live preview of a scene in the web browser, redrawn when the file changes."""

from __future__ import annotations

import sys

from ..errors import UsageError
from .app import SUMMARIES, add_subcommand, positive_int
from ..cl.device import get_context
from ..model.colors import ColorError, scheme_color
from ..viewer.frames import warm_up
from ..viewer.server import ViewerServer, bind
from ..viewer.session import Session, parse_radius
from .runs import Run
from .sample import parse_positive

VIEW_DESCRIPTION = """
    Sample SCENE (.json, OpenSCAD .csg or .scad) and show it in a local web page: drag to
    orbit, right-drag or shift-drag to pan, the wheel (or a pinch) to zoom.  Frames come from
    the splat renderer on --device, smaller while the view moves and supersampled when it
    rests; a checkbox shows the exact ray tracer instead.  When SCENE, or a .scad file it
    includes or uses, changes, the page shows the new model and keeps the camera; a broken
    edit shows its error in the page and the last good model stays.  The status line shows
    samples, radius, quadrics, sampling and frame times; a radius field samples again; buttons
    save the view as PNG (or with depth and quadric ids as .npz) and the samples as PLY.  The
    server listens on 127.0.0.1 only; Ctrl-C stops it.
"""

VIEW_EPILOG = """
    examples:
      clcsg view examples/rook.scad                   # opens the page in the default browser
      clcsg view part.json --port 8765 --no-browser   # then open http://127.0.0.1:8765/
      clcsg view model.csg -r 0.5 --colors openscad
"""


def add_parser(subparsers):
    p = add_subcommand(subparsers, "view", help=SUMMARIES["view"],
                       description=VIEW_DESCRIPTION, epilog=VIEW_EPILOG)
    p.add_argument("scene", metavar="SCENE", help="scene file (.json, OpenSCAD .csg or .scad)")
    p.add_argument("-r", "--radius", metavar="R", default=None,
                   help="splat radius: scene units, or a percentage of the scene bound's diagonal (default: 1%%)")
    p.add_argument("--port", metavar="N", type=int, default=0, help="TCP port on 127.0.0.1 (default: a free one)")
    p.add_argument("--no-browser", action="store_true", help="do not open the page in the web browser")
    p.add_argument("--normal-form", choices=("tree", "dnf"), default="tree",
                   help="sample the CSG tree itself (default) or the paper's disjunctive normal form")
    p.add_argument("--colors", choices=("clcsg", "openscad"), default="clcsg",
                   help="color of primitives without one: clcsg's light grey (default) or OpenSCAD's #f9d72c")
    p.add_argument("--floor", metavar="F", default=None,
                   help="the sampler's floor (clcsg sample --floor; default: min(radius / 10, 1/1000 of the "
                        "diagonal)); a larger one samples faster, with more unresolved cells along edges")
    p.add_argument("--max-samples", metavar="N", type=positive_int, default=None,
                   help="refuse radii whose sampling would pass N samples (default: 5000000)")
    p.add_argument("--force-polling", action="store_true",
                   help="watch the files by polling (for file systems without change events, such as some "
                        "network mounts)")
    return p


def _require_packages() -> None:
    missing = []
    for name in ("aiohttp", "watchfiles"):
        try:
            __import__(name)
        except ImportError:
            missing.append(name)
    if missing:
        raise UsageError(f"clcsg view needs {' and '.join(missing)}: pip install 'clcsg[view]' "
                         "(or pip install aiohttp watchfiles)")


def _logger(reporter):
    """log(kind, message): one line on the terminal (stdout for info, stderr for errors), or a
    JSON event with --progress json."""
    def log(kind: str, message: str) -> None:
        line = " ".join(str(message).split())
        if reporter.mode == "json":
            reporter.event("warning" if kind == "error" else "info", message=line)
        elif kind == "error":
            print(f"clcsg: warning: {line}", file=sys.stderr, flush=True)
        elif not reporter.quiet:
            print(f"clcsg view: {line}", flush=True)
    return log


def run(args) -> int:
    import asyncio
    import signal
    import webbrowser

    _require_packages()
    try:
        radius = parse_radius(args.radius)
    except UsageError as e:
        raise UsageError(f"--radius: {e}") from None
    floor = None
    if args.floor is not None:
        floor = parse_positive(args.floor, "--floor")
    if not 0 <= args.port <= 65535:
        raise UsageError(f"--port must be from 0 to 65535, got {args.port}")
    try:
        default_color = scheme_color(args.colors)
    except ColorError as e:
        raise UsageError(f"--colors: {e}") from None
    sock = bind(args.port)  # before the slow part: a port in use fails at once
    try:
        ctx = get_context(args.device)
        run = Run("view")
        session = Session(args.scene, ctx, radius, args.normal_form, default_color, args.max_samples, floor)
        with run.step("sample", f"loading and sampling {args.scene}"):
            model = session.load()
        with run.step("build", "building the splat renderer"):
            warm_up(ctx, model)
        log = _logger(run.reporter)
        server = ViewerServer(session, sock, log, run.reporter, force_polling=True if args.force_polling else None)
    except BaseException:
        sock.close()
        raise
    log("info", f"{len(model.samples):,} samples on {model.tape.n_quadrics} quadrics (r = {model.radius:.6g}) in "
                f"{model.times.get('total_s', 0.0):.2f} s")

    def ready():
        log("info", f"serving {args.scene} at {server.url} (Ctrl-C to stop)")
        if not args.no_browser:
            try:
                webbrowser.open(server.url)
            except Exception as e:  # no browser: the URL is printed
                log("error", f"could not open a web browser ({e}); open {server.url}")

    async def main():
        loop = asyncio.get_running_loop()
        for sig in (signal.SIGINT, signal.SIGTERM):
            try:
                loop.add_signal_handler(sig, server.stop.set)
            except (NotImplementedError, RuntimeError):  # not the main thread, or Windows
                pass
        await server.serve(ready)

    try:
        asyncio.run(main())
    finally:
        sock.close()
    run.summary(f"clcsg view: stopped after {server.frames_sent:,} frames", frames=server.frames_sent)
    return 0

